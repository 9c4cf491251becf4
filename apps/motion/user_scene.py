"""A user's own scene for `volsmpl motion --scene`: read once at any size, checked on an overview, its points taken
where the walk can go at a density given in metres, and its floor found there.

    sc = load_user_scene("temple.ply", (1200, 400), (3100, 2000), frames=80, up="z", units="mm")
    sc.points, sc.floor          # the corridor's points (Y up, metres, floor at y = 0) and which are floor
    sc.lift                      # the floor's height in the scan (Y up, metres): added back for the outputs

The steps, each refusing what cannot be right in one line before the next (and before any network loads):

1. the file is read once (volsmpl.scene.scan.open_scan: a mesh keeps its triangles, a cloud its points) and an
   overview of OVERVIEW_POINTS points of the whole scene is checked (scene_checks.check_scene: size against
   --units, up axis against --up); the start and goal are checked against the walk's reach (scenes.check_pair);
2. the corridor: every pelvis position p of a walk of `frames` frames that ends within GOAL_MISSED_M of the goal
   (a walk ending farther is flagged goal_missed) satisfies |p - start| + |p - goal| <= reach(frames) +
   GOAL_MISSED_M, where reach(frames) = SPEED_HI * (frames - 1) / FPS is the longest path the walking model makes
   (top speed 2.2 m/s, 30 fps). The pelvis thus stays inside the ellipse with foci start and goal and that major
   axis; the corridor is the ellipse's bounding box, widened by BODY_REACH_M (the farthest a vertex of the
   default body gets from its pelvis, horizontally, while walking: 0.57 m at 0.3-2.2 m/s) plus the collision
   term's AABB_MARGIN (0.4 m: points farther than this from the body's box never enter the term). An 80-frame
   walk between points 3 m apart gets an 8.3 x 7.5 m corridor (axis-aligned);
3. the floor's level there: the densest slab of the corridor's heights among their lowest FLOOR_LOW_SHARE
   (volsmpl.scene.floor.floor_level: stray points under the floor do not move it), from points at
   COLUMN_SPACING_M over the scene's whole height; `floor_y` (--floor-y) overrides it;
4. the corridor's points from FLOOR_BELOW_M under that floor to HEAD_ROOM_M above it (a person's height,
   scenes.BODY_HEIGHT, plus AABB_MARGIN), at one point per `spacing` metres (--spacing; a mesh's faces sampled
   by area, a cloud voxel-thinned: Scan.points). A region that would need more than MAX_POINTS points is refused
   naming a --spacing that fits. The floor points are those within FLOOR_BAND_M of the floor;
5. one line says what was found: the up axis, the floor level (and the given one), the corridor and its points.

DEFAULT_SPACING_M (5 cm): a 20 cm lantern (0.24 m^2 of surface) gets ~96 points, where a 16,384-point cloud of
a whole 124 x 121 m temple gave it 0-2. The collision term's cost follows the (frame, body part) pairs that hold
points near the body far more than the points' number: on generated room 0's first two pairs (80-frame straight
walks; corridors 8.1 x 8.1 and 8.3 x 7.8 m), one optimisation step (walk, collision term over all frames, backward)
took 761 / 816 ms for VolumetricSMPL with the room's 16,384-point cloud (10.6k points above the floor), 835 / 889
ms with the corridor's points at 5 cm (48-50k above the floor; +10 %) and 896 / 951 ms at 3 cm (134-140k; +17 %);
the exact mesh 1043 / 1152, 1093 / 1229 and 1181 / 1311 ms (2 CPU threads, the fastest of 3 steps).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .objective import AABB_MARGIN
from .scenes import BODY_HEIGHT, MotionScene, check_pair, floor_xz

__all__ = ["BODY_REACH_M", "COLUMN_SPACING_M", "DEFAULT_SPACING_M", "FLOOR_BAND_M", "FLOOR_BELOW_M", "FLOOR_LOW_SHARE",
           "HEAD_ROOM_M", "MAX_POINTS", "OVERVIEW_POINTS", "corridor", "load_user_scene", "reach"]

DEFAULT_SPACING_M = 0.05
OVERVIEW_POINTS = 65536    # the whole scene's points for the checks of size and up axis
BODY_REACH_M = 0.6         # measured: a vertex of the default body is at most 0.57 m from its pelvis (horizontally)
COLUMN_SPACING_M = 0.1     # the points the floor is found in
FLOOR_BELOW_M = 0.1        # the corridor starts this far under the floor
FLOOR_BAND_M = 0.03        # floor points: within this of the floor level
MAX_POINTS = 1_000_000     # a corridor needing more points is refused, naming a --spacing that fits
#: the floor is the densest slab among the lowest 60 % of the corridor's height range (floor_level's default, 40 %,
#: missed it under a 1.3 m tall scene with strays 1 m under its floor; a ceiling lies in the top 40 % still)
FLOOR_LOW_SHARE = 0.6
HEAD_ROOM_M = BODY_HEIGHT + AABB_MARGIN   # the corridor's top above the floor: a person's height + the AABB margin


def reach(frames: int) -> float:
    """The longest pelvis path (metres) of a walk of `frames` frames: the walking model's top speed x its duration."""
    from .synth import SPEED_HI
    from .walk import FPS

    return SPEED_HI * (int(frames) - 1) / FPS


