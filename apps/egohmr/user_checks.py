"""Plausibility of a user's frame and scene (`volsmpl egohmr sample --frame F.json --scene S`), checked before any
network runs. What is clearly wrong is refused in one line naming the option or field and the fix; what is merely
unusual is a warning (stderr and results.json's `warnings`). The size is checked on an overview of the whole scene,
the up axis and the camera's place on the scene around the camera (user_scene.read_user_inputs), so a scan of any
size is judged by the room the person is in.

- the scene's size after --units, against a person's: a robust extent (the largest of the 0.5-99.5 percentile
  ranges along the axes) above EXTENT_REFUSE[1] or below EXTENT_REFUSE[0] metres is refused, naming the --units
  that would give a room-sized scene; outside EXTENT_USUAL a warning;
- the up axis, from the floor (`floor_up`): the direction that the most flat scene surfaces face minus the most
  face against it (normals by PCA of each point's neighbours, turned towards the centre of the scene's box: the
  floor and the seats and table tops on it face up, walls on opposite sides cancel), trusted only where the scan
  shows such a room around it (a view of one wall or a corner cannot tell a wall from a floor: a warning). With
  'world_to_camera' the scene's world is Y-up after --up, so the floor must face along the file's y (--up y) or z
  (--up z) axis within UP_TOL_DEG: clearly the other axis is refused naming --up, the x axis refused too (--up has
  no x), a tilted floor a warning; without it the scene is in camera coordinates and a floor farther than
  CAMERA_TILT_DEG from the camera's vertical (a head-mounted camera looks down at a person) is a warning;
- the camera: a focal length whose horizontal field of view lies outside FOV_REFUSE_DEG, or fx and fy more than
  ASPECT_REFUSE apart, is refused naming 'K' (a camera matrix for another image size?); outside the training
  data's range (FOV_USUAL_DEG) a warning (the principal point and the keypoints against image_size: userframe.py);
- the keypoints: all within a few pixels of one another (normalised [0, 1] coordinates?) refused; a person spanning
  less than KP_SPAN_WARN of the image, or fewer than 6 confident keypoints (the training data's minimum), a warning;
- the camera's place: the camera centre far outside the scene (a 'world_to_camera' in other units, or a
  camera_to_world) refused, somewhat outside a warning.
"""
from __future__ import annotations

import numpy as np
from volsmpl.apps.checks import warn
from volsmpl.scene.floor import floor_up

#: a scene's robust extent (m) outside this range is refused: no room a person stands in
EXTENT_REFUSE = (0.5, 2000.0)
#: outside this range a warning: a room-sized scene around a person spans a few metres (ROOM_M: a typical one)
EXTENT_USUAL, ROOM_M = (1.5, 200.0), 6.0
#: the floor's normal may lie this far (degrees) from the axis --up names (a world_to_camera in a Y-up world)
UP_TOL_DEG = 25.0
#: without world_to_camera: the floor's normal may lie this far (degrees) from the camera's vertical
CAMERA_TILT_DEG = 75.0
#: a principal point farther than this share of the image from its centre is warned about (calibrated cameras: a
#: few %; the generated frames: at the centre; a [W, H] image_size of a 4:3 image: 17 %)
PP_WARN = 0.1
#: horizontal field of view (degrees): refused outside FOV_REFUSE_DEG, a warning outside FOV_USUAL_DEG
FOV_REFUSE_DEG = (3.0, 170.0)
FOV_USUAL_DEG = (30.0, 120.0)
#: fy / fx outside [1 / ASPECT_REFUSE, ASPECT_REFUSE] is refused (pixels are nearly square)
ASPECT_REFUSE = 1.5
#: confident keypoints spanning fewer pixels than this are refused (normalised coordinates), less than this
#: fraction of the image diagonal a warning
KP_SPAN_REFUSE_PX, KP_SPAN_WARN = 3.0, 0.03
#: the camera centre farther than this (m) outside the scene's box is refused, farther than CAMERA_OUT_WARN a warning
CAMERA_OUT_REFUSE, CAMERA_OUT_WARN = 20.0, 1.0

AXES = "xyz"


