"""Sampling a split with each guide, and its measures (what `volsmpl egohmr sample` reports).

    prep = prepare(net, body, frames)                        # regressor outputs, scene crops, guidance points
    recs = sample_frames(net, body, frames, prep, volume, GuideOptions(scale=30))   # per-frame records
    b = max_batch(net, body, frames[0], volume, opts, budget_mb=2048)                # measured, not assumed

Every guide of a run samples from the same noise (a generator seeded per batch) and is scored by the same exact
tests, so rows differ only by the guidance.
"""
from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass

import numpy as np
import torch

from .diffusion import Guidance, Schedule, sample
from .guidance import CollisionScore
from .metrics import contact, frame_errors, inside_masks, joint_means
from .pose import POSE_DIM, pose_body_finite, pose_joints

GUIDE_POINTS = 20000  # scene points of the collision score (supp. D.2: 20k in a 2 x 2 m cube)
GUIDE_CUBE = 2.0
MIN_SCENE_POINTS = 500  # fewer distinct scene points in the cube are refused (data.scene_points, a user's scene)


@dataclass
class GuideOptions:
    """How the sampler is guided (diffusion.Guidance, guidance.CollisionScore; paper defaults: pelvis_step 0 and
    support 'off' keep the regressed pelvis)."""

    scale: float = 0.0
    steps: int = 10
    plain_steps: int = 5
    plain_factor: float = 1.0
    wrt: str = "denoised"
    joints: str = "all"
    reduce: str = "mean"
    pelvis_step: float = 0.0
    support: str = "off"
    pelvis_along: str = "ray"

    @property
    def guided(self) -> bool:
        """Whether these options guide at all (a pose scale, a pelvis step or the support term)."""
        return bool(self.scale or self.pelvis_step or self.support != "off")


@torch.no_grad()
def prepare(net, body, frames, n_guide: int = GUIDE_POINTS, seed: int = 0) -> dict:
    """Guide-independent inputs of frames: keypoint features, regressed pelvis / betas / pose, scene crops around
    the regressed pelvis for the condition (net.config.scene_points) and for guidance and the collision metric
    (n_guide points, camera frame), the world's up in the camera frame ('up', the second column of the frame's
    world-to-camera rotation R) and which guidance points lie on a support ('support', support.support_mask).
    n_guide=0 skips the guidance points."""
    from .dataset import frame_tensors, scene_crops

    dev = next(net.parameters()).device
    d = {k: v.to(dev) for k, v in frame_tensors(frames, n_scene=0).items()}
    c_kp = net.keypoints(d["kp"])
    pelvis, betas, pose_reg = net.regress(c_kp)
    d.update(c_kp=c_kp, pelvis_hat=pelvis, betas_hat=betas, pose_reg=pose_reg)
    d["scene_cond"] = scene_crops(frames, pelvis, net.config.scene_points, net.config.scene_size, seed).to(dev)
    if n_guide:
        from .support import support_mask

        d["guide_points"] = scene_crops(frames, pelvis, n_guide, GUIDE_CUBE, seed + 7919).to(dev) + pelvis[:, None]
        d["up"] = torch.as_tensor(np.stack([np.asarray(f.R, np.float64)[:, 1] for f in frames]),
                                  dtype=torch.float32, device=dev)
        d["support"] = torch.as_tensor(np.stack([support_mask(p.cpu().numpy(), u.cpu().numpy())
                                                 for p, u in zip(d["guide_points"], d["up"])]), device=dev)
    return d


def _rows(d: dict, idx) -> dict:
    return {k: v[idx] for k, v in d.items()}


def guide_score(body, volume, d: dict, opts: GuideOptions):
    """The CollisionScore of a prepared batch d under opts (its support term from d's 'support' and 'up' when
    opts.support is 'on')."""
    from .support import SupportGap

    sup = None
    if opts.support != "off":
        sup = SupportGap(d["guide_points"], d["support"], d["up"], body.faces)
    return CollisionScore(body, volume, d["betas_hat"], d["pelvis_hat"], d["guide_points"], opts.wrt, opts.joints,
                          opts.reduce, pelvis_step=opts.pelvis_step, support=sup, along=opts.pelvis_along)


