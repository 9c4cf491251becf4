"""Evaluation of a volumetric body model against exact mesh SDFs (paper Table 1 columns), and `volsmpl eval`.

    from volsmpl.evaluate import evaluate, evaluate_checkpoint
    res = evaluate_checkpoint("runs/x/ckpt")                  # 64 bodies x 60k points, default settings
    res = evaluate(lambda out, pts: vol.query(out, pts))      # any predictor of SDF (negative inside)
    print(format_table(res)); res.to_dict()                   # JSON-able
    volsmpl eval --checkpoint PATH [--n-bodies 64] [--points 60000] [--out results.json] [--timing]

The parts of the protocol live in their own modules:
  - `volsmpl.validation`: the fixed validation set (bodies, query points, digests);
  - `volsmpl.part_points`: COAP's per-part query points (`sampling='parts'`), the other sampling protocol;
  - `volsmpl.groundtruth_cache`: the exact ground-truth SDF of those points, cached on disk;
  - `volsmpl.metrics`: IoU (near-surface / uniform points) and SDF MSEs, per body then averaged.
Every result records where and when it was made (`volsmpl.provenance.machine_info`, key 'meta').

Resources (optional, `timing=True`): `volsmpl.eval_resources.measure_resources`, in a fresh subprocess on
validation body 0 (batch 1) and all its evaluation points. On a CPU shared with other busy processes time with
`--threads 1`: OpenMP threads waiting for each other can slow a query many times.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, Optional

import numpy as np
import torch

from . import paper
from .groundtruth import SIGN_MODES
from .groundtruth_cache import default_cache_dir, ground_truth
from .meter import Meter
from .metrics import compute_metrics
from .models import model_kind
from .precision import PRECISIONS
from .provenance import machine_info
from .validation import VAL_SEED, digest, pose_bodies, query_points, validation_bodies, validation_labels
from .volume_api import BodyVolume

__all__ = ["PAPER_TABLE1", "SAMPLINGS", "EvalConfig", "EvalResult", "evaluate", "evaluation_points", "evaluate_volume",
           "evaluate_checkpoint", "format_table", "add_parser", "run"]

def _paper_table1() -> dict:
    """The paper's Table 1 (volsmpl.paper) as this module prints it: IoU as fractions, MSE in m^2, time in ms."""
    names = {"volsmpl": "VolumetricSMPL (paper)", "coap": "COAP (paper)", "leap": "LEAP (paper)"}
    out = {}
    for key, row in paper.rows("1").items():
        out[names[key]] = dict(t_ms=row["t_ms"], mem=f"{row['gpu_gb']} G GPU",
                               **{k: round(row[k] / 100, 6) for k in ("iou_mean", "iou_surf", "iou_unif")},
                               mse_sdf=row["mse_sdf"], mse_abs_sdf=row["mse_abs_sdf"])
    return out


#: where `evaluate` puts the query points (EvalConfig.sampling)
SAMPLINGS = ("body", "parts")

#: the paper's Table 1 (fractions for IoU, m^2 for MSE, GPU memory in GB, time in ms), for reference
PAPER_TABLE1 = _paper_table1()