def robust_extent(points: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(extent, lo, hi): the scene's box between the 0.5 and 99.5 percentiles of each axis (a few stray points do
    not count) and its largest side, metres. Shape: points (N, 3)."""
    lo, hi = np.percentile(points, [0.5, 99.5], axis=0)
    return float((hi - lo).max()), lo, hi


def check_extent(points: np.ndarray, units: str, path, warnings: list | None = None) -> float:
    """Refuse a scene whose robust extent (metres, after --units) no person's room has, naming the --units that
    would give one; warn outside EXTENT_USUAL. Returns the extent."""
    from volsmpl.scene.scan import UNITS

    ext = robust_extent(points)[0]
    if EXTENT_USUAL[0] <= ext <= EXTENT_USUAL[1]:
        return ext
    raw = ext / UNITS[units]
    fits = sorted((u for u in UNITS if u != units and EXTENT_USUAL[0] <= raw * UNITS[u] <= EXTENT_USUAL[1]),
                  key=lambda u: abs(np.log(raw * UNITS[u] / ROOM_M)))     # the one nearest a room's size first
    names = {"m": "metres", "cm": "centimetres", "mm": "millimetres"}
    fix = (f"the file is probably in {names[fits[0]]} ({raw * UNITS[fits[0]]:.3g} m): give --units {fits[0]}"
           if fits else "check the file's units (--units)")
    what = f"--scene {path} spans {ext:.3g} m with --units {units}"
    if not EXTENT_REFUSE[0] <= ext <= EXTENT_REFUSE[1]:
        raise ValueError(f"{what}, {'more' if ext > EXTENT_REFUSE[1] else 'less'} than any room a person stands in "
                         f"({EXTENT_REFUSE[0]:g}-{EXTENT_REFUSE[1]:g} m): {fix}")
    warn("egohmr", f"{what}, unusual for a room around a person ({EXTENT_USUAL[0]:g}-{EXTENT_USUAL[1]:g} m): "
                   f"{fix if fits else 'check --units'}", warnings)
    return ext


def _angle(u: np.ndarray, axis: int) -> float:
    """Degrees between the line of u and a coordinate axis (0-90)."""
    return float(np.degrees(np.arccos(np.clip(abs(u[axis]), 0.0, 1.0))))


def check_up(points: np.ndarray, up: str, world: bool, path, warnings: list | None = None, seed: int = 0,
             camera=None):
    """Compare --up with the floor of the scene file (points in the file's axes, metres): refuse when the floor
    clearly faces along the other axis --up offers (naming it) or along x; warn when no floor stands out or it is
    tilted. world: the frame file gives 'world_to_camera' (else the file is in camera coordinates). Returns the
    estimated up direction (file axes) or None. camera: the camera centre in the file's axes (metres), inside the
    room: the surfaces' normals are turned towards it (volsmpl.scene.floor.floor_up's `towards`)."""
    u, _, _ = floor_up(points, seed=seed, towards=camera)
    where = f"--scene {path}"
    if u is None:
        warn("egohmr", f"{where}: the scan shows no floor with walls on opposite sides (a partial view?), so --up "
                       f"{up} is not checked against it: make sure the file's up axis is {up}", warnings)
        return None
    ang = {ax: _angle(u, i) for i, ax in enumerate(AXES)}
    desc = f"its floor faces along ({u[0]:.2f}, {u[1]:.2f}, {u[2]:.2f}) in the file's axes"
    alt = "z" if up == "y" else "y"
    if not world:   # camera coordinates: the floor faces within CAMERA_TILT_DEG of the camera's vertical (y)
        if ang["y"] > CAMERA_TILT_DEG:
            warn("egohmr", f"{where}: {desc}, {ang['y']:.0f} degrees from the camera's vertical (y; a head-mounted "
                           f"camera: up to {CAMERA_TILT_DEG:g}): is the scene in camera coordinates? else give "
                           f"'world_to_camera' in the frame file", warnings)
        return u
    if ang[up] <= UP_TOL_DEG:
        return u
    if ang[alt] <= UP_TOL_DEG:
        raise ValueError(f"{where}: {desc}, {ang[alt]:.0f} degrees from its {alt} axis, but --up {up} reads {up} "
                         f"as up ({ang[up]:.0f} degrees off): give --up {alt}")
    if ang["x"] <= UP_TOL_DEG:
        raise ValueError(f"{where}: {desc}, along its x axis; --up takes y or z: rotate the scan so that its up axis "
                         f"is y or z")
    warn("egohmr", f"{where}: {desc}, {ang[up]:.0f} degrees from its {up} axis (--up {up}; tolerance "
                   f"{UP_TOL_DEG:g}): is the scan tilted? check --up and 'world_to_camera'", warnings)
    return u


def check_camera(frame, where: str, warnings: list | None = None) -> None:
    """The focal lengths against the image size and the keypoints' spread (module docstring); where: the frame
    file's option and name."""
    K, (H, W) = frame.K, frame.image_size
    fx, fy = float(K[0, 0]), float(K[1, 1])
    fov = float(np.degrees(2 * np.arctan(W / (2 * fx))))
    if not FOV_REFUSE_DEG[0] <= fov <= FOV_REFUSE_DEG[1]:
        raise ValueError(f"{where}: 'K' has fx = {fx:g} px, a {fov:.1f} degree horizontal field of view for the "
                         f"{W:g} px wide image_size [H, W] = [{H:g}, {W:g}]: a camera matrix for another image size? "
                         f"give K in pixels of this image (scale fx, fy, cx, cy by the ratio of the sizes)")
    if not 1 / ASPECT_REFUSE <= fy / fx <= ASPECT_REFUSE:
        raise ValueError(f"{where}: 'K' has fx = {fx:g} and fy = {fy:g} px, pixels {fy / fx:.2f} times as tall as "
                         f"wide: a camera matrix for another image size? give fx and fy of this image's pixels")
    cx, cy = float(K[0, 2]), float(K[1, 2])
    if abs(cx - W / 2) > PP_WARN * W or abs(cy - H / 2) > PP_WARN * H:
        warn("egohmr", f"{where}: 'K': the principal point ({cx:g}, {cy:g}) lies far from the centre ({W / 2:g}, "
                       f"{H / 2:g}) of image_size [H, W] = [{H:g}, {W:g}]: image_size given as [W, H]? or a K of "
                       f"another image size?", warnings)
    if not FOV_USUAL_DEG[0] <= fov <= FOV_USUAL_DEG[1]:
        warn("egohmr", f"{where}: 'K' gives a {fov:.0f} degree horizontal field of view; the network was trained on "
                       f"60-75 degrees (apps/egohmr/data.py), so its samples may be poor", warnings)
    seen = frame.conf > 0
    kp = frame.keypoints[seen]
    span = float((kp.max(0) - kp.min(0)).max())
    if span < KP_SPAN_REFUSE_PX:
        raise ValueError(f"{where}: the {int(seen.sum())} confident 'keypoints' span {span:.3g} px of the "
                         f"[{H:g}, {W:g}] image: normalised [0, 1] coordinates? give them in pixels (u along W, "
                         f"v along H)")
    if span < KP_SPAN_WARN * np.hypot(H, W):
        warn("egohmr", f"{where}: the confident 'keypoints' span only {span:.0f} px of the [{H:g}, {W:g}] image: a "
                       f"person this small is far outside the training data's distances (0.8-2.5 m)", warnings)
    if seen.sum() < 6:
        warn("egohmr", f"{where}: only {int(seen.sum())} keypoints have a confidence above 0 (the training frames "
                       f"have at least 6); the pose is mostly guessed", warnings)


