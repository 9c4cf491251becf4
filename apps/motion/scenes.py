"""Scenes and start/goal pairs of the motion app: generated rooms (volsmpl.scene) and a user's own scan.

A `MotionScene` is a point cloud (a generated room: 16,384 farthest-point samples of the surfaces, floor
included; a user's scan: the points of its walk's corridor; Y up, metres, floor at `floor_y`) with a name, and its
start/goal pairs (x, z floor positions). Generated rooms (`room_scene(seed)`) come with the room itself (for
footprints in plots). `volsmpl motion --scene` takes a user's scan through user_scene.load_user_scene (the walk's
corridor at a spacing in metres, any size of scene). `load_scene(path, ...)` here reads a small scene whole: a
mesh or a point cloud in any format trimesh reads (ply, obj, off, stl, glb, xyz...) or a .npy/.npz/.txt array of
points, converts up-axis and units, and samples it to 16,384 points (about 1 m apart over a 124 m temple: for
anything larger than a room, load_user_scene); its size and up axis are checked right after reading
(scene_checks.py: refused when they cannot be right, warned about when unusual) and its name is made file-safe
(volsmpl.apps.checks.safe_name: `my room.ply` -> 'my_room-<hash>').

`check_endpoint` refuses a start or goal off the floor or inside an obstacle, `check_pair` a pair that the walk
cannot cover in its frames (a scene in the wrong --units), each with a clear ValueError that repeats what looked odd
about the scene (its `doubts`: units, up axis) as the likely cause.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from volsmpl.scene import farthest_point_sample, make_room, room_points
from volsmpl.scene.scan import UNITS, to_y_up

N_POINTS = 16384
BODY_CLEAR = 0.15     # metres: no obstacle point this close (horizontally) to a start or goal, below BODY_HEIGHT
BODY_HEIGHT = 1.8
MIN_PAIR_DISTANCE = 1.6   # metres: shorter pairs cannot have furniture between two 0.5 m-clear ends
CROSS_TOL = 0.02     # metres: a pair's straight line passes this close to (or through) a furniture footprint
FLOOR_REACH = 0.3     # metres: a floor point must lie this close to a start or goal


@dataclass
class MotionScene:
    """A scene cloud and its start/goal pairs. points (N, 3) float32, floor (N,) bool (floor points), pairs:
    list of (start (2,), goal (2,)) floor positions (x, z); doubts: what looked odd about a user's scene
    (scene_checks.check_scene), repeated by the refusals of its start and goal; floor_found: the floor level found
    in a user's scan, in this cloud's heights (None: the cloud's 1st height percentile stands for it); lift: the
    height subtracted from the scan's points to put the floor at y = 0 (added back for the outputs)."""

    name: str
    points: np.ndarray
    floor: np.ndarray
    floor_y: float = 0.0
    room: object = None
    pairs: list = field(default_factory=list)
    doubts: list = field(default_factory=list)
    floor_found: float | None = None
    lift: float = 0.0


def _likely(scene: MotionScene) -> str:
    """' (the scene looked odd: ...)' naming its doubts, or '' for a scene that looked right."""
    doubts = getattr(scene, "doubts", None) or []
    return f" (the scene looked odd: {'; '.join(doubts)}: check --units and --up)" if doubts else ""


def check_endpoint(scene: MotionScene, xz, which: str) -> np.ndarray:
    """ValueError unless the floor position xz (2,) is on the floor (a floor point within FLOOR_REACH) and free
    (no obstacle point within BODY_CLEAR horizontally, between 5 cm and BODY_HEIGHT above the floor)."""
    q = np.asarray(xz, dtype=np.float64).reshape(-1)
    if q.shape != (2,) or not np.isfinite(q).all():
        raise ValueError(f"{which} must be two finite numbers x,z; got {xz!r}")
    P = scene.points
    d = np.linalg.norm(P[:, [0, 2]] - q, axis=1)
    if not (scene.floor & (d < FLOOR_REACH)).any():
        found = getattr(scene, "floor_found", None)
        low = float(np.percentile(P[:, 1], 1)) if found is None else float(found)
        gap = scene.floor_y - low
        level = (f" (the floor level lies {abs(gap):.2f} m {'above' if gap > 0 else 'below'} the scene's lowest "
                 f"points: check --floor-y)" if abs(gap) > FLOOR_REACH else "")
        raise ValueError(f"{which} ({q[0]:.2f}, {q[1]:.2f}) is off the floor of scene '{scene.name}': no floor point "
                         f"within {FLOOR_REACH} m; pick a position on the floor{level}{_likely(scene)}")
    h = P[:, 1] - scene.floor_y
    obst = (~scene.floor) & (h > 0.05) & (h < BODY_HEIGHT) & (d < BODY_CLEAR)
    if obst.any():
        raise ValueError(f"{which} ({q[0]:.2f}, {q[1]:.2f}) is inside an obstacle of scene '{scene.name}' "
                         f"({int(obst.sum())} scene points within {BODY_CLEAR} m); pick a free floor position"
                         f"{_likely(scene)}")
    return q


def check_pair(scene: MotionScene, s: np.ndarray, g: np.ndarray, frames: int, units: str) -> None:
    """ValueError unless a walk of `frames` frames at the walking model's top speed (synth.SPEED_HI) can cover the
    start-goal distance (metres) and the two are 10 cm apart or more. A scene in the wrong --units scales its
    start/goal with it (both are read in the file's units): a mm scan read as cm becomes a 40 m room whose 30 m walk
    no sequence reaches, so the message names the scene's size and --units."""
    from .synth import SPEED_HI
    from .walk import FPS

    dist = float(np.linalg.norm(np.asarray(g) - np.asarray(s)))
    size = np.ptp(scene.points, axis=0)
    where = (f"in metres after --units {units}, the unit of --start/--goal too; the scene is {size[0]:.1f} x "
             f"{size[2]:.1f} m and {size[1]:.1f} m tall")
    if dist < 0.1:
        raise ValueError(f"--start and --goal are {dist:.3f} m apart ({where}): nothing to walk; check --units or "
                         f"pick points farther apart{_likely(scene)}")
    reach = SPEED_HI * (frames - 1) / FPS
    if dist > reach:
        need = int(np.ceil(dist / SPEED_HI * FPS)) + 1
        raise ValueError(f"--start and --goal are {dist:.2f} m apart ({where}); {frames} frames walk at most "
                         f"{reach:.2f} m: check --units, or give --frames {need} or more{_likely(scene)}")


def walk_distance(frames: int, speed: float = 1.1) -> float:
    """Start-goal distance of a sequence of `frames` frames at `speed` m/s (leaves room for a detour)."""
    return speed * (frames - 1) / 30.0


def room_scene(seed: int, sequences: int = 8, frames: int = 80, clearance: float = 0.5) -> MotionScene:
    """A generated room (volsmpl.scene.make_room) with `sequences` start/goal pairs, each farther than `clearance`
    from furniture and walls (0.5 m: the first frame is mid-stride, its front foot ~0.35 m ahead of the pelvis), whose straight line crosses a furniture footprint (Room.sample_start_goal(blocked=True)
    and Room.path_clearance <= CROSS_TOL); ValueError if the room has too few."""
    room = make_room(int(seed))
    pairs = []
    dist = max(walk_distance(frames), MIN_PAIR_DISTANCE)
    seen = set()
    for k in range(sequences * 8):
        if len(pairs) == sequences:
            break
        for dd in (dist, 0.85 * dist, 0.7 * dist):
            try:
                s, g = room.sample_start_goal(dd, clearance=clearance, seed=1000 * k + int(seed), blocked=True)
            except ValueError:
                continue
            key = (round(s[0], 2), round(s[2], 2), round(g[0], 2), round(g[2], 2))
            if room.path_clearance(s, g) > CROSS_TOL:   # the straight line must cross a piece of furniture
                continue
            if key not in seen:
                seen.add(key)
                pairs.append((s[[0, 2]], g[[0, 2]]))
            break
    if len(pairs) < sequences:
        raise ValueError(f"room {seed} has only {len(pairs)} blocked start/goal pairs")
    cloud = room_points(int(seed))   # the (cached) 16,384-point FPS cloud, only for rooms that are kept
    return MotionScene(f"room{seed}", cloud["points"], cloud["labels"] == -1, room.floor_y, room, pairs)


def room_scenes(n: int, sequences: int = 8, frames: int = 80, first_seed: int = 0, max_seed: int = 100) -> list:
    """The first n generated rooms (seeds from first_seed up) that hold `sequences` blocked pairs each."""
    out, seed = [], first_seed
    while len(out) < n and seed < first_seed + max_seed:
        try:
            out.append(room_scene(seed, sequences, frames))
        except ValueError:
            pass
        seed += 1
    if len(out) < n:
        raise ValueError(f"only {len(out)} of {n} rooms with {sequences} blocked start/goal pairs in seeds "
                         f"{first_seed}..{first_seed + max_seed - 1}; ask for fewer scenes or sequences")
    return out


def floor_xz(ab, up: str, units: str) -> np.ndarray:
    """A user's floor coordinates (the input's horizontal axes in order: y-up x,z; z-up x,y; the input's units)
    -> our (x, z) in metres."""
    a, b = (float(v) * UNITS[units] for v in ab)
    return np.array([a, b]) if up == "y" else np.array([a, -b])


def load_scene(path, up: str = "y", units: str = "m", n: int = N_POINTS, floor_y: float | None = None,
               floor_band: float = 0.03, seed: int = 0, warn=None) -> MotionScene:
    """A user's mesh or point cloud as a MotionScene (module docstring). The file is read and checked first
    (scene_checks.read_points, check_scene: its size after `units`, its up axis; `warn(text)` gets the warnings).
    The floor is at `floor_y` (metres, after conversion; default the 1st percentile of the heights) and the floor
    points are those within floor_band; the cloud is shifted so that the floor is at y = 0. The scene's name is
    the file's stem made file-safe (safe_name)."""
    from volsmpl.apps.checks import safe_name

    from .scene_checks import check_scene, read_points

    raw = read_points(path, "--scene", units, n * 4, seed)
    doubts = check_scene(raw, path, up, units, floor_y, warn)
    pts = to_y_up(raw, up)
    if len(pts) > n:
        pts = pts[farthest_point_sample(pts, n, seed=seed)]
    fy = float(np.percentile(pts[:, 1], 1.0)) if floor_y is None else float(floor_y)
    floor = np.abs(pts[:, 1] - fy) < floor_band
    if not floor.any():
        raise ValueError(f"--scene {path}: no floor points at height {fy:.3f} m (+/- {floor_band} m); check --up, "
                         f"--units and --floor-y")
    pts[:, 1] -= fy   # the walking model's floor is y = 0
    return MotionScene(safe_name(Path(path).stem), pts.astype(np.float32), floor, 0.0, doubts=doubts)
