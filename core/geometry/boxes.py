"""Geometry of rigidly placed part boxes: containment, pairwise overlap (exact SAT test) and
uniform sampling of box overlaps (for the self-penetration loss, paper eq. 8 / supp. D.4)."""
from __future__ import annotations

import torch


def inside_boxes(x_local: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor) -> torch.Tensor:
    """x_local (B, K, N, 3) in part frames, box_min/max (B, K, 3) -> (B, K, N) bool (closed boxes)."""
    return ((x_local >= box_min[:, :, None]) & (x_local <= box_max[:, :, None])).all(dim=-1)


def box_centred(points: torch.Tensor, G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor):
    """Every point in every part's box-centred frame, u = R_k^T (x - t_k) - c_k, by one batched matmul, and the
    boxes' half extents. The product is taken about each body's mean part origin o (x - o, t_k - o), so that
    world-sized coordinates cancel before the rounding.

    Shape: points (B, N, 3), G (B, K, 4, 4) part-to-world, box_min/max (B, K, 3) in part frames -> u (B, N, K, 3)
    (each point's K parts contiguous), half (B, K, 3). Use with nn.analytic.box_excess (membership: max_axis
    |u| - half <= 0).
    """
    B, K = G.shape[:2]
    R, t = G[..., :3, :3], G[..., :3, 3]                                  # (B, K, 3, 3), (B, K, 3)
    c = 0.5 * (box_min + box_max)
    W = R.permute(0, 2, 1, 3).reshape(B, 3, K * 3)                        # row x @ R_k = (R_k^T x)^T
    o = t.mean(dim=1, keepdim=True)                                       # (B, 1, 3)
    bias = -(torch.einsum("bki,bkij->bkj", t - o, R) + c).reshape(B, 1, K * 3)
    u = torch.baddbmm(bias, points - o, W).view(B, points.shape[1], K, 3)
    return u, 0.5 * (box_max - box_min)


@torch.no_grad()
def box_test(points: torch.Tensor, G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor):
    """Every point in every part's box-centred frame and its largest excess over the box, without autograd.

    Shape: points (B, N, 3), G (B, K, 4, 4), box_min/max (B, K, 3) -> u (B, N, K, 3) (box_centred) and q_max
    (B, N, K), the maximum over the axes of nn.analytic.box_excess's q = |u| - half (the point is in the box where
    q_max <= 0; NaN points in none). The per-axis excess is not kept (a pass over 4 x 3 floats per (point, part)):
    callers form it for the points that need it. Use with parts_holding."""
    u, half = box_centred(points, G, box_min, box_max)
    return u, u.abs().sub_(half[:, None]).amax(dim=-1)


def parts_holding(q_max: torch.Tensor) -> torch.Tensor:
    """(K,) bool: the parts whose box holds at least one point of some body, from box_test's q_max (B, N, K)."""
    return (q_max <= 0).any(dim=1).any(dim=0)