def check_camera_place(frame, points: np.ndarray, where: str, warnings: list | None = None) -> None:
    """The camera centre of 'world_to_camera' against the scene (points (N, 3) in the Y-up world, metres): refuse
    one far outside (a translation in other units, or a camera_to_world), warn when it lies outside."""
    if np.allclose(frame.world_to_camera, np.eye(4)):
        return
    R, t = frame.world_to_camera[:3, :3], frame.world_to_camera[:3, 3]
    c = -R.T @ t
    _, lo, hi = robust_extent(points)
    out = float(np.linalg.norm(np.maximum(lo - c, 0) + np.maximum(c - hi, 0)))
    if out > CAMERA_OUT_REFUSE:
        raise ValueError(f"{where}: 'world_to_camera' puts the camera {out:.3g} m outside the scene: give its "
                         f"translation in metres (of --scene after --units), and world to camera (not camera to "
                         f"world: invert it)")
    if out > CAMERA_OUT_WARN:
        warn("egohmr", f"{where}: 'world_to_camera' puts the camera {out:.1f} m outside the scene's box; a head-"
                       f"mounted camera is in the room: check it (world to camera, metres)", warnings)


__all__ = ["EXTENT_REFUSE", "EXTENT_USUAL", "UP_TOL_DEG", "CAMERA_TILT_DEG", "robust_extent", "check_extent",
           "check_up", "check_camera", "check_camera_place"]
