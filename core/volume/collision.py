"""Reduction of per-point penetration values into a collision loss, shared by every model kind."""
from __future__ import annotations

import torch

REDUCTIONS = ("mean", "sum", "none")


def reduce_penetration(pen: torch.Tensor, reduction: str = "mean") -> torch.Tensor:
    """Reduce per-point penetration (B, N) (>= 0, 0 outside the body).

    reduction: 'mean' (scalar over all bodies and points; 0 for no points), 'sum' (per body, (B,)) or
    'none' ((B, N)).
    Example:
        >>> reduce_penetration(torch.tensor([[0.0, 0.2], [0.1, 0.1]]), "sum")
        tensor([0.2000, 0.2000])
    """
    if reduction not in REDUCTIONS:
        raise ValueError(f"reduction must be 'mean', 'sum' or 'none', got {reduction!r}")
    if reduction == "none":
        return pen
    if reduction == "sum":
        return pen.sum(dim=1)
    return pen.mean() if pen.numel() else pen.sum()
