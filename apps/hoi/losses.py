"""Loss terms of the human–object joint optimisation (supplementary eq. D.2 and its terms), as plain functions of
points in the camera frame.

    L = w_contact L_contact + w_normal L_normal + w_pen L_pen + w_scale L_scale  (+ the image terms)

- `contact_terms`: for each interacting (body part, object region) pair, the object region's points that face the
  part (normal test: the region's normal points towards the part's centre), then the one-way Chamfer distance from
  the part's vertices to those points (mean squared distance to the nearest one, m^2): L_contact; and 1 + cos of the
  normals of each part vertex and its nearest region point (zero when the surfaces face each other): L_normal.
- `penetration`: mean over object vertices v of ReLU-type penetration of v expressed in the body frame in which
  the body was encoded, x = R_h^T (v - t_h) / s_h: the paper's f(v / s_h) with the human's current similarity
  entering through the frame (the model kind's `collision_loss`: ReLU(-sdf), or COAP's occupancy term).
- `scale_prior`: |s - s_prior| per similarity (the paper's language-model prior stands in a table of real sizes).
- `keypoint_term`, `silhouette_term`: the first stage's observations, kept: squared reprojection error of the body
  joints (confidence-weighted) and a two-way 2D Chamfer between the projected object vertices and the silhouette
  pixels, both in units of the focal length (so about radians^2), by kornia's pinhole projection.
All functions are batched over cases (B, ...); object points may be padded, with a mask.
"""
from __future__ import annotations

import torch
from kornia.geometry.camera.perspective import project_points

__all__ = ["to_camera", "to_body_frame", "contact_terms", "penetration", "scale_prior", "keypoint_term",
           "silhouette_term"]