def draw(net, body, d: dict, volume=None, opts: GuideOptions | None = None, seed: int = 0, quiet: bool = True,
         desc: str = "denoising"):
    """One sample per frame of a prepared batch, guided by `volume` (None: unguided). Returns (poses (B, 144),
    pelvis (B, 3): the regressed one, or where the guidance moved it, the CollisionScore or None).
    quiet=False: a bar `desc` over the denoising steps on a terminal (volsmpl.apps.progress)."""
    from volsmpl.apps.progress import progress

    sched = Schedule(net.config.steps)
    cond = net.condition(d["c_kp"], d["scene_cond"], d["pelvis_hat"])
    gen = torch.Generator().manual_seed(seed)
    guide, score = None, None
    if volume is not None and opts is not None and opts.guided:
        score = guide_score(body, volume, d, opts)
        guide = Guidance(score.gradient, opts.scale, opts.steps, opts.plain_steps, opts.plain_factor,
                         pelvis=score.moves_pelvis)
    bar = lambda steps: progress(steps, desc, quiet=quiet, total=sched.T, unit="step")  # noqa: E731
    warm = volume.warm_start() if guide is not None else contextlib.nullcontext()
    with warm:   # a volume set to carry code corrections carries the frames' through the denoising steps
        x = sample(lambda xt, t: net.denoise(xt, t, cond), (len(cond), POSE_DIM), sched, gen, guide,
                   device=cond.device, bar=bar)
    pelvis = d["pelvis_hat"] if score is None else score.placed()
    return x, pelvis, score


def sample_frames(net, body, frames, prep: dict, volume=None, opts: GuideOptions | None = None, batch: int = 16,
                  seed: int = 0, scenes=None, poses: torch.Tensor | None = None, quiet: bool = True,
                  desc: str = "egohmr") -> list[dict]:
    """Per-frame records of one guide over frames (prep: `prepare` of the same frames): errors (mm), the
    recovered pelvis (camera frame, m) and its error (`pelvis_err_mm`), collision ratio, contact, sampling seconds
    per frame, and the frame's status judged without ground truth (status.py: `status`, `status_why` and the
    measures it reads). scenes: the frames' scene meshes (camera frame) for contact.
    poses: score these pose vectors (B, 144) instead of sampling (e.g. the regressor's, prep['pose_reg']).
    quiet=False: a bar `desc` over the batches and one over each batch's denoising steps, on a terminal."""
    from volsmpl.apps.progress import progress

    from .data import scene_mesh
    from .status import judge, measure

    recs = []
    faces = torch.as_tensor(body.faces, device=prep["kp"].device)
    starts = range(0, len(frames), batch)
    for s in progress(starts, desc, quiet=quiet, total=len(starts), unit="batch"):
        idx = torch.arange(s, min(s + batch, len(frames)), device=prep["kp"].device)
        d = _rows(prep, idx)
        t0 = time.perf_counter()
        x, pelvis = (draw(net, body, d, volume, opts, seed=seed + s, quiet=quiet, desc=f"{desc}: denoising")[:2]
                     if poses is None else (poses[idx], d["pelvis_hat"]))
        secs = (time.perf_counter() - t0) / len(idx)
        with torch.no_grad():
            out = pose_body_finite(body, d["betas_hat"], x, pelvis)
            pel_err = 1000.0 * (pelvis - d["pelvis"]).norm(dim=-1).cpu().numpy()
            err = frame_errors(out.joints[:, :24], d["joints"], d["visible"])
            # the collision ratio's inside test, kept for the status's penetration depth; a diverged body (NaN or
            # Inf) has no collision ratio and no contact, and its status says so
            finite = torch.isfinite(out.vertices).flatten(1).all(1).cpu().numpy()
            inside = inside_masks(out.vertices, faces, d["guide_points"])
            coll = np.where(finite, inside.float().mean(1).cpu().numpy(), np.nan)
            checks = measure(x, out.joints[:, :24], out.vertices, faces, d["kp"], d["guide_points"], inside)
        meshes = [scenes[int(i)] if scenes is not None else scene_mesh(frames[int(i)]) for i in idx]
        cont = np.zeros(len(idx), dtype=bool)
        if finite.any():
            cont[finite] = contact(out.vertices.cpu().numpy()[finite], [m for m, ok in zip(meshes, finite) if ok])
        for j, i in enumerate(idx.tolist()):
            status, why = judge(checks[j])
            recs.append({"frame": frames[i].name, "activity": frames[i].activity,
                         **{k: float(v[j]) for k, v in err.items()},
                         "pelvis_err_mm": float(pel_err[j]), "collision_ratio": float(coll[j]),
                         "contact": bool(cont[j]), "s_per_frame": secs, **checks[j], "status": status,
                         "status_why": why, "pose": x[j].cpu().tolist(), "pelvis": pelvis[j].cpu().tolist()})
    return recs


