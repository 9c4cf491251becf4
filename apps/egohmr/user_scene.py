"""The scene of a user's frame (`volsmpl egohmr sample --frame F.json --scene S [--units mm] [--up z] [--spacing M]`),
read once and taken where the body is, so a scan of any size (a room, a floor of a building, a 124 m temple) works
as a scan cropped to the room does.

- `read_user_inputs`: the frame file and the scene file, checked (user_checks.py): the scene's size on an overview
  of all of it (`Scan.overview`, OVERVIEW_POINTS area-weighted points: the size check reads percentiles, which such
  a sample gives at any size); the up axis and the camera's place on the scene around the camera (`around_camera`),
  so that a hall's or a building's floor, most of a big scan's surface, hides neither the room's walls from the
  floor check nor the room's height from the camera check. Then the scene is turned Y-up; nothing else is sampled.
- `around_camera`: the scene's points within CHECK_RADIUS of the camera centre at CHECK_SPACING (the overview where
  the camera is not near the scene: a 'world_to_camera' in other units, to be refused).
- `cube_points`: the scene's points in the cube of edge `size` around the estimated pelvis, in the camera frame. The
  cube's axes are the camera's, so the world-frame box that contains the cube (its 8 corners mapped by
  camera_to_world) is taken from the scan (`Scan.points`: a mesh's faces in the box sampled at one point per
  spacing^2 of area, a cloud thinned to one point per spacing-sized voxel), mapped to the camera frame and cropped
  exactly to the cube.
- `take`: the fixed budget the network and the guidance read (net.config.scene_points, GUIDE_POINTS) drawn from them,
  refused in one line when the cube holds fewer than MIN_SCENE_POINTS.

The spacing (`--spacing`, metres of the scene after --units) defaults to DEFAULT_SPACING: a floor across the 2 m cube
then holds GUIDE_POINTS points, so the guidance's 20,000 points are distinct where the body stands on a floor (the
generated frames' scenes are sampled at 1 point per cm^2); MAX_SPACING is the coarsest at which such a floor holds
MIN_SCENE_POINTS, MIN_SPACING the finest accepted.

    frame, scan, up = read_user_inputs(args, warnings)              # UserFrame, volsmpl.scene.scan.Scan (Y up)
    pts = cube_points(frame, scan, pelvis, 2.0, spacing_of(args))   # (N, 3) camera frame, inside the cube
    guide = take(pts, pelvis, 2.0, GUIDE_POINTS, seed=7919)         # (20000, 3)
"""
from __future__ import annotations

import math

import numpy as np

from .evaluate import GUIDE_CUBE, GUIDE_POINTS, MIN_SCENE_POINTS

#: points of the whole-scene overview the size check reads
OVERVIEW_POINTS = 100_000
#: the up-axis and camera-place checks read the scene within CHECK_RADIUS metres of the camera centre (a room, its
#: neighbours), at one point per CHECK_SPACING metres, where it holds at least CHECK_MIN points
CHECK_RADIUS, CHECK_SPACING, CHECK_MIN = 10.0, 0.05, 1000
#: metres between scene points by default: a floor across the guidance's cube holds GUIDE_POINTS (1.41 cm)
DEFAULT_SPACING = GUIDE_CUBE / math.sqrt(GUIDE_POINTS)
#: the coarsest --spacing: a floor across the cube holds MIN_SCENE_POINTS (8.9 cm)
MAX_SPACING = GUIDE_CUBE / math.sqrt(MIN_SCENE_POINTS)
#: the finest --spacing: 5 mm gives the guidance's GUIDE_POINTS on half a square metre; finer adds nothing it reads
#: and makes a furnished box around the cube need more than MAX_REGION_POINTS
MIN_SPACING = 0.005
#: points the box around the cube may need before the spacing is refused (naming one that fits)
MAX_REGION_POINTS = 2_000_000


def spacing_of(args) -> float:
    """--spacing in metres, DEFAULT_SPACING when not given."""
    s = getattr(args, "spacing", None)
    return DEFAULT_SPACING if s is None else float(s)