def corridor(start, goal, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The horizontal box (lo (2,), hi (2,); x, z metres) that holds every scene point a walk of `frames` frames from
    `start` to `goal` (floor positions x, z) can touch (module docstring, step 2)."""
    from .status import GOAL_MISSED_M

    s, g = np.asarray(start, float), np.asarray(goal, float)
    d = float(np.linalg.norm(g - s))
    a = 0.5 * (reach(frames) + GOAL_MISSED_M)          # semi-major axis
    a = max(a, 0.5 * d)
    b = np.sqrt(max(a * a - 0.25 * d * d, 0.0))       # semi-minor axis
    u = (g - s) / d if d > 0 else np.array([1.0, 0.0])
    half = np.sqrt((a * u) ** 2 + (b * u[::-1]) ** 2)  # the rotated ellipse's half extents along x and z
    pad = BODY_REACH_M + AABB_MARGIN
    c = 0.5 * (s + g)
    return c - half - pad, c + half + pad


def _spacing_fix(err: ValueError, option: str = "--spacing") -> ValueError:
    """Scan.points' refusal of a region too dense ('... give a spacing of 7.3 cm or more') naming the option in
    metres; other errors as they are."""
    import re

    msg = str(err)
    m = re.search(r"give a spacing of ([\d.]+) cm or more", msg)
    if not m:
        return err
    fit = float(m.group(1)) / 100.0
    return ValueError(msg[:m.start()] + f"give {option} {fit:.3g} or more (metres), or a --start and --goal closer "
                                        f"together, or fewer --frames (the corridor follows from them)")


def load_user_scene(path, start, goal, frames: int, up: str = "y", units: str = "m",
                    spacing: float = DEFAULT_SPACING_M, floor_y: float | None = None, warn=None,
                    option: str = "--scene", log=print) -> MotionScene:
    """A user's scene file as a MotionScene holding the walk's corridor (module docstring) with its pair
    [(start, goal)] (x, z metres; `start`/`goal` are given as A,B in the file's horizontal axes and units, as
    --start/--goal). ValueError in one line for what cannot be right; `warn(text)` gets the warnings, `log(line)`
    the line of what was found."""
    from volsmpl.apps.checks import safe_name
    from volsmpl.scene.floor import floor_level
    from volsmpl.scene.scan import to_y_up

    from .scene_checks import check_scene, open_scene_file
    from .scenes import check_endpoint

    scan = open_scene_file(path, option, units)
    overview = scan.overview(OVERVIEW_POINTS)
    doubts = check_scene(overview, path, up, units, floor_y, warn, option=option)
    name = safe_name(Path(path).stem)
    whole = MotionScene(name, to_y_up(overview, up), np.zeros(len(overview), bool), doubts=doubts)
    s, g = floor_xz(start, up, units), floor_xz(goal, up, units)
    check_pair(whole, s, g, frames, units)
    scan = scan.to_y_up(up)
    (x0, z0), (x1, z1) = corridor(s, g, frames)
    b0, b1 = sorted((z0, z1) if up == "y" else (-z1, -z0))   # the file's second horizontal axis
    box = f"x {x0:.1f}..{x1:.1f}, {'z' if up == 'y' else 'y'} {b0:.1f}..{b1:.1f} m"
    y0, y1 = scan.bounds()[:, 1]
    column = scan.points(spacing=COLUMN_SPACING_M, box=(np.array([x0, y0, z0]), np.array([x1, y1, z1])))
    if len(column) == 0:
        raise ValueError(f"{option} {path}: no scene points around --start and --goal (the corridor {box}); pick "
                         f"positions inside the scene, in its horizontal axes and --units{_doubt(doubts)}")
    found = floor_level(column[:, 1], low_share=FLOOR_LOW_SHARE)
    level = found if floor_y is None else float(floor_y)
    try:
        pts = scan.points(spacing=spacing, box=(np.array([x0, level - FLOOR_BELOW_M, z0]),
                                                np.array([x1, level + HEAD_ROOM_M, z1])), max_points=MAX_POINTS)
    except ValueError as e:
        raise _spacing_fix(e) from None
    h = pts[:, 1] - level
    floor = np.abs(h) < FLOOR_BAND_M
    if not floor.any():
        raise ValueError(f"{option} {path}: no floor points at height {level:.3f} m (+/- {FLOOR_BAND_M} m) around "
                         f"--start and --goal; check --up, --units and --floor-y{_doubt(doubts)}")
    pts[:, 1] = h
    sc = MotionScene(name, pts.astype(np.float32), floor, 0.0, doubts=doubts, floor_found=found - level, lift=level)
    where = (f"{found:.2f} m along {up} (the densest low slab of the points around the walk)" if floor_y is None
             else f"{level:.2f} m along {up} as --floor-y gives (the densest low slab around the walk: {found:.2f} m)")
    log(f"{option} {path}: up {up}, floor at {where}; corridor {box}: {len(pts):,} points {100 * spacing:g} cm apart ({int((~floor).sum()):,} above the floor)")
    sc.pairs = [(check_endpoint(sc, s, "--start"), check_endpoint(sc, g, "--goal"))]
    return sc


def _doubt(doubts: list) -> str:
    return f" (the scene looked odd: {'; '.join(doubts)}: check --units and --up)" if doubts else ""