def summarize(recs: list[dict]) -> dict:
    """A guide's row: joint-weighted MPJPE (all / visible / invisible), PA-MPJPE, pelvis error (mm), the joints'
    reprojection error (status.reprojection_error), collision ratio, contact %, seconds per frame; means over
    frames. n_diverged: the frames whose sample holds NaN or Inf (status 'diverged'); where there is one, the row's
    errors, collision ratio and contact are NaN (a mean without them would hide it)."""
    if not recs:
        return {"n_frames": 0}
    arr = lambda k: np.array([r[k] for r in recs], dtype=np.float64)  # noqa: E731
    errs = {k: arr(k) for k in ("mpjpe_mm", "mpjpe_visible_mm", "mpjpe_invisible_mm", "n_visible", "n_invisible")}
    row = {"n_frames": len(recs), **joint_means(errs),
           "pa_mpjpe_mm": float(arr("pa_mpjpe_mm").mean()),
           "pelvis_err_mm": float(np.mean([r.get("pelvis_err_mm", np.nan) for r in recs])),
           "reproj_err": float(np.mean([r.get("reproj_err", np.nan) for r in recs])),
           "collision_ratio": float(arr("collision_ratio").mean()),
           "contact_pct": 100.0 * float(np.mean([r["contact"] for r in recs])),
           "s_per_frame": float(arr("s_per_frame").mean())}
    row["n_diverged"] = sum(not r.get("finite", True) for r in recs)
    if row["n_diverged"]:
        row.update({k: float("nan") for k in ("mpjpe_mm", "mpjpe_visible_mm", "mpjpe_invisible_mm", "pa_mpjpe_mm",
                                               "pelvis_err_mm", "reproj_err", "collision_ratio", "contact_pct")})
    return row


def by_activity(recs: list[dict]) -> dict:
    """`summarize`'s MPJPE, PA-MPJPE, pelvis error, collision ratio and contact per activity of the frames
    ({activity: row}, sorted by name): where the sampler's error lies (seated or leaning bodies sampled upright)."""
    keep = ("n_frames", "mpjpe_mm", "pa_mpjpe_mm", "pelvis_err_mm", "collision_ratio", "contact_pct")
    acts = sorted({r["activity"] for r in recs})
    return {a: {k: v for k, v in summarize([r for r in recs if r["activity"] == a]).items() if k in keep}
            for a in acts}


