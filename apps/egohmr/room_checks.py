"""Room geometry and exact body-room tests of the egocentric app's placements (placement.py).

- `load_room`: make_room(seed) kept in memory; `visible_faces`: the faces one can see from inside a room;
- `room_cloud`: the dense surface sample of a room (CLOUD_DENSITY points per m² of visible surface, user cache);
  `crop`: its points in a box;
- `penetration`: the deepest body vertex inside a closed scene component (`RoomSolids`: boxes for the floor slab
  and walls, libigl's generalised winding number for the items) and the deepest scene point inside the body
  (`BodyMesh`: winding numbers counted along 3 rays, open3d); `surface_distance`: the smallest distance to a mesh.

Where open3d does not import (e.g. a CUDA machine without it), the ray counts and distances are those of
`volsmpl.geometry.triangle_queries.MeshQuery` (exact integer winding numbers by signed ray crossings, exact float64 distances,
torch on the CPU); where libigl does not import, an item's inside test is MeshQuery's winding number >= 1, which
equals libigl's generalised winding number > 1/2 off the surface of a closed item. The answers agree with open3d's
and libigl's up to open3d's float32 distances (~1e-7 m).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import torch

from volsmpl.runtime import deps
from volsmpl.geometry.groundtruth import raycasting_scene
from volsmpl.geometry.triangle_queries import MeshQuery
from volsmpl.scene import cached, code_version, make_room, sample_surface

CLOUD_DENSITY = 1e4  # room_cloud: points per square metre of visible surface (1 per cm²)
CLOUD_VERSION = 2


@lru_cache(maxsize=8)
def load_room(seed: int):
    """make_room(seed), kept in memory (8 rooms) with its mesh and ray-casting caches."""
    return make_room(int(seed))


def visible_faces(room) -> np.ndarray:
    """(F,) bool: the room-mesh faces one can see from inside (floor top, walls' inner faces, furniture except the
    bottoms resting on the floor)."""
    mesh, labels = room.mesh(return_labels=True)
    nrm, ctr = mesh.face_normals, mesh.triangles_center
    (x0, _, z0), (x1, _, z1) = room.interior
    keep = ~((labels == -1) & (nrm[:, 1] < 0.9))
    keep &= ~((labels == -2) & ((ctr[:, 1] >= room.size[1] - 1e-6) | (ctr[:, 1] < 0)))
    inward = ((ctr[:, 0] - 0.5 * (x0 + x1)) * nrm[:, 0] + (ctr[:, 2] - 0.5 * (z0 + z1)) * nrm[:, 2]) < 0
    keep &= ~((labels == -2) & ~inward)
    keep &= ~((labels >= 0) & (nrm[:, 1] < -0.9) & (ctr[:, 1] < 1e-3))
    return keep


@lru_cache(maxsize=6)
def room_cloud(seed: int) -> np.ndarray:
    """The dense surface sample of a room (world frame): CLOUD_DENSITY area-uniform points per m² of its visible
    faces, inside the interior, sorted by x (for `crop`) (~1-1.8 M points, 12-22 MB), cached in the user cache and in memory (6 rooms).

    Shape: -> (N, 3) float32."""
    def build():
        room = make_room(int(seed))
        mesh, keep = room.mesh(), visible_faces(room)
        n = int(np.ceil(mesh.area_faces[keep].sum() * CLOUD_DENSITY))
        p, _ = sample_surface(mesh, n, seed=int(seed), faces=keep)
        (x0, _, z0), (x1, _, z1) = room.interior
        p = p[(p[:, 0] >= x0 - 1e-6) & (p[:, 0] <= x1 + 1e-6) & (p[:, 2] >= z0 - 1e-6) & (p[:, 2] <= z1 + 1e-6)
              & (p[:, 1] >= -1e-6)]
        return {"points": p[np.argsort(p[:, 0], kind="stable")].astype(np.float32)}

    return cached("egohmr_room_cloud", code_version(CLOUD_VERSION, "volsmpl.scene", __name__), int(seed), build)["points"]


_RAY_DIRS = np.random.default_rng(20251124).normal(size=(3, 3))
_RAY_DIRS /= np.linalg.norm(_RAY_DIRS, axis=1, keepdims=True)


def _winding(o3d, scene, normals: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(N,) integer winding numbers of p (N, 3) w.r.t. the closed mesh in an open3d scene (face normals (F, 3)):
    signed crossings along 3 fixed rays, median (as volsmpl.geometry.groundtruth.ray_winding_number, on a prebuilt scene)."""
    o = np.ascontiguousarray(p, dtype=np.float32)
    per_ray = []
    for d in _RAY_DIRS:
        rays = np.concatenate([o, np.broadcast_to(d.astype(np.float32), o.shape)], axis=1)
        hits = scene.list_intersections(o3d.core.Tensor(rays))
        sign = np.sign(normals[hits["primitive_ids"].numpy()] @ d)
        per_ray.append(np.bincount(hits["ray_ids"].numpy(), weights=sign, minlength=len(p)).round())
    return np.median(np.stack(per_ray), axis=0)


