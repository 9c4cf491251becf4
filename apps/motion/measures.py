"""Measures of a synthesised walk (`walk.Walk`): the objective's terms, foot skating, and a picture strip.

What it holds: `pose_prior` (quadratic prior on the pose residuals), `jerk` (DartControl's jerk term, weighted by
`JERK_WEIGHT` in the objective), `foot_skate` (cm per frame of the contact feet), `render_strip` (a side-view strip of
frames with the floor dots, contact feet, the obstacles near the body and the scene points inside it) and `check_tensor` (the shape/dtype/finiteness checks of tensors given to
the walking model and to these measures).

    loss = jerk(walk.joints).mean() + pose_prior(residual).mean()
    skate_cm = foot_skate(walk.joints, walk.contacts)
"""
from __future__ import annotations

import numpy as np
import torch

from volsmpl.body.gait import FOOT_JOINTS

__all__ = ["JERK_WEIGHT", "check_tensor", "pose_prior", "jerk", "foot_skate", "render_strip"]

JERK_WEIGHT = 0.1      # weight of the jerk term in the objective (DartControl's optimisation)


def check_tensor(name: str, x, shape: tuple, like: torch.Tensor | None = None) -> torch.Tensor:
    """Validate a tensor: its shape (None: any size), floating point, finite, and the dtype/device of `like`."""
    if not torch.is_tensor(x):
        raise ValueError(f"{name} must be a torch.Tensor of shape {shape}, got {type(x).__name__}")
    if x.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, x.shape)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} has shape {tuple(x.shape)}, expected {want}")
    if not x.is_floating_point():
        raise ValueError(f"{name} must be a floating-point tensor, got {x.dtype}")
    if not torch.isfinite(x).all():
        raise ValueError(f"{name} contains NaN or Inf; controls must be finite.")
    if like is not None and (x.dtype != like.dtype or x.device != like.device):
        raise ValueError(f"{name} is {x.dtype} on {x.device} but the body is {like.dtype} on {like.device}; "
                         f"move one with .to(...).")
    return x


# ------------------------------------------------------------------------------------------------ objective terms
def pose_prior(pose_residual: torch.Tensor, smooth_weight: float = 10.0) -> torch.Tensor:
    """Quadratic prior on the pose residuals: mean squared residual + smooth_weight x mean squared change per frame.

    0 for the bare walk cycle; penalises large and jittery deviations from it.

    Shape: (B, T, 69) -> (B,).
    Example:
        >>> pose_prior(torch.zeros(2, 98, 69))     # tensor([0., 0.])
    """
    check_tensor("pose_residual", pose_residual, (None, None, 69))
    mag = (pose_residual ** 2).sum(-1).mean(-1)
    if pose_residual.shape[1] < 2:
        return mag
    d = pose_residual[:, 1:] - pose_residual[:, :-1]
    return mag + smooth_weight * (d ** 2).sum(-1).mean(-1)


def jerk(joints: torch.Tensor, weight: float = JERK_WEIGHT) -> torch.Tensor:
    """DartControl's jerk term: weight x the maximum over frames and joints of the norm of the joints' third finite
    difference (metres per frame^3, no fps scaling, as DartControl's calc_jerk); weight 0.1 is the objective's.
    DartControl's loss is the batch mean of this; weight=1 gives the bare maximum jerk.

    Shape: (B, T, J, 3) with T >= 4 -> (B,).
    Example:
        >>> jerk(walk.joints)          # (B,)
    """
    check_tensor("joints", joints, (None, None, None, 3))
    if joints.shape[1] < 4:
        raise ValueError(f"jerk needs at least 4 frames, got joints of shape {tuple(joints.shape)}")
    j3 = joints[:, 3:] - 3 * joints[:, 2:-1] + 3 * joints[:, 1:-2] - joints[:, :-3]
    return weight * j3.norm(dim=-1).amax(dim=(1, 2))


def foot_skate(joints: torch.Tensor, contacts: torch.Tensor, foot_joints: tuple[int, int] = FOOT_JOINTS) -> torch.Tensor:
    """Foot skating, cm: the mean horizontal (x, z) displacement per frame of each foot joint over the frame pairs
    where that foot is in contact in both frames (0 where there are none).

    Args:
        joints: (B, T, J, 3) world joints (Y up, metres); contacts: (B, T, 2) bool or {0, 1} (left, right);
        foot_joints: the joint of each foot, default the balls ('left_foot', 'right_foot').

    Shape: (B, T, J, 3), (B, T, 2) -> (B,).
    Example:
        >>> foot_skate(walk.joints, walk.contacts)   # (B,) cm per frame
    """
    check_tensor("joints", joints, (None, None, None, 3))
    B, T = joints.shape[:2]
    if not torch.is_tensor(contacts) or tuple(contacts.shape) != (B, T, 2):
        raise ValueError(f"contacts must be a (B, T, 2) = {(B, T, 2)} tensor, got "
                         f"{tuple(contacts.shape) if torch.is_tensor(contacts) else type(contacts).__name__}")
    if T < 2:
        raise ValueError(f"foot_skate needs at least 2 frames, got {T}")
    c = contacts.to(joints.dtype)
    feet = joints[:, :, list(foot_joints)][..., [0, 2]]                 # (B, T, 2, 2)
    slide = (feet[:, 1:] - feet[:, :-1]).norm(dim=-1)                   # (B, T-1, 2)
    both = c[:, 1:] * c[:, :-1]
    n = both.sum((1, 2))
    return 100.0 * (slide * both).sum((1, 2)) / n.clamp(min=1.0)


