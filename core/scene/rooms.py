"""Procedural furnished indoor rooms, deterministic from an integer seed: `make_room` and the scene cloud.

`make_room(seed)` builds a rectangular room (interior 3.2-8 m by 3.2-8 m, walls 2.5-3.0 m high; see `room.py` for
the `Room` it returns and its queries) of one of ROOM_KINDS (chosen by seed % 4), and furnishes it through
`furnish.furnish_room` (the layout generator: which furniture, placed without overlaps).

Any non-negative seed gives a room; seeds 0 .. ROOM_COUNT-1 are the standard set (all distinct). Generation
takes ~0.1 s (one core); `room_points` caches its farthest-point-sampled scene cloud (see cache.py).

Example:
    >>> room = make_room(7)
    >>> scene = room.mesh()                                   # one trimesh, world frame
    >>> start, goal = room.sample_start_goal(3.0, clearance=0.3, seed=0)
    >>> pts = room_points(7)["points"]                        # (16384, 3) FPS scene cloud, cached
"""
from __future__ import annotations

import numpy as np

from .furnish import furnish_room
from .room import Room

ROOM_VERSION = 1
ROOM_COUNT = 100
ROOM_KINDS = ("living", "bedroom", "dining", "office")


def make_room(seed: int) -> Room:
    """Generate the furnished room of a seed (deterministic: the same seed gives byte-identical meshes).

    Args:
        seed: a non-negative int; the kind is ROOM_KINDS[seed % 4], sizes and furniture follow from the seed.

    Returns: a Room.

    Example:
        >>> room = make_room(3)
        >>> [it.category for it in room.items], room.size
    """
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}.")
    rng = np.random.default_rng([int(seed), ROOM_VERSION])
    kind = ROOM_KINDS[int(seed) % len(ROOM_KINDS)]
    size = np.array([rng.uniform(3.2, 8.0), rng.uniform(2.5, 3.0), rng.uniform(3.2, 8.0)])
    return Room(int(seed), kind, size, furnish_room(kind, size, rng))


def room_points(seed: int, n: int = 16384, oversample: int = 4, cache: bool = True) -> dict[str, np.ndarray]:
    """The farthest-point-sampled surface cloud of a room, as the scene-constrained motion app uses it.

    Samples n * oversample area-uniform points on the surfaces one can see from inside (floor top, walls' inner
    faces, furniture; not the undersides resting on the floor, wall corners or walls below the floor), then keeps n by
    farthest-point sampling (open3d). Cached in the user cache (cache.py) by ROOM_VERSION, the source of the
    generator (`code_version` of volsmpl.scene) and seed.

    Returns: {'points': (n, 3) float32, 'normals': (n, 3) float32, 'labels': (n,) int32 (item index, -1 floor,
    -2 walls)}.

    Example:
        >>> cloud = room_points(0)["points"]  # (16384, 3)
    """
    from .cache import cached, code_version
    from .points import farthest_point_sample, sample_surface

    def build():
        room = make_room(seed)
        mesh, labels = room.mesh(return_labels=True)
        nrm, ctr = mesh.face_normals, mesh.triangles_center
        (x0, _, z0), (x1, _, z1) = room.interior
        keep = ~((labels == -1) & (nrm[:, 1] < 0.9))  # floor slab: top face only
        keep &= ~((labels == -2) & ((ctr[:, 1] >= room.size[1] - 1e-6) | (ctr[:, 1] < 0)))  # wall tops, below floor
        inward = ((ctr[:, 0] - 0.5 * (x0 + x1)) * nrm[:, 0] + (ctr[:, 2] - 0.5 * (z0 + z1)) * nrm[:, 2]) < 0
        keep &= ~((labels == -2) & ~inward)  # wall faces looking out of the room
        keep &= ~((labels >= 0) & (nrm[:, 1] < -0.9) & (ctr[:, 1] < 1e-3))  # furniture bottoms on the floor
        p, nn, fid = sample_surface(mesh, n * oversample, seed=seed, faces=keep, return_faces=True)
        inside = ((p[:, 0] >= x0 - 1e-6) & (p[:, 0] <= x1 + 1e-6) & (p[:, 2] >= z0 - 1e-6) & (p[:, 2] <= z1 + 1e-6)
                  & (p[:, 1] >= -1e-6))  # drop the wall corners and the walls' feet beside the floor slab
        p, nn, fid = p[inside], nn[inside], fid[inside]
        idx = farthest_point_sample(p, n, seed=seed)
        return {"points": p[idx].astype(np.float32), "normals": nn[idx].astype(np.float32),
                "labels": labels[fid[idx]].astype(np.int32)}

    if not cache:
        return build()
    return cached(f"room_points_{n}_x{oversample}", code_version(ROOM_VERSION, "volsmpl.scene"), seed, build)
