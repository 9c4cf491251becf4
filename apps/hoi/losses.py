"""Loss terms of the human–object joint optimisation (supplementary eq. D.2 and its terms), as plain functions of
points (camera frame for the image terms, the human's body frame for contact and penetration).

    L = w_contact L_contact + w_normal L_normal + w_pen L_pen + w_scale L_scale  (+ the image terms)

- `contact_terms`: for each interacting (body part, object region) pair, the object region's points that face the
  part (normal test: the region's normal points towards the part's centre); for each part vertex its nearest such
  point; the part vertices whose normal opposes that point's (the surfaces face each other: the paper's indicator
  1(n_h, n_o)) and, of those, the `fraction` nearest to the region: the part's contact patch. L_contact is their
  one-way Chamfer distance to the region (mean squared distance to the region's surface, m^2), L_normal is 1 + cos
  of the two contact sets' normals (the paper's n_{P_h} and n_{P_o}: the patch's mean vertex normal and the mean
  normal of the region where the patch's vertices are nearest; zero when the surfaces face each other; a mean of
  per-vertex cosines is biased on curved contacts, 1 + cos ~ 0.5 at the truth of a hand round a cup). A coarse
  part is much larger than where it touches (at the truth of the seated cases 4-9 % of the pelvis' and thighs' vertices are within 2 cm of the
  seat), so the plain Chamfer over the whole part (fraction 1) is far from zero at the truth and pulls the pair
  out of it (it shrinks the human and tilts the object).
- `relative_similarity`: the object's frame -> the body's frame, R_h^T (s_o R_o x + t_o - t_h) / s_h: contact and
  penetration are measured there, so a common scaling of the pair about the camera centre changes neither.
- `body_query` + `penetration`: mean over object vertices v of ReLU-type penetration of v expressed in the body
  frame in which the body was encoded, x = R_h^T (v - t_h) / s_h: the paper's f(v / s_h) with the human's current
  similarity entering through the frame (the model kind's `penetration` of its query values: ReLU(-sdf), or
  COAP's occupancy term). The body's pose is fixed during the joint stage, so `body_query` prepares it once.
- `scale_prior`: |s - s_prior| per similarity beyond a free band (the paper's language-model prior stands in a table
  of real sizes; the band is the category's spread of sizes, FitConfig.scale_free_std).
- `keypoint_term`, `silhouette_term`: the first stage's observations, kept: squared reprojection error of the body
  joints (confidence-weighted, in units of the focal length: about radians^2) and a two-way 2D Chamfer between the
  projected object vertices and the silhouette pixels relative to the silhouette's spread (dimensionless), by
  kornia's pinhole projection.
All functions are batched over cases (B, ...); object points may be padded, with a mask.
"""
from __future__ import annotations

import math

import torch
from kornia.geometry.camera.perspective import project_points

from volsmpl.geometry.point_mesh_distance import closest_points_on_triangles

