"""Where a posed body touches itself: vertices near a vertex that is far from them on the body (self-contact).

A vertex is *in contact* when some vertex lies within `radius` of it in the posed body but was more than
`rest_gap` away in the rest pose: a hand on the chest, one thigh against the other, the calf pressed to the
thigh in a squat. Neighbours across a joint are near in both poses and never count, whatever the part
labels, so this needs no part table and works for any SMPL-family body. Exact (a k-d tree finds every pair
within the radius; scipy), on the CPU; inputs on another device are copied there and the mask returned there.

    mask = contact_vertices(posed.vertices, body.v_template)      # (B, V) bool
    pts = sample_contact_points(posed.vertices, mask, 512, sigma=(0.005, 0.01), generator=g)
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch

__all__ = ["contact_vertices", "sample_contact_points", "CONTACT_RADIUS", "REST_GAP"]

#: metres: posed distance below which two vertices touch
CONTACT_RADIUS = 0.01
#: metres: rest-pose distance above which two touching vertices belong to different places of the body
REST_GAP = 0.10


def contact_vertices(vertices: torch.Tensor, rest_vertices: torch.Tensor, radius: float = CONTACT_RADIUS,
                     rest_gap: float = REST_GAP) -> torch.Tensor:
    """Per body, the vertices in self-contact (module docstring).

    Shape: vertices (B, V, 3) posed, rest_vertices (V, 3) or (B, V, 3) the same bodies at rest -> (B, V) bool.
    """
    from scipy.spatial import cKDTree

    if vertices.dim() != 3 or vertices.shape[-1] != 3:
        raise ValueError(f"contact_vertices expects vertices (B, V, 3), got {tuple(vertices.shape)}")
    B, V = vertices.shape[:2]
    rest = rest_vertices if rest_vertices.dim() == 3 else rest_vertices.unsqueeze(0).expand(B, V, 3)
    if tuple(rest.shape) != (B, V, 3):
        raise ValueError(f"contact_vertices: rest_vertices {tuple(rest_vertices.shape)} do not match vertices {(B, V, 3)}")
    if not (radius > 0 and rest_gap > radius):
        raise ValueError(f"contact_vertices needs 0 < radius < rest_gap, got radius={radius}, rest_gap={rest_gap}")
    v = vertices.detach().to("cpu", torch.float64).numpy()
    r = rest.detach().to("cpu", torch.float64).numpy()
    out = np.zeros((B, V), dtype=bool)
    for b in range(B):
        pairs = cKDTree(v[b]).query_pairs(radius, output_type="ndarray")       # (P, 2), i < j, |v_i - v_j| <= radius
        if len(pairs):
            far = np.linalg.norm(r[b, pairs[:, 0]] - r[b, pairs[:, 1]], axis=1) > rest_gap
            out[b, pairs[far].reshape(-1)] = True
    return torch.as_tensor(out, device=vertices.device)


def sample_contact_points(vertices: torch.Tensor, mask: torch.Tensor, n: int, sigma: float | Sequence[float] = (0.005, 0.01),
                          generator: torch.Generator | None = None) -> torch.Tensor:
    """n points per body around its contact vertices: a uniformly drawn contact vertex plus an isotropic Gaussian
    offset (the first n / len(sigma) with sigma[0], ...); a body without contact draws from all its vertices.

    Shape: vertices (B, V, 3), mask (B, V) bool -> (B, n, 3) float64 on the generator's device (else the vertices')."""
    if mask.shape != vertices.shape[:2]:
        raise ValueError(f"sample_contact_points: mask {tuple(mask.shape)} does not match vertices {tuple(vertices.shape[:2])}")
    sig = [float(sigma)] if np.isscalar(sigma) else [float(s) for s in sigma]
    if not sig or any(not (s >= 0 and np.isfinite(s)) for s in sig):
        raise ValueError(f"sigma={sigma!r}: give one or more finite standard deviations >= 0 in metres")
    dev = generator.device if generator is not None else vertices.device
    f64 = dict(dtype=torch.float64, device=dev)
    v = vertices.detach().to(**f64)
    w = mask.to(dev).to(torch.float64)
    w = torch.where(w.sum(1, keepdim=True) > 0, w, torch.ones_like(w))            # no contact: any vertex
    idx = torch.multinomial(w, n, replacement=True, generator=generator)          # (B, n)
    base, rem = divmod(n, len(sig))
    scale = torch.cat([torch.full((base + (i < rem),), s, **f64) for i, s in enumerate(sig)])
    off = torch.randn(v.shape[0], n, 3, generator=generator, **f64) * scale[:, None]
    return torch.gather(v, 1, idx[..., None].expand(-1, -1, 3)) + off
