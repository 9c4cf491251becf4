"""Where a posed body touches itself: vertices near a vertex that is far from them on the body (self-contact).

A vertex is *in contact* when some vertex lies within `radius` of it in the posed body but was more than
`rest_gap` away in the rest pose: a hand on the chest, one thigh against the other, the calf pressed to the
thigh in a squat. Neighbours across a joint are near in both poses and never count, whatever the part
labels, so this needs no part table and works for any SMPL-family body. Exact (a k-d tree finds every pair
within the radius; scipy), on the CPU; inputs on another device are copied there and the mask returned there.

    mask = contact_vertices(posed.vertices, body.v_template)      # (B, V) bool
    # training queries around them: volsmpl.training_queries.sample_contact_points
"""
from __future__ import annotations

import numpy as np
import torch

__all__ = ["contact_vertices", "CONTACT_RADIUS", "REST_GAP"]

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
