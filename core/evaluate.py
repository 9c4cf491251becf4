"""Evaluation of a volumetric body model against exact mesh SDFs (paper Table 1 protocol).

    from volsmpl.evaluate import evaluate, evaluate_checkpoint, validation_bodies
    res = evaluate_checkpoint("runs/x/ckpt")                  # 64 bodies x 60k points, default settings
    res = evaluate(lambda out, pts: vol.query(out, pts))      # any predictor of SDF (negative inside)
    print(format_table(res)); res.to_dict()                   # JSON-able
    volsmpl eval --checkpoint PATH [--n-bodies 64] [--points 60000] [--out results.json] [--timing]

Validation set (`validation_bodies`): bodies the training sampler never draws, regenerated bit-identically
from a seed (default VAL_SEED). Body i is built from its own random stream SeedSequence([seed, i]), so
`validation_bodies(n)` is a prefix of `validation_bodies(m)` for n <= m, independent of n:
  - pose: odd i < 2 * len(NAMED_POSES) take the named poses in NAMED_POSES order (all 12 at n >= 24);
    every other body an *extreme* pose (`sample_poses(mode='extreme')`: every joint angle uniform over its
    full anatomical range; training draws 'realistic' poses by default, the shipped checkpoint's last phase a
    50/50 mix of realistic and extreme, from other seeds). At n=64: 12 named + 52 extreme.
  - shape: group (i // 2) % 4 of SHAPE_GROUPS: tall (>= 1.85 m), short (<= 1.55 m), male (gender <= 0.25),
    female (gender >= 0.75), drawn from the calibrated population by `sample_betas`.
  - global orientation uniform over SO(3) (upside-down bodies included); translation uniform in
    [-0.5, 0.5]^3 m.
`digest(tensors)` is the sha256 of the tensors' names, dtypes, shapes and bytes: equal digests mean
bit-identical sets (on the same numpy/scipy/torch stack).

Query points (`query_points`), per body, from a per-body torch.Generator (seed SeedSequence([seed, 1, i])),
float32, laid out [uniform | near-surface]:
  - round(n * (1 - surface_fraction)) points uniform in the body's axis-aligned bounding box padded by
    `bbox_padding` (5 cm) on every side;
  - the rest near the surface: area-weighted uniform samples on the posed mesh + isotropic Gaussian
    offsets N(0, sigma^2 I), sigma = 1 cm (the paper's protocol follows COAP; COAP's evaluation
    perturbs surface samples at the centimetre scale, where the "surf." IoU is decided).
Defaults give the paper's 60k = 30k uniform + 30k near-surface. COAP's released training code (whose
protocol the paper follows) uses the same sigma (0.01) but draws its "uniform" half inside the padded part
boxes rather than the body's box; the body box is the paper's wording ("uniformly sampled around the body")
and does not depend on the model's partition, so models with different boxes see the same points.
Shapes come from the same population bank as training shapes (`sample_betas`, 1024 bodies): what training
never sees are the validation bodies themselves (their seeds), the named poses, the orientations and the shape-group
extremes (and, with the default `pose_mode='realistic'`, the extreme pose distribution).

Ground truth: `volsmpl.groundtruth.batch_mesh_sdf` (exact distance; sign from the exact integer winding number
of the closed posed mesh, counted along 3 rays by default: `gt_sign='ray_winding'`), cached in
`<cache_dir>/gt_<key>.npz` with key = sha256 of (vertices, faces, points, sign mode): any change of the
bodies, the body model, the points or the sign mode is a cache miss. The winding number calls the overlap
of self-intersecting parts (hand inside the torso, pressed thighs) inside, the union of the parts, which is
what a min-over-parts volumetric model represents; ray parity (`gt_sign='raycast'`) calls it outside. On
four extreme validation bodies (4k points each) the two signs disagreed on 0.2-2.3% of the points (IoU
0.92-0.99 between them), the size of the differences Table 1 reports. libigl's exact generalised winding
number (`gt_sign='winding'`) gives the same signs on all 3.84M validation points (and the same distances)
but takes ~5 s per body at 60k points on one core (~5 min for 64 bodies) against 25 s for all 64 with
'ray_winding' (2 busy cores); either is computed once and cached. Figures in this project before 2026-11-22
evening used 'raycast', until 2026-11-23 'winding'.

Metrics, per body, then the plain mean over bodies (all bodies have the same number of points, so the
MSE means equal the means over all points):
  - IoU(S) = |{pred < 0} & {gt < 0}| / |{pred < 0} | {gt < 0}| over the point set S (1 when both are
    empty); iou_surf on the near-surface set, iou_unif on the uniform set, iou_mean = their average.
  - mse_sdf = mean (pred - gt)^2, mse_abs_sdf = mean (|pred| - |gt|)^2 (metres^2), over all points;
    `_surf` / `_unif` suffixes: over the near-surface / uniform set only. Note ||a| - |b|| <= |a - b|, so
    mse_abs_sdf <= mse_sdf on any point set; the paper's Table 2 has rows with |SDF| > SDF, so its
    exact definition must differ (not stated); these are the well-defined ones.
Resources (optional, `timing=True`): measured in a fresh subprocess on body 0 (batch 1) and all its
points, under torch.no_grad(): median wall time over `timing_repeats` after `timing_warmup` runs,
with encoding (partition + PointNet + NBW weights + query) and without (query on a given encoding);
memory on CUDA = torch.cuda.max_memory_allocated during one encode+query (minus what was allocated
before); on CPU = peak RSS during the first encode+query minus the RSS just before it (ru_maxrss when
the query sets the process's high-water mark, else RSS polled every 0.2 ms in a thread).
On a CPU shared with other busy processes, time with `--threads 1`: OpenMP threads waiting for each other
made an encode+query 10x slower with 2 threads than with 1 on the 2-core development machine.

Cost (2 shared CPU cores, 64 bodies x 60k points): ground truth ~22 s once (then read from the cache in
~0.2 s), a randomly initialised default network ~27 s with 1 thread; timing adds ~10 s.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional

import numpy as np
import torch

from .groundtruth import SIGN_MODES

#: seed of the validation set (PosePrior's 316 validation bodies in the paper). Training uses other seeds
#: (and 'realistic' or 'mixed' poses); do not train on bodies from this seed.
VAL_SEED = 316

#: shape groups of the validation set, cycled every 2 bodies: keyword arguments of `sample_betas`
SHAPE_GROUPS = {
    "tall": dict(height_range=(1.85, 3.0)),
    "short": dict(height_range=(0.0, 1.55)),
    "male": dict(gender_range=(0.0, 0.25)),
    "female": dict(gender_range=(0.75, 1.0)),
}

#: the paper's Table 1 (fractions for IoU, m^2 for MSE, GPU memory in GiB, time in ms), for reference
PAPER_TABLE1 = {
    "VolumetricSMPL (paper)": dict(t_ms=15, mem="3.1 G GPU", iou_mean=0.9467, iou_surf=0.9425, iou_unif=0.9510,
                                   mse_sdf=3.7e-5, mse_abs_sdf=3.5e-5),
    "COAP (paper)": dict(t_ms=140, mem="18.7 G GPU", iou_mean=0.9431, iou_surf=0.9398, iou_unif=0.9463,
                         mse_sdf=None, mse_abs_sdf=None),
    "LEAP (paper)": dict(t_ms=79, mem="7.7 G GPU", iou_mean=0.7598, iou_surf=0.6998, iou_unif=0.8197,
                         mse_sdf=None, mse_abs_sdf=None),
}

_GT_CACHE_VERSION = "gt-v1"


def default_cache_dir() -> Path:
    """$VOLSMPL_CACHE_DIR, else `data/cache/` of the source checkout (git-ignored), else ~/.cache/volsmpl."""
    env = os.environ.get("VOLSMPL_CACHE_DIR")
    if env:
        return Path(env)
    root = Path(__file__).resolve().parent.parent
    if (root / "pyproject.toml").exists():
        return root / "data" / "cache"
    return Path.home() / ".cache" / "volsmpl"


@dataclass
class EvalConfig:
    """Settings of one evaluation (defaults: the paper's Table 1 protocol on our validation set).

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

    def __post_init__(self):
        for name in ("n_bodies", "n_points", "batch_size", "timing_repeats"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"EvalConfig.{name} must be a positive integer, got {v!r}.")
        if not isinstance(self.timing_warmup, int) or self.timing_warmup < 0:
            raise ValueError(f"EvalConfig.timing_warmup must be an integer >= 0, got {self.timing_warmup!r}.")
        if self.timing_threads is not None and (not isinstance(self.timing_threads, int) or self.timing_threads < 1):
            raise ValueError(f"EvalConfig.timing_threads={self.timing_threads!r}: give a positive integer or None.")
        if not 0.0 <= self.surface_fraction <= 1.0:
            raise ValueError(f"EvalConfig.surface_fraction={self.surface_fraction} must lie in [0, 1] (0.5: half near the surface).")
        if not (self.bbox_padding >= 0 and self.surface_sigma >= 0):
            raise ValueError(f"EvalConfig.bbox_padding={self.bbox_padding} and surface_sigma={self.surface_sigma} "
                             f"must be >= 0 (metres).")
        if self.device not in ("cpu", "cuda") and not str(self.device).startswith("cuda:"):
            raise ValueError(f"EvalConfig.device={self.device!r}: use 'cpu' or 'cuda'.")


# ---------------------------------------------------------------------------------------------- validation set
def _sub_seed(*words: int) -> int:
    """A 32-bit seed derived from integers (independent streams per (seed, body, purpose))."""
    return int(np.random.SeedSequence([int(w) for w in words]).generate_state(1)[0])


def _body_spec(i: int, seed: int) -> dict:
    from .body.poses import NAMED_POSES

    names = list(NAMED_POSES)
    group = list(SHAPE_GROUPS)[(i // 2) % len(SHAPE_GROUPS)]
    pose = f"named:{names[i // 2]}" if i % 2 == 1 and i // 2 < len(names) else "extreme"
    return {"pose": pose, "shape": group, "seed": _sub_seed(seed, i)}


def validation_labels(n: int = 64, seed: int = VAL_SEED) -> List[str]:
    """Human-readable composition of `validation_bodies(n, seed)`: 'pose/shape' per body, e.g. 'named:sitting/short'."""
    return [f"{s['pose']}/{s['shape']}" for s in (_body_spec(i, seed) for i in range(n))]


def validation_bodies(n: int = 64, seed: int = VAL_SEED, num_betas: int = 10) -> Dict[str, torch.Tensor]:
    """The fixed validation set (see the module docstring for its composition).

    Args:
        n: number of bodies; seed: validation seed; num_betas: shape coefficients per body.
    Returns:
        dict of float32 CPU tensors: betas (n, num_betas), global_orient (n, 3), body_pose (n, 69),
        transl (n, 3). Bit-identical for equal (n, seed, num_betas); body i does not depend on n.
    """
    from scipy.spatial.transform import Rotation

    from .body.poses import named_pose, sample_poses
    from .body.shapes import sample_betas

    if not isinstance(n, int) or n < 1:
        raise ValueError(f"validation_bodies needs n >= 1 bodies, got {n!r}.")
    betas, orient, pose, transl = [], [], [], []
    for i in range(n):
        spec = _body_spec(i, seed)
        s = spec["seed"]
        if spec["pose"] == "extreme":
            pose.append(sample_poses(1, seed=_sub_seed(s, 0), mode="extreme"))
        else:
            pose.append(named_pose(spec["pose"].split(":", 1)[1]))
        betas.append(sample_betas(1, num_betas=num_betas, seed=_sub_seed(s, 1), **SHAPE_GROUPS[spec["shape"]]))
        rng = np.random.default_rng(_sub_seed(s, 2))
        orient.append(Rotation.random(1, random_state=rng).as_rotvec())
        transl.append(rng.uniform(-0.5, 0.5, size=(1, 3)))
    f32 = dict(dtype=torch.float32)
    return {
        "betas": torch.cat(betas).to(**f32),
        "global_orient": torch.as_tensor(np.concatenate(orient), **f32),
        "body_pose": torch.cat(pose).to(**f32),
        "transl": torch.as_tensor(np.concatenate(transl), **f32),
    }


def digest(tensors) -> str:
    """sha256 hex digest of a tensor / array or a dict of them (names, dtypes, shapes and raw bytes, keys sorted)."""
    h = hashlib.sha256()
    items = sorted(tensors.items()) if isinstance(tensors, dict) else [("", tensors)]
    for name, t in items:
        a = t.detach().cpu().contiguous().numpy() if torch.is_tensor(t) else np.ascontiguousarray(t)
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def pose_bodies(body, bodies: Dict[str, torch.Tensor], batch_size: int = 16) -> torch.Tensor:
    """Posed vertices (B, V, 3) float32 CPU of the bodies (dict of betas/global_orient/body_pose/transl)."""
    like = body.v_template
    verts = []
    B = len(bodies["betas"])
    with torch.no_grad():
        for s in range(0, B, batch_size):
            chunk = {k: v[s:s + batch_size].to(like.device, like.dtype) for k, v in bodies.items()}
            verts.append(body(**chunk).vertices.float().cpu())
    return torch.cat(verts)


# ---------------------------------------------------------------------------------------------- query points
def _surface_samples(vertices: torch.Tensor, faces: torch.Tensor, n: int, g: torch.Generator) -> torch.Tensor:
    """Area-weighted uniform samples on one mesh: vertices (V, 3) float64, faces (F, 3) long -> (n, 3)."""
    tri = vertices[faces]  # (F, 3, 3)
    area = 0.5 * torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=-1).norm(dim=-1)
    fid = torch.multinomial(area, n, replacement=True, generator=g)
    u = torch.rand(n, 2, generator=g, dtype=torch.float64)
    r = u[:, :1].sqrt()  # uniform in the triangle: (1 - r, r (1 - u2), r u2)
    bary = torch.cat([1 - r, r * (1 - u[:, 1:]), r * u[:, 1:]], dim=1)
    return (bary[:, :, None] * tri[fid]).sum(dim=1)


def query_points(vertices: torch.Tensor, faces, n_points: int = 60000, seed: int = VAL_SEED,
                 surface_fraction: float = 0.5, bbox_padding: float = 0.05, surface_sigma: float = 0.01):
    """Evaluation queries per body (module docstring): [uniform in the padded AABB | near-surface].

    Args:
        vertices (B, V, 3) posed bodies; faces (F, 3); n_points per body; seed: body i samples from a
        generator seeded with SeedSequence([seed, 1, i]), so its points do not depend on B or on batching.
    Returns:
        points (B, n_points, 3) float32; is_surface (n_points,) bool, True for the near-surface block.
    """
    v = torch.as_tensor(vertices).detach().cpu().to(torch.float64)
    if v.ndim != 3 or v.shape[-1] != 3:
        raise ValueError(f"vertices must be (B, V, 3), got {tuple(v.shape)}.")
    f = torch.as_tensor(np.asarray(faces), dtype=torch.long)
    n_surf = int(round(n_points * surface_fraction))
    n_unif = n_points - n_surf
    out = torch.empty(v.shape[0], n_points, 3, dtype=torch.float64)
    for i in range(v.shape[0]):
        g = torch.Generator().manual_seed(_sub_seed(seed, 1, i))
        lo, hi = v[i].amin(0) - bbox_padding, v[i].amax(0) + bbox_padding
        out[i, :n_unif] = lo + torch.rand(n_unif, 3, generator=g, dtype=torch.float64) * (hi - lo)
        if n_surf:
            surf = _surface_samples(v[i], f, n_surf, g)
            out[i, n_unif:] = surf + torch.randn(n_surf, 3, generator=g, dtype=torch.float64) * surface_sigma
    is_surface = torch.zeros(n_points, dtype=torch.bool)
    is_surface[n_unif:] = True
    return out.float(), is_surface


# ---------------------------------------------------------------------------------------------- ground truth
def ground_truth(vertices: torch.Tensor, faces, points: torch.Tensor, sign: str = "ray_winding",
                 nsamples: int = 3, cache_dir: str | Path | None = None, use_cache: bool = True) -> torch.Tensor:
    """Exact SDF (B, N) float32 of points (B, N, 3) w.r.t. the meshes (vertices (B, V, 3), faces (F, 3)),
    by `groundtruth.batch_mesh_sdf`, cached as `<cache_dir>/gt_<key>.npz` (key: module docstring)."""
    from .groundtruth import batch_mesh_sdf

    v = torch.as_tensor(vertices).detach().cpu().float()
    p = torch.as_tensor(points).detach().cpu().float()
    f = np.asarray(faces, dtype=np.int64)
    key = digest({"vertices": v, "faces": f, "points": p, "mode": np.frombuffer(
        f"{_GT_CACHE_VERSION}|{sign}|{nsamples}".encode(), dtype=np.uint8)})
    path = Path(cache_dir if cache_dir is not None else default_cache_dir()) / f"gt_{key[:24]}.npz"
    if use_cache and path.exists():
        try:
            with np.load(path) as d:
                if str(d["key"]) == key and d["sdf"].shape == tuple(p.shape[:2]):
                    return torch.from_numpy(d["sdf"].astype(np.float32))
        except (OSError, ValueError, KeyError):
            pass  # unreadable cache entry: recompute and overwrite
    sdf = batch_mesh_sdf(v.numpy(), f, p.numpy(), sign=sign, nsamples=nsamples).astype(np.float32)
    if use_cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
        os.close(fd)
        try:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, sdf=sdf, key=np.array(key))
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)
    return torch.from_numpy(sdf)


