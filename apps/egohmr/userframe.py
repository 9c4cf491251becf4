"""A user's own egocentric frame: 2D keypoints and a camera in a JSON file, the scene in any mesh or point-cloud file.

    {
      "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],       # pinhole intrinsics, pixels
      "image_size": [H, W],
      "keypoints": [[u, v], ...],                        # the 24 SMPL joints in SMPL order, pixels
      "conf": [c0, ..., c23],                            # detector confidences in [0, 1]; 0 = not detected
                                                         #   or out of view (confident keypoints lie in the image)
      "world_to_camera": [[...], [...], [...], [...]]    # optional 4x4 (OpenCV camera axes: x right, y down,
    }                                                    #   z forward); absent: the scene file is in camera coordinates

K, image_size and the keypoints describe one image: a principal point outside the image's central 80 % or a
confident keypoint more than 5 % of the image outside it is refused (the signs of K or keypoints made for another
resolution, or of [W, H] given for [H, W], which would otherwise silently scale the network's input); the focal
lengths and the keypoints' spread are checked by user_checks.check_camera. The frame's name (its figure's file name)
is the file's stem made file-name safe (volsmpl.apps.checks.safe_name).

The scene file (`--scene`, read by volsmpl.scene.scan, `--units` m / cm / mm, `--up` y or z) is turned Y-up
(a z-up scan's (x, y, z) becomes (x, z, -y)) and then mapped by `world_to_camera`, which is therefore given in
the Y-up world. The network sees everything in the camera frame.

    frame = load_user_frame("my_frame.json")
    pts = camera_points(frame, to_y_up(read_scan("scan.ply", units="mm", n_surface=1_000_000), "z"))  # camera frame
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .pose import NUM_JOINTS


#: the principal point must lie within this fraction range of the image (a K made for another resolution does not)
CENTRE = (0.1, 0.9)
#: keypoints with a confidence above 0 may lie at most this fraction of the image size outside it (detector slack)
OUTSIDE = 0.05


@dataclass
class UserFrame:
    name: str
    K: np.ndarray             # (3, 3)
    image_size: tuple         # (H, W)
    keypoints: np.ndarray     # (24, 2)
    conf: np.ndarray          # (24,)
    world_to_camera: np.ndarray  # (4, 4)
    has_world: bool = False      # the file gives world_to_camera (else the scene is in camera coordinates)


def _array(d: dict, key: str, shape: tuple, where: str) -> np.ndarray:
    if key not in d:
        raise ValueError(f"{where}: missing '{key}' (format in apps/egohmr/userframe.py)")
    try:
        a = np.asarray(d[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: '{key}' is not an array of numbers") from None
    if a.shape != shape:
        extra = (f"; give the {NUM_JOINTS} SMPL joints in SMPL order (0 confidence for the ones not detected)"
                 if key in ("keypoints", "conf") else "")
        raise ValueError(f"{where}: '{key}' has shape {a.shape}, expected {shape}{extra}")
    if not np.isfinite(a).all():
        raise ValueError(f"{where}: '{key}' holds NaN or Inf; give 0 confidence (and any finite keypoint) for "
                         f"joints that were not detected")
    return a


def load_user_frame(path) -> UserFrame:
    """The frame file (module docstring), checked: one clear ValueError naming the problem otherwise."""
    from volsmpl.apps.checks import read_json, safe_name

    p = Path(path)
    d = read_json(p, "the frame file", "--frame")
    where = f"--frame {path}"
    if not isinstance(d, dict):
        raise ValueError(f"{where}: the frame file must hold one JSON object with K, image_size, keypoints and conf "
                         f"(format in apps/egohmr/userframe.py)")
    K = _array(d, "K", (3, 3), where)
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]):
        raise ValueError(f"{where}: 'K' must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
    size = _array(d, "image_size", (2,), where)
    if (size < 1).any():
        raise ValueError(f"{where}: 'image_size' must be [H, W] in pixels, got {size.tolist()}")
    kp = _array(d, "keypoints", (NUM_JOINTS, 2), where)
    conf = _array(d, "conf", (NUM_JOINTS,), where)
    if ((conf < 0) | (conf > 1)).any():
        raise ValueError(f"{where}: 'conf' values must lie in [0, 1]")
    if (conf > 0).sum() < 4:
        raise ValueError(f"{where}: only {(conf > 0).sum()} keypoints have a confidence above 0; at least 4 are needed")
    H, W = float(size[0]), float(size[1])
    cx, cy = K[0, 2], K[1, 2]
    if not (CENTRE[0] * W <= cx <= CENTRE[1] * W and CENTRE[0] * H <= cy <= CENTRE[1] * H):
        raise ValueError(f"{where}: 'K': the principal point (cx, cy) = ({cx:g}, {cy:g}) lies outside the central "
                         f"80 % of image_size [H, W] = [{H:g}, {W:g}]: a camera matrix for another image size? (scale "
                         f"fx, fy, cx, cy by the ratio of the sizes) or image_size given as [W, H]? give K, image_size "
                         f"and keypoints of one image")
    seen = conf > 0
    off = seen & ((kp[:, 0] < -OUTSIDE * W) | (kp[:, 0] > (1 + OUTSIDE) * W)
                  | (kp[:, 1] < -OUTSIDE * H) | (kp[:, 1] > (1 + OUTSIDE) * H))
    if off.any():
        j = int(np.flatnonzero(off)[0])
        raise ValueError(f"{where}: {int(off.sum())} keypoints with a confidence above 0 lie outside the image "
                         f"[H, W] = [{H:g}, {W:g}] (joint {j} at ({kp[j, 0]:g}, {kp[j, 1]:g})): give keypoints in "
                         f"pixels of that image (u along W, v along H), and confidence 0 for joints out of view")
    world = "world_to_camera" in d
    T = _array(d, "world_to_camera", (4, 4), where) if world else np.eye(4)
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1]) or not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise ValueError(f"{where}: 'world_to_camera' must be a rigid 4x4 transform (rotation and translation)")
    return UserFrame(safe_name(p.stem), K, (int(size[0]), int(size[1])), np.where(conf[:, None] > 0, kp, 0.0), conf,
                     T, world)


def camera_points(frame: UserFrame, points: np.ndarray) -> np.ndarray:
    """Scene points (N, 3) in the frame file's world coordinates -> camera coordinates."""
    T = frame.world_to_camera
    return points @ T[:3, :3].T + T[:3, 3]


__all__ = ["UserFrame", "load_user_frame", "camera_points"]
