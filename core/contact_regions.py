"""Where a posed body touches itself: vertices near a vertex that is far from them on the body (self-contact).

A vertex is *in contact* when some vertex lies within `radius` of it in the posed body but was more than
`rest_gap` away in the rest pose: a hand on the chest, one thigh against the other, the calf pressed to the
thigh in a squat. Neighbours across a joint are near in both poses and never count, whatever the part
labels, so this needs no part table and works for any SMPL-family body. Exact, by either of two methods with the
same result: 'kdtree' (scipy's k-d tree finds every pair within the radius, on the CPU: ~25 ms a body on one thread)
or 'torch' (every pair's distance in blocks of rows, on the vertices' device, float64: the training batch on a GPU,
where copying to the host and the k-d tree took most of the batch's time). 'auto': the k-d tree for CPU tensors,
torch elsewhere.

    mask = contact_vertices(posed.vertices, body.v_template)      # (B, V) bool
    # training queries around them: volsmpl.training_queries.sample_contact_points
"""
from __future__ import annotations

import numpy as np
import torch

__all__ = ["contact_vertices", "CONTACT_RADIUS", "REST_GAP", "METHODS"]

#: metres: posed distance below which two vertices touch
CONTACT_RADIUS = 0.01
#: metres: rest-pose distance above which two touching vertices belong to different places of the body
REST_GAP = 0.10
#: how the pairs within the radius are found (module docstring)
METHODS = ("auto", "kdtree", "torch")
#: the torch method's rows per block: (B, rows, V) distances at once (8 bodies of 13k vertices: ~0.9 GB in float64)
TORCH_ROWS = 1024


def contact_vertices(vertices: torch.Tensor, rest_vertices: torch.Tensor, radius: float = CONTACT_RADIUS,
                     rest_gap: float = REST_GAP, method: str = "auto") -> torch.Tensor:
    """Per body, the vertices in self-contact (module docstring), on the vertices' device.

    Shape: vertices (B, V, 3) posed, rest_vertices (V, 3) or (B, V, 3) the same bodies at rest -> (B, V) bool.
    method: 'auto', 'kdtree' or 'torch' (module docstring; the same mask).
    """
    if vertices.dim() != 3 or vertices.shape[-1] != 3:
        raise ValueError(f"contact_vertices expects vertices (B, V, 3), got {tuple(vertices.shape)}")
    B, V = vertices.shape[:2]
    shared = rest_vertices.dim() == 2   # one rest shape for every body: its distances are computed once per block
    rest = rest_vertices.unsqueeze(0) if shared else rest_vertices
    if tuple(rest.shape[1:]) != (V, 3) or len(rest) not in ((1,) if shared else (B,)):
        raise ValueError(f"contact_vertices: rest_vertices {tuple(rest_vertices.shape)} do not match vertices {(B, V, 3)}")
    if not (radius > 0 and rest_gap > radius):
        raise ValueError(f"contact_vertices needs 0 < radius < rest_gap, got radius={radius}, rest_gap={rest_gap}")
    if method not in METHODS:
        raise ValueError(f"contact_vertices: method must be one of {METHODS}, got {method!r}")
    if method == "torch" or (method == "auto" and vertices.device.type != "cpu"):
        return _contact_torch(vertices, rest.to(vertices.device), radius, rest_gap)
    from scipy.spatial import cKDTree

    v = vertices.detach().to("cpu", torch.float64).numpy()
    r = rest.detach().to("cpu", torch.float64).numpy()
    out = np.zeros((B, V), dtype=bool)
    for b in range(B):
        pairs = cKDTree(v[b]).query_pairs(radius, output_type="ndarray")       # (P, 2), i < j, |v_i - v_j| <= radius
        if len(pairs):
            rb = r[0 if shared else b]
            far = np.linalg.norm(rb[pairs[:, 0]] - rb[pairs[:, 1]], axis=1) > rest_gap
            out[b, pairs[far].reshape(-1)] = True
    return torch.as_tensor(out, device=vertices.device)


def _contact_torch(vertices: torch.Tensor, rest: torch.Tensor, radius: float, rest_gap: float) -> torch.Tensor:
    """contact_vertices by every pair's distance (float64, differences not matrix products) in blocks of TORCH_ROWS
    rows. Shape: vertices (B, V, 3), rest (1 or B, V, 3) -> (B, V) bool on the vertices' device."""
    v = vertices.detach().to(torch.float64)
    r = rest.detach().to(torch.float64)
    B, V = v.shape[:2]
    out = torch.empty(B, V, dtype=torch.bool, device=v.device)
    for s in range(0, V, TORCH_ROWS):
        e = min(V, s + TORCH_ROWS)
        near = torch.cdist(v[:, s:e], v, compute_mode="donot_use_mm_for_euclid_dist") <= radius     # (B, n, V)
        far = torch.cdist(r[:, s:e], r, compute_mode="donot_use_mm_for_euclid_dist") > rest_gap     # (1 or B, n, V)
        out[:, s:e] = (near & far).any(dim=2)
    return out