def read_user_inputs(args, warnings: list):
    """The checked frame and its scene: (UserFrame, Scan in the Y-up world (metres), the floor's up direction (3,) in
    that world or None where the scan shows no clear floor). args: frame, scene, units, up, seed."""
    from volsmpl.scene.scan import open_scan, to_y_up

    from .user_checks import check_camera, check_camera_place, check_extent, check_up
    from .userframe import load_user_frame

    frame = load_user_frame(args.frame)
    where = f"--frame {args.frame}"
    check_camera(frame, where, warnings)
    scan = open_scan(args.scene, args.units)
    raw = scan.overview(OVERVIEW_POINTS, seed=args.seed)
    check_extent(raw, args.units, args.scene, warnings)
    near = around_camera(frame, scan, args.up, raw, seed=args.seed)
    u = check_up(near, args.up, frame.has_world, args.scene, warnings, seed=args.seed,
                 camera=camera_in_file(frame, args.up) if frame.has_world else None)
    check_camera_place(frame, to_y_up(near, args.up), where, warnings)
    return frame, scan.to_y_up(args.up), None if u is None else to_y_up(np.asarray(u)[None], args.up)[0]


def camera_in_file(frame, up: str) -> np.ndarray:
    """The camera centre of the frame's 'world_to_camera' (the Y-up world, metres) in the scene file's axes (--up).
    Shape: -> (3,)."""
    from volsmpl.scene.scan import from_y_up

    T = frame.world_to_camera
    return from_y_up((-T[:3, :3].T @ T[:3, 3])[None], up)[0]


def around_camera(frame, scan, up: str, overview: np.ndarray, seed: int = 0) -> np.ndarray:
    """The points of `scan` (metres, the file's axes) within CHECK_RADIUS of the camera centre (per axis) at
    CHECK_SPACING; `overview` where they are fewer than CHECK_MIN or more than the sampler takes. The camera centre
    of 'world_to_camera' is in the Y-up world, so it is turned into the file's axes by --up first. Shape: (N, 3)."""
    c = camera_in_file(frame, up)
    try:
        pts = scan.points(spacing=CHECK_SPACING, box=(c - CHECK_RADIUS, c + CHECK_RADIUS), seed=seed)
    except ValueError:                      # a scene too dense for the sampler there: the overview serves
        return overview
    return pts if len(pts) >= CHECK_MIN else overview


def world_box(frame, centre, size: float) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): the axis-aligned box of the Y-up world that contains the camera-frame cube of edge `size` centred at
    `centre` (its 8 corners mapped by camera_to_world). Shape: centre (3,) -> (3,), (3,)."""
    T = frame.world_to_camera
    R, t = T[:3, :3], T[:3, 3]
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=np.float64)
    corners = np.asarray(centre, np.float64) + 0.5 * size * signs
    world = (corners - t) @ R          # R^T (c - t), row vectors
    return world.min(0), world.max(0)


def cube_points(frame, scan, centre, size: float, spacing: float, seed: int = 0) -> np.ndarray:
    """The scene's points inside the camera-frame cube of edge `size` around `centre` at one point per `spacing`
    metres (module docstring). scan: the Y-up world Scan of `read_user_inputs`. Shape: -> (N, 3) camera frame."""
    from volsmpl.scene import crop_cube

    from .userframe import camera_points

    lo, hi = world_box(frame, centre, size)
    try:
        pts = scan.points(spacing=spacing, box=(lo, hi), seed=seed, max_points=MAX_REGION_POINTS)
    except ValueError as e:
        raise ValueError(f"--spacing {spacing:g} m: {e}") from None
    cam = camera_points(frame, pts)
    return cam[crop_cube(cam, centre, size)]


def take(points: np.ndarray, centre, size: float, n: int, seed: int, spacing: float | None = None) -> np.ndarray:
    """n of the points (camera frame) inside the cube of edge `size` around `centre` (all of them plus random repeats
    where fewer, volsmpl.scene.subsample); one ValueError line when the cube holds fewer than MIN_SCENE_POINTS.
    Shape: (N, 3) -> (n, 3)."""
    from volsmpl.scene import crop_cube, subsample

    c = points[crop_cube(points, centre, size)]
    if len(c) < MIN_SCENE_POINTS:
        at = f" at --spacing {spacing:.3g} m" if spacing is not None else ""
        finer = "a smaller --spacing or " if spacing is not None else ""
        raise ValueError(f"the scene has {len(c)} points{at} in the {size:g} m cube around the estimated pelvis "
                         f"{np.round(np.asarray(centre, float), 2).tolist()} (camera frame, m), fewer than "
                         f"{MIN_SCENE_POINTS}: check --units and 'world_to_camera', or give {finer}a denser scan")
    return c[subsample(c, n, seed=seed)]


__all__ = ["camera_in_file", "OVERVIEW_POINTS", "CHECK_RADIUS", "CHECK_SPACING", "CHECK_MIN", "DEFAULT_SPACING", "MAX_SPACING",
           "MIN_SPACING", "MAX_REGION_POINTS", "spacing_of", "read_user_inputs", "around_camera", "world_box",
           "cube_points", "take"]