__all__ = ["to_camera", "to_body_frame", "relative_similarity", "contact_terms", "body_query", "penetration",
           "scale_prior", "keypoint_term", "silhouette_term"]


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
                  region_normals: torch.Tensor, region_mask: torch.Tensor, fraction: float = 1.0,
                  region_tris: torch.Tensor | None = None, tri_mask: torch.Tensor | None = None, huber: float = 0.0,
                  part_mask: torch.Tensor | None = None, patch_k: torch.Tensor | None = None,
                  tri_owner: torch.Tensor | None = None, margin: float = 0.0):
    """L_contact and L_normal of one interacting pair per case (module docstring).

    Shape: part_pts / part_normals (B, P, 3) (the body part's vertices and unit normals); region_pts /
    region_normals (B, Q, 3), region_mask (B, Q) (points sampled on the object region, padding False), all in one
    frame; region_tris (B, F, 3, 3), tri_mask (B, F): the region's triangles (outward), or None
    -> (contact (B,) m^2, normal (B,), facing (B, Q) bool: the region points used, patch (B, P) bool: the part
    vertices used). fraction in (0, 1]: the share of the part's vertices in its contact patch (at least one).
    The patch is chosen by the distance to the nearest facing region point; with region_tris its vertices' terms
    use the exact distance to the nearest facing triangle of the region and that triangle's normal (no floor from
    the sampling's spacing, several cm on a sofa's seat), else the nearest point and its normal.
    huber > 0 (metres): each squared distance d^2 becomes 2 h^2 (sqrt(1 + d^2 / h^2) - 1) (pseudo-Huber: d^2 up to
    a few percent for d < h / 2, linear, of slope 2 h, far away), so the first steps from a first stage tens of cm
    off do not make gradients 10-100x those near contact (Adam's second-moment estimate would keep later steps
    small for the rest of the run); 0: the squared distance.
    margin >= 0 (metres): a patch vertex within this distance of the region counts as touching it, its distance d
    becomes max(d - margin, 0) before the pseudo-Huber (the contact stops pulling at the margin, so the penetration
    term alone decides how near a thin object comes); 0: the distance itself.
    A case whose region has no point (triangle) facing the part (all behind it) uses the whole region; one whose
    part has no vertex facing the region uses every vertex as a candidate.
    Padded batches (cases of different sizes): part_mask (B, P) marks each case's part vertices (padding False);
    patch_k (B,) int is each case's patch size (default: ceil(fraction * P), the same for all cases). Triangles
    without padding: region_tris (T, 3, 3) of all cases at once with tri_owner (T,) int64, each one's case (every
    case at least one; tri_mask unused): a case's patch is measured against its own triangles only.
    Example:
        >>> p = torch.zeros(1, 1, 3); n = torch.tensor([[[0., 1, 0]]])
        >>> q = torch.tensor([[[0., 0.1, 0]]]); nq = torch.tensor([[[0., -1, 0]]])
        >>> c, nrm, _, _ = contact_terms(p, n, q, nq, torch.ones(1, 1, dtype=torch.bool))
        >>> float(c), float(nrm)
        (0.010000000707805157, 0.0)
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction must be in (0, 1], got {fraction}")
    if not margin >= 0:
        raise ValueError(f"margin must be a length >= 0 (metres), got {margin}")
    if part_mask is None:
        part_mask = torch.ones(part_pts.shape[:2], dtype=torch.bool, device=part_pts.device)
    pm = part_mask.to(part_pts.dtype)[..., None]
    centre = (part_pts * pm).sum(dim=1, keepdim=True) / pm.sum(dim=1, keepdim=True).clamp_min(1.0)  # (B, 1, 3)
    facing = _facing(centre, region_pts, region_normals, region_mask)
    d2, idx = _nearest(part_pts, region_pts, facing)
    nq = torch.gather(region_normals, 1, idx[..., None].expand(-1, -1, 3))
    cos = torch.nn.functional.cosine_similarity(part_normals, nq, dim=-1)  # (B, P)
    opposing = (cos < 0) & part_mask
    candidate = torch.where(opposing.any(dim=1, keepdim=True), opposing, part_mask)
    if patch_k is None:
        k = max(1, math.ceil(fraction * part_pts.shape[1]))
        patch_k = torch.full(part_pts.shape[:1], k, device=part_pts.device)
    k = int(patch_k.max())
    _, sel = torch.topk(d2.detach().masked_fill(~candidate, float("inf")), k, dim=1, largest=False)  # (B, k), nearest first
    # the selected candidates (fewer than k candidates: those), up to each case's own k
    w = torch.gather(candidate, 1, sel) & (torch.arange(k, device=sel.device) < patch_k[:, None])
    patch = torch.zeros_like(candidate).scatter(1, sel, w)
    w = w.to(d2.dtype)
    if region_tris is None:
        d2k, nk = torch.gather(d2, 1, sel), _take(nq, sel)
    else:
        near = _nearest_triangles if tri_owner is None else _nearest_owned_triangles
        d2k, nk = near(_take(part_pts, sel), region_tris, centre, tri_mask if tri_owner is None else tri_owner)
    if margin > 0:  # the clamp keeps sqrt's gradient finite at d = 0 (its own gradient there is 0)
        d2k = (d2k.clamp_min(1e-12).sqrt() - margin).clamp_min(0.0).square()
    if huber > 0:
        d2k = 2 * huber ** 2 * ((1 + d2k / huber ** 2).sqrt() - 1)
    # the normals of the two contact sets: the patch's mean normal and that of the region where its vertices are nearest
    n_part = (_take(part_normals, sel) * w[..., None]).sum(dim=1)
    n_region = (nk * w[..., None]).sum(dim=1)
    normal = 1.0 + torch.nn.functional.cosine_similarity(n_part, n_region, dim=-1)
    return (d2k * w).sum(dim=1) / w.sum(dim=1), normal, facing, patch


def _take(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """x (B, P, 3) at idx (B, k) -> (B, k, 3)."""
    return torch.gather(x, 1, idx[..., None].expand(-1, -1, x.shape[-1]))


def _facing(centre: torch.Tensor, pts: torch.Tensor, normals: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B, Q) bool: the points whose normal points towards the part's centre (B, 1, 3); all of `mask` when none."""
    facing = (((centre - pts) * normals).sum(-1) > 0) & mask
    return torch.where(facing.any(dim=1, keepdim=True), facing, mask)


