"""The objective of scene-constrained walking (supp. D.3): goal term, scene collision term, jerk; the optimiser.

    L = Huber_1(p_T, g) + w * L_coll + 0.1 * max jerk          (walk.jerk carries the 0.1)

- `goal_loss`: Huber (delta 1, torch's smooth L1) between the last frame's pelvis and the goal, on the floor's
  two axes (x, z; the goal is a floor position, the pelvis height is the body's own), summed over the two.
- `SceneCollision`: L_coll = mean over the evaluated frames of sum over scene points of the volume's per-point
  penetration (`volume.collision_loss(..., reduction='sum')`: ReLU(-f) for 'volsmpl' and 'mesh', COAP's
  occupancy term for 'coap'). All frames of all sequences go through the volume batched; points in no padded part
  box of a frame are left out of that frame (their penetration is exactly 0 for every kind: the analytic box
  distance is positive, COAP's masked occupancy is 0, and such points are outside the mesh), and frames are grouped
  by the set of parts that hold points, so the encoder runs only on (frame, part) pairs that matter. The value and
  the gradient are those of `collision_loss` on the full cloud (tests/apps/motion/test_app.py checks it).
  `frames='all'` or an int n: only n evenly spaced frames (the authors' COAP setting, 16, when all frames do not fit).
- `UnitGradAdam`: Adam whose gradients are scaled to unit length per problem (over all variables of that problem)
  before each step, as DartControl's `optim_unit_grad`.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import torch

from volsmpl.geometry.boxes import inside_boxes
from volsmpl.body.partition import Partition

__all__ = ["goal_loss", "goal_distance", "SceneCollision", "UnitGradAdam", "linear_decay", "frame_subset",
           "walk_output"]

FAR = 1.0e3   # filler points (padding of per-frame point sets) sit this far above the frame's pelvis
AABB_MARGIN = 0.4   # metres around a frame's vertices where points are tested against the padded part boxes


def goal_loss(pelvis: torch.Tensor, goal: torch.Tensor, delta: float = 1.0) -> torch.Tensor:
    """Huber (delta) between the last frame's pelvis and the goal on the floor axes, summed over x and z.

    Shape: pelvis (B, 3) (the last frame's pelvis, Y up), goal (B, 3) or (B, 2) (x, z) -> (B,).
    Example:
        >>> goal_loss(torch.tensor([[0.5, 0.9, 0.0]]), torch.tensor([[0.0, 0.0]]))   # 0.5 * 0.25 = 0.125
    """
    g = goal if goal.shape[-1] == 2 else goal[..., [0, 2]]
    p = pelvis[..., [0, 2]]
    return torch.nn.functional.huber_loss(p, g.to(p), reduction="none", delta=delta).sum(-1)


def goal_distance(pelvis: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """Horizontal distance (m) from the last frame's pelvis to the goal. (B, 3), (B, 3)|(B, 2) -> (B,)."""
    g = goal if goal.shape[-1] == 2 else goal[..., [0, 2]]
    return (pelvis[..., [0, 2]] - g.to(pelvis)).norm(dim=-1)


def walk_output(walk, rows=None) -> SimpleNamespace:
    """A body-output view of a Walk (vertices, joints, full_pose per frame, world frame), rows b*T + t
    (all when None), for `volume.collision_loss` without a second body forward pass."""
    B, T = walk.body_pose.shape[:2]
    v = walk.vertices.reshape(B * T, *walk.vertices.shape[2:])
    j = walk.joints.reshape(B * T, *walk.joints.shape[2:])
    fp = torch.cat([walk.global_orient, walk.body_pose], dim=-1).reshape(B * T, -1)
    if rows is not None:
        v, j, fp = v[rows], j[rows], fp[rows]
    return SimpleNamespace(vertices=v, joints=j, full_pose=fp)


def frame_subset(T: int, frames) -> np.ndarray:
    """Indices of the frames the collision term evaluates: all (frames 'all' or None or >= T), else `frames`
    evenly spaced ones including the first and the last."""
    if frames in (None, "all") or int(frames) >= T:
        return np.arange(T)
    n = int(frames)
    if n < 1:
        raise ValueError(f"the collision term needs at least 1 frame, got {frames}")
    return np.unique(np.round(np.linspace(0, T - 1, n)).astype(int))


class SceneCollision:
    """L_coll of a batch of walks against one scene cloud (module docstring).

    Args:
        volume: any BodyVolume (`volsmpl.attach_volume(body, model=...)`).
        points: (N, 3) scene points (torch or numpy), the body's dtype/device after `.to`.
        frames: 'all' or the number of evenly spaced frames to evaluate.
    Call: term(walk) -> (B,) mean over the evaluated frames of the summed penetration; `last` keeps the per-frame
    values (B, n) of the last call and `last_stats` how many (frame, point) and (frame, part) pairs went in.
    """

    def __init__(self, volume, points, frames="all"):
        pts = torch.as_tensor(np.asarray(points) if not torch.is_tensor(points) else points)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"scene points must be (N, 3), got {tuple(pts.shape)}")
        if len(pts) == 0:
            raise ValueError("the scene cloud is empty: nothing to collide with")
        if not torch.isfinite(pts).all():
            raise ValueError("the scene cloud holds NaN or Inf coordinates")
        self.volume, self.frames = volume, frames
        self.points = pts.to(volume.device, torch.float32)
        self.last, self.last_stats = None, {}

    @torch.no_grad()
    def _select(self, out) -> tuple[list, torch.Tensor]:
        """Per row: the kept points (M_r, 3) and the parts holding them (K,) bool."""
        part: Partition = self.volume.partition
        P = self.points.to(out.vertices.dtype)
        V = out.vertices.detach()
        lo, hi = V.amin(1) - AABB_MARGIN, V.amax(1) + AABB_MARGIN
        G = part.part_transforms(out.full_pose.detach(), out.joints.detach())
        bmin, bmax = part.boxes(V, G)
        kept, need = [], torch.zeros(len(V), part.num_parts, dtype=torch.bool, device=V.device)
        for r in range(len(V)):
            cand = P[((P >= lo[r]) & (P <= hi[r])).all(-1)]
            if len(cand) == 0:
                kept.append(cand)
                continue
            ins = inside_boxes(Partition.canonicalize(cand[None], G[r:r + 1]), bmin[r:r + 1], bmax[r:r + 1])[0]
            kept.append(cand[ins.any(0)])
            need[r] = ins.any(1)
        return kept, need

    def per_frame(self, out, ids: torch.Tensor | None = None) -> torch.Tensor:
        """Summed penetration per body of a body output (R bodies) -> (R,), through the grouped, culled calls.
        ids: (R,) the bodies' lasting identities (frame rows), which key the code corrections a volume carries
        across iterations (`Volume.warm_keys`: warm refinement, learned passes at an interval); None: 0..R-1."""
        kept, need = self._select(out)
        R = len(kept)
        loss = out.vertices.new_zeros(R)
        groups: dict[bytes, list[int]] = {}
        for r in range(R):
            if len(kept[r]):
                groups.setdefault(need[r].cpu().numpy().tobytes(), []).append(r)
        n_points = 0
        for rows in groups.values():
            m = max(len(kept[r]) for r in rows)
            pts = out.vertices.new_empty(len(rows), m, 3)
            for i, r in enumerate(rows):
                k = len(kept[r])
                pts[i, :k] = kept[r]
                pts[i, k:] = out.joints[r, 0].detach() + torch.tensor([0.0, FAR, 0.0], dtype=pts.dtype, device=pts.device)
                n_points += k
            idx = torch.as_tensor(rows, device=loss.device)
            sub = SimpleNamespace(vertices=out.vertices[idx], joints=out.joints[idx], full_pose=out.full_pose[idx])
            with self.volume.warm_keys(idx.cpu() if ids is None else ids[idx.cpu()]):
                pen = self.volume.collision_loss(sub, pts, reduction="sum")
            loss = loss.index_copy(0, idx, pen.to(loss.dtype))
        self.last_stats = {"rows": R, "active_rows": sum(len(g) for g in groups.values()), "groups": len(groups),
                           "points": n_points, "part_pairs": int(need.sum())}
        return loss

    def __call__(self, walk) -> torch.Tensor:
        B, T = walk.body_pose.shape[:2]
        ft = frame_subset(T, self.frames)
        rows = (np.arange(B)[:, None] * T + ft[None]).reshape(-1)
        out = walk_output(walk, torch.as_tensor(rows, device=walk.vertices.device))
        vals = self.per_frame(out, torch.as_tensor(rows)).reshape(B, len(ft))
        self.last = vals.detach()
        return vals.mean(dim=1)


class UnitGradAdam(torch.optim.Adam):
    """Adam with every problem's gradient scaled to unit length (over all its variables) before the step.
    Problems are the first dimension of every parameter (volsmpl.optim's convention)."""

    @torch.no_grad()
    def step(self, closure=None):
        params = [p for g in self.param_groups for p in g["params"] if p.grad is not None]
        if params:
            B = params[0].shape[0]
            sq = sum(p.grad.reshape(B, -1).pow(2).sum(1) for p in params)
            scale = 1.0 / sq.sqrt().clamp_min(1e-12)
            for p in params:
                p.grad.mul_(scale.reshape(-1, *[1] * (p.grad.ndim - 1)).to(p.grad.dtype))
        return super().step(closure)


def unit_grad_adam(groups, lr):
    """Optimizer factory for volsmpl.optim.optimize."""
    return UnitGradAdam(groups, lr=lr)


def linear_decay(iters: int):
    """LambdaLR multiplier: lr x (1 - i / iters), DartControl's annealing."""
    return lambda i: max(0.0, 1.0 - i / max(1, iters))
