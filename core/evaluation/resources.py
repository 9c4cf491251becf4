"""Time and memory of one query of a volume under `volsmpl eval`'s protocol (`volsmpl eval --timing`,
`volsmpl bench`'s cross-check): batch 1, validation body 0 and all its evaluation points, in a fresh subprocess.

    res = measure_resources({"checkpoint": None}, EvalConfig())      # {'t_ms', 't_query_ms', 'mem_bytes', ...}

Measured with `volsmpl.runtime.meter` under torch.no_grad(): median wall time over `timing_repeats` after
`timing_warmup` runs, with encoding (a fresh encoding: partition + PointNet + NBW weights, then the query) and
without (the query on a given encoding); peak memory of the first encode+query: CUDA max_memory_allocated, or on
the CPU the peak RSS increase (see `volsmpl.runtime.meter.Meter`).
"""
from __future__ import annotations

import dataclasses
import os
import tempfile
from typing import Optional

import numpy as np
import torch

from volsmpl.evaluation.config import EvalConfig
from volsmpl.evaluation.points import evaluation_points
from volsmpl.runtime.meter import peak_memory, run_isolated, timed_ms
from volsmpl.evaluation.validation_set import pose_bodies, validation_bodies

__all__ = ["measure_resources", "resource_job"]


def measure_resources(spec: dict, config: Optional[EvalConfig] = None, **overrides) -> dict:
    """Time and memory of one query (batch 1, body 0 of the validation set, all its points), in a fresh
    Python subprocess (`meter.run_isolated` of `resource_job`) so that memory peaks are not hidden by
    earlier allocations of this process.

    Args:
        spec: {'checkpoint': PATH or None (shipped), 'model': 'volsmpl' | 'coap'} or {'config': VolumeConfig
            dict, 'init_seed': int}; optional 'body_model': SMPL-format file (default body if None).
        config: EvalConfig (n_points, seed, device, timing_repeats, timing_warmup, timing_threads, ...).
    Returns:
        dict: t_ms (median, encoding included), t_query_ms (median, encoding excluded), t_ms_all /
        t_query_ms_all (every timed run), mem_bytes, mem_total_bytes, mem_kind ('cuda max_memory_allocated'
        or 'cpu peak RSS increase'), mem_method (see `volsmpl.runtime.meter.Meter`), device, threads, points.
    """
    cfg = dataclasses.replace(config or EvalConfig(), **overrides)
    from volsmpl.body.model import create_body

    body = create_body(spec.get("body_model"))
    bodies = {k: v[:1] for k, v in validation_bodies(1, cfg.seed, num_betas=body.num_betas).items()}
    verts = pose_bodies(body, bodies)
    points, _ = evaluation_points(body, bodies, verts, cfg)
    with tempfile.TemporaryDirectory() as tmp:
        inputs = os.path.join(tmp, "inputs.pt")
        torch.save({"bodies": bodies, "points": points}, inputs)
        job = {"spec": spec, "inputs": inputs, "device": cfg.device, "repeats": cfg.timing_repeats,
               "warmup": cfg.timing_warmup, "threads": cfg.timing_threads or torch.get_num_threads(),
               "precision": cfg.precision, "encoder_draws": cfg.encoder_draws,
               "refine_steps": cfg.refine_steps, "passes": cfg.passes}
        return run_isolated("volsmpl.evaluation.resources:resource_job", job, timeout_s=1800)


def resource_job(job: dict) -> dict:
    """The measurement of `measure_resources`, run in the isolated process: job {'spec', 'inputs' (a file of
    {'bodies', 'points'}), 'device', 'threads', 'warmup', 'repeats'}; returns its result dict."""
    import gc

    from volsmpl.body.model import create_body
    from volsmpl.nn.config import VolumeConfig
    from volsmpl.volume.attach import attach_volume

    torch.set_num_threads(int(job["threads"]))
    device = torch.device(job["device"])
    spec = job["spec"]
    body = create_body(spec.get("body_model"))
    if "config" in spec:
        torch.manual_seed(int(spec.get("init_seed", 0)))
        vol = attach_volume(body, pretrained=False, config=VolumeConfig.from_dict(spec["config"]))
    else:
        vol = attach_volume(body, checkpoint=spec.get("checkpoint"), model=spec.get("model", "volsmpl"))
    body, vol = body.to(device), vol.to(device)
    if job.get("precision", "full") != "full":
        vol.set_precision(job["precision"])
    if job.get("encoder_draws") is not None:
        vol.set_encoder_draws(int(job["encoder_draws"]))
    if job.get("refine_steps"):
        vol.set_code_refinement(int(job["refine_steps"]))
    if job.get("passes") is not None:
        vol.set_passes(int(job["passes"]))
    data = torch.load(job["inputs"])
    with torch.no_grad():
        out = body(**{k: v.to(device) for k, v in data["bodies"].items()})
    pts = data["points"].to(device)
    warmup, repeats = int(job["warmup"]), int(job["repeats"])

    def full():  # encoding included: a fresh encoding (bypasses the per-output cache), then the query
        return vol.query_encoded(vol.encode(out, fresh=True), pts)

    gc.collect()
    res = {"device": str(device), "threads": torch.get_num_threads(), "points": int(pts.shape[1])}
    with torch.no_grad():
        res.update(peak_memory(full, device))  # the first call: one-time allocations included
        for _ in range(warmup):
            full()
        t_full = timed_ms([full] * repeats, device)
        enc = vol.encode(out, fresh=True)
        query = lambda: vol.query_encoded(enc, pts)
        for _ in range(warmup):
            query()
        t_query = timed_ms([query] * repeats, device)
    res.update(t_ms=float(np.median(t_full)), t_query_ms=float(np.median(t_query)), t_ms_all=t_full, t_query_ms_all=t_query)
    return res
