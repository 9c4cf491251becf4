"""Training data of `volsmpl train`: the batch of step s on rank r (make_batch: random bodies, query points,
exact signed distances), depending only on (seed, s, r), and the stream of batches of a run (batch_stream),
made in the training process or ahead of it by DataLoader worker processes (StepBatches).

Device: a batch is made where the body is: LBS, the part frames and boxes, the query sampling (a generator on
that device) and the ground truth (`groundtruth.batch_sdf`, `TrainConfig.gt_backend`: 'auto' is the torch
backend off the CPU) all stay there; only the body parameters are drawn on the CPU (numpy: a few hundred
numbers) and moved once. So a batch is deterministic for a seed on each device type (the CPU and CUDA random
streams differ). `batch_stream(..., device='cuda')` makes the batches on the GPU in the training process.
Every batch carries `timing`: seconds spent making it ('make_s') and in the ground truth alone ('gt_s').
"""
from __future__ import annotations

import copy
import json
import time
from pathlib import Path

import torch

from volsmpl.body.poses import sample_poses
from volsmpl.body.shapes import sample_betas
from volsmpl.body.contact_regions import contact_vertices
from volsmpl.geometry.groundtruth import batch_sdf
from volsmpl.train.config import TrainConfig
from volsmpl.train.queries import sample_contact_points, sample_training_queries