# ------------------------------------------------------------------------------------------------ pictures
NEAR_M = 0.15   # scene points this close to the body are drawn in a strip's tile


def _near_and_inside(V: np.ndarray, faces: np.ndarray, points: np.ndarray, floor: np.ndarray, near: float):
    """Of the scene points, those above the floor within `near` of one frame's body (vertices V), and those inside
    the body (exact signed distance to its mesh < 0, floor points included) with their depths (m)."""
    from scipy.spatial import cKDTree
    from volsmpl.geometry.point_mesh_distance import mesh_signed_distance

    lo, hi = V.min(0) - near, V.max(0) + near
    box = ((points >= lo) & (points <= hi)).all(1)
    if not box.any():
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    cand, cfloor = points[box], floor[box]
    d, _ = cKDTree(V).query(cand, k=1)
    close = d < near
    if not close.any():
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    sd = mesh_signed_distance(torch.as_tensor(V), torch.as_tensor(faces).long(),
                              torch.as_tensor(cand[close])).numpy()
    inside = cand[close][sd < 0]
    return cand[close & ~cfloor], inside, -sd[sd < 0]


def render_strip(walk, faces, path=None, every: int = 10, sequence: int = 0, size: int = 360,
                 yaw: float | None = None, pitch: float = 10.0, extent: float = 2.2, scene_points=None,
                 scene_floor=None, near: float = NEAR_M):
    """Side view of every `every`-th frame of one sequence, side by side (one tile per frame, the camera following
    the pelvis, one scale, looking across the walk's overall direction unless `yaw` is given), with a floor grid of
    dots every 10 cm (fixed in the world, so a sliding foot shows as a foot moving against the dots) and the
    contact feet's balls in green. With `scene_points` ((N, 3), Y up, floor at y = 0; `scene_floor` (N,) bool: the
    floor points): the obstacle points within `near` metres of the body as blue-grey dots, and the scene points
    inside the body (exact mesh test) in red, drawn over the body so that a penetration always shows; each tile
    names the frame, the gait phase and how many points are inside, how deep.

    Shape: -> (size, n * size, 3) uint8 RGB; written as PNG where `path` is given.
    Example:
        >>> render_strip(model(*straight_controls(1, 12)), body.faces, "walk_strip.png", scene_points=sc.points,
        ...              scene_floor=sc.floor)
    """
    import cv2

    from volsmpl.viz.render import render_scene, save_png, scene_pixels
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    V = walk.vertices[sequence].detach().cpu().double().numpy()
    Jt = walk.joints[sequence].detach().cpu().double().numpy()
    C = walk.contacts[sequence].detach().cpu().numpy()
    faces = np.asarray(faces)
    if yaw is None:   # across the walk: the camera on the walk's left of its start-to-end direction
        d = Jt[-1, 0, [0, 2]] - Jt[0, 0, [0, 2]]
        yaw = float(np.degrees(np.arctan2(d[0], d[1]))) + 90.0 if np.linalg.norm(d) > 1e-6 else 90.0
    P = None if scene_points is None else np.asarray(scene_points, dtype=np.float64).reshape(-1, 3)
    PF = (np.zeros(0 if P is None else len(P), bool) if scene_floor is None
          else np.asarray(scene_floor, bool).reshape(-1))
    lo, hi = Jt[:, 0, [0, 2]].min(0) - 1.2, Jt[:, 0, [0, 2]].max(0) + 1.2
    gx, gz = np.meshgrid(np.arange(lo[0], hi[0], 0.1), np.arange(lo[1], hi[1], 0.1))
    grid = np.stack([gx.ravel(), np.zeros(gx.size), gz.ravel()], 1)
    close = np.linalg.norm(grid[:, None, [0, 2]] - Jt[None, :, 0, [0, 2]], axis=-1).min(1) < 0.3
    grid = grid[close]                                   # a band of floor dots along the path
    tiles = []
    for t in range(0, V.shape[0], every):
        feet = Jt[t, list(FOOT_JOINTS)][C[t]]
        obst = inside = np.zeros((0, 3))
        depth = np.zeros(0)
        if P is not None and len(P):
            obst, inside, depth = _near_and_inside(V[t], faces, P, PF, near)
        pts = np.concatenate([grid, obst, feet])
        cols = np.concatenate([np.tile((0.6, 0.6, 0.6), (len(grid), 1)), np.tile((0.25, 0.35, 0.6), (len(obst), 1)),
                               np.tile((0.1, 0.6, 0.15), (len(feet), 1))])
        centre = np.array([Jt[t, 0, 0], 0.85, Jt[t, 0, 2]])
        img = render_scene([(V[t], faces, (0.85, 0.65, 0.5))], size=size, yaw=yaw, pitch=pitch, extent=extent,
                           center=centre, points=pts, point_colors=cols, point_radius=1, max_edge=None)
        for c, r in np.round(scene_pixels(inside, size, yaw, pitch, extent, centre)).astype(int):   # over the body
            cv2.circle(img, (int(c), int(r)), 3, (220, 0, 0), -1, cv2.LINE_AA)
        cv2.putText(img, f"t={t} ph={walk.phase[sequence, t].item():.2f}", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (20, 20, 20), 1, cv2.LINE_AA)
        if P is not None:
            text = (f"{len(inside)} pts inside, {100 * depth.max():.1f} cm deep" if len(inside) else "no point inside")
            cv2.putText(img, text, (6, 36), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (150, 0, 0) if len(inside) else
                        (60, 60, 60), 1, cv2.LINE_AA)
        tiles.append(img)
    strip = np.concatenate(tiles, axis=1)
    if path is not None:
        save_png(path, strip)
    return strip
