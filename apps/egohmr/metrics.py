"""Metrics of the egocentric app (EgoHMR's protocol on our data), every one against exact references.

- `mpjpe`: per-joint position error of the 24 SMPL joints after aligning the pelvises (mm), split by the
  frame's `visible` mask (the ground-truth joint projects inside the image, in front of the camera);
- `pa_mpjpe`: the error after a similarity Procrustes alignment of the 24 joints (mm);
- `collision_ratio`: fraction of the frame's scene points (the 2 x 2 m cube around the body used for guidance)
  inside the predicted body mesh, by the exact winding-number test (the same test for every guide, so rows compare);
- `contact`: whether a body vertex lies within 2 cm of the scene mesh (exact distance: open3d's BVH, or
  `volsmpl.geometry.triangle_queries.MeshQuery` on the faces near the body where open3d does not import) or inside one of its
  closed components (integer winding number >= 1 by `volsmpl.geometry.point_mesh_distance.winding_numbers`: exact float64 signed
  crossings for a scene of several components; float32 ray casts call some open-air points inside where they touch).

    e = mpjpe(pred_joints, gt_joints)                  # (B, 24) mm
    r = collision_ratio(vertices, faces, points)       # (B,) in [0, 1]
    c = contact(vertices, scene_meshes, 0.02)          # (B,) bool
"""
from __future__ import annotations

import numpy as np
import torch

from volsmpl.runtime import deps
from volsmpl.geometry.point_mesh_distance import winding_numbers
from volsmpl.geometry.triangle_queries import MeshQuery


