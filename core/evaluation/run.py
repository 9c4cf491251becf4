"""Evaluation of a volumetric body model against exact mesh SDFs (paper Table 1 columns), and `volsmpl eval`.

    from volsmpl.evaluation.run import evaluate, evaluate_checkpoint
    res = evaluate_checkpoint("runs/x/ckpt")                  # 64 bodies x 60k points, default settings
    res = evaluate(lambda out, pts: vol.query(out, pts))      # any predictor of SDF (negative inside)
    print(format_table(res)); res.to_dict()                   # JSON-able
    volsmpl eval --checkpoint PATH [--n-bodies 64] [--points 60000] [--out results.json] [--timing]

The parts of the protocol live in their own modules:
  - `volsmpl.evaluation.validation_set`: the fixed validation set (bodies, query points, digests);
  - `volsmpl.evaluation.points`: COAP's per-part query points (`sampling='parts'`), the other sampling protocol;
  - `volsmpl.evaluation.gt_cache`: the exact ground-truth SDF of those points, cached on disk;
  - `volsmpl.evaluation.metrics`: IoU (near-surface / uniform points) and SDF MSEs, per body then averaged.
Every result records where and when it was made (`volsmpl.io.provenance.machine_info`, key 'meta').

Resources (optional, `timing=True`): `volsmpl.evaluation.resources.measure_resources`, in a fresh subprocess on
validation body 0 (batch 1) and all its evaluation points. On a CPU shared with other busy processes time with
`--threads 1`: OpenMP threads waiting for each other can slow a query many times.
"""
from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Callable, Dict, Optional

import numpy as np
import torch

from volsmpl.evaluation.gt_cache import ground_truth
from volsmpl.runtime.meter import Meter
from volsmpl.evaluation.metrics import compute_metrics
from volsmpl.volume.models import model_kind
from volsmpl.io.provenance import machine_info
from volsmpl.evaluation.validation_set import digest, pose_bodies, validation_bodies, validation_labels
from volsmpl.volume.api import BodyVolume

from volsmpl.evaluation.config import PAPER_TABLE1, EvalConfig, EvalResult
from volsmpl.evaluation.points import evaluation_points

__all__ = ["evaluate", "evaluate_volume", "evaluate_checkpoint", "format_table"]


