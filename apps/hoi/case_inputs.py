"""Reading what a user gives `volsmpl hoi make-case` (make_case.py): the body, keypoints, camera, mask, selection and
object-pose files and the numbers of options, each checked on entry: a missing file, a wrong shape or a number that
is not finite is a ValueError of one line naming the option or field and the fix.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["existing_file", "json_object", "numbers_option", "read_body", "read_camera", "read_keypoints", "read_mask",
           "read_object_pose", "read_selection"]


def existing_file(path, flag: str) -> Path:
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{flag} {path}: no such file; give the path of an existing file")
    return p


def numbers_option(text, flag: str, n: int, kind=float, what: str = "") -> list:
    parts = [t.strip() for t in str(text).split(",")]
    try:
        vals = [kind(t) for t in parts]
    except ValueError:
        vals = []
    if len(vals) != n or not all(np.isfinite(vals)):
        many = f"{n} comma-separated " if n > 1 else "a "
        raise ValueError(f"{flag} {text!r}: give {many}{'whole ' if kind is int else ''}number{'s' if n > 1 else ''}"
                         f"{what}")
    return vals


def _array(d: dict, key: str, n: int, where: str, default=None) -> np.ndarray:
    if key not in d and default is not None:
        return np.asarray(default, dtype=np.float64)
    try:
        a = np.asarray(d[key], dtype=np.float64).reshape(-1)
    except KeyError:
        raise ValueError(f"{where}: '{key}' is missing; give {n} numbers") from None
    except (TypeError, ValueError):
        raise ValueError(f"{where}: '{key}' must be a list of {n} numbers") from None
    if a.size != n or not np.isfinite(a).all():
        raise ValueError(f"{where}: '{key}' must be {n} finite numbers, got {a.size}")
    return a


def json_object(path, flag: str, what: str):
    from volsmpl.apps.checks import read_json

    try:
        return read_json(existing_file(path, flag), what, flag)
    except FileNotFoundError as e:
        raise ValueError(str(e)) from None


def read_body(path) -> dict:
    """--body: {betas (10, optional), global_orient (3,), body_pose (69,), transl (3,)} float64 arrays."""
    d = json_object(path, "--body", "the body file")
    where = f"--body {path}"
    if not isinstance(d, dict):  # a user's file: one line of ValueError (volsmpl.cli)
        raise ValueError(f"{where}: give a JSON object with betas, global_orient, body_pose and transl")  # noqa: TRY004
    return {"betas": _array(d, "betas", 10, where, default=np.zeros(10)),
            "global_orient": _array(d, "global_orient", 3, where), "body_pose": _array(d, "body_pose", 69, where),
            "transl": _array(d, "transl", 3, where)}


def read_keypoints(path) -> np.ndarray:
    """--keypoints: (24, 3) [u, v, confidence in [0, 1]]."""
    d = json_object(path, "--keypoints", "the keypoints file")
    d = d.get("keypoints_2d") if isinstance(d, dict) else d
    try:
        kp = np.asarray(d, dtype=np.float64)
    except (TypeError, ValueError):
        kp = np.zeros(0)
    if kp.shape != (24, 3) or not np.isfinite(kp).all():
        raise ValueError(f"--keypoints {path}: give 24 x [u, v, confidence] (SMPL joint order, pixels), got shape "
                         f"{kp.shape}")
    if ((kp[:, 2] < 0) | (kp[:, 2] > 1)).any():
        raise ValueError(f"--keypoints {path}: confidences (third column) must lie in [0, 1]; give 0 for a joint "
                         f"not detected")
    return kp


def read_camera(args, mask_shape) -> tuple[np.ndarray, tuple]:
    """(K (3, 3), (H, W)) from --K, or --focal with --image-size (or the mask's size) and --principal."""
    size = None if args.image_size is None else tuple(numbers_option(args.image_size, "--image-size", 2, int, " H,W"))
    if size is not None and min(size) < 1:
        raise ValueError(f"--image-size {args.image_size}: give H,W in pixels, both >= 1")
    if args.K is not None:
        if args.focal is not None or args.principal is not None:
            raise ValueError("give the camera as --K FILE or as --focal (and --principal), not both")
        d = json_object(args.K, "--K", "the camera file")
        try:
            K = np.asarray(d.get("K") if isinstance(d, dict) else d, dtype=np.float64)
        except (TypeError, ValueError):
            K = np.zeros(0)
        if K.shape != (3, 3) or not np.isfinite(K).all() or not (K[0, 0] > 0 and K[1, 1] > 0):
            raise ValueError(f"--K {args.K}: give the 3 x 3 camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] "
                             f"with fx, fy > 0 (pixels)")
        given = d.get("image_size") if isinstance(d, dict) else None
        if given is not None and size is None:
            text = ",".join(map(str, given)) if isinstance(given, list) else str(given)
            size = tuple(numbers_option(text, f"--K {args.K}: image_size", 2, int, " [H, W]"))
    else:
        if args.focal is None:
            raise ValueError("the camera is missing: give --focal F (pixels) with --image-size H,W, or --K FILE")
        f = numbers_option(args.focal, "--focal", 1, what=" (pixels)")[0]
        if f <= 0:
            raise ValueError(f"--focal {args.focal}: give the focal length in pixels, > 0")
        K = np.array([[f, 0, 0], [0, f, 0], [0, 0, 1.0]])
    if mask_shape is not None:
        if size is not None and tuple(size) != tuple(mask_shape):
            raise ValueError(f"the mask is {mask_shape[0]} x {mask_shape[1]} pixels (H x W), the image size given is "
                             f"{size[0]} x {size[1]}: give the mask of this image (or drop --image-size)")
        size = tuple(mask_shape)
    if size is None:
        raise ValueError("the image size is missing: give --image-size H,W (or a --mask, or image_size in --K)")
    if args.K is None:
        H, W = size
        cx, cy = ((W - 1) / 2, (H - 1) / 2) if args.principal is None else numbers_option(args.principal, "--principal",
                                                                                     2, what=" cx,cy (pixels)")
        K[0, 2], K[1, 2] = cx, cy
    return K, (int(size[0]), int(size[1]))


def read_mask(path) -> np.ndarray:
    """The object's mask (H, W) bool from an image OpenCV reads (module docstring: which pixels are the object)."""
    import cv2

    img = cv2.imread(str(existing_file(path, "--mask")), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"--mask {path}: OpenCV cannot read it as an image; give a PNG, JPEG, BMP or TIFF")
    top = float(np.iinfo(img.dtype).max) if np.issubdtype(img.dtype, np.integer) else 1.0
    if img.ndim == 3 and img.shape[2] == 4 and (img[..., 3] < top).any():
        img = img[..., 3]  # an alpha channel that cuts out the object
    elif img.ndim == 3:
        img = img[..., :3].max(axis=2)
    mask = img > top / 2
    if not mask.any():
        raise ValueError(f"--mask {path}: no object pixel (none above half the image's maximum value); give a mask "
                         f"where the object is white (non-zero) on black")
    return mask


def read_selection(path, what: str, flag: str) -> np.ndarray:
    """A selection file: 0-based ids, one per line ('#' comments) or a JSON list. Shape: -> (n,) int64 unique."""
    p = existing_file(path, flag)
    text = p.read_text(encoding="utf-8", errors="replace")
    try:
        ids = json.loads(text) if text.lstrip().startswith("[") else [
            int(line.split("#")[0]) for line in text.splitlines() if line.split("#")[0].strip()]
        a = np.asarray(ids)
        ok = a.ndim == 1 and len(a) > 0 and np.issubdtype(a.dtype, np.integer) and (a >= 0).all()
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(f"{flag} {path}: give {what} ids, integers >= 0, one per line or as a JSON list")
    return np.unique(a.astype(np.int64))


def read_object_pose(path, scale_prior: float):
    from .case import Similarity

    d = json_object(path, "--object-pose", "the object pose file")
    if not isinstance(d, dict):  # a user's file: one line of ValueError (volsmpl.cli)
        raise ValueError(f"--object-pose {path}: give a JSON object: rotation (3 x 3), translation (3)")  # noqa: TRY004
    return Similarity.from_dict({"scale": scale_prior, **d}, f"--object-pose {path}")


# ------------------------------------------------------------------------------------------- geometry
