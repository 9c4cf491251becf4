"""Each sampled frame judged without ground truth: its record's `status` and `status_why`.

    ok                  none of the below
    diverged            the pose vector or the posed body holds NaN or Inf
    past_joint_limits   a body joint's Euler angle lies more than LIMIT_TOL_DEG outside volsmpl.body.poses.JOINT_LIMITS
    penetrating         more than DEEP_RATIO of the scene points around the body (the guidance points, a 2 m cube) lie
                        more than DEEP_M inside the body
    far_from_keypoints  the body's joints project, on average over the confidently detected keypoints, more than
                        FAR_REPROJ (normalised image units: pixels / focal length) from them

The first that applies is the status; `status_why` gives the numbers of every one that applies. The thresholds were
set on the test split (200 frames, the shipped network, seed 0, every guide at the paper's scale), measured by
`measure` for the ground-truth bodies, the regressor's pose and each guide's samples:

- reprojection: the ground-truth bodies' mean error is at most 0.028 (the keypoints' detector noise); the samples'
  has median 0.037-0.039 and 99th percentile 0.135 for every guide (the regressor's 0.145); FAR_REPROJ = 0.15
  (60-85 px at the frames' focal lengths of 417-554 px) flags 1 frame of 200 per guide (2 of the regressor's);
- joint limits: the ground-truth poses lie within the limits (excess 0); the samples' largest excess has 99th
  percentile 6.1 and maximum 12.1 degrees (the regressor's 13.7); LIMIT_TOL_DEG = 15 flags none of them;
- penetration: no ground-truth body holds a scene point more than DEEP_M = 5 cm inside; the fraction of such points
  has 99th percentile 0.0095 unguided, 0.0073-0.0088 guided; DEEP_RATIO = 0.005 (100 of the 20,000 points) flags
  11 frames of 200 unguided and COAP-guided, 6 VolumetricSMPL- and mesh-guided.

    recs = measure(x, out.joints, out.vertices, faces, kp, guide_points, inside)   # per-frame measures (B dicts)
    status, why = judge(rec)
"""
from __future__ import annotations

import math

import numpy as np
import torch

#: degrees a joint angle may lie outside volsmpl.body.poses.JOINT_LIMITS before the pose is past the limits
LIMIT_TOL_DEG = 15.0
#: depth (m) below which a scene point inside the body counts as deep
DEEP_M = 0.05
#: fraction of the scene points around the body deeper than DEEP_M inside it above which the body is penetrating
DEEP_RATIO = 0.005
#: mean reprojection error (normalised image units) above which the body is far from the keypoints
FAR_REPROJ = 0.15
#: one joint's reprojection error is capped at this (normalised units): a joint behind the camera counts as this far
REPROJ_CAP = 1.0

STATUSES = ("ok", "diverged", "past_joint_limits", "penetrating", "far_from_keypoints")
GOOD = frozenset({"ok"})


def limit_excess(body_pose: torch.Tensor) -> tuple[np.ndarray, list]:
    """How far each pose lies outside the joint limits: the largest excess over joints and Euler axes (degrees, 0
    inside) and where ('left_knee x'). Shape: body_pose (B, 69) axis-angle -> (B,), B strings."""
    from volsmpl.body.poses import BODY_JOINTS, JOINT_LIMITS, body_pose_to_euler

    lim = np.array([JOINT_LIMITS[j] for j in BODY_JOINTS])            # (23, 3, 2)
    e = body_pose_to_euler(body_pose)                                 # (B, 23, 3)
    over = np.maximum(np.maximum(lim[..., 0] - e, e - lim[..., 1]), 0.0).reshape(len(e), -1)
    k = over.argmax(1)
    where = [f"{BODY_JOINTS[i // 3]} {'xyz'[i % 3]}" for i in k]
    return np.degrees(over.max(1)), where


def reprojection_error(joints: torch.Tensor, kp: torch.Tensor) -> np.ndarray:
    """Mean distance between the projected joints and the keypoints with a confidence above 0, in normalised image
    units ((u - cx) / fx, (v - cy) / fy: the network's keypoint input); each joint's capped at REPROJ_CAP (a joint
    at or behind the camera counts as REPROJ_CAP); NaN for a frame without such keypoints.
    Shape: joints (B, 24, 3) camera frame, kp (B, 24, 3) keypoint input (x, y, conf) -> (B,)."""
    j = joints.detach().double().cpu()
    k = kp.detach().double().cpu()
    z = j[..., 2]
    ahead = z > 1e-3
    xy = j[..., :2] / torch.where(ahead, z, torch.ones_like(z))[..., None]
    err = torch.where(ahead, (xy - k[..., :2]).norm(dim=-1).clamp(max=REPROJ_CAP), torch.full_like(z, REPROJ_CAP))
    seen = k[..., 2] > 0
    n = seen.sum(1)
    mean = (err * seen).sum(1) / n.clamp(min=1)
    return torch.where(n > 0, mean, torch.full_like(mean, float("nan"))).numpy()