def to_camera(x: torch.Tensor, scale: torch.Tensor, R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """x_cam = scale * R x + t. Shape: x (B, N, 3), scale (B,), R (B, 3, 3), t (B, 3) -> (B, N, 3)."""
    return scale[:, None, None] * x @ R.transpose(1, 2) + t[:, None]


def to_body_frame(v: torch.Tensor, scale: torch.Tensor, R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """The inverse similarity: R^T (v - t) / scale. Shape: v (B, N, 3) -> (B, N, 3)."""
    return (v - t[:, None]) @ R / scale[:, None, None]


def _nearest(p: torch.Tensor, q: torch.Tensor, q_mask: torch.Tensor):
    """Squared distance (B, P) and index (B, P) of the nearest valid q (B, Q, 3) of each p (B, P, 3)."""
    d2 = torch.cdist(p, q).square()
    d2 = d2.masked_fill(~q_mask[:, None, :], float("inf"))
    return d2.min(dim=2)


def contact_terms(part_pts: torch.Tensor, part_normals: torch.Tensor, region_pts: torch.Tensor,
                  region_normals: torch.Tensor, region_mask: torch.Tensor):
    """L_contact and L_normal of one interacting pair per case.

    Shape: part_pts / part_normals (B, P, 3) (the body part's vertices and unit normals, camera frame);
    region_pts / region_normals (B, Q, 3), region_mask (B, Q) (the object region's points, padding False)
    -> (contact (B,) m^2, normal (B,), facing (B, Q) bool).
    A case whose region has no point facing the part (all behind it) falls back to the whole region.
    Example:
        >>> p = torch.zeros(1, 1, 3); n = torch.tensor([[[0., 1, 0]]])
        >>> q = torch.tensor([[[0., 0.1, 0]]]); nq = torch.tensor([[[0., -1, 0]]])
        >>> c, nrm, _ = contact_terms(p, n, q, nq, torch.ones(1, 1, dtype=torch.bool))
        >>> float(c), float(nrm)
        (0.010000000707805157, 0.0)
    """
    centre = part_pts.mean(dim=1, keepdim=True)  # (B, 1, 3)
    facing = ((centre - region_pts) * region_normals).sum(-1) > 0
    facing = facing & region_mask
    facing = torch.where(facing.any(dim=1, keepdim=True), facing, region_mask)
    d2, idx = _nearest(part_pts, region_pts, facing)
    contact = d2.mean(dim=1)
    nq = torch.gather(region_normals, 1, idx[..., None].expand(-1, -1, 3))
    cos = torch.nn.functional.cosine_similarity(part_normals, nq, dim=-1)
    return contact, (1.0 + cos).mean(dim=1), facing


def penetration(volume, out, obj_cam: torch.Tensor, obj_mask: torch.Tensor, scale: torch.Tensor, R: torch.Tensor,
                t: torch.Tensor) -> torch.Tensor:
    """L_pen: mean over each case's object vertices of the kind's penetration of the vertices in the body frame.

    Shape: obj_cam (B, N, 3) camera frame, obj_mask (B, N) (padding False), scale (B,), R (B, 3, 3), t (B, 3)
    -> (B,). `out` is the body output of the B cases (body frame); `volume` any model kind (BodyVolume).
    """
    x = to_body_frame(obj_cam, scale, R, t)
    pen = volume.collision_loss(out, x, reduction="none")  # (B, N)
    m = obj_mask.to(pen.dtype)
    return (pen * m).sum(dim=1) / m.sum(dim=1).clamp_min(1.0)


def scale_prior(scale: torch.Tensor, prior) -> torch.Tensor:
    """|scale - prior|. Shape: (B,), (B,) or float -> (B,)."""
    return (scale - torch.as_tensor(prior, dtype=scale.dtype, device=scale.device)).abs()


def _project(x: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Pixels of camera-frame points. Shape: x (B, N, 3), K (B, 3, 3) -> (B, N, 2)."""
    B, N = x.shape[:2]
    z = x[..., 2:].clamp_min(1e-3)  # behind the camera: projected as if just in front (the term stays finite)
    xs = torch.cat([x[..., :2], z], dim=-1)
    return project_points(xs.reshape(-1, 3), K[:, None].expand(B, N, 3, 3).reshape(-1, 3, 3)).reshape(B, N, 2)


def keypoint_term(joints_cam: torch.Tensor, keypoints: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Confidence-weighted mean squared reprojection error in focal-length units.

    Shape: joints_cam (B, J, 3), keypoints (B, J, 3) [u, v, confidence], K (B, 3, 3) -> (B,).
    """
    uv = _project(joints_cam, K)
    f = K[:, 0, 0][:, None]
    err = ((uv - keypoints[..., :2]) ** 2).sum(-1) / f ** 2
    w = keypoints[..., 2]
    return (err * w).sum(dim=1) / w.sum(dim=1).clamp_min(1e-9)


def silhouette_term(obj_cam: torch.Tensor, obj_mask: torch.Tensor, silhouette: torch.Tensor, sil_mask: torch.Tensor,
                    K: torch.Tensor) -> torch.Tensor:
    """Two-way 2D Chamfer (mean squared nearest distances, focal-length units) between the projected object
    vertices and the silhouette's pixels.

    Shape: obj_cam (B, N, 3), obj_mask (B, N), silhouette (B, S, 2), sil_mask (B, S), K (B, 3, 3) -> (B,).
    """
    uv = _project(obj_cam, K) / K[:, 0, 0][:, None, None]
    sil = silhouette / K[:, 0, 0][:, None, None]
    d2 = torch.cdist(uv, sil).square()
    big = torch.finfo(d2.dtype).max
    a = d2.masked_fill(~sil_mask[:, None, :], big).min(dim=2).values  # each vertex to its nearest pixel
    b = d2.masked_fill(~obj_mask[:, :, None], big).min(dim=1).values  # each pixel to its nearest vertex
    ma, mb = obj_mask.to(d2.dtype), sil_mask.to(d2.dtype)
    return (a * ma).sum(1) / ma.sum(1).clamp_min(1) + (b * mb).sum(1) / mb.sum(1).clamp_min(1)