def part_normalization(box_min: torch.Tensor, box_max: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Similarity that maps each padded part box into [-1, 1]^3 along its longest side: centre (B, K, 3) and
    isotropic scale (B, K, 1) = half the longest side. Decoders of normalised models read (x_k - c) / s and
    their output times s is metres: distances scale with the similarity, so the SDF stays an SDF."""
    return 0.5 * (box_min + box_max), 0.5 * (box_max - box_min).amax(dim=-1, keepdim=True)


def obb(G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor):
    """World-frame oriented boxes: centres (..., 3), axes (..., 3, 3) as columns, half extents (..., 3)."""
    c_local = 0.5 * (box_min + box_max)
    centre = (G[..., :3, :3] @ c_local[..., None])[..., 0] + G[..., :3, 3]
    return centre, G[..., :3, :3], 0.5 * (box_max - box_min)


def world_bounds(G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Axis-aligned world bounds of each body's placed part boxes (of their `obb`s: centre +- |R| half extents).

    Shape: G (B, K, 4, 4) part-to-world, box_min/max (B, K, 3) in part frames -> lo, hi (B, 3)."""
    c, R, h = obb(G, box_min, box_max)
    reach = (R.abs() @ h[..., None])[..., 0]                                          # (B, K, 3)
    return (c - reach).amin(dim=1), (c + reach).amax(dim=1)


def near_boxes(points: torch.Tensor, G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor):
    """The points within each body's world bounds of its part boxes (`world_bounds`), packed to the front: a
    point outside them is in no part box. One host sync (the largest count).

    Shape: points (B, N, 3) -> packed (B, M, 3) (rows of each body's own points, its points inside first; M the
    largest count), rows (B, M) int64 (their indices into N, distinct per body), valid (B, M) bool (False: a
    filler point from outside, in no box). Example:
        >>> packed, rows, valid = near_boxes(pts, enc.G, enc.box_min, enc.box_max)
        >>> full = torch.zeros(B, N).scatter(1, rows, torch.where(valid, values_at(packed), 0.0))
    """
    with torch.no_grad():
        lo, hi = world_bounds(G.detach(), box_min.detach(), box_max.detach())
        p = points.detach()
        inside = ((p >= lo[:, None]) & (p <= hi[:, None])).all(dim=-1)              # (B, N)
        M = int(inside.sum(dim=1).max()) if inside.numel() else 0
        rows = torch.argsort((~inside).to(torch.uint8), dim=1, stable=True)[:, :M]  # inside first
        valid = torch.gather(inside, 1, rows)
    packed = torch.gather(points, 1, rows[..., None].expand(-1, -1, 3))
    return packed, rows, valid


def boxes_overlap(G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor, eps: float = 1e-9) -> torch.Tensor:
    """Exact pairwise overlap test of oriented boxes by the separating axis theorem (15 axes).

    Args: G (B, K, 4, 4) part-to-world; box_min/max (B, K, 3) in part frames.
    Returns: (B, K, K) bool, symmetric, True where two boxes intersect (touching counts).
    """
    c, R, h = obb(G, box_min, box_max)
    B, K = c.shape[:2]
    Ra, Rb = R[:, :, None], R[:, None, :]  # (B,K,1,3,3), (B,1,K,3,3)
    ha, hb = h[:, :, None], h[:, None, :]
    d = c[:, None, :] - c[:, :, None]  # (B,K,K,3) centre of b minus centre of a
    ea, eb = Ra.expand(B, K, K, 3, 3).transpose(-1, -2), Rb.expand(B, K, K, 3, 3).transpose(-1, -2)  # rows = axes
    cross = torch.linalg.cross(ea[..., :, None, :].expand(-1, -1, -1, 3, 3, -1), eb[..., None, :, :].expand(-1, -1, -1, 3, 3, -1))
    axes = torch.cat([ea, eb, cross.reshape(B, K, K, 9, 3)], dim=3)  # (B,K,K,15,3)
    proj_a = (torch.einsum("bklsc,bklic->bklsi", axes, ea).abs() * ha[..., None, :]).sum(-1)
    proj_b = (torch.einsum("bklsc,bklic->bklsi", axes, eb).abs() * hb[..., None, :]).sum(-1)
    dist = torch.einsum("bklsc,bklc->bkls", axes, d).abs()
    degenerate = axes.norm(dim=-1) < 1e-6  # parallel edges give a zero cross product: not a separating axis
    separated = (dist > proj_a + proj_b + eps) & ~degenerate
    return ~separated.any(dim=-1)


def sample_overlaps(G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor, pairs: torch.Tensor,
                    n_points: int = 300, generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Uniform samples in the overlap of box pairs of one body (COAP's procedure): n_points uniform in
    each box of the pair, kept when inside the other box.

    Args: G (K, 4, 4); box_min/max (K, 3); pairs (P, 2) part ids.
    Returns: points (M, 3) world frame (no gradient), pair_id (M,) index into pairs.
    """
    dev, dt = G.device, G.dtype
    if pairs.numel() == 0:
        return torch.zeros(0, 3, dtype=dt, device=dev), torch.zeros(0, dtype=torch.long, device=dev)
    with torch.no_grad():
        src, dst = torch.cat([pairs[:, 0], pairs[:, 1]]), torch.cat([pairs[:, 1], pairs[:, 0]])
        pid = torch.arange(pairs.shape[0], device=dev).repeat(2)
        u = torch.rand(src.shape[0], n_points, 3, generator=generator, dtype=dt, device=dev if generator is None else generator.device)
        u = u.to(dev)
        local = box_min[src, None] + u * (box_max[src] - box_min[src])[:, None]
        world = (G[src, None, :3, :3] @ local[..., None])[..., 0] + G[src, None, :3, 3]
        other = (G[dst, None, :3, :3].transpose(-1, -2) @ (world - G[dst, None, :3, 3])[..., None])[..., 0]
        keep = ((other >= box_min[dst, None]) & (other <= box_max[dst, None])).all(-1)
        return world[keep], pid[:, None].expand(-1, n_points)[keep]