def paired_interval(recs: list[dict], base: list[dict], key: str = "mpjpe_mm") -> tuple[float, float, float]:
    """Mean of the per-frame differences recs[key] - base[key] (the same frames, in order) and its 95 % BCa
    bootstrap interval (volsmpl.apps.stats.paired_mean_ci); NaN where a frame has none (a diverged one) or the
    lists differ in length."""
    from volsmpl.apps.stats import paired_mean_ci

    a = np.array([r[key] for r in recs], np.float64)
    b = np.array([r[key] for r in base], np.float64)
    if len(a) != len(b) or len(a) < 2 or not (np.isfinite(a).all() and np.isfinite(b).all()):
        return float("nan"), float("nan"), float("nan")
    return paired_mean_ci(a, b)


@torch.no_grad()
def regressor_and_sample_errors(net, body, frames, seed: int = 0) -> dict:
    """Validation during training: MPJPE (all, invisible joints) of the regressor's pose and of one unguided
    diffusion sample per frame, joints by forward kinematics with the regressed shape."""
    d = prepare(net, body, frames, n_guide=0, seed=seed)
    x = draw(net, body, d, seed=seed)[0]
    res = {}
    for name, pose in (("regressor", d["pose_reg"]), ("diffusion", x)):
        J = pose_joints(body, d["betas_hat"], pose, d["pelvis_hat"])
        m = joint_means(frame_errors(J, d["joints"], d["visible"]))
        res[f"{name}_mpjpe_mm"] = m["mpjpe_mm"]
        for kind in ("invisible", "visible"):
            v = m[f"mpjpe_{kind}_mm"]
            res[f"{name}_{kind}_mm"] = float("nan") if v is None else v
    res["pelvis_err_mm"] = float(1000 * (d["pelvis_hat"] - d["pelvis"]).norm(dim=-1).mean())
    return res


def max_batch(net, body, frame_prep: dict, volume, opts: GuideOptions, budget_mb: float, device="cpu",
              cap: int = 128, also: tuple = ()) -> dict:
    """The largest batch whose guided sampling step (denoiser + collision gradient) stays within `budget_mb`
    of peak memory, measured (volsmpl.runtime.meter) by doubling from 1 up to `cap`, then bisecting. frame_prep: one
    prepared frame (batch of 1) replicated; `also`: further batch sizes to measure (e.g. the run's).
    Returns {'max_batch', 'measured_mb': {batch: peak MB}, 'capped'}."""
    from volsmpl.runtime.meter import Meter, malloc_trim

    measured = {}

    def peak(b: int) -> float:
        d = {k: v.expand(b, *v.shape[1:]).contiguous() for k, v in frame_prep.items()}
        sched = Schedule(net.config.steps)
        malloc_trim()
        with Meter(device) as m:
            cond = net.condition(d["c_kp"], d["scene_cond"], d["pelvis_hat"])
            dev = d["c_kp"].device
            xt = torch.randn(b, POSE_DIM, device=dev)
            tt = torch.zeros(b, dtype=torch.long, device=dev)
            with torch.no_grad():
                x0 = net.denoise(xt, tt, cond)
            if volume is not None and opts.guided:
                score = guide_score(body, volume, d, opts)
                Guidance(score.gradient, opts.scale, pelvis=score.moves_pelvis).step(xt, x0, 0,
                                                                                   sched.posterior(x0, xt, tt)[1])
        measured[b] = m.peak_bytes / 2**20
        return measured[b]

    for b in also:
        peak(b)
    best, b = 0, 1
    while b <= cap and peak(b) <= budget_mb:
        best, b = b, b * 2
    lo, hi = best, min(b, cap + 1)
    while hi - lo > 1 and lo >= 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if peak(mid) <= budget_mb else (lo, mid)
    return {"max_batch": lo, "measured_mb": {str(k): round(v, 1) for k, v in sorted(measured.items())},
            "capped": lo >= cap}


__all__ = ["GuideOptions", "prepare", "guide_score", "draw", "sample_frames", "summarize", "by_activity", "paired_interval",
           "regressor_and_sample_errors", "max_batch", "GUIDE_POINTS", "GUIDE_CUBE", "MIN_SCENE_POINTS"]