def deep_ratio(vertices: torch.Tensor, faces, points: torch.Tensor, inside: torch.Tensor) -> np.ndarray:
    """Fraction of each frame's scene points inside its body (`inside`, the winding-number test of the collision
    ratio) deeper than DEEP_M: the exact distance to the body surface (room_checks.BodyMesh) of the points whose
    nearest body vertex is farther than DEEP_M (the surface is never farther than the nearest vertex).
    Shape: vertices (B, V, 3), faces (F, 3), points (B, N, 3), inside (B, N) bool -> (B,)."""
    from scipy.spatial import cKDTree

    from .room_checks import BodyMesh

    out = np.zeros(len(vertices))
    f = np.asarray(torch.as_tensor(faces).cpu(), np.int64)
    for b in range(len(vertices)):
        v = vertices[b].detach().double().cpu().numpy()
        p = points[b][inside[b]].detach().double().cpu().numpy()
        if not len(p) or not np.isfinite(v).all():
            continue
        cand = p[cKDTree(v).query(p, k=1)[0] > DEEP_M]
        if len(cand):
            out[b] = float((BodyMesh(v, f).distances(cand) > DEEP_M).sum()) / points.shape[1]
    return out


def measure(x: torch.Tensor, joints: torch.Tensor, vertices: torch.Tensor, faces, kp: torch.Tensor,
            points: torch.Tensor, inside: torch.Tensor) -> list[dict]:
    """The per-frame measures `judge` reads: finite, joint_limit_excess_deg, joint_limit_at, deep_ratio,
    reproj_err. Shape: x (B, 144) pose vectors, joints (B, 24, 3) and vertices (B, V, 3) of the posed bodies
    (camera frame), kp (B, 24, 3) keypoint input, points (B, N, 3) scene points, inside (B, N) bool."""
    from .pose import axis_angle

    finite = (torch.isfinite(x).all(1) & torch.isfinite(vertices).flatten(1).all(1)
              & torch.isfinite(joints).flatten(1).all(1)).cpu().numpy()
    excess, where = np.full(len(x), np.nan), [""] * len(x)
    if finite.any():
        idx = np.flatnonzero(finite)
        e, w = limit_excess(axis_angle(x[torch.as_tensor(idx, device=x.device)].detach())[1])
        excess[idx] = e
        for i, wi in zip(idx, w):
            where[i] = wi
    deep = deep_ratio(vertices, faces, points, inside)
    reproj = reprojection_error(joints, kp)
    return [{"finite": bool(finite[b]), "joint_limit_excess_deg": float(excess[b]), "joint_limit_at": where[b],
             "deep_ratio": float(deep[b]) if finite[b] else float("nan"),
             "reproj_err": float(reproj[b]) if finite[b] else float("nan")} for b in range(len(x))]


def judge(rec: dict) -> tuple[str, str]:
    """(status, why) of a record holding `measure`'s keys (module docstring)."""
    if not rec.get("finite", True):
        return "diverged", "the pose or the posed body holds NaN or Inf"
    found = []
    ex = rec.get("joint_limit_excess_deg")
    if ex is not None and math.isfinite(ex) and ex > LIMIT_TOL_DEG:
        found.append(("past_joint_limits", f"{rec.get('joint_limit_at', 'a joint')} lies {ex:.0f} degrees outside "
                                           f"its limit (tolerance {LIMIT_TOL_DEG:g})"))
    deep = rec.get("deep_ratio")
    if deep is not None and math.isfinite(deep) and deep > DEEP_RATIO:
        found.append(("penetrating", f"{100 * deep:.2f} % of the scene points around the body lie more than "
                                     f"{100 * DEEP_M:g} cm inside it (limit {100 * DEEP_RATIO:g} %)"))
    err = rec.get("reproj_err")
    if err is not None and math.isfinite(err) and err > FAR_REPROJ:
        found.append(("far_from_keypoints", f"the joints project {err:.3f} (pixels / focal length) from the keypoints "
                                            f"on average (limit {FAR_REPROJ:g})"))
    if not found:
        return "ok", ""
    return found[0][0], "; ".join(w for _, w in found)


__all__ = ["LIMIT_TOL_DEG", "DEEP_M", "DEEP_RATIO", "FAR_REPROJ", "REPROJ_CAP", "STATUSES", "GOOD", "limit_excess",
           "reprojection_error", "deep_ratio", "measure", "judge"]
