"""Room geometry and exact body-room tests of the egocentric app's placements (placement.py).

- `load_room`: make_room(seed) kept in memory; `visible_faces`: the faces one can see from inside a room;
- `room_cloud`: the dense surface sample of a room (CLOUD_DENSITY points per m² of visible surface, user cache);
  `crop`: its points in a box;
- `penetration`: the deepest body vertex inside a closed scene component (`RoomSolids`: boxes for the floor slab
  and walls, libigl's generalised winding number for the items) and the deepest scene point inside the body
  (`BodyMesh`: winding numbers counted along 3 rays, open3d); `surface_distance`: the smallest distance to a mesh.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from volsmpl.deps import open3d
from volsmpl.groundtruth import raycasting_scene
from volsmpl.scene import cached, make_room, sample_surface

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

    return cached("egohmr_room_cloud", CLOUD_VERSION, int(seed), build)["points"]


_RAY_DIRS = np.random.default_rng(20251124).normal(size=(3, 3))
_RAY_DIRS /= np.linalg.norm(_RAY_DIRS, axis=1, keepdims=True)


def _winding(scene, normals: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(N,) integer winding numbers of p (N, 3) w.r.t. the closed mesh in an open3d scene (face normals (F, 3)):
    signed crossings along 3 fixed rays, median (as volsmpl.groundtruth.ray_winding_number, on a prebuilt scene)."""
    o3d = open3d("the egohmr room checks (ray casts and distances)")
    o = np.ascontiguousarray(p, dtype=np.float32)
    per_ray = []
    for d in _RAY_DIRS:
        rays = np.concatenate([o, np.broadcast_to(d.astype(np.float32), o.shape)], axis=1)
        hits = scene.list_intersections(o3d.core.Tensor(rays))
        sign = np.sign(normals[hits["primitive_ids"].numpy()] @ d)
        per_ray.append(np.bincount(hits["ray_ids"].numpy(), weights=sign, minlength=len(p)).round())
    return np.median(np.stack(per_ray), axis=0)


class BodyMesh:
    """A closed triangle mesh with its open3d scene: winding numbers and distances of points."""

    def __init__(self, vertices, faces):
        v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
        self.scene = raycasting_scene(v, f)
        self.normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])

    def depth(self, p: np.ndarray) -> float:
        """Deepest point of p (N, 3) inside the mesh (winding >= 1), metres; 0 when none is inside."""
        if not len(p):
            return 0.0
        ins = _winding(self.scene, self.normals, p) >= 1
        if not ins.any():
            return 0.0
        o3d = open3d("the egohmr room checks (penetration depth)")
        return float(self.scene.compute_distance(o3d.core.Tensor(p[ins].astype(np.float32))).numpy().max())


class RoomSolids:
    """The closed components of a room for inside tests: the floor slab and walls (axis-aligned boxes: inside =
    strictly within the bounds) and the items (libigl's exact generalised winding number of the item's faces above
    1/2: robust to the coplanar faces where components touch, which break ray counting, e.g. a mattress on its
    frame or a chair foot on the floor)."""

    def __init__(self, room):
        self.boxes = [m.bounds for _, m in room.structure()]
        self.items = [(it.mesh.bounds, it.mesh) for it in room.items]
        self._scenes = {}

    def depth(self, p: np.ndarray) -> float:
        """Deepest point of p (N, 3) inside a component, metres (0 when none is inside)."""
        from volsmpl.groundtruth import winding_number
        deepest = 0.0
        for lo, hi in self.boxes:
            d = np.minimum(p - lo, hi - p).min(1)
            if (d > 0).any():
                deepest = max(deepest, float(d.max()))
        for k, ((lo, hi), mesh) in enumerate(self.items):
            q = p[((p > lo) & (p < hi)).all(1)]
            if not len(q):
                continue
            ins = q[winding_number(mesh.vertices, mesh.faces, q) > 0.5]
            if len(ins):
                o3d = open3d("the egohmr room checks (penetration depth)")
                if k not in self._scenes:
                    self._scenes[k] = raycasting_scene(mesh.vertices, mesh.faces)
                dist = self._scenes[k].compute_distance(o3d.core.Tensor(ins.astype(np.float32))).numpy()
                deepest = max(deepest, float(dist.max()))
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
    """Smallest distance (m) from points (N, 3) to a triangle mesh (open3d BVH)."""
    o3d = open3d("the egohmr room checks (ray casts and distances)")
    q = o3d.core.Tensor(np.asarray(points, dtype=np.float32))
    return float(raycasting_scene(mesh.vertices, mesh.faces).compute_distance(q).numpy().min())


__all__ = ["CLOUD_DENSITY", "CLOUD_VERSION", "load_room", "visible_faces", "room_cloud", "crop", "BodyMesh",
           "RoomSolids", "room_solids", "penetration", "surface_distance"]
