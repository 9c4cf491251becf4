"""NeRF-style positional encoding of query points (paper A.1, Mildenhall et al. 2020).

gamma(x) = [x, sin(2^0 pi x), cos(2^0 pi x), ..., sin(2^{L-1} pi x), cos(2^{L-1} pi x)]

With L = 2 levels a 3-D point becomes 3 + 3*2*2 = 15 numbers; L = 0 is the identity.
"""
from __future__ import annotations

import math

import torch
from torch import nn


def posenc_dim(in_dim: int, levels: int) -> int:
    """Output size of :func:`positional_encoding` for ``in_dim`` inputs and ``levels`` levels."""
    return in_dim * (1 + 2 * levels)


def positional_encoding(x: torch.Tensor, levels: int) -> torch.Tensor:
    """Encode points with ``levels`` frequency levels.

    Args:
        x: (..., D) points.
        levels: number L >= 0 of frequencies 2^l * pi, l < L.
    Returns:
        (..., D * (1 + 2L)) ordered [x, sin(f_0 x), cos(f_0 x), sin(f_1 x), cos(f_1 x), ...].
    """
    if levels < 0:
        raise ValueError(f"positional encoding needs levels >= 0, got {levels}")
    if levels == 0:
        return x
    parts = [x]
    for l in range(levels):
        fx = x * ((2.0 ** l) * math.pi)
        parts.append(torch.sin(fx))
        parts.append(torch.cos(fx))
    return torch.cat(parts, dim=-1)


class PositionalEncoding(nn.Module):
    """Module wrapper of :func:`positional_encoding` (no parameters)."""

    def __init__(self, levels: int, in_dim: int = 3):
        super().__init__()
        if levels < 0:
            raise ValueError(f"positional encoding needs levels >= 0, got {levels}")
        self.levels = int(levels)
        self.in_dim = int(in_dim)
        self.out_dim = posenc_dim(self.in_dim, self.levels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(..., in_dim) -> (..., out_dim)."""
        if x.shape[-1] != self.in_dim:
            raise ValueError(f"PositionalEncoding expects (..., {self.in_dim}) inputs, got shape {tuple(x.shape)}")
        return positional_encoding(x, self.levels)

    def extra_repr(self) -> str:
        return f"levels={self.levels}, in_dim={self.in_dim}, out_dim={self.out_dim}"
