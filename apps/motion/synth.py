"""Scene-constrained walk synthesis: one start/goal pair, one volume, the objective of supp. D.3 (objective.py),
the metrics, and the per-frame cost of the collision term.

    res = synthesize(model, volume, scene, start, goal, w=1.0, cfg=SynthConfig())
    res["metrics"]   # goal_dist_m, collision_cm, collision_frames_pct, foot_skate_cm, ...
    cost = measure_cost(volume, walk, scene.points)   # per-frame ms and MB, forward and forward + backward

Variables (one problem per sequence): the walking model's heading change and speed per primitive (speed through a
sigmoid into [0.3, 2.2] m/s, so the model's `speed >= 0` always holds), and optionally (`residuals=True`) per-frame
pose residuals with the model's quadratic pose prior; the walk starts at the start facing the goal, at the speed that
covers the straight line in the sequence's duration. Optimiser: Adam lr 0.05, linear decay to 0 over `iters`
steps, gradients scaled to unit length per sequence (DartControl's optimisation).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np
import torch

from volsmpl.runtime.meter import Meter
from volsmpl.geometry.point_mesh_distance import mesh_signed_distance
from volsmpl.optim import Term, Variable, optimize

from volsmpl.apps.motion import walk as W
from .objective import (SceneCollision, frame_subset, goal_distance, goal_loss, linear_decay, unit_grad_adam,
                        walk_output)

SPEED_LO, SPEED_HI = 0.3, 2.2
PEN_TOL = 0.002     # metres: a frame counts as colliding when a scene point is deeper than this inside the body


@dataclass
class SynthConfig:
    """frames: T (>= 4, the jerk term needs 4); iters: Adam steps; lr: initial learning rate (linear decay);
    residuals/w_prior/residual_lr: optimise pose residuals too, with the pose prior at this weight and their own lr;
    floor_in_loss: keep the floor points in the collision term (they always sit under the feet, so every frame's feet
    get encoded: slow on a CPU; the metrics count them either way); coll_frames: 'all' or n evenly spaced frames."""

    frames: int = 80
    iters: int = 100
    lr: float = 0.05
    residuals: bool = False
    w_prior: float = 1.0
    residual_lr: float = 0.01
    floor_in_loss: bool = False
    coll_frames: object = "all"
    device: str = "cpu"


def speed_of_control(u: torch.Tensor) -> torch.Tensor:
    """Walking speed (m/s) of the unbounded speed control: a sigmoid onto [SPEED_LO, SPEED_HI]."""
    return SPEED_LO + (SPEED_HI - SPEED_LO) * torch.sigmoid(u)


def control_of_speed(s: float) -> float:
    """The inverse of speed_of_control (speeds outside the range are brought just inside it)."""
    x = min(max((s - SPEED_LO) / (SPEED_HI - SPEED_LO), 1e-3), 1 - 1e-3)
    return math.log(x / (1 - x))


def initial_controls(start, goal, frames: int, dtype=torch.float32, device="cpu") -> dict:
    """Straight walk from start towards goal covering the distance in the sequence's duration."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    d = goal - start
    P = W.num_primitives(frames)
    speed = float(np.linalg.norm(d)) / ((frames - 1) / W.FPS)
    return {"heading_delta": torch.zeros(1, P, dtype=dtype, device=device),
            "speed_u": torch.full((1, P), control_of_speed(speed), dtype=dtype, device=device),
            "heading0": torch.tensor([math.atan2(d[0], d[1])], dtype=dtype, device=device),
            "start": torch.as_tensor(start[None], dtype=dtype, device=device)}


def check_frames(frames) -> int:
    """--frames: a whole number >= 4 (the walking model needs 2 frames, the objective's jerk term 4)."""
    if int(frames) != frames or int(frames) < 4:
        raise ValueError(f"--frames {frames}: give a whole number >= 4 (the jerk term of the objective needs 4 "
                         f"frames)")
    return int(frames)


def synthesize(model: W.WalkModel, volume, scene, start, goal, w: float = 1.0, cfg: SynthConfig | None = None,
               progress: bool | None = False) -> dict:
    """Optimise one walk from start to goal (floor positions (x, z)) in `scene` (scenes.MotionScene).

    Returns {'walk': the final Walk (detached), 'metrics': evaluate(...), 'optim': the harness summary,
    'collision_frames': the evaluated frames, 'records': per-step totals}.
    """
    return synthesize_batch(model, volume, scene, [(start, goal)], w, cfg, progress)[0]