# ---------------------------------------------------------------------------------------------- metrics
def iou(pred_occ: torch.Tensor, gt_occ: torch.Tensor) -> torch.Tensor:
    """Intersection over union of boolean occupancies (B, N) -> (B,) float64; 1.0 where both are empty."""
    pred_occ, gt_occ = torch.as_tensor(pred_occ).bool(), torch.as_tensor(gt_occ).bool()
    if pred_occ.shape != gt_occ.shape:
        raise ValueError(f"occupancies must have equal shapes, got {tuple(pred_occ.shape)} and {tuple(gt_occ.shape)}.")
    inter = (pred_occ & gt_occ).sum(-1).double()
    union = (pred_occ | gt_occ).sum(-1).double()
    return torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(union))


def compute_metrics(pred: torch.Tensor, gt: torch.Tensor, is_surface: torch.Tensor) -> Dict[str, torch.Tensor]:
    """Per-body metrics (module docstring). pred, gt (B, N) SDF, negative inside; is_surface (N,) bool.

    Returns: dict name -> (B,) float64: iou_mean, iou_surf, iou_unif, mse_sdf, mse_abs_sdf and the
    `_surf` / `_unif` variants of the two MSEs.
    """
    pred, gt = torch.as_tensor(pred).double(), torch.as_tensor(gt).double()
    if pred.shape != gt.shape or pred.ndim != 2:
        raise ValueError(f"pred and gt must both be (B, N), got {tuple(pred.shape)} and {tuple(gt.shape)}.")
    if not torch.isfinite(pred).all():
        bad = int((~torch.isfinite(pred)).sum())
        raise ValueError(f"the predictor returned {bad} non-finite SDF values; fix the model (NaN weights?) before evaluating.")
    surf = torch.as_tensor(is_surface).bool()
    sets = {"": slice(None), "_surf": surf, "_unif": ~surf}
    m = {}
    for tag in ("_surf", "_unif"):
        m["iou" + tag] = iou(pred[:, sets[tag]] < 0, gt[:, sets[tag]] < 0)
    m["iou_mean"] = 0.5 * (m["iou_surf"] + m["iou_unif"])
    for tag, sel in sets.items():
        p, g = pred[:, sel], gt[:, sel]
        empty = p.shape[1] == 0
        m["mse_sdf" + tag] = torch.full((len(p),), math.nan, dtype=torch.float64) if empty else ((p - g) ** 2).mean(1)
        m["mse_abs_sdf" + tag] = torch.full((len(p),), math.nan, dtype=torch.float64) if empty else \
            ((p.abs() - g.abs()) ** 2).mean(1)
    return m


