"""Where a posed body touches itself: vertices near a vertex that is far from them on the body (self-contact).

A vertex is *in contact* when some vertex lies within `radius` of it in the posed body but was more than
`rest_gap` away in the rest pose: a hand on the chest, one thigh against the other, the calf pressed to the
thigh in a squat. Neighbours across a joint are near in both poses and never count, whatever the part
labels, so this needs no part table and works for any SMPL-family body. Exact, by either of two methods with the
same result: 'kdtree' (scipy's k-d tree finds every pair within the radius, on the CPU: ~30 ms a body on one thread)
or 'torch' (a uniform grid of cells as wide as the radius, every vertex against the vertices of its 27 cells, in
float64 on the vertices' device: a training batch on a GPU, where the copy to the host and the k-d tree took most
of the batch's time). 'auto': the k-d tree for CPU tensors, torch elsewhere.

    mask = contact_vertices(posed.vertices, body.v_template)      # (B, V) bool
    # training queries around them: volsmpl.train.queries.sample_contact_points
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


def contact_vertices(vertices: torch.Tensor, rest_vertices: torch.Tensor, radius: float = CONTACT_RADIUS,
                     rest_gap: float = REST_GAP, method: str = "auto") -> torch.Tensor:
    """Per body, the vertices in self-contact (module docstring), on the vertices' device.

    Shape: vertices (B, V, 3) posed, rest_vertices (V, 3) or (B, V, 3) the same bodies at rest -> (B, V) bool.
    method: 'auto', 'kdtree' or 'torch' (module docstring; the same mask).
    """
    if vertices.dim() != 3 or vertices.shape[-1] != 3:
        raise ValueError(f"contact_vertices expects vertices (B, V, 3), got {tuple(vertices.shape)}")
    B, V = vertices.shape[:2]
    shared = rest_vertices.dim() == 2   # one rest shape for every body (not expanded: indexed per body)
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


def _contact_torch(vertices: torch.Tensor, rest: torch.Tensor, radius: float, rest_gap: float,
                   rows: int | None = None) -> torch.Tensor:
    """contact_vertices on the vertices' device by a uniform grid: cells a little wider than the radius, so that two
    vertices within the radius sit in the same or neighbouring cells; every vertex is compared with the vertices of
    its 27 cells (all bodies at once: the body is part of the cell key; `rows` vertices a block), by differences in
    float64, as the k-d tree path. rows: None is 8,192 on the CPU (in cache: 8 bodies in ~1 s on one thread, 1.8 s
    with 2^16), 2^17 elsewhere (fewer launches). Shape: vertices (B, V, 3), rest (1 or B, V, 3) -> (B, V) bool there."""
    rows = rows or (8192 if vertices.device.type == "cpu" else 1 << 17)
    v = vertices.detach().to(torch.float64)
    r = rest.detach().to(torch.float64)
    B, V = v.shape[:2]
    dev = v.device
    cell = torch.floor((v - v.amin(dim=1, keepdim=True)) / (radius * (1 + 1e-6))).long() + 1   # (B, V, 3) >= 1
    dims = cell.amax(dim=(0, 1)) + 2                                                # the neighbours of every cell fit
    body = torch.arange(B, device=dev)[:, None].expand(B, V)
    key = (((body * dims[0] + cell[..., 0]) * dims[1] + cell[..., 1]) * dims[2] + cell[..., 2]).reshape(-1)
    order = torch.argsort(key)
    cells, counts = torch.unique_consecutive(key[order], return_counts=True)        # (U,) occupied cells, sorted
    counts = torch.cat([counts, counts.new_zeros(1)])                               # index U: no cell, no vertex
    start = torch.cumsum(counts, 0) - counts
    d = torch.arange(-1, 2, device=dev)
    offsets = ((d[:, None, None] * dims[1] + d[None, :, None]) * dims[2] + d[None, None, :]).reshape(-1)   # (27,)
    flat_v, flat_r = v.reshape(-1, 3), r.reshape(-1, 3)
    out = torch.zeros(B * V, dtype=torch.bool, device=dev)
    for s in range(0, B * V, rows):
        i = torch.arange(s, min(B * V, s + rows), device=dev)
        near_key = key[i, None] + offsets                                           # (n, 27)
        at = torch.searchsorted(cells, near_key).clamp(max=len(cells) - 1)
        at = torch.where(cells[at] == near_key, at, len(cells)).reshape(-1)         # (n * 27,) cell or none
        n = counts[at]
        pi = torch.repeat_interleave(i.repeat_interleave(len(offsets)), n)          # (P,) the vertex of each pair
        first = torch.cumsum(n, 0) - n
        pj = order[torch.repeat_interleave(start[at] - first, n) + torch.arange(len(pi), device=dev)]
        near = (flat_v[pi] - flat_v[pj]).norm(dim=-1) <= radius
        ri, rj = (pi, pj) if len(r) == B else (pi % V, pj % V)
        far = (flat_r[ri] - flat_r[rj]).norm(dim=-1) > rest_gap
        hit = pi[near & far]
        out[hit] = True
    return out.view(B, V)
