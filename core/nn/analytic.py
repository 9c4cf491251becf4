"""Analytic signed distance to bounding boxes (paper Sec. 3.2, eq. 4).

Far from the body (outside every part box B_k) VolumetricSMPL returns the distance to the union
of the boxes instead of querying the network. Boxes are axis-aligned in their part's canonical
frame; a part frame is placed rigidly in the world by G_k, so distances computed in the part frame
equal world distances.
"""
from __future__ import annotations

from typing import Tuple

import torch


def box_sdf(x_local: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor) -> torch.Tensor:
    """Exact signed distance to an axis-aligned box (negative inside, zero on the surface).

    Args:
        x_local: (..., 3) points in the box's frame.
        box_min: (..., 3) lower corner (broadcastable against ``x_local``).
        box_max: (..., 3) upper corner, >= box_min.
    Returns:
        (...) signed distance. Outside: Euclidean distance to the box; inside: minus the distance
        to the closest face. Differentiable everywhere except on the box's medial planes/surface
        (the gradient there is one of the one-sided ones, never NaN).
    """
    center = 0.5 * (box_min + box_max)
    half = 0.5 * (box_max - box_min)
    q = (x_local - center).abs() - half                                # (..., 3)
    qp = q.clamp(min=0.0)
    # the norm as m |qp / m| with m the largest component, which does not overflow (squares do above 1.8e19 m:
    # inf for distances float32 holds) and has a finite derivative wherever m > 0, also where a component is
    # exactly 0 on a box face's plane (nested hypot gave 0/0 there); evaluated only where the point is outside.
    m = qp.amax(dim=-1, keepdim=True)
    pos = m[..., 0] > 0
    ms = torch.where(pos[..., None], m, torch.ones_like(m))
    r2 = (qp / ms).square().sum(dim=-1)  # >= 1 outside
    norm = ms[..., 0] * torch.where(pos, r2, torch.ones_like(r2)).sqrt()
    outside = torch.where(pos, norm, torch.zeros_like(norm))
    inside = q.amax(dim=-1).clamp(max=0.0)
    return outside + inside


def box_excess(u: torch.Tensor, half: torch.Tensor) -> torch.Tensor:
    """Per-axis excess q = |u| - half of points over centred boxes, and its maximum over the axes.

    A point is in (or on) box k when max_axis q <= 0 (the same test as |u| <= half on every axis: the sign of a
    float difference is exact); q feeds `outside_distance` for the points in no box.

    Shape: u (..., K, 3) coordinates relative to the box centres, half (..., K, 3) half extents (broadcastable)
    -> q (..., K, 3), q_max (..., K).
    """
    q = u.abs() - half
    return q, torch.maximum(torch.maximum(q[..., 0], q[..., 1]), q[..., 2])