# ---------------------------------------------------------------------------------------------- evaluation
@dataclass
class EvalResult:
    """Outcome of `evaluate`: metrics (means over bodies), per-body values, timings and provenance."""

    name: str
    metrics: Dict[str, float]
    per_body: Dict[str, list]
    config: dict
    validation_digest: str
    points_digest: str
    seconds: Dict[str, float]
    resources: Optional[dict] = None
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["paper_table1"] = PAPER_TABLE1
        return d


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
        EvalResult (timings of ground truth and predictor in `seconds`; resources None: see evaluate_volume).
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
    seconds = {}
    t0 = time.perf_counter()
    verts = pose_bodies(body, bodies, cfg.batch_size)
    points, is_surface = query_points(verts, body.faces, cfg.n_points, cfg.seed, cfg.surface_fraction,
                                      cfg.bbox_padding, cfg.surface_sigma)
    seconds["points"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    gt = ground_truth(verts, body.faces, points, cfg.gt_sign, cfg.gt_nsamples, cfg.cache_dir, cfg.use_cache)
    seconds["ground_truth"] = time.perf_counter() - t0

    preds = []
    t0 = time.perf_counter()
    B = len(verts)
    like = body.v_template
    with torch.no_grad():
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
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    seconds["predict"] = time.perf_counter() - t0
    per = compute_metrics(torch.cat(preds), gt, is_surface)
    metrics = {k: float(v.mean()) for k, v in per.items()}
    per_body = {"label": validation_labels(B, cfg.seed) if _is_validation_set(bodies, cfg) else [f"body{i}" for i in range(B)]}
    per_body.update({k: v.tolist() for k, v in per.items()})
    return EvalResult(name=name, metrics=metrics, per_body=per_body, config=dataclasses.asdict(cfg),
                      validation_digest=digest(bodies), points_digest=digest(points), seconds=seconds)


def _is_validation_set(bodies, cfg: EvalConfig) -> bool:
    ref = validation_bodies(len(bodies["betas"]), cfg.seed, num_betas=bodies["betas"].shape[1])
    return digest(ref) == digest(bodies)


def evaluate_volume(volume, body, config: Optional[EvalConfig] = None, name: str = "VolumetricSMPL (ours)",
                    resource_spec: Optional[dict] = None, **overrides) -> EvalResult:
    """`evaluate` of `volume.query` (volume attached to `body`); with config.timing also `measure_resources`,
    which needs `resource_spec` (how the subprocess rebuilds the volume: see measure_resources)."""
    cfg = dataclasses.replace(config or EvalConfig(), **overrides)
    volume = volume.to(torch.device(cfg.device))
    if volume.is_sdf:
        res = evaluate(lambda out, pts: volume.query(out, pts), body=body, config=cfg, name=name)
    else:  # occupancy (COAP): level - occupancy is negative inside, so the IoU columns are exact
        res = evaluate(lambda out, pts: volume.level - volume.query(out, pts), body=body, config=cfg, name=name)
        for k in [k for k in res.metrics if k.startswith("mse")]:  # not distances: no SDF error to report
            res.metrics[k] = None
            res.per_body[k] = [None] * len(res.per_body[k])
        res.extra["output"] = "occupancy"
    if cfg.timing:
        if resource_spec is None:
            raise ValueError("timing=True needs resource_spec={'checkpoint': PATH} or {'config': dict, 'init_seed': int} "
                             "so the subprocess can rebuild the same volume; or use evaluate_checkpoint.")
        res.resources = measure_resources(resource_spec, cfg)
    return res


def evaluate_checkpoint(path: str | os.PathLike | None, config: Optional[EvalConfig] = None, body=None,
                        random_init: Optional[dict] = None, **overrides) -> EvalResult:
    """Evaluate a checkpoint (None: the shipped VolumetricSMPL one) with the default body (or `body`).
    The checkpoint says which model it holds (VolumetricSMPL or COAP); occupancy models get IoU only.

    random_init: instead of a checkpoint, {'config': VolumeConfig dict, 'init_seed': int} for a randomly
    initialised volume (benchmarks before training). Other arguments as `evaluate`.
    """
    from .body.model import create_body
    from .checkpoint import checkpoint_model
    from .nn.config import VolumeConfig
    from .volume import attach_volume

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
    res = evaluate_volume(vol, body, config=config, name=name, resource_spec=spec, **overrides)
    res.extra["checkpoint"] = spec.get("checkpoint")
    return res


# ---------------------------------------------------------------------------------------------- resources
def measure_resources(spec: dict, config: Optional[EvalConfig] = None, **overrides) -> dict:
    """Time and memory of one query (batch 1, body 0 of the validation set, all its points), in a fresh
    Python subprocess so that memory peaks are not hidden by earlier allocations of this process.

    Args:
        spec: {'checkpoint': PATH or None (shipped)} or {'config': VolumeConfig dict, 'init_seed': int};
            optional 'body_model': SMPL-format file (default body if None).
        config: EvalConfig (n_points, seed, device, timing_repeats, timing_warmup, ...).
    Returns:
        dict: t_ms (median, encoding included), t_query_ms (median, encoding excluded), t_ms_all /
        t_query_ms_all (every timed run), mem_bytes, mem_kind ('cuda max_memory_allocated' or
        'cpu peak RSS increase'), mem_method (CPU: 'ru_maxrss' when the query raised the process's
        high-water mark, else the peak of the RSS polled every 0.2 ms during the query: model
        construction can peak higher than a query), device, threads.
    """
    cfg = dataclasses.replace(config or EvalConfig(), **overrides)
    from .body.model import create_body

    body = create_body(spec.get("body_model"))
    bodies = {k: v[:1] for k, v in validation_bodies(1, cfg.seed, num_betas=body.num_betas).items()}
    verts = pose_bodies(body, bodies)
    points, _ = query_points(verts, body.faces, cfg.n_points, cfg.seed, cfg.surface_fraction, cfg.bbox_padding,
                             cfg.surface_sigma)
    with tempfile.TemporaryDirectory() as tmp:
        torch.save({"bodies": bodies, "points": points}, os.path.join(tmp, "inputs.pt"))
        job = {"spec": spec, "inputs": os.path.join(tmp, "inputs.pt"), "device": cfg.device,
               "repeats": cfg.timing_repeats, "warmup": cfg.timing_warmup, "threads": cfg.timing_threads or torch.get_num_threads()}
        proc = subprocess.run([sys.executable, "-c", "import sys; from volsmpl.evaluate import _resource_worker; "
                               "_resource_worker(sys.argv[1])", json.dumps(job)],
                              capture_output=True, text=True, timeout=1800)
    if proc.returncode != 0:
        raise RuntimeError(f"the timing subprocess failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _rss_bytes() -> int:
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        return -1


def _maxrss_bytes() -> int:
    import resource
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(r) if sys.platform == "darwin" else int(r) * 1024  # Linux reports KiB


def _malloc_trim() -> None:
    try:
        import ctypes
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: RSS may then include reusable freed memory
        pass


class _RssSampler:
    """Context manager polling this process's RSS in a thread (torch ops release the GIL); .peak in bytes."""

    def __init__(self, interval: float = 2e-4):
        self.interval, self.peak = interval, _rss_bytes()

    def __enter__(self):
        import threading
        self._stop = threading.Event()

        def poll():
            while not self._stop.is_set():
                self.peak = max(self.peak, _rss_bytes())
                self._stop.wait(self.interval)
        self._thread = threading.Thread(target=poll, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, _rss_bytes())
        return False


def _resource_worker(job_json: str) -> None:
    """Body of the timing subprocess (see measure_resources); prints one JSON line."""
    import gc

    job = json.loads(job_json)
    torch.set_num_threads(int(job["threads"]))
    from .body.model import create_body
    from .nn.config import VolumeConfig
    from .volume import attach_volume

    device = torch.device(job["device"])
    spec = job["spec"]
    body = create_body(spec.get("body_model"))
    if "config" in spec:
        torch.manual_seed(int(spec.get("init_seed", 0)))
        vol = attach_volume(body, pretrained=False, config=VolumeConfig.from_dict(spec["config"]))
    else:
        vol = attach_volume(body, checkpoint=spec.get("checkpoint"), model=spec.get("model", "volsmpl"))
    body, vol = body.to(device), vol.to(device)
    data = torch.load(job["inputs"])
    with torch.no_grad():
        out = body(**{k: v.to(device) for k, v in data["bodies"].items()})
    pts = data["points"].to(device)

    def sync():
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    def full():  # encoding included: a fresh encoding (bypasses the per-output cache), then the query
        return vol.query_encoded(vol._encode(out, None), pts)

    gc.collect()
    res = {"device": str(device), "threads": torch.get_num_threads(), "points": int(pts.shape[1])}
    with torch.no_grad():
        if device.type == "cuda":
            sync()
            torch.cuda.reset_peak_memory_stats(device)
            base = torch.cuda.memory_allocated(device)
            full()
            sync()
            res.update(mem_bytes=int(torch.cuda.max_memory_allocated(device) - base),
                       mem_total_bytes=int(torch.cuda.max_memory_allocated(device)),
                       mem_kind="cuda max_memory_allocated", mem_method="torch.cuda.max_memory_allocated")
        else:
            _malloc_trim()  # return freed set-up memory to the OS, so the query's pages count in the RSS
            base, peak0 = _rss_bytes(), _maxrss_bytes()
            with _RssSampler() as sampler:
                full()
            peak1 = _maxrss_bytes()
            # ru_maxrss is a high-water mark that Linux carries over fork+exec from the parent, so a parent with a
            # large RSS hides the query's peak: then fall back to the polled RSS.
            if peak1 > peak0:  # the query set a new high-water mark: exact
                res.update(mem_bytes=int(peak1 - base), mem_total_bytes=int(peak1), mem_method="ru_maxrss")
            else:  # the set-up's peak was higher: use the sampled RSS (may miss sub-millisecond spikes)
                res.update(mem_bytes=int(sampler.peak - base), mem_total_bytes=int(sampler.peak),
                           mem_method=f"RSS sampled every {sampler.interval * 1e3:g} ms")
            res.update(mem_kind="cpu peak RSS increase")
        for _ in range(int(job["warmup"])):
            full()
        sync()
        t_full, t_query = [], []
        for _ in range(int(job["repeats"])):
            t0 = time.perf_counter()
            full()
            sync()
            t_full.append((time.perf_counter() - t0) * 1e3)
        enc = vol._encode(out, None)
        for _ in range(int(job["warmup"])):
            vol.query_encoded(enc, pts)
        sync()
        for _ in range(int(job["repeats"])):
            t0 = time.perf_counter()
            vol.query_encoded(enc, pts)
            sync()
            t_query.append((time.perf_counter() - t0) * 1e3)
    res.update(t_ms=float(np.median(t_full)), t_query_ms=float(np.median(t_query)), t_ms_all=t_full, t_query_ms_all=t_query)
    print(json.dumps(res))


# ---------------------------------------------------------------------------------------------- report
def _fmt_mem(r: dict) -> str:
    if not r:
        return "-"
    mib = r["mem_bytes"] / 2 ** 20
    where = "GPU" if r["mem_kind"].startswith("cuda") else "CPU"
    s = f"{mib / 1024:.2f} G {where}" if mib >= 1024 else f"{mib:.0f} M {where}"
    return s


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
    p = sub.add_parser("eval", help="evaluate a checkpoint on the validation set (paper Table 1 protocol)",
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
    p.add_argument("--out", default=None, help="write the results as JSON here")
    return p


def run(args) -> int:
    if args.checkpoint is not None and args.random_init:
        raise ValueError("--checkpoint and --random-init exclude each other; give one.")
    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads {args.threads}: give a positive number of CPU threads.")
        torch.set_num_threads(args.threads)
    cfg = EvalConfig(n_bodies=args.n_bodies, n_points=args.points, seed=args.seed, batch_size=args.batch_size,
                     device=args.device, timing=args.timing, timing_repeats=args.repeats, cache_dir=args.cache_dir,
                     use_cache=not args.no_cache, timing_threads=args.threads, gt_sign=args.gt_sign)
    res = evaluate_checkpoint(args.checkpoint, config=cfg, random_init={"config": {}, "init_seed": 0} if args.random_init else None)
    print(f"validation set: {cfg.n_bodies} bodies (seed {cfg.seed}, digest {res.validation_digest[:12]}), "
          f"{cfg.n_points} points each; ground truth {res.seconds['ground_truth']:.1f} s, "
          f"model {res.seconds['predict']:.1f} s")
    print(format_table(res))
    if res.resources:
        print(f"time: batch 1 x {res.resources['points']} points on {res.resources['device']} "
              f"({res.resources['threads']} threads), median of {cfg.timing_repeats}; t = encoding + query, "
              f"t query = query only; mem = {res.resources['mem_kind']}")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        with open(args.out, "w") as fh:
            json.dump(res.to_dict(), fh, indent=1)
        print(f"wrote {args.out}")
    return 0