def synthesize_batch(model: W.WalkModel, volume, scene, pairs, w: float = 1.0, cfg: SynthConfig | None = None,
                     progress: bool | None = False) -> list:
    """Optimise the walks of several (start, goal) pairs of one scene in one run of the harness: each walk keeps
    its own objective, unit-length gradient and Adam moments (volsmpl.optim's problems), while the collision term
    culls and groups the frames of all walks together (on a GPU: one large query instead of many small ones).
    Each result is `synthesize`'s for its pair, up to float rounding; `metrics` adds 'batch' (the pairs optimised
    together), and with more than one pair 'optim_s' is the run's wall time shared equally and 'optim_peak_mem_mb'
    the run's peak (all walks).
    """
    cfg = cfg or SynthConfig()
    T = check_frames(cfg.frames)
    pairs = list(pairs)
    if not pairs:
        raise ValueError("synthesize_batch needs at least one (start, goal) pair")
    like = model.body.v_template
    inits = [initial_controls(s, g, T, like.dtype, like.device) for s, g in pairs]
    init = {k: torch.cat([i[k] for i in inits]) for k in inits[0]}
    B = len(pairs)
    goal_t = torch.as_tensor(np.asarray([g for _, g in pairs], float), dtype=like.dtype, device=like.device)
    pts = scene.points if cfg.floor_in_loss else scene.points[~scene.floor]
    coll = SceneCollision(volume, pts if len(pts) else scene.points[:1] * 0 + 1e3, cfg.coll_frames)
    variables = {"heading_delta": Variable(init["heading_delta"]), "speed_u": Variable(init["speed_u"])}
    if cfg.residuals:
        variables["residual"] = Variable(torch.zeros(B, T, 69, dtype=like.dtype, device=like.device), lr=cfg.residual_lr)

    def prepare(s):
        return {"walk": model(s.heading_delta, speed_of_control(s.speed_u), s.get("residual"), frames=T, start=init["start"],
                              heading0=init["heading0"])}

    terms = {"goal": Term(lambda s: goal_loss(s.walk.joints[:, -1, 0], goal_t), 1.0),
             "collision": Term(lambda s: coll(s.walk), float(w)),
             "jerk": Term(lambda s: W.jerk(s.walk.joints), 1.0)}
    if cfg.residuals:
        terms["prior"] = Term(lambda s: W.pose_prior(s.residual), cfg.w_prior)
    t0 = time.perf_counter()
    res = optimize(variables, terms, prepare=prepare, optimizer=unit_grad_adam, lr=cfg.lr,
                   schedule=linear_decay(cfg.iters), max_iters=cfg.iters, progress=progress,
                   frozen=[volume], device=cfg.device)
    wall = time.perf_counter() - t0
    v = res.variables
    with torch.no_grad():
        walks = model(v["heading_delta"], speed_of_control(v["speed_u"]), v.get("residual"), frames=T,
                      start=init["start"], heading0=init["heading0"])
    summ = res.summary()
    out = []
    for b, (_, goal) in enumerate(pairs):
        walk = walks.select(b)
        metrics = evaluate(walk, model.body.faces, scene, goal)
        metrics.update({"iterations": res.iterations[b], "stop": res.status[b], "optim_s": wall / B, "ms_per_iter": summ["ms_per_iter"],
                        "optim_peak_mem_mb": summ["peak_mem_mb"], "memory_kind": summ["memory_kind"], "batch": B,
                        "final_terms": {k: vv[b] for k, vv in res.records[-1].terms.items()},
                        "initial_terms": {k: vv[b] for k, vv in res.records[0].terms.items()}})
        out.append({"walk": walk, "metrics": metrics, "collision_frames": [int(i) for i in frame_subset(T, cfg.coll_frames)],
                    "records": [r.total[b] for r in res.records], "config": asdict(cfg), "w": float(w)})
    return out


@torch.no_grad()
def penetration_depths(vertices: torch.Tensor, faces, points: np.ndarray, margin: float = 0.05) -> list:
    """Exact depth (m) of the scene points inside each posed mesh: per frame an array of the depths of the points
    with negative signed distance (mesh_signed_distance; points outside a frame's bounding box are outside).
    vertices (T, V, 3) -> list of T arrays."""
    P = torch.as_tensor(np.asarray(points), dtype=torch.float64)
    F = torch.as_tensor(np.asarray(faces)).long()
    out = []
    for t in range(vertices.shape[0]):
        v = vertices[t].detach().cpu().double()
        lo, hi = v.amin(0) - margin, v.amax(0) + margin
        cand = P[((P >= lo) & (P <= hi)).all(-1)]
        if len(cand) == 0:
            out.append(np.zeros(0))
            continue
        sd = mesh_signed_distance(v, F, cand)
        out.append((-sd[sd < 0]).numpy())
    return out


