"""The geometry `volsmpl hoi make-case` (make_case.py) builds a case with: projection, the object's silhouette
pixels, its placement from a mask, and contact regions picked automatically or moved over from a template.

    uv, z = project(K, x)                                     # pixels and depth of camera-frame points
    pix = raster_pixels(K, (H, W), v_cam, faces)              # (P, 2) the pixels the mesh covers
    faces = auto_region(tris_cam, part_points)                # the object's triangles nearest a body part
"""
from __future__ import annotations

import numpy as np

__all__ = ["AUTO_BAND", "MIN_Z", "TRANSFER_TOL", "UPRIGHT", "auto_region", "place_from_mask", "project",
           "raster_mask", "raster_pixels", "transfer_region"]

AUTO_BAND = 0.02  # metres: `auto` takes the object's triangles within this of its nearest to the part
TRANSFER_TOL = 0.1  # share of the mesh's largest extent: a template region's triangles further are not moved over
UPRIGHT = np.diag([1.0, -1.0, -1.0])  # the object frame's +Y up in the image, +Z towards the camera
MIN_Z = 0.05  # metres: points nearer the camera plane count as behind it


def project(K: np.ndarray, x: np.ndarray):
    """Pixels (N, 2) and depths (N,) of camera-frame points x (N, 3): u = fx x / z + cx, v = fy y / z + cy."""
    z = x[:, 2]
    uv = (x @ K.T)[:, :2] / np.where(np.abs(z) > 1e-9, z, 1e-9)[:, None]
    return uv, z


def raster_mask(K: np.ndarray, size, vertices_cam: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(H, W) uint8 mask of the projection of a camera-frame mesh: the union of its triangles in front of the
    camera, each filled by OpenCV on its own (one fillPoly of them all keeps only the pixels an odd number of
    triangles cover: a closed mesh's front and back cancel)."""
    import cv2

    uv, z = project(K, vertices_cam)
    faces = faces[(z[faces] > MIN_Z).all(axis=1)]
    m = np.zeros(tuple(size), np.uint8)
    for tri in np.round(np.clip(uv[faces], -1e5, 1e5) * 16).astype(np.int32):
        cv2.fillConvexPoly(m, tri, 1, lineType=cv2.LINE_8, shift=4)
    return m


def raster_pixels(K: np.ndarray, size, vertices_cam: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The (u, v) pixels (N, 2) of `raster_mask`, row-major order."""
    v, u = np.nonzero(raster_mask(K, size, vertices_cam, faces))
    return np.stack([u, v], axis=1).astype(np.float64)


def place_from_mask(K: np.ndarray, mask: np.ndarray, mesh, scale: float):
    """The object's first-stage similarity from its mask alone (module docstring: upright, facing the camera, the
    depth from its size against the mask's extent, the centre on the mask centroid's ray)."""
    from .case import Similarity

    v, u = np.nonzero(mask)
    w_px, h_px = u.max() - u.min() + 1.0, v.max() - v.min() + 1.0
    ext = scale * np.asarray(mesh.extents)
    z = float(np.hypot(K[0, 0] * ext[0], K[1, 1] * ext[1]) / np.hypot(w_px, h_px))
    centre = z * np.linalg.solve(K, np.array([u.mean(), v.mean(), 1.0]))
    return Similarity(scale, UPRIGHT.copy(), centre - scale * UPRIGHT @ np.asarray(mesh.bounds).mean(axis=0))


def _face_distances(tris: np.ndarray, points: np.ndarray, chunk: int = 1 << 20) -> np.ndarray:
    """The distance (F,) of each triangle (F, 3, 3) to its nearest point of `points` (P, 3) (exact, float64)."""
    import torch
    from volsmpl.geometry.point_mesh_distance import closest_points_on_triangles

    t = torch.as_tensor(tris, dtype=torch.float64)
    p = torch.as_tensor(points, dtype=torch.float64)
    out = torch.empty(len(t), dtype=torch.float64)
    step = max(1, chunk // max(1, len(p)))
    for i in range(0, len(t), step):
        a, b, c = (x[:, None] for x in t[i:i + step].unbind(1))  # (f, 1, 3)
        q = closest_points_on_triangles(p[None].expand(len(a), -1, -1), a, b, c)
        out[i:i + step] = (q - p[None]).norm(dim=-1).min(dim=1).values
    return out.numpy()


def auto_region(tris_cam: np.ndarray, part_points: np.ndarray, band: float = AUTO_BAND) -> np.ndarray:
    """`auto`: the ids of the triangles (F, 3, 3) within `band` metres of the nearest one to the part, by their
    exact distance to the part's points (P, 3) (both in one frame). Shape: -> (R,) int64, R >= 1."""
    d = _face_distances(tris_cam, part_points)
    return np.nonzero(d <= d.min() + band)[0]


def transfer_region(mesh, category: str, region: str, tol: float = TRANSFER_TOL) -> np.ndarray:
    """A template region moved onto a mesh in the template's frame (module docstring). Shape: -> (R,) int64."""
    import torch
    from volsmpl.geometry.point_mesh_distance import (
        closest_points_on_triangles,
        nearest_faces,
    )
    from volsmpl.scene.objects import make_object

    tmpl = make_object(category)
    lo, hi = np.asarray(tmpl.mesh.bounds)
    mlo, mhi = np.asarray(mesh.bounds)
    tv = (np.asarray(tmpl.mesh.vertices) - lo) * ((mhi - mlo) / (hi - lo)) + mlo
    tf = np.asarray(tmpl.mesh.faces)
    centres = torch.as_tensor(np.array(mesh.triangles_center), dtype=torch.float64)
    near = nearest_faces(torch.as_tensor(tv), torch.as_tensor(tf), centres).cpu().numpy()
    tri = torch.as_tensor(tv[tf[near]])
    dist = (closest_points_on_triangles(centres, tri[:, 0], tri[:, 1], tri[:, 2]) - centres).norm(dim=-1).numpy()
    return np.nonzero(np.isin(near, tmpl.regions[region]) & (dist <= tol * float(np.max(mesh.extents))))[0]


# ------------------------------------------------------------------------------------------- the command