def _query(vertices, faces) -> MeshQuery:
    """MeshQuery of a mesh given as numpy arrays, on the CPU in float64."""
    return MeshQuery(torch.as_tensor(np.asarray(vertices, np.float64)), torch.as_tensor(np.asarray(faces, np.int64)))


def _tensor(p: np.ndarray) -> torch.Tensor:
    """Points (N, 3) as a float64 CPU tensor."""
    return torch.as_tensor(np.asarray(p, np.float64))


class BodyMesh:
    """A closed triangle mesh: winding numbers and distances of points, by open3d's scene (ray casts, BVH) where
    open3d imports, else by MeshQuery (exact, torch on the CPU)."""

    def __init__(self, vertices, faces):
        v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
        self.o3d = deps.open3d_or_none()
        if self.o3d is None:
            self.query = _query(v, f)
        else:
            self.scene = raycasting_scene(v, f)
            self.normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])

    def winding(self, p: np.ndarray) -> np.ndarray:
        """(N,) integer winding numbers of p (N, 3) (float64 values)."""
        if self.o3d is None:
            return self.query.winding_numbers(_tensor(p)).double().numpy()
        return _winding(self.o3d, self.scene, self.normals, p)

    def distances(self, p: np.ndarray) -> np.ndarray:
        """(N,) unsigned distances (m) of p (N, 3) to the mesh."""
        if self.o3d is None:
            return self.query.distances(_tensor(p)).numpy()
        return self.scene.compute_distance(self.o3d.core.Tensor(np.asarray(p, np.float32))).numpy()

    def depth(self, p: np.ndarray) -> float:
        """Deepest point of p (N, 3) inside the mesh (winding >= 1), metres; 0 when none is inside."""
        if not len(p):
            return 0.0
        ins = self.winding(p) >= 1
        if not ins.any():
            return 0.0
        return float(self.distances(p[ins]).max())