def outside_distance(q: torch.Tensor, q_max: torch.Tensor, absent: torch.Tensor | None = None) -> torch.Tensor:
    """Distance to the nearest of K boxes from points outside all of them: min_k ||max(q_k, 0)|| (`box_excess`).

    Exact and free of overflow for any finite coordinates: with s = min_k max_axis q_k > 0 (every box has an axis
    the point is beyond), min_k ||q_k^+|| = s sqrt(min_k sum((q_k^+ / s)^2)), and the nearest box's ratio is at most
    sqrt(3). A farther box's ratio is capped at 1e18 before squaring: it can never be the nearest, and an overflow
    to inf would make its zero gradient NaN (0 x inf) in the backward pass. s is a constant of the gradient (the
    value does not depend on it), so the gradient is q^+ / ||q^+|| of the nearest box, finite.
    A row with some q_max <= 0 lies in or on a box: a caller whose box test found it in none computed q in another
    rounding (a point within rounding of a face). Its distance is 0 with a gradient of 0, not the NaN gradient of a
    norm at 0.
    absent: (F, K) bool parts that do not count (their distance is +inf; all absent gives +inf).

    Shape: q (F, K, 3), q_max (F, K) -> (F,).

    Example:
        >>> q, q_max = box_excess(torch.tensor([[[3.0, 0.0, 4.0]]]), torch.zeros(1, 1, 3))
        >>> outside_distance(q, q_max)
        tensor([5.])
    """
    if q.dim() != 3 or q.shape[-1] != 3 or q_max.shape != q.shape[:2]:
        raise ValueError(f"outside_distance expects q (F, K, 3) and q_max (F, K), got {tuple(q.shape)} and "
                         f"{tuple(q_max.shape)}")
    if absent is not None:
        q_max = torch.where(absent, float("inf"), q_max)
    s = q_max.amin(dim=-1, keepdim=True).detach()                       # (F, 1), > 0 for points in no box
    touching = s[:, 0] <= 0                                             # in or on a box, by this rounding
    s = torch.where(s > 0, s, torch.ones_like(s))
    w = (q.clamp(min=0.0) / s[..., None]).clamp(max=1e18)
    w = w * w
    r2 = w[..., 0] + w[..., 1] + w[..., 2]                              # (F, K), >= 1 at the nearest box
    if absent is not None:
        r2 = torch.where(absent, float("inf"), r2)
    r2 = torch.where(touching, torch.ones_like(s[:, 0]), r2.amin(dim=-1))
    return torch.where(touching, torch.zeros_like(s[:, 0]), s[:, 0] * r2.sqrt())


def transform_points(T: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Apply 4x4 transforms to points.

    Args:
        T: (B, K, 4, 4) homogeneous transforms.
        x: (B, N, 3) points.
    Returns:
        (B, K, N, 3) with out[b, k, n] = (T[b, k] @ [x[b, n], 1])[:3].
    """
    R = T[..., :3, :3]                                                  # (B, K, 3, 3)
    t = T[..., :3, 3]                                                   # (B, K, 3)
    return torch.einsum("bkij,bnj->bkni", R, x) + t[:, :, None, :]


def union_box_sdf(x: torch.Tensor, G_inv: torch.Tensor, box_min: torch.Tensor,
                  box_max: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """Signed distance to the union of K rigidly placed boxes, and box membership.

    The distance is min_k box_sdf(G_inv[k] x, box_k). Outside all boxes this is the exact
    distance to the union; inside the union it is only a bound (VolumetricSMPL uses the neural
    SDF there, eq. 3).

    Args:
        x: (B, N, 3) world points.
        G_inv: (B, K, 4, 4) rigid world->part transforms (inverse bone transforms G_k^-1).
        box_min: (B, K, 3) box lower corners in part frames.
        box_max: (B, K, 3) box upper corners in part frames.
    Returns:
        sdf: (B, N) signed distance to the union of boxes.
        inside: (B, K, N) bool, True where point n lies in (or on) box k.
    """
    if x.dim() != 3 or x.shape[-1] != 3:
        raise ValueError(f"union_box_sdf: x must be (B, N, 3), got {tuple(x.shape)}")
    B, K = G_inv.shape[:2]
    if G_inv.shape != (B, K, 4, 4) or x.shape[0] != B:
        raise ValueError(f"union_box_sdf: G_inv must be (B, K, 4, 4) with B={x.shape[0]} matching x, "
                         f"got {tuple(G_inv.shape)}")
    if box_min.shape != (B, K, 3) or box_max.shape != (B, K, 3):
        raise ValueError(f"union_box_sdf: box_min/box_max must be (B, K, 3) = {(B, K, 3)}, "
                         f"got {tuple(box_min.shape)} and {tuple(box_max.shape)}")
    x_local = transform_points(G_inv, x)                               # (B, K, N, 3)
    d = box_sdf(x_local, box_min[:, :, None, :], box_max[:, :, None, :])  # (B, K, N)
    return d.amin(dim=1), d <= 0