def _sync(device: torch.device) -> None:
    """Wait for the device's queued work, so that wall-clock times are the device's (no-op on the CPU)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def make_batch(cfg: TrainConfig, body, partition, step: int, rank: int = 0) -> dict:
    """The training batch of (step, rank), on the body's device: body parameters, the posed bodies, query points,
    exact SDF, timing {'make_s', 'gt_s'} (seconds, the device synchronised).

    Shape: -> points (B, N, 3), sdf (B, N), posed vertices (B, V, 3), joints (B, J, 3), full_pose (B, 3J).
    """
    dev = body.v_template.device
    _sync(dev)
    t0 = time.perf_counter()
    seed = (cfg.seed * 1_000_003 + step) * 131 + rank
    g = torch.Generator(device=dev).manual_seed(seed)
    B = cfg.batch_size
    params = {
        "betas": sample_betas(B, num_betas=body.num_betas, seed=seed).to(dev),
        "body_pose": sample_poses(B, seed=seed, mode=cfg.pose_mode, extreme_fraction=cfg.extreme_fraction,
                                  contact_fraction=cfg.contact_fraction).to(dev),
        "global_orient": torch.randn(B, 3, generator=g, device=dev) * cfg.global_orient_scale,
        "transl": torch.zeros(B, 3, device=dev),
    }
    with torch.no_grad():
        out = body(**params)
        G = partition.part_transforms(out.full_pose, out.joints)
        bmin, bmax = partition.boxes(out.vertices, G)
        pts = sample_training_queries(out.vertices, body.faces_tensor, G, bmin, bmax, cfg.n_uniform, cfg.n_surface,
                                      sigma=cfg.surface_sigma, face_ids_per_part=partition.tight_face_ids, generator=g,
                                      n_body=cfg.n_body_surface, body_sigma=cfg.body_surface_sigma)
        if cfg.n_contact_surface:   # after every other block, so that 0 leaves those unchanged
            touching = contact_vertices(out.vertices, body.v_template)
            near = sample_contact_points(out.vertices, touching, cfg.n_contact_surface, cfg.contact_sigma, generator=g)
            pts = torch.cat([pts, near.to(pts.dtype)], dim=1)
        _sync(dev)
        t1 = time.perf_counter()
        gt = batch_sdf(out.vertices, body.faces_tensor, pts, sign=cfg.gt_sign, nsamples=cfg.gt_rays,
                       backend=cfg.gt_backend, check_closed=False)
        _sync(dev)
    posed = {"vertices": out.vertices, "joints": out.joints, "full_pose": out.full_pose}
    t2 = time.perf_counter()
    return {"params": params, "posed": posed, "points": pts, "sdf": gt, "seed": seed,
            "timing": {"make_s": t2 - t0, "gt_s": t2 - t1}}


class StepBatches(torch.utils.data.Dataset):
    """Batch of step s (make_batch) as item s, for DataLoader worker processes. The body and a CPU copy of
    the partition reach the workers by fork; every batch depends only on (seed, step, rank), so any number
    of workers gives the batches of the serial loop, in order."""

    def __init__(self, cfg: TrainConfig, body, partition, rank: int):
        self.cfg, self.body, self.partition, self.rank = cfg, body, partition, rank

    def __len__(self) -> int:
        return self.cfg.steps

    def __getitem__(self, step: int) -> dict:
        return make_batch(self.cfg, self.body, self.partition, int(step), self.rank)


def _one_thread(_worker_id: int) -> None:
    torch.set_num_threads(1)


def batch_stream(cfg: TrainConfig, body, partition, start: int, end: int, rank: int = 0, device=None):
    """Iterator over the batches of steps start..end-1: made here (num_workers 0) or by worker processes
    (one torch thread each, two batches ahead per worker). device: make them there (a copy of the body and of
    the partition moves to it; None or a CPU device: where the body is); worker processes make CPU batches only."""
    dev = torch.device(device) if device is not None else body.v_template.device
    if dev != body.v_template.device:
        if cfg.num_workers:
            raise ValueError(f"num_workers={cfg.num_workers} makes batches in CPU processes, but device={dev} asks for "
                             f"them on {dev}; set num_workers=0 to make them on the device (or train on the CPU).")
        vol = getattr(body, "volume", None)  # an attached volume is not the body's: share it, do not copy it
        body = copy.deepcopy(body, memo={} if vol is None else {id(vol): vol}).to(dev)
        partition = copy.deepcopy(partition).to(dev)
    if cfg.num_workers == 0 or end <= start:
        return (make_batch(cfg, body, partition, s, rank) for s in range(start, end))
    loader = torch.utils.data.DataLoader(
        StepBatches(cfg, body, partition, rank), batch_size=None, sampler=range(start, end),
        num_workers=cfg.num_workers, worker_init_fn=_one_thread, prefetch_factor=2,
        multiprocessing_context="fork", persistent_workers=False)
    return iter(loader)


class StepProfile:
    """Per-step time breakdown of the training loop: `last` = {'data_s' (waiting for the batch: making it when
    made in the training process, plus moving it), 'make_s' and 'gt_s' (making the batch and its ground truth,
    wherever it was made), 'fwd_bwd_s', 'opt_s' (optimiser step and weight average), 'step_s' (their sum with
    data_s), 'gt_share' (gt_s / step_s when made in this process), 'device'}. Call it after the optimiser step
    with that step's start time (perf_counter); the device is synchronised first so GPU times are real."""

    def __init__(self):
        self.last: dict = {}

    def __call__(self, batch: dict, data_s: float, fwd_bwd_s: float, opt_start: float, device) -> dict:
        dev = torch.device(device)
        _sync(dev)
        opt_s = time.perf_counter() - opt_start
        timing = batch.get("timing", {})
        step_s = data_s + fwd_bwd_s + opt_s
        self.last = {"data_s": data_s, "make_s": timing.get("make_s"), "gt_s": timing.get("gt_s"),
                     "fwd_bwd_s": fwd_bwd_s, "opt_s": opt_s, "step_s": step_s,
                     "gt_share": timing["gt_s"] / step_s if "gt_s" in timing and step_s > 0 else None,
                     "device": str(dev)}
        return self.last


def write_profile(path: str | Path, step: int, record: dict) -> None:
    """Append {'step': step, **record} as one JSON line to `path` (the run's profile.jsonl)."""
    with open(path, "a") as fh:
        fh.write(json.dumps({"step": step, **{k: round(v, 6) if isinstance(v, float) else v
                                               for k, v in record.items()}}) + "\n")