class RoomSolids:
    """The closed components of a room for inside tests: the floor slab and walls (axis-aligned boxes: inside =
    strictly within the bounds) and the items (libigl's exact generalised winding number of the item's faces above
    1/2: robust to the coplanar faces where components touch, which break ray counting, e.g. a mattress on its
    frame or a chair foot on the floor; without libigl MeshQuery's exact integer winding number >= 1, whose
    crossings of coplanar faces are decided exactly)."""

    def __init__(self, room):
        self.boxes = [m.bounds for _, m in room.structure()]
        self.items = [(it.mesh.bounds, it.mesh) for it in room.items]
        self._meshes, self._queries = {}, {}

    def inside(self, k: int, q: np.ndarray) -> np.ndarray:
        """(M,) bool: the points q (M, 3) inside item k."""
        mesh = self.items[k][1]
        if deps.igl_or_none() is not None:
            from volsmpl.geometry.groundtruth import winding_number
            return winding_number(mesh.vertices, mesh.faces, q) > 0.5
        if k not in self._queries:
            self._queries[k] = _query(mesh.vertices, mesh.faces)
        return self._queries[k].winding_numbers(_tensor(q)).numpy() >= 1

    def depth(self, p: np.ndarray) -> float:
        """Deepest point of p (N, 3) inside a component, metres (0 when none is inside)."""
        deepest = 0.0
        for lo, hi in self.boxes:
            d = np.minimum(p - lo, hi - p).min(1)
            if (d > 0).any():
                deepest = max(deepest, float(d.max()))
        for k, ((lo, hi), mesh) in enumerate(self.items):
            q = p[((p > lo) & (p < hi)).all(1)]
            if not len(q):
                continue
            ins = q[self.inside(k, q)]
            if len(ins):
                if k not in self._meshes:
                    self._meshes[k] = BodyMesh(mesh.vertices, mesh.faces)
                deepest = max(deepest, float(self._meshes[k].distances(ins).max()))
        return deepest


@lru_cache(maxsize=8)
def room_solids(seed: int):
    """The closed components of room `seed` (RoomSolids) and its mesh vertices (V, 3), built once (8 rooms)."""
    room = load_room(seed)
    return RoomSolids(room), np.asarray(room.mesh().vertices)


def crop(points: np.ndarray, lo, hi) -> np.ndarray:
    """The points of an x-sorted cloud (room_cloud) inside the closed box [lo, hi]. Shape: (N, 3) -> (M, 3)."""
    i0, i1 = np.searchsorted(points[:, 0], [lo[0], hi[0]], side="left"), None
    i0, i1 = int(i0[0]), int(np.searchsorted(points[:, 0], hi[0], side="right"))
    sub = points[i0:i1]
    return sub[((sub >= lo) & (sub <= hi)).all(1)]


def penetration(vertices: np.ndarray, faces: np.ndarray, room, cloud: np.ndarray, body=None,
                shift=None) -> tuple[float, float]:
    """Exact interpenetration of a posed body and a room: the deepest body vertex inside a closed scene component
    and the deepest scene point (room vertices and the x-sorted `cloud`) inside the body (winding number counted
    along rays), metres (0 when none is inside). body, shift: the body's prebuilt `BodyMesh` at `vertices` and a
    translation (3,) to apply (a rigidly moved body, for settling).

    Shape: vertices (V, 3) world, faces (F, 3), cloud (N, 3) -> (float, float)."""
    solids, sv = room_solids(room.seed)
    v = np.asarray(vertices, dtype=np.float64)
    s = np.zeros(3) if shift is None else np.asarray(shift, dtype=np.float64)
    vs = v + s
    d_body = solids.depth(vs)
    lo, hi = vs.min(0) - 0.01, vs.max(0) + 0.01
    pts = np.concatenate([sv[((sv >= lo) & (sv <= hi)).all(1)], crop(cloud, lo, hi)])
    if not len(pts):
        return d_body, 0.0
    body = BodyMesh(v, faces) if body is None else body
    return d_body, body.depth(pts - s)


def surface_distance(points: np.ndarray, mesh) -> float:
    """Smallest distance (m) from points (N, 3) to a triangle mesh (open3d BVH; MeshQuery without open3d)."""
    o3d = deps.open3d_or_none()
    if o3d is None:
        return float(_query(mesh.vertices, mesh.faces).distances(_tensor(points)).min())
    q = o3d.core.Tensor(np.asarray(points, dtype=np.float32))
    return float(raycasting_scene(mesh.vertices, mesh.faces).compute_distance(q).numpy().min())


__all__ = ["CLOUD_DENSITY", "CLOUD_VERSION", "load_room", "visible_faces", "room_cloud", "crop", "BodyMesh",
           "RoomSolids", "room_solids", "penetration", "surface_distance"]