def _nearest_triangles(p: torch.Tensor, tris: torch.Tensor, centre: torch.Tensor, tri_mask: torch.Tensor | None):
    """Squared distance (B, k) from p (B, k, 3) to the nearest of the triangles (B, F, 3, 3) that face `centre`
    (brute force over the triangles), and that triangle's unit normal (B, k, 3)."""
    a, b, c = tris.unbind(dim=2)  # (B, F, 3) each
    normal = torch.nn.functional.normalize(torch.linalg.cross(b - a, c - a), dim=-1)
    mask = torch.ones(tris.shape[:2], dtype=torch.bool, device=tris.device) if tri_mask is None else tri_mask
    facing = _facing(centre, (a + b + c) / 3, normal, mask)
    q = closest_points_on_triangles(p[:, :, None], a[:, None], b[:, None], c[:, None])  # (B, k, F, 3)
    d2 = (p[:, :, None] - q).square().sum(-1).masked_fill(~facing[:, None], float("inf"))
    d2, j = d2.min(dim=2)
    return d2, torch.gather(normal, 1, j[..., None].expand(-1, -1, 3))


def _nearest_owned_triangles(p: torch.Tensor, tris: torch.Tensor, centre: torch.Tensor, owner: torch.Tensor):
    """`_nearest_triangles` without padding: triangles (T, 3, 3) of all B cases, owner (T,) the case of each; each
    case's points p (B, k, 3) against its own triangles only (T x k distances in all)."""
    a, b, c = tris.unbind(dim=1)  # (T, 3) each
    normal = torch.nn.functional.normalize(torch.linalg.cross(b - a, c - a), dim=-1)
    facing = (((centre[owner, 0] - (a + b + c) / 3) * normal).sum(-1) > 0)  # (T,)
    n_facing = torch.zeros(p.shape[0], dtype=torch.long, device=p.device).index_add(0, owner, facing.long())
    facing = facing | (n_facing[owner] == 0)  # a case with no triangle facing its part uses all of its triangles
    po = p[owner]  # (T, k, 3)
    q = closest_points_on_triangles(po, a[:, None], b[:, None], c[:, None])  # (T, k, 3)
    d2 = (po - q).square().sum(-1).masked_fill(~facing[:, None], float("inf"))  # (T, k)
    with torch.no_grad():  # the nearest triangle of each (case, point); ties: the last
        k = p.shape[1]
        own = owner[:, None].expand(-1, k)
        best = d2.new_full(p.shape[:2], float("inf")).scatter_reduce(0, own, d2, "amin")
        rows = torch.arange(len(owner), device=p.device)[:, None].expand(-1, k)
        j = torch.full(p.shape[:2], -1, dtype=torch.long, device=p.device).scatter_reduce(
            0, own, torch.where(d2 == best[owner], rows, -1), "amax")
    cols = torch.arange(k, device=p.device)[None].expand_as(j)
    return d2[j, cols], normal[j]


def relative_similarity(human, obj):
    """The object's frame -> the human's body frame, x_body = s R x + t, from the two camera-frame similarities
    (scale (B,), R (B, 3, 3), t (B, 3)) each: s = s_o / s_h, R = R_h^T R_o, t = R_h^T (t_o - t_h) / s_h."""
    (sh, Rh, th), (so, Ro, to) = human, obj
    return so / sh, Rh.transpose(1, 2) @ Ro, ((to - th)[:, None] @ Rh)[:, 0] / sh[:, None]


