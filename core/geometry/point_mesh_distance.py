"""Exact, differentiable distances from points to a triangle mesh (torch), for the 'mesh' model kind.

    d = mesh_signed_distance(vertices, faces, points)     # (N,), negative inside, grads to points and vertices

Two steps: the nearest triangle of every point is found without gradients (open3d's BVH on the CPU when
open3d imports, else `volsmpl.geometry.triangle_queries.MeshQuery`: exact, cluster-culled, chunked, in torch on the vertices'
device), then the closest point on that
triangle is computed in torch (Ericson's region tests), so the distance is differentiable with respect to
the points and the vertices. By the envelope theorem the gradient of the minimum over triangles is the
gradient for the minimising triangle, so holding the nearest triangle fixed gives the exact gradient
wherever the nearest triangle is unique. The sign: the winding number of the mesh (exact; a closed mesh's is
an integer, counted along rays by open3d or by MeshQuery's signed crossings in torch; an open mesh's is the
generalised winding number, inside above 1/2).
"""
from __future__ import annotations

import hashlib

import numpy as np
import torch

from volsmpl.runtime.deps import open3d_or_none
from volsmpl.geometry.groundtruth import closed_mesh_problems, ray_winding_number, winding_number_reference
from volsmpl.geometry.triangle_queries import DEFAULT_CHUNK, MeshQuery, closest_points_on_triangles

__all__ = ["closest_points_on_triangles", "nearest_faces", "winding_numbers", "mesh_signed_distance"]


def _backend(backend: str):
    """open3d module for backend 'open3d' (or 'auto' when it imports), None for torch."""
    if backend not in ("auto", "open3d", "torch"):
        raise ValueError(f"backend must be 'auto', 'open3d' or 'torch', got {backend!r}")
    o3d = open3d_or_none() if backend != "torch" else None
    if backend == "open3d" and o3d is None:
        raise ValueError("backend='open3d' but open3d does not import; install it (pip install open3d) or use backend='torch'")
    return o3d


@torch.no_grad()
def nearest_faces(vertices: torch.Tensor, faces: torch.Tensor, points: torch.Tensor, backend: str = "auto",
                  chunk: int = DEFAULT_CHUNK) -> torch.Tensor:
    """Index of the nearest triangle of every point.

    Shape: vertices (V, 3), faces (F, 3) int, points (N, 3) -> (N,) int64 on the points' device.
    backend: 'open3d' (BVH on the CPU, float32), 'torch' (`MeshQuery`: exact in float64 on the vertices' device,
    at most `chunk` point-triangle pairs at once), 'auto' (open3d when it imports, else torch).
    """
    o3d = _backend(backend)
    if len(points) == 0:
        return torch.zeros(0, dtype=torch.long, device=points.device)
    if o3d is not None:
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(vertices.detach().float().cpu().numpy()),
                            o3d.core.Tensor(faces.detach().cpu().numpy().astype("uint32")))
        ans = scene.compute_closest_points(o3d.core.Tensor(points.detach().float().cpu().numpy()))
        return torch.from_numpy(ans["primitive_ids"].numpy().astype("int64")).to(points.device)
    return MeshQuery(vertices, faces, chunk=chunk).nearest_faces(points).to(points.device)


@torch.no_grad()
def winding_numbers(vertices: torch.Tensor, faces: torch.Tensor, points: torch.Tensor, closed: bool | None = None,
                    backend: str = "auto", chunk: int = DEFAULT_CHUNK) -> torch.Tensor:
    """Winding numbers of points w.r.t. a mesh: integers for a closed mesh (signed crossings along 3 rays by open3d
    for a mesh of one connected surface, such as a posed body; else, and without open3d, along one ray by
    `MeshQuery` in float64 in torch on the vertices' device), the exact generalised winding number (float64 solid
    angles, brute force on the CPU) for an open one. open3d's float32 rays miscount where separate components
    touch or share planes (generated sofas and beds: 1-3 % of the points of their boxes, against libigl), so a mesh
    of several components never takes them.

    Shape: vertices (V, 3), faces (F, 3), points (N, 3) -> (N,) float on the points' device.
    closed: whether the mesh is closed (checked from the faces when None). backend: as `nearest_faces`.
    """
    o3d = _backend(backend)
    if closed is None:
        closed = closed_mesh_problems(faces.cpu().numpy()) is None
    if closed and o3d is not None and surface_count(faces) == 1:
        w = ray_winding_number(vertices.detach().cpu(), faces.cpu(), points.detach().cpu(), nsamples=3)
    elif closed:
        w = MeshQuery(vertices, faces, chunk=chunk).winding_numbers(points)
    else:
        w = winding_number_reference(vertices.detach().cpu().double(), faces.cpu(), points.detach().cpu().double())
    return w.to(points.device, points.dtype)


def surface_count(faces: torch.Tensor) -> int:
    """Number of connected surfaces of a triangle mesh (faces joined through shared vertices), remembered per face
    array (the body's faces are asked at every query of the 'mesh' kind). Shape: faces (F, 3)."""
    f = faces.detach().cpu().numpy().astype(np.int64, copy=False)
    if f.size == 0:
        return 0
    key = hashlib.sha1(f.tobytes()).hexdigest()
    if key not in _SURFACES:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        V = int(f.max()) + 1
        edges = coo_matrix((np.ones(3 * len(f)), (f.ravel(), np.roll(f, -1, axis=1).ravel())), shape=(V, V))
        _, labels = connected_components(edges, directed=False)
        if len(_SURFACES) > 64:
            _SURFACES.clear()
        _SURFACES[key] = len(np.unique(labels[np.unique(f)]))
    return _SURFACES[key]


_SURFACES: dict = {}


def mesh_signed_distance(vertices: torch.Tensor, faces: torch.Tensor, points: torch.Tensor, closed: bool | None = None,
                         backend: str = "auto") -> torch.Tensor:
    """Signed distance of points to a triangle mesh: exact, negative inside (winding number above 1/2).

    Shape: vertices (V, 3), faces (F, 3) int, points (N, 3) -> (N,). Differentiable w.r.t. points and vertices.
    Example:
        >>> import trimesh
        >>> box = trimesh.creation.box((2, 2, 2))
        >>> v, f = torch.tensor(box.vertices), torch.tensor(box.faces)
        >>> mesh_signed_distance(v, f, torch.tensor([[0., 0, 0], [3, 0, 0]]))
        tensor([-1.,  2.], dtype=torch.float64)
    """
    faces = faces.to(vertices.device).long()
    if closed is None:
        closed = closed_mesh_problems(faces.cpu().numpy()) is None
    if _backend(backend) is None and closed:  # one MeshQuery for the nearest faces and the sign
        mq = MeshQuery(vertices, faces)
        idx, inside = mq.nearest_faces(points).to(points.device), mq.winding_numbers(points).to(points.device) > 0
    else:
        idx = nearest_faces(vertices, faces, points, backend)
        inside = winding_numbers(vertices, faces, points, closed, backend) > 0.5
    tri = vertices[faces[idx]]  # (N, 3, 3), differentiable in the vertices
    q = closest_points_on_triangles(points, tri[:, 0], tri[:, 1], tri[:, 2])
    diff = points - q
    sq = (diff * diff).sum(-1)
    # sqrt with a finite gradient on the surface itself (d = 0): the gradient there is taken as 0
    dist = torch.where(sq > 0, sq.clamp_min(torch.finfo(sq.dtype).tiny).sqrt(), torch.zeros_like(sq))
    return torch.where(inside, -dist, dist)