@dataclass
class EvalConfig:
    """Settings of one evaluation (defaults: 60k points per body, half uniform in the body's padded box, half
    within 1 cm of the surface, on our validation set; the paper does not publish the sampling behind its Table 1).

    Attributes:
        n_bodies: validation bodies (64). seed: validation seed (VAL_SEED) for bodies and points.
        n_points: query points per body (60k). surface_fraction: share of near-surface points (0.5).
        bbox_padding: padding of the uniform sampling box around the posed body, metres (0.05).
        surface_sigma: std of the Gaussian offsets of near-surface points, metres (0.01).
        gt_sign / gt_nsamples: sign mode and rays of `batch_mesh_sdf` ('ray_winding' with 3 rays).
        batch_size: bodies per predictor call. device: 'cpu' or 'cuda' for the predictor.
        cache_dir: ground-truth cache folder (None: `default_cache_dir()`); use_cache: read/write it.
        timing: measure time and memory (checkpoint/volume evaluations only); timing_repeats / timing_warmup:
            timed runs (median reported) and untimed warm-up runs; timing_threads: torch CPU threads of the
            timing subprocess (None: this process's torch.get_num_threads()). On a shared machine use 1:
            with other processes busy, OpenMP threads waiting for each other can slow a CPU query 100x.
        precision: the volume's decoder arithmetic during the evaluation ('full', 'bf16', 'tf32';
            `Volume.set_precision`), for the accuracy cost of a reduced-precision mode.
        sampling: where the points lie: 'body' (uniform in the body's padded bounding box, near-surface samples
            on the whole mesh: `validation.query_points`) or 'parts' (COAP's per-part sampling: the same number
            of points per body part, uniform in its padded box and near its own faces: `part_points`;
            bbox_padding does not apply, the boxes are the models' 12.5 %).
        encoder_draws: surface sample sets whose codes the encoder averages (`Volume.set_encoder_draws`) during
            the evaluation; None (default): the checkpoint's own (1 unless it was trained with more).
        refine_steps: test-time refinement of the part codes on the posed mesh's own surface
            (`Volume.set_code_refinement`, volsmpl.code_refinement) during the evaluation; 0 (default): none.
    """

    n_bodies: int = 64
    seed: int = VAL_SEED
    n_points: int = 60000
    surface_fraction: float = 0.5
    bbox_padding: float = 0.05
    surface_sigma: float = 0.01
    gt_sign: str = "ray_winding"
    gt_nsamples: int = 3
    batch_size: int = 8
    device: str = "cpu"
    cache_dir: Optional[str] = None
    use_cache: bool = True
    timing: bool = False
    timing_repeats: int = 10
    timing_warmup: int = 3
    timing_threads: Optional[int] = None
    precision: str = "full"
    sampling: str = "body"
    encoder_draws: Optional[int] = None
    refine_steps: int = 0

    def __post_init__(self):
        for name in ("n_bodies", "n_points", "batch_size", "timing_repeats"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"EvalConfig.{name} must be a positive integer, got {v!r}.")
        if not isinstance(self.timing_warmup, int) or self.timing_warmup < 0:
            raise ValueError(f"EvalConfig.timing_warmup must be an integer >= 0, got {self.timing_warmup!r}.")
        if self.timing_threads is not None and (not isinstance(self.timing_threads, int) or self.timing_threads < 1):
            raise ValueError(f"EvalConfig.timing_threads={self.timing_threads!r}: give a positive integer or None.")
        if not 0.0 < self.surface_fraction < 1.0:
            raise ValueError(f"EvalConfig.surface_fraction={self.surface_fraction} must lie strictly between 0 and 1 "
                             f"(0.5: half near the surface): each IoU column needs points of its own.")
        if not math.isfinite(self.surface_sigma) or self.surface_sigma < 0:
            raise ValueError(f"--surface-sigma {self.surface_sigma}: give a finite scale >= 0 in metres (default 0.01).")
        if not math.isfinite(self.bbox_padding) or self.bbox_padding < 0:
            raise ValueError(f"EvalConfig.bbox_padding={self.bbox_padding}: give a finite padding >= 0 in metres (0.05).")
        if self.encoder_draws is not None and (not isinstance(self.encoder_draws, int) or self.encoder_draws < 1):
            raise ValueError(f"--encoder-draws {self.encoder_draws}: give a positive number of surface sample sets.")
        if not isinstance(self.refine_steps, int) or isinstance(self.refine_steps, bool) or self.refine_steps < 0:
            raise ValueError(f"--refine-steps {self.refine_steps}: give an integer >= 0 (0: no code refinement).")
        if self.sampling not in SAMPLINGS:
            raise ValueError(f"EvalConfig.sampling={self.sampling!r}: use one of {', '.join(SAMPLINGS)}.")
        n_surf = int(round(self.n_points * self.surface_fraction))
        if self.sampling == "body" and not 0 < n_surf < self.n_points:
            raise ValueError(f"--points {self.n_points} leaves the {'near-surface' if n_surf == 0 else 'uniform'} set "
                             f"empty at surface_fraction {self.surface_fraction}; give more points per body.")
        if self.device not in ("cpu", "cuda") and not str(self.device).startswith("cuda:"):
            raise ValueError(f"EvalConfig.device={self.device!r}: use 'cpu' or 'cuda'.")
        if self.precision not in PRECISIONS:
            raise ValueError(f"EvalConfig.precision={self.precision!r}: use one of {', '.join(PRECISIONS)}.")
        if self.precision == "tf32" and not str(self.device).startswith("cuda"):
            raise ValueError("precision tf32 runs on CUDA tensor cores: add --device cuda, or use --precision bf16 "
                             "or full on the CPU.")


