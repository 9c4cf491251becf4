"""Input checks shared by every query: one clear message per user error, nothing silently fixed."""
from __future__ import annotations

import torch


def check_points(points, like: torch.Tensor, finite: bool = True) -> torch.Tensor:
    """Validate query points against a body output's vertices.

    Args:
        points: (B, N, 3), or (N, 3) shared by all B bodies (expanded, no copy).
        like: out.vertices (B, V, 3) (or any (B, ...) tensor of the bodies): fixes B, dtype and device.
        finite: also refuse NaN or Inf (one pass over the points and a host sync; False where NaN may
            propagate to the values).
    Returns:
        (B, N, 3) points.
    """
    B = like.shape[0]
    if not torch.is_tensor(points):
        raise TypeError(f"points must be a torch.Tensor of shape (B, N, 3) or (N, 3), got {type(points).__name__}")
    given = points  # as the caller gave them: NaN counts are of these, not of the expanded (B, N, 3)
    if points.ndim == 2 and points.shape[-1] == 3:
        points = points[None].expand(B, -1, -1)
    if points.ndim != 3 or points.shape[-1] != 3:
        raise ValueError(f"points must have shape (B, N, 3) or (N, 3), got {tuple(points.shape)}")
    if points.shape[0] != B:
        raise ValueError(f"points are for {points.shape[0]} bodies but the body output has {B}; pass (B={B}, N, 3), "
                         f"or (N, 3) to query the same points on every body.")
    if not points.is_floating_point():
        raise TypeError(f"points must be floating point, got {points.dtype}; convert with points.to({like.dtype}).")
    if points.dtype != like.dtype:
        raise TypeError(f"points are {points.dtype} but the body output is {like.dtype}; convert with points.to({like.dtype}).")
    if points.device != like.device:
        raise ValueError(f"points are on {points.device} but the body output is on {like.device}; move them with points.to('{like.device}').")
    if not finite:
        return points
    bad = ~torch.isfinite(given).all(dim=-1)
    if bad.any():
        raise nonfinite_points_error(int(bad.sum()), bad.numel())
    return points


def nonfinite_points_error(n_bad: int, n_points: int) -> ValueError:
    """The error for query points with NaN or Inf: n_bad of the caller's n_points points."""
    return ValueError(f"points contain NaN or Inf ({n_bad} of {n_points} points); remove or fix them before querying.")