# ---------------------------------------------------------------------------------------------- evaluation
def evaluate(predict_fn: Callable, bodies: Optional[Dict[str, torch.Tensor]] = None, body=None,
             config: Optional[EvalConfig] = None, name: str = "model", **overrides) -> EvalResult:
    """Evaluate an SDF predictor on the validation set.

    Args:
        predict_fn(out, points) -> (B, N) SDF (torch or numpy, negative inside), with out = body(...) of a
            batch of B validation bodies (on config.device) and points (B, N, 3) in the body's dtype.
            Called under torch.no_grad().
        bodies: dict of betas/global_orient/body_pose/transl (B, .); default validation_bodies(n_bodies, seed).
        body: the body model (default volsmpl.create_body()); moved to config.device.
        config: EvalConfig; overrides: EvalConfig fields (e.g. n_bodies=2, n_points=4000).
    Returns:
        EvalResult (timings of points, ground truth and predictor in `seconds`; resources None: see
        evaluate_volume).
    """
    cfg = dataclasses.replace(config or EvalConfig(), **overrides)
    if body is None:
        from volsmpl.body.model import create_body
        body = create_body()
    if bodies is None:
        bodies = validation_bodies(cfg.n_bodies, cfg.seed, num_betas=body.num_betas)
    missing = {"betas", "global_orient", "body_pose", "transl"} - set(bodies)
    if missing:
        raise ValueError(f"bodies lacks {sorted(missing)}; pass a dict like validation_bodies() returns.")
    device = torch.device(cfg.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise RuntimeError("device='cuda' but torch sees no CUDA GPU; use --device cpu.")
    body = body.to(device)
    with Meter("cpu", memory=False) as m_points:
        verts = pose_bodies(body, bodies, cfg.batch_size)
        points, is_surface = evaluation_points(body, bodies, verts, cfg)
    with Meter("cpu", memory=False) as m_gt:
        gt = ground_truth(verts, body.faces, points, cfg.gt_sign, cfg.gt_nsamples, cfg.cache_dir, cfg.use_cache)

    preds = []
    B = len(verts)
    like = body.v_template
    with torch.no_grad(), Meter(device, memory=False) as m_pred:
        for s in range(0, B, cfg.batch_size):
            chunk = {k: v[s:s + cfg.batch_size].to(device, like.dtype) for k, v in bodies.items()}
            out = body(**chunk)
            p = points[s:s + cfg.batch_size].to(device, like.dtype)
            pred = predict_fn(out, p)
            pred = torch.as_tensor(pred.detach().cpu() if torch.is_tensor(pred) else np.asarray(pred))
            if tuple(pred.shape) != tuple(p.shape[:2]):
                raise ValueError(f"predict_fn returned shape {tuple(pred.shape)} for points {tuple(p.shape)}; "
                                 f"it must return one SDF value per point, (B, N).")
            preds.append(pred.double())
    seconds = {"points": m_points.seconds, "ground_truth": m_gt.seconds, "predict": m_pred.seconds}
    per = compute_metrics(torch.cat(preds), gt, is_surface)
    metrics = {k: float(v.mean()) for k, v in per.items()}
    per_body = {"label": validation_labels(B, cfg.seed) if _is_validation_set(bodies, cfg) else [f"body{i}" for i in range(B)]}
    per_body.update({k: v.tolist() for k, v in per.items()})
    return EvalResult(name=name, metrics=metrics, per_body=per_body, config=dataclasses.asdict(cfg),
                      validation_digest=digest(bodies), points_digest=digest(points), seconds=seconds,
                      meta=machine_info(cfg.device, torch.get_num_threads()))


def _is_validation_set(bodies, cfg: EvalConfig) -> bool:
    ref = validation_bodies(len(bodies["betas"]), cfg.seed, num_betas=bodies["betas"].shape[1])
    return digest(ref) == digest(bodies)


def evaluate_volume(volume, body, config: Optional[EvalConfig] = None, name: str = "VolumetricSMPL (ours)",
                    resource_spec: Optional[dict] = None, bodies: Optional[Dict[str, torch.Tensor]] = None,
                    **overrides) -> EvalResult:
    """`evaluate` of `volume.query` (volume attached to `body`); with config.timing also `measure_resources`,
    which needs `resource_spec` (how the subprocess rebuilds the volume: see measure_resources)."""
    cfg = dataclasses.replace(config or EvalConfig(), **overrides)
    volume = volume.to(torch.device(cfg.device))
    before = volume.precision if isinstance(volume, BodyVolume) else "full"   # stand-ins compute as they are
    if cfg.precision != before:
        volume.set_precision(cfg.precision)   # ValueError for a volume without that mode
    draws_before = None
    if cfg.encoder_draws is not None:
        draws_before = volume.partition.draws
        volume.set_encoder_draws(cfg.encoder_draws)   # ValueError for a volume without an encoder
    refine_before = None
    if cfg.refine_steps:
        refine_before = volume.refine_steps
        volume.set_code_refinement(cfg.refine_steps)  # ValueError for a volume without part codes
    passes_before = volume.passes if cfg.passes is not None else None
    if cfg.passes is not None:
        volume.set_passes(cfg.passes)                 # ValueError for more passes than the volume has
    try:
        if volume.is_sdf:
            res = evaluate(lambda out, pts: volume.query(out, pts), bodies=bodies, body=body, config=cfg, name=name)
        else:  # occupancy (COAP): level - occupancy is negative inside, so the IoU columns are exact
            res = evaluate(lambda out, pts: volume.level - volume.query(out, pts), bodies=bodies, body=body,
                           config=cfg, name=name)
    finally:
        if cfg.precision != before:
            volume.set_precision(before)
        if draws_before is not None:
            volume.set_encoder_draws(draws_before)
        if refine_before is not None:
            volume.set_code_refinement(refine_before)
        if cfg.passes is not None:
            volume.set_passes(passes_before)
    if not volume.is_sdf:
        for k in [k for k in res.metrics if k.startswith("mse")]:  # not distances: no SDF error to report
            res.metrics[k] = None
            res.per_body[k] = [None] * len(res.per_body[k])
        res.extra["output"] = "occupancy"
    if cfg.timing:
        if resource_spec is None:
            raise ValueError("timing=True needs resource_spec={'checkpoint': PATH} or {'config': dict, 'init_seed': int} "
                             "so the subprocess can rebuild the same volume; or use evaluate_checkpoint.")
        from volsmpl.evaluation.resources import measure_resources
        res.resources = measure_resources(resource_spec, cfg)
    return res


def evaluate_checkpoint(path: str | os.PathLike | None, config: Optional[EvalConfig] = None, body=None,
                        random_init: Optional[dict] = None, bodies: Optional[Dict[str, torch.Tensor]] = None,
                        **overrides) -> EvalResult:
    """Evaluate a checkpoint (None: the shipped VolumetricSMPL one) with the default body (or `body`).
    The checkpoint says which model it holds (VolumetricSMPL or COAP); occupancy models get IoU only.

    random_init: instead of a checkpoint, {'config': VolumeConfig dict, 'init_seed': int} for a randomly
    initialised volume (benchmarks before training). Other arguments as `evaluate`.
    """
    from volsmpl.body.model import create_body
    from volsmpl.volume.models import checkpoint_model
    from volsmpl.nn.config import VolumeConfig
    from volsmpl.volume.attach import attach_volume

    body = body if body is not None else create_body()
    if random_init is not None:
        torch.manual_seed(int(random_init.get("init_seed", 0)))
        vol = attach_volume(body, pretrained=False, config=VolumeConfig.from_dict(dict(random_init.get("config", {}))))
        spec = {"config": vol.net.config.to_dict(), "init_seed": int(random_init.get("init_seed", 0))}
        name = "random init"
    else:
        kind = "volsmpl" if path is None else checkpoint_model(path)
        vol = attach_volume(body, checkpoint=path, model=kind)
        spec = {"checkpoint": None if path is None else os.fspath(path), "model": kind}
        name = "ours" if path is None else Path(os.fspath(path)).name
    spec["body_model"] = getattr(body, "model_path", None)
    res = evaluate_volume(vol, body, config=config, name=name, resource_spec=spec, bodies=bodies, **overrides)
    shipped = f"shipped {model_kind('volsmpl').checkpoint}" if random_init is None else None
    res.extra["checkpoint"] = spec.get("checkpoint") or shipped
    return res


# ---------------------------------------------------------------------------------------------- report
def _fmt_mem(r: dict) -> str:
    if not r:
        return "-"
    mib = r["mem_bytes"] / 2 ** 20
    where = "GPU" if r["mem_kind"].startswith("cuda") else "CPU"
    return f"{mib / 1024:.2f} G {where}" if mib >= 1024 else f"{mib:.0f} M {where}"


def format_table(results) -> str:
    """Table 1 layout: one row per EvalResult, then the paper's rows (IoU in %, MSE in m^2)."""
    results = [results] if isinstance(results, EvalResult) else list(results)
    head = ["model", "t [ms]", "t query [ms]", "mem", "IoU mean", "surf.", "unif.", "MSE SDF", "MSE |SDF|",
            "MSE SDF surf."]
    rows = []

    def num(x, f):
        return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f.format(x)

    for r in results:
        m, res = r.metrics, r.resources or {}
        rows.append([r.name, num(res.get("t_ms"), "{:.1f}"), num(res.get("t_query_ms"), "{:.1f}"), _fmt_mem(res),
                     num(100 * m["iou_mean"], "{:.2f}"), num(100 * m["iou_surf"], "{:.2f}"),
                     num(100 * m["iou_unif"], "{:.2f}"), num(m["mse_sdf"], "{:.2e}"), num(m["mse_abs_sdf"], "{:.2e}"),
                     num(m["mse_sdf_surf"], "{:.2e}")])
    for name, p in PAPER_TABLE1.items():
        rows.append([name, num(p["t_ms"], "{:.0f}"), "-", p["mem"], num(100 * p["iou_mean"], "{:.2f}"),
                     num(100 * p["iou_surf"], "{:.2f}"), num(100 * p["iou_unif"], "{:.2f}"),
                     num(p["mse_sdf"], "{:.1e}"), num(p["mse_abs_sdf"], "{:.1e}"), "-"])
    widths = [max(len(str(x[i])) for x in [head] + rows) for i in range(len(head))]
    line = lambda cells: "  ".join(str(c).ljust(w) if i == 0 else str(c).rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))
    out = [line(head), line(["-" * w for w in widths])] + [line(r) for r in rows[: len(results)]]
    out += [line(["-" * w for w in widths])] + [line(r) for r in rows[len(results):]]
    return "\n".join(out)