@dataclass
class EvalResult:
    """Outcome of `evaluate`: metrics (means over bodies), per-body values, timings, resources and provenance
    (meta: `volsmpl.provenance.machine_info`)."""

    name: str
    metrics: Dict[str, float]
    per_body: Dict[str, list]
    config: dict
    validation_digest: str
    points_digest: str
    seconds: Dict[str, float]
    resources: Optional[dict] = None
    extra: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["paper_table1"] = PAPER_TABLE1
        return d


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
        from .body.model import create_body
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


def evaluation_points(body, bodies: Dict[str, torch.Tensor], verts: torch.Tensor, cfg: EvalConfig):
    """The query points of an evaluation by `cfg.sampling`: points (B, n_points, 3), is_surface (n_points,).
    verts: the bodies posed (B, V, 3), for the body-box sampling; the per-part one poses them itself."""
    if cfg.sampling == "parts":
        from .part_points import part_query_points
        return part_query_points(body, bodies, cfg.n_points, cfg.seed, cfg.surface_fraction, cfg.surface_sigma)
    return query_points(verts, body.faces, cfg.n_points, cfg.seed, cfg.surface_fraction, cfg.bbox_padding,
                        cfg.surface_sigma)


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
    if not volume.is_sdf:
        for k in [k for k in res.metrics if k.startswith("mse")]:  # not distances: no SDF error to report
            res.metrics[k] = None
            res.per_body[k] = [None] * len(res.per_body[k])
        res.extra["output"] = "occupancy"
    if cfg.timing:
        if resource_spec is None:
            raise ValueError("timing=True needs resource_spec={'checkpoint': PATH} or {'config': dict, 'init_seed': int} "
                             "so the subprocess can rebuild the same volume; or use evaluate_checkpoint.")
        from .eval_resources import measure_resources
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
    from .body.model import create_body
    from .checkpoint import checkpoint_model
    from .nn.config import VolumeConfig
    from .attach import attach_volume

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


# ---------------------------------------------------------------------------------------------- CLI
def add_parser(sub):
    d = EvalConfig()
    p = sub.add_parser("eval", help="evaluate a checkpoint on the validation set (paper Table 1 columns)",
                       description="IoU (surface / uniform points) and SDF MSE against exact mesh SDFs on a fixed "
                                   "validation set of extreme poses and unusual shapes; optional time and memory.")
    p.add_argument("--checkpoint", default=None, help="checkpoint path (with or without .safetensors); default: shipped one")
    p.add_argument("--random-init", action="store_true", help="evaluate a randomly initialised default network instead")
    p.add_argument("--n-bodies", type=int, default=d.n_bodies)
    p.add_argument("--points", type=int, default=d.n_points, help="query points per body (half near the surface)")
    p.add_argument("--seed", type=int, default=d.seed, help="validation seed (default VAL_SEED)")
    p.add_argument("--batch-size", type=int, default=d.batch_size)
    p.add_argument("--device", default=d.device, choices=["cpu", "cuda"])
    p.add_argument("--timing", action="store_true", help="also measure query time and memory (subprocess)")
    p.add_argument("--repeats", type=int, default=d.timing_repeats, help="timed runs (median reported)")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice); "
                   "1 gives stable CPU timings on a busy machine")
    p.add_argument("--gt-sign", default=d.gt_sign, choices=SIGN_MODES,
                   help="ground-truth sign: the winding number of the posed mesh (self-overlaps inside), counted along "
                        "rays (default, exact) or through libigl (exact, or its fast approximation), or ray parity "
                        "(calls self-overlaps outside); cached")
    p.add_argument("--cache-dir", default=None, help=f"ground-truth cache (default {default_cache_dir()})")
    p.add_argument("--no-cache", action="store_true", help="recompute the ground truth, do not write the cache")
    p.add_argument("--precision", default="full", choices=list(PRECISIONS),
                   help="decoder arithmetic: full (default), bf16 (bfloat16 layers) or tf32 (CUDA tensor cores); "
                        "reduced precision trades accuracy for speed on GPUs")
    p.add_argument("--sampling", default=d.sampling, choices=list(SAMPLINGS),
                   help="where the points lie: body (default: uniform in the body's padded bounding box + near the whole "
                        "surface) or parts (COAP's per-part sampling: as many points per part, in its padded box and "
                        "near its own faces; --points a multiple of the part count)")
    p.add_argument("--surface-sigma", type=float, default=d.surface_sigma,
                   help=f"std of the near-surface points' offsets, metres (default {d.surface_sigma}); the surface "
                        "IoU depends strongly on it")
    p.add_argument("--encoder-draws", type=int, default=None,
                   help="encode each part as the mean code of this many fixed surface sample sets (default: the "
                        "checkpoint's own, 1 unless trained with more); more sets, steadier codes, slower encoding")
    p.add_argument("--refine-steps", type=int, default=0,
                   help="refine each body's part codes by this many optimiser steps on the posed mesh's own surface "
                        "before querying (volsmpl.code_refinement; default 0: the encoder's codes); each step costs "
                        "about half an encoding")
    p.add_argument("--out", default=None, help="write the results as JSON here")
    p.add_argument("--split", default="all", choices=["standard", "self_contact", "all"],
                   help="validation split: the standard set, the self-contact poses (volsmpl.contact_split: min(n-bodies, "
                        "16) bodies, same points and metrics; no timing) or both (default; JSON: the standard result "
                        "with the self-contact one under 'splits')")
    return p


