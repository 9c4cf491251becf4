"""Training data of `volsmpl train`: the batch of step s on rank r (make_batch: random bodies, query points,
exact signed distances), depending only on (seed, s, r), and the stream of batches of a run (batch_stream),
made in the training process or ahead of it by DataLoader worker processes (StepBatches).
"""
from __future__ import annotations

import torch

from .body.poses import sample_poses
from .body.shapes import sample_betas
from .groundtruth import batch_mesh_sdf
from .train_config import TrainConfig
from .training_queries import sample_training_queries


def make_batch(cfg: TrainConfig, body, partition, step: int, rank: int = 0) -> dict:
    """The training batch of (step, rank): body parameters, the posed bodies (vertices, joints, full_pose),
    query points (B, N, 3), exact SDF (B, N)."""
    seed = (cfg.seed * 1_000_003 + step) * 131 + rank
    g = torch.Generator().manual_seed(seed)
    B = cfg.batch_size
    params = {
        "betas": sample_betas(B, num_betas=body.num_betas, seed=seed),
        "body_pose": sample_poses(B, seed=seed, mode=cfg.pose_mode, extreme_fraction=cfg.extreme_fraction),
        "global_orient": torch.randn(B, 3, generator=g) * cfg.global_orient_scale,
        "transl": torch.zeros(B, 3),
    }
    with torch.no_grad():
        out = body(**params)
        G = partition.part_transforms(out.full_pose, out.joints)
        bmin, bmax = partition.boxes(out.vertices, G)
        pts = sample_training_queries(out.vertices, body.faces_tensor, G, bmin, bmax, cfg.n_uniform, cfg.n_surface,
                                      sigma=cfg.surface_sigma, face_ids_per_part=partition.tight_face_ids, generator=g,
                                      n_body=cfg.n_body_surface, body_sigma=cfg.body_surface_sigma)
        gt = batch_mesh_sdf(out.vertices, body.faces, pts, sign=cfg.gt_sign, nsamples=cfg.gt_rays, check_closed=False)
    posed = {"vertices": out.vertices, "joints": out.joints, "full_pose": out.full_pose}
    return {"params": params, "posed": posed, "points": pts, "sdf": gt, "seed": seed}


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


def batch_stream(cfg: TrainConfig, body, partition, start: int, end: int, rank: int = 0):
    """Iterator over the batches of steps start..end-1: made here (num_workers 0) or by worker processes
    (one torch thread each, two batches ahead per worker)."""
    if cfg.num_workers == 0 or end <= start:
        return (make_batch(cfg, body, partition, s, rank) for s in range(start, end))
    loader = torch.utils.data.DataLoader(
        StepBatches(cfg, body, partition, rank), batch_size=None, sampler=range(start, end),
        num_workers=cfg.num_workers, worker_init_fn=_one_thread, prefetch_factor=2,
        multiprocessing_context="fork", persistent_workers=False)
    return iter(loader)