def mpjpe(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """Per-joint error after pelvis alignment, millimetres. Shape: (B, J, 3), (B, J, 3) -> (B, J)."""
    if pred.shape != gt.shape:
        raise ValueError(f"predicted joints {tuple(pred.shape)} and ground truth {tuple(gt.shape)} differ in shape")
    return 1000.0 * ((pred - pred[:, :1]) - (gt - gt[:, :1])).norm(dim=-1)


def procrustes(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """`pred` moved by the similarity (scale, rotation, translation) that best fits it to `gt` in least squares
    (Umeyama 1991). Shape: (B, J, 3), (B, J, 3) -> (B, J, 3)."""
    p, g = pred.double(), gt.double()
    mp, mg = p.mean(1, keepdim=True), g.mean(1, keepdim=True)
    p0, g0 = p - mp, g - mg
    H = p0.transpose(1, 2) @ g0  # (B, 3, 3)
    U, S, Vt = torch.linalg.svd(H)
    d = torch.sign(torch.linalg.det(Vt.transpose(1, 2) @ U.transpose(1, 2)))
    D = torch.diag_embed(torch.stack([torch.ones_like(d), torch.ones_like(d), d], dim=-1))
    R = Vt.transpose(1, 2) @ D @ U.transpose(1, 2)
    scale = (S * torch.diagonal(D, dim1=1, dim2=2)).sum(-1) / (p0 ** 2).sum((1, 2))
    out = scale[:, None, None] * p0 @ R.transpose(1, 2) + mg
    return out.to(pred.dtype)


def pa_mpjpe(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """Per-joint error after Procrustes alignment, millimetres; NaN for a frame whose prediction holds NaN or Inf.
    Shape: -> (B, J)."""
    ok = torch.isfinite(pred).flatten(1).all(1)[:, None, None]
    e = 1000.0 * (procrustes(torch.where(ok, pred, gt), gt) - gt).norm(dim=-1)
    return torch.where(ok[..., 0], e, float("nan"))


def collision_ratio(vertices: torch.Tensor, faces: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Fraction of each frame's points inside its body mesh (winding number > 1/2, exact).
    Shape: vertices (B, V, 3), faces (F, 3), points (B, N, 3) -> (B,)."""
    return torch.stack([(winding_numbers(vertices[b].detach(), faces, points[b]) > 0.5).float().mean()
                        for b in range(len(vertices))])


def inside_masks(vertices: torch.Tensor, faces: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Which of each frame's points lie inside its body mesh (winding number > 1/2, exact: the test of
    `collision_ratio`); none for a body with NaN or Inf vertices (a diverged sample).
    Shape: vertices (B, V, 3), faces (F, 3), points (B, N, 3) -> (B, N) bool."""
    finite = torch.isfinite(vertices.detach()).flatten(1).all(1).tolist()
    return torch.stack([winding_numbers(vertices[b].detach(), faces, points[b]) > 0.5 if finite[b]
                        else torch.zeros(points.shape[1], dtype=torch.bool, device=points.device)
                        for b in range(len(vertices))])


def _near_exact(vertices: np.ndarray, mesh, threshold: float) -> bool:
    """Whether a vertex (V, 3) is within `threshold` of the mesh, by MeshQuery on the CPU: distances only to the
    faces whose bounding box comes within `threshold` of the vertices' box (the others are farther than that from
    every vertex)."""
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    lo, hi = vertices.min(0) - threshold, vertices.max(0) + threshold
    tri = v[f]
    near = ((tri.max(1) >= lo) & (tri.min(1) <= hi)).all(1)
    return bool(near.any() and (MeshQuery(torch.as_tensor(v), torch.as_tensor(f[near]), cluster_size=8)
                                .distances(torch.as_tensor(vertices)) <= threshold).any())


def _inside_exact(vertices: np.ndarray, mesh) -> bool:
    """Whether a vertex (V, 3) lies inside a closed component of the mesh: integer winding number >= 1 by
    `winding_numbers`, which counts a scene of several components exactly (MeshQuery, float64): float32 ray casts
    miscount where components touch (open3d's parity occupancy called 27 of 16,553 open-air points of room 3
    inside, the median of 3 rays' signed crossings 2)."""
    w = winding_numbers(torch.as_tensor(np.asarray(mesh.vertices, np.float64)),
                        torch.as_tensor(np.asarray(mesh.faces, np.int64)), torch.as_tensor(vertices), closed=True)
    return bool((w >= 1).any())


def contact(vertices: np.ndarray, scenes: list, threshold: float = 0.02) -> np.ndarray:
    """Whether some body vertex is within `threshold` metres of the scene mesh or inside one of its closed
    components. Shape: vertices (B, V, 3), scenes: B trimesh meshes -> (B,) bool.
    Distances by open3d's BVH where it imports (else MeshQuery), the inside test by MeshQuery (module docstring)."""
    o3d = deps.open3d_or_none()
    out = np.zeros(len(vertices), dtype=bool)
    for b, mesh in enumerate(scenes):
        v = np.asarray(vertices[b], np.float64)
        if o3d is None:
            near = _near_exact(v, mesh, threshold)
        else:
            rc = o3d.t.geometry.RaycastingScene()
            rc.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                             o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
            near = bool((rc.compute_distance(o3d.core.Tensor(v.astype(np.float32))).numpy() <= threshold).any())
        out[b] = near or _inside_exact(v, mesh)
    return out


def frame_errors(pred_joints: torch.Tensor, gt_joints: torch.Tensor, visible: torch.Tensor) -> dict:
    """Per-frame MPJPE (all, visible, invisible joints; NaN where a frame has none) and PA-MPJPE, mm.
    Shape: (B, 24, 3), (B, 24, 3), (B, 24) bool -> dict of (B,) arrays."""
    e, pa = mpjpe(pred_joints, gt_joints), pa_mpjpe(pred_joints, gt_joints)
    vis = visible.bool()
    nv, ni = vis.sum(1), (~vis).sum(1)
    ev = torch.where(nv > 0, (e * vis).sum(1) / nv.clamp_min(1), torch.full_like(e[:, 0], float("nan")))
    ei = torch.where(ni > 0, (e * ~vis).sum(1) / ni.clamp_min(1), torch.full_like(e[:, 0], float("nan")))
    return {"mpjpe_mm": e.mean(1).cpu().numpy(), "mpjpe_visible_mm": ev.cpu().numpy(),
            "mpjpe_invisible_mm": ei.cpu().numpy(), "pa_mpjpe_mm": pa.mean(1).cpu().numpy(),
            "n_visible": nv.cpu().numpy(), "n_invisible": ni.cpu().numpy()}


def joint_means(errors: dict) -> dict:
    """MPJPE over all joints, the visible and the invisible ones, across frames: each frame's per-joint mean
    weighted by its number of such joints (EgoHMR averages over joints, not frames); None where there are none.
    errors: frame_errors' keys (arrays over frames) -> {'mpjpe_mm', 'mpjpe_visible_mm', 'mpjpe_invisible_mm'}."""
    nv, ni = np.asarray(errors["n_visible"], np.float64), np.asarray(errors["n_invisible"], np.float64)
    out = {}
    for key, n in (("mpjpe_mm", nv + ni), ("mpjpe_visible_mm", nv), ("mpjpe_invisible_mm", ni)):
        den = float(n.sum())
        out[key] = float(np.nansum(np.asarray(errors[key], np.float64) * n)) / den if den else None
    return out


__all__ = ["mpjpe", "procrustes", "pa_mpjpe", "collision_ratio", "inside_masks", "contact", "frame_errors",
           "joint_means"]