def evaluate(walk: W.Walk, faces, scene, goal) -> dict:
    """Metrics of one walk (B = 1): horizontal goal distance, exact collision (every scene point, floor included,
    and obstacles only), foot skating, jerk, path length."""
    V = walk.vertices[0]
    depths = penetration_depths(V, faces, scene.points)
    obst = penetration_depths(V, faces, scene.points[~scene.floor]) if scene.floor.any() else depths
    frame_mean = np.array([d.mean() if len(d) else 0.0 for d in depths])
    frame_obst = np.array([d.mean() if len(d) else 0.0 for d in obst])
    frame_max = np.array([d.max() if len(d) else 0.0 for d in depths])
    pel = walk.joints[0, :, 0]
    g = torch.as_tensor(np.asarray(goal, float)[None], dtype=pel.dtype)
    return {
        "goal_dist_m": float(goal_distance(pel[-1:], g)[0]),
        "collision_cm": 100.0 * float(frame_mean.mean()),
        "collision_obstacles_cm": 100.0 * float(frame_obst.mean()),
        "collision_frames_pct": 100.0 * float((frame_max > PEN_TOL).mean()),
        "max_depth_cm": 100.0 * float(frame_max.max()),
        "points_inside_per_frame": float(np.mean([len(d) for d in depths])),
        "foot_skate_cm": float(W.foot_skate(walk.joints, walk.contacts)[0]),
        "jerk_max": float(W.jerk(walk.joints, weight=1.0)[0]),
        "path_m": float((pel[1:, [0, 2]] - pel[:-1, [0, 2]]).norm(dim=-1).sum()),
        "pelvis_xz": pel[:, [0, 2]].cpu().numpy().round(4).tolist(),
    }


def published_penetration(volume, out, points: torch.Tensor) -> torch.Tensor:
    """The collision term as COAP's published code computes it: every part's decoder at every scene point (no
    culling by boxes or body bounds; a `dense` volume masks the parts whose box does not hold the point), the
    penetration summed per body. Same values as `volume.collision_loss(out, points, 'sum')`, far more work.

    Shape: out with B bodies, points (N, 3) -> (B,).
    """
    B = out.vertices.shape[0]
    return volume.penetration(volume.query(out, points.expand(B, -1, -1), dense=True)).sum(dim=1)


def measure_cost(volume, walk: W.Walk, points, frames: int = 8, repeats: int = 3, device="cpu", loss=None) -> dict:
    """Per-frame time and peak memory of the collision term on the full cloud (the paper's per-frame figures):
    `frames` evenly spaced frames of `walk` batched through `volume.collision_loss(out, points, 'sum')` (or
    `loss(volume, out, points)` -> (B,), e.g. `published_penetration`), forward alone (autograd on: the graph an
    optimisation keeps) and forward + backward (to the vertices, joints and pose), the median of `repeats` runs
    after a warm-up, divided by the frames."""
    T = walk.body_pose.shape[1]
    rows = torch.as_tensor(np.unique(np.round(np.linspace(0, T - 1, min(frames, T))).astype(int)))
    base = walk_output(walk, rows)
    P = torch.as_tensor(np.asarray(points), dtype=base.vertices.dtype, device=base.vertices.device)
    n = len(rows)

    def leaf():
        from types import SimpleNamespace
        return SimpleNamespace(**{k: getattr(base, k).detach().clone().requires_grad_(True)
                                  for k in ("vertices", "joints", "full_pose")})

    def fwd():
        if loss is not None:
            return loss(volume, leaf(), P).sum()
        return volume.collision_loss(leaf(), P, reduction="sum").sum()

    def fwdbwd():
        fwd().backward()

    fwdbwd()   # warm-up
    res = {}
    for name, fn in (("fwd", fwd), ("fwdbwd", fwdbwd)):
        ts, ms = [], []
        for _ in range(repeats):
            with Meter(device) as m:
                r = fn()
                del r
            ts.append(m.seconds)
            ms.append(m.peak_bytes)
        res[f"ms_per_frame_{name}"] = 1e3 * float(np.median(ts)) / n
        res[f"mem_per_frame_{name}_mb"] = float(np.median(ms)) / n / 2 ** 20
        res["memory_kind"] = m.kind
    res["frames_measured"] = n
    res["points"] = int(len(P))
    return res