def body_query(volume, out):
    """The kind's per-point penetration (B, N) of points (B, N, 3) in the body frame of `out`, for a body output
    that stays as it is through the fit: a learned kind encodes its parts once (`volume.encode`: all parts) and
    every call only decodes (`query_encoded`); the exact mesh kind measures the exact signed distances to the
    posed mesh at every call (`query`)."""
    from volsmpl.volume.models import model_kind

    if model_kind(volume.kind).learned:
        enc = volume.encode(out)
        return lambda x: volume.penetration(volume.query_encoded(enc, x))
    return lambda x: volume.penetration(volume.query(out, x))


def penetration(query, x_body: torch.Tensor, obj_mask: torch.Tensor) -> torch.Tensor:
    """L_pen: mean over each case's object vertices of the kind's penetration at the vertices in the body frame.

    Shape: x_body (B, N, 3) (the object vertices in the body frame, e.g. by `relative_similarity`, or
    `to_body_frame` of camera-frame vertices), obj_mask (B, N) (padding False) -> (B,). `query`: a
    `body_query` of the B cases' bodies.
    """
    pen = query(x_body)  # (B, N)
    m = obj_mask.to(pen.dtype)
    return (pen * m).sum(dim=1) / m.sum(dim=1).clamp_min(1.0)


def scale_prior(scale: torch.Tensor, prior, free=0.0) -> torch.Tensor:
    """max(|scale - prior| - free, 0): no pull within `free` of the prior (a category's real sizes spread about its
    mean; the image decides there), a constant one beyond. Shape: scale (B,), prior and free (B,) or float -> (B,).

    Example:
        >>> scale_prior(torch.tensor([1.05, 1.3]), 1.0, free=0.1)
        tensor([0.0000, 0.2000])
    """
    prior = torch.as_tensor(prior, dtype=scale.dtype, device=scale.device)
    free = torch.as_tensor(free, dtype=scale.dtype, device=scale.device)
    return ((scale - prior).abs() - free).clamp_min(0.0)


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
    """Two-way 2D Chamfer (mean squared nearest distances) between the projected object vertices and the silhouette's
    pixels, divided by the silhouette's spread (the mean squared distance of its pixels from their centroid): a
    dimensionless term that charges a turn of the object the same whatever its size in the image. Without the
    division a cup 3 m away (spread 1.9e-4 focal lengths squared) is held 200x more weakly than a bed (4e-2): at
    the truth of the database's tuning cups and phones its rotation gradient is 1-4, the contact normal term's
    350-870, and the fit turns them over.

    Shape: obj_cam (B, N, 3), obj_mask (B, N), silhouette (B, S, 2), sil_mask (B, S), K (B, 3, 3) -> (B,).
    Example:
        >>> K = torch.tensor([[[100.0, 0, 0], [0, 100, 0], [0, 0, 1]]])
        >>> sil = torch.tensor([[[-10.0, 0], [10.0, 0]]])          # spread 10^2 px^2
        >>> x = torch.tensor([[[0.0, 0.0, 1.0]]])                  # projects to (0, 0): 10 px from both pixels
        >>> float(silhouette_term(x, torch.ones(1, 1, dtype=torch.bool), sil, torch.ones(1, 2, dtype=torch.bool), K))
        2.0
    """
    f = K[:, 0, 0][:, None, None]
    uv = _project(obj_cam, K) / f
    sil = silhouette / f
    d2 = torch.cdist(uv, sil).square()
    big = torch.finfo(d2.dtype).max
    a = d2.masked_fill(~sil_mask[:, None, :], big).min(dim=2).values  # each vertex to its nearest pixel
    b = d2.masked_fill(~obj_mask[:, :, None], big).min(dim=1).values  # each pixel to its nearest vertex
    ma, mb = obj_mask.to(d2.dtype), sil_mask.to(d2.dtype)
    chamfer = (a * ma).sum(1) / ma.sum(1).clamp_min(1) + (b * mb).sum(1) / mb.sum(1).clamp_min(1)
    n = mb.sum(1).clamp_min(1)[:, None]
    centre = (sil * mb[..., None]).sum(1) / n
    spread = ((sil - centre[:, None]).square().sum(-1) * mb).sum(1) / n[:, 0]
    # a one-pixel silhouette has no spread: a pixel's (1 / f^2) stands in for it
    return chamfer / spread.clamp_min(1.0 / K[:, 0, 0] ** 2)