def run(args) -> int:
    from .outputs import check_writable, write_atomic
    if args.out:  # before the evaluation: a bad path fails in seconds, not after it
        check_writable(args.out, "file", "--out")
    if args.cache_dir is not None and not args.no_cache:  # written after the ground truth: checked before it
        check_writable(args.cache_dir, "dir", "--cache-dir")
    if args.timing and args.split == "self_contact":
        raise ValueError("--timing measures validation body 0 of the standard split, which --split self_contact does "
                         "not run: use --split standard or all with --timing.")
    if args.checkpoint is not None and args.random_init:
        raise ValueError("--checkpoint and --random-init exclude each other; give one.")
    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads {args.threads}: give a positive number of CPU threads.")
        torch.set_num_threads(args.threads)
    cfg = EvalConfig(n_bodies=args.n_bodies, n_points=args.points, seed=args.seed, batch_size=args.batch_size,
                     device=args.device, timing=args.timing, timing_repeats=args.repeats, cache_dir=args.cache_dir,
                     use_cache=not args.no_cache, timing_threads=args.threads, gt_sign=args.gt_sign,
                     precision=args.precision, sampling=args.sampling, surface_sigma=args.surface_sigma,
                     encoder_draws=args.encoder_draws, refine_steps=args.refine_steps)
    init = {"config": {}, "init_seed": 0} if args.random_init else None
    if args.split == "self_contact":
        from .contact_split import evaluate_self_contact
        return _write_split(args, evaluate_self_contact(args.checkpoint, cfg, init))
    res = evaluate_checkpoint(args.checkpoint, config=cfg, random_init=init)
    print(f"validation set: {cfg.n_bodies} bodies (seed {cfg.seed}, digest {res.validation_digest[:12]}), "
          f"{cfg.n_points} points each ({cfg.sampling} sampling, sigma {cfg.surface_sigma:g} m); ground truth {res.seconds['ground_truth']:.1f} s, "
          f"model {res.seconds['predict']:.1f} s")
    print(format_table(res))
    if res.resources:
        print(f"time: batch 1 x {res.resources['points']} points on {res.resources['device']} "
              f"({res.resources['threads']} threads), median of {cfg.timing_repeats}; t = encoding + query, "
              f"t query = query only; mem = {res.resources['mem_kind']}")
    if args.split == "all":
        from .contact_split import evaluate_self_contact
        return _write_split(args, res, evaluate_self_contact(args.checkpoint, cfg, init))
    return _write_split(args, res)


def _write_split(args, res: EvalResult, contact: Optional[EvalResult] = None) -> int:
    """Print the self-contact table (when `contact`, or when `res` is it) and write --out: `res` with `contact`
    under 'splits'."""
    from .outputs import write_atomic
    for r in [x for x in (res, contact) if x is not None and x.extra.get("split") == "self_contact"]:
        poses = dict.fromkeys(x.split(":")[-1].split("/")[0].rstrip("~") for x in r.per_body["label"])
        print(f"self-contact split: {r.config['n_bodies']} bodies (seed {r.config['seed']}; {', '.join(poses)})")
        print(format_table(r))
    if args.out:
        d = res.to_dict()
        if contact is not None:
            d["splits"] = {"self_contact": contact.to_dict()}
        write_atomic(args.out, json.dumps(d, indent=1))
        print(f"wrote {args.out}")
    return 0
