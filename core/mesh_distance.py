"""Exact, differentiable distances from points to a triangle mesh (torch), for the 'mesh' model kind.

    d = mesh_signed_distance(vertices, faces, points)     # (N,), negative inside, grads to points and vertices

Two steps: the nearest triangle of every point is found without gradients (open3d's BVH on the CPU when
open3d imports, else a chunked brute force in torch on the points' device), then the closest point on that
triangle is computed in torch (Ericson's region tests), so the distance is differentiable with respect to
the points and the vertices. By the envelope theorem the gradient of the minimum over triangles is the
gradient for the minimising triangle, so holding the nearest triangle fixed gives the exact gradient
wherever the nearest triangle is unique. The sign: the winding number of the mesh (exact; a closed mesh's is
an integer, counted along rays by open3d; an open mesh's is the generalised winding number, inside above 1/2).
"""
from __future__ import annotations

import torch

from .groundtruth import closed_mesh_problems, ray_winding_number, winding_number_reference

__all__ = ["closest_points_on_triangles", "nearest_faces", "winding_numbers", "mesh_signed_distance"]


def closest_points_on_triangles(p: torch.Tensor, a: torch.Tensor, b: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
    """Closest point to p on the triangle (a, b, c), elementwise (Ericson, Real-Time Collision Detection 5.1.5).

    Shape: p, a, b, c (..., 3) broadcastable -> (..., 3). Differentiable almost everywhere.
    Example:
        >>> t = torch.tensor([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
        >>> closest_points_on_triangles(torch.tensor([0.2, 0.2, 1.0]), *t)
        tensor([0.2000, 0.2000, 0.0000])
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = p - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = p - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    tiny = torch.finfo(p.dtype).tiny

    def safe(n, d):
        return n / torch.where(d.abs() > tiny, d, torch.full_like(d, tiny))

    denom = va + vb + vc
    v_in, w_in = safe(vb, denom), safe(vc, denom)
    out = a + ab * v_in[..., None] + ac * w_in[..., None]  # interior (face region)
    # edge regions, then vertex regions: later assignments take precedence, as in Ericson's early returns
    w_bc = safe(d4 - d3, (d4 - d3) + (d5 - d6))
    out = torch.where(((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0))[..., None], b + (c - b) * w_bc[..., None], out)
    w_ac = safe(d2, d2 - d6)
    out = torch.where(((vb <= 0) & (d2 >= 0) & (d6 <= 0))[..., None], a + ac * w_ac[..., None], out)
    v_ab = safe(d1, d1 - d3)
    out = torch.where(((vc <= 0) & (d1 >= 0) & (d3 <= 0))[..., None], a + ab * v_ab[..., None], out)
    out = torch.where(((d6 >= 0) & (d5 <= d6))[..., None], c.expand_as(out), out)
    out = torch.where(((d3 >= 0) & (d4 <= d3))[..., None], b.expand_as(out), out)
    out = torch.where(((d1 <= 0) & (d2 <= 0))[..., None], a.expand_as(out), out)
    return out


def _open3d_or_none():
    try:
        import open3d as o3d
    except ImportError:
        return None
    return o3d


@torch.no_grad()
def nearest_faces(vertices: torch.Tensor, faces: torch.Tensor, points: torch.Tensor, backend: str = "auto",
                  chunk: int = 1 << 22) -> torch.Tensor:
    """Index of the nearest triangle of every point.

    Shape: vertices (V, 3), faces (F, 3) int, points (N, 3) -> (N,) int64 on the points' device.
    backend: 'open3d' (BVH on the CPU, float32), 'torch' (brute force in `chunk` point-triangle pairs at a time,
    on the points' device, in their dtype), 'auto' (open3d when it imports, else torch).
    """
    if backend not in ("auto", "open3d", "torch"):
        raise ValueError(f"backend must be 'auto', 'open3d' or 'torch', got {backend!r}")
    o3d = _open3d_or_none() if backend != "torch" else None
    if backend == "open3d" and o3d is None:
        raise ValueError("backend='open3d' but open3d does not import; install it (pip install open3d) or use backend='torch'")
    if len(points) == 0:
        return torch.zeros(0, dtype=torch.long, device=points.device)
    if o3d is not None:
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(vertices.detach().float().cpu().numpy()),
                            o3d.core.Tensor(faces.detach().cpu().numpy().astype("uint32")))
        ans = scene.compute_closest_points(o3d.core.Tensor(points.detach().float().cpu().numpy()))
        return torch.from_numpy(ans["primitive_ids"].numpy().astype("int64")).to(points.device)
    tri = vertices.detach()[faces.to(vertices.device)]  # (F, 3, 3)
    step = max(1, chunk // max(1, len(faces)))
    out = []
    for s in range(0, len(points), step):
        p = points[s:s + step].detach()[:, None]  # (n, 1, 3)
        q = closest_points_on_triangles(p, tri[None, :, 0], tri[None, :, 1], tri[None, :, 2])
        out.append(((q - p) ** 2).sum(-1).argmin(dim=1))
    return torch.cat(out)


@torch.no_grad()
def winding_numbers(vertices: torch.Tensor, faces: torch.Tensor, points: torch.Tensor, closed: bool | None = None) -> torch.Tensor:
    """Winding numbers of points w.r.t. a mesh: integers counted along 3 rays (open3d) for a closed mesh, the
    exact generalised winding number (float64 solid angles, brute force) for an open one or without open3d.

    Shape: vertices (V, 3), faces (F, 3), points (N, 3) -> (N,) float on the points' device.
    closed: whether the mesh is closed (checked from the faces when None).
    """
    if closed is None:
        closed = closed_mesh_problems(faces.cpu().numpy()) is None
    if closed and _open3d_or_none() is not None:
        w = ray_winding_number(vertices.detach().cpu(), faces.cpu(), points.detach().cpu(), nsamples=3)
    else:
        w = winding_number_reference(vertices.detach().cpu().double(), faces.cpu(), points.detach().cpu().double())
    return w.to(points.device, points.dtype)


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
    idx = nearest_faces(vertices, faces, points, backend)
    tri = vertices[faces[idx]]  # (N, 3, 3), differentiable in the vertices
    q = closest_points_on_triangles(points, tri[:, 0], tri[:, 1], tri[:, 2])
    diff = points - q
    sq = (diff * diff).sum(-1)
    # sqrt with a finite gradient on the surface itself (d = 0): the gradient there is taken as 0
    dist = torch.where(sq > 0, sq.clamp_min(torch.finfo(sq.dtype).tiny).sqrt(), torch.zeros_like(sq))
    inside = winding_numbers(vertices, faces, points, closed) > 0.5
    return torch.where(inside, -dist, dist)
