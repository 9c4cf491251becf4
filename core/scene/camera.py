"""Pinhole cameras in a Y-up world, on kornia: intrinsics from a field of view, look-at extrinsics, projection.

Conventions:
- world: the project's (metres, Y up, right-handed);
- camera frame: OpenCV's, x right, y down, z forward (the viewing direction); depth is camera-frame z;
- extrinsics: world -> camera, E = [[R, t], [0, 1]], x_cam = R x_world + t (kornia's `PinholeCamera` semantics);
- pixels: (u, v) = (column, row) with integer pixel centres (kornia's): pixel (0, 0) is centred at (0, 0), the
  image spans [-0.5, W - 0.5] x [-0.5, H - 0.5] and the principal point of a centred camera is ((W-1)/2, (H-1)/2).

A camera is a `kornia.geometry.camera.PinholeCamera` (batched, (B, 4, 4) intrinsics and extrinsics). Everything is
batched torch and differentiable (w.r.t. points, eye, target and focal length).

Example:
    >>> cam = make_camera(eye=[0.0, 1.6, 2.0], target=[0.0, 1.0, 0.0], image_size=(480, 640), fov_deg=60)
    >>> uv, depth, visible = project(points, cam)  # points (1, N, 3) world
"""
from __future__ import annotations

import math

import torch
from kornia.geometry.camera import PinholeCamera
from kornia.geometry.camera.perspective import project_points, unproject_points
from kornia.geometry.linalg import transform_points


def _vec3(x, name: str, dtype=None, device=None) -> torch.Tensor:
    if dtype is None:
        dtype = x.dtype if torch.is_tensor(x) and x.is_floating_point() else torch.float32
    t = torch.as_tensor(x, dtype=dtype, device=device)
    if t.ndim == 1:
        t = t[None]
    if t.ndim != 2 or t.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (3,) or (B, 3), got {tuple(t.shape)}.")
    if not torch.isfinite(t).all():
        raise ValueError(f"{name} contains NaN/inf; pass finite coordinates in metres.")
    return t


def intrinsics_from_fov(image_size: tuple[int, int], fov_deg=60.0, axis: str = "horizontal",
                        dtype=torch.float32, device=None) -> torch.Tensor:
    """Pinhole intrinsics of a centred camera with square pixels from the image size and a field of view.

    Args:
        image_size: (height, width) in pixels.
        fov_deg: field of view in degrees along `axis`, a float or a (B,) tensor (0 < fov < 180).
        axis: 'horizontal' (across the width) or 'vertical' (across the height).

    Returns: K with fx = fy = (S / 2) / tan(fov / 2) (S the width or height), cx = (W - 1) / 2, cy = (H - 1) / 2.

    Shape: -> (B, 3, 3) (B = 1 for a float fov).

    Example:
        >>> K = intrinsics_from_fov((480, 640), 60.0)  # fx = 320 / tan(30 deg) = 554.3
    """
    H, W = (int(s) for s in image_size)
    if H < 1 or W < 1:
        raise ValueError(f"image_size must be (height, width) with positive ints, got {image_size}.")
    if axis not in ("horizontal", "vertical"):
        raise ValueError(f"axis must be 'horizontal' or 'vertical', got {axis!r}.")
    fov = torch.as_tensor(fov_deg, dtype=dtype, device=device).reshape(-1)
    if not ((fov > 0) & (fov < 180)).all():
        raise ValueError(f"fov_deg must be in (0, 180) degrees, got {fov.tolist()}.")
    f = 0.5 * (W if axis == "horizontal" else H) / torch.tan(torch.deg2rad(fov) / 2)
    K = torch.zeros(len(fov), 3, 3, dtype=dtype, device=device)
    K[:, 0, 0], K[:, 1, 1] = f, f
    K[:, 0, 2], K[:, 1, 2], K[:, 2, 2] = (W - 1) / 2, (H - 1) / 2, 1.0
    return K


def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> torch.Tensor:
    """World -> camera extrinsics of a camera at `eye` looking at `target` (OpenCV axes: x right, y down, z forward).

    The camera's z axis is (target - eye) normalised, x = z x up (right on the screen), y = z x x (down).

    Shape: eye, target (3,) or (B, 3); up (3,) -> (B, 4, 4).

    Example:
        >>> E = look_at([0, 1.6, 2], [0, 1, 0])  # a head-height camera 2 m in front of the origin
    """
    eye = _vec3(eye, "eye")
    target = _vec3(target, "target", dtype=eye.dtype, device=eye.device)
    up = _vec3(up, "up", dtype=eye.dtype, device=eye.device)
    b, c = eye.shape[0], target.shape[0]
    if b != c and 1 not in (b, c):
        raise ValueError(f"eye has {b} positions and target {c}; pass one or the same number of each.")
    eye, target = eye.expand(max(b, c), 3), target.expand(max(b, c), 3)  # one eye for B targets, or B eyes for one
    fwd = target - eye
    dist = fwd.norm(dim=-1, keepdim=True)
    if (dist < 1e-9).any():
        raise ValueError("eye and target coincide; put the camera at a distance from what it looks at.")
    z = fwd / dist
    x = torch.linalg.cross(z, up.expand_as(z))
    nx = x.norm(dim=-1, keepdim=True)
    if (nx < 1e-6 * up.norm(dim=-1, keepdim=True)).any():
        raise ValueError("the viewing direction is parallel to `up`; pass another up vector (e.g. (0, 0, -1) to "
                         "look straight down).")
    x = x / nx
    y = torch.linalg.cross(z, x)
    R = torch.stack([x, y, z], dim=-2)  # rows: camera axes in world coordinates
    E = torch.zeros(eye.shape[0], 4, 4, dtype=eye.dtype, device=eye.device)
    E[:, :3, :3] = R
    E[:, :3, 3] = -(R @ eye[..., None])[..., 0]
    E[:, 3, 3] = 1.0
    return E


def make_camera(eye, target, image_size: tuple[int, int] = (480, 640), fov_deg=60.0, up=(0.0, 1.0, 0.0),
                axis: str = "horizontal") -> PinholeCamera:
    """A kornia PinholeCamera at `eye` looking at `target`, with a field of view `fov_deg` along `axis`.

    Shape: eye, target (3,) or (B, 3) -> a camera of batch B (intrinsics, extrinsics (B, 4, 4)).

    Example:
        >>> cam = make_camera([2.0, 1.7, 2.0], [0.0, 0.9, 0.0], (480, 640), 60)
    """
    E = look_at(eye, target, up)
    B = E.shape[0]
    K3 = intrinsics_from_fov(image_size, fov_deg, axis, dtype=E.dtype, device=E.device)
    if K3.shape[0] not in (1, B):
        raise ValueError(f"fov_deg has {K3.shape[0]} values for {B} cameras; pass one or B values.")
    K = torch.eye(4, dtype=E.dtype, device=E.device).repeat(B, 1, 1)
    K[:, :3, :3] = K3.expand(B, 3, 3)
    H, W = image_size
    return PinholeCamera(K, E, torch.full((B,), float(H), dtype=E.dtype, device=E.device),
                         torch.full((B,), float(W), dtype=E.dtype, device=E.device))


def _batch(x: torch.Tensor, camera: PinholeCamera, name: str, last: int):
    """Check x (B, N, last) against the camera's batch; return x, extrinsics, intrinsics (3x3), height, width, all
    expanded to the common batch (a batch of 1 on either side broadcasts)."""
    if not torch.is_tensor(x) or x.ndim != 3 or x.shape[-1] != last:
        raise ValueError(f"{name} must be a (B, N, {last}) tensor, got {tuple(getattr(x, 'shape', ())) or type(x)}.")
    b, c = x.shape[0], camera.batch_size
    if b != c and 1 not in (b, c):
        raise ValueError(f"{name} has batch {b} but the camera has {c}; match them (or use a batch of 1).")
    B = max(b, c)
    E, K = camera.extrinsics, camera.intrinsics[:, :3, :3]
    return (x.expand(B, *x.shape[1:]), E.expand(B, 4, 4), K.expand(B, 3, 3), camera.height.expand(B),
            camera.width.expand(B))


def world_to_camera(points: torch.Tensor, camera: PinholeCamera) -> torch.Tensor:
    """World points in the camera frame (x right, y down, z forward).

    Shape: (B, N, 3) -> (B, N, 3).
    """
    points, E, *_ = _batch(points, camera, "points", 3)
    return transform_points(E, points)


def camera_to_world(points: torch.Tensor, camera: PinholeCamera) -> torch.Tensor:
    """Camera-frame points back to the world: x_world = R^T (x_cam - t).

    Shape: (B, N, 3) -> (B, N, 3).
    """
    points, E, *_ = _batch(points, camera, "points", 3)
    R, t = E[:, :3, :3], E[:, :3, 3]
    return (points - t[:, None]) @ R


def camera_center(camera: PinholeCamera) -> torch.Tensor:
    """The camera's position in the world, -R^T t. Shape: -> (B, 3)."""
    R, t = camera.extrinsics[:, :3, :3], camera.extrinsics[:, :3, 3]
    return -(R.transpose(-1, -2) @ t[..., None])[..., 0]


def project(points: torch.Tensor, camera: PinholeCamera, near: float = 1e-3):
    """Project world points to pixels (u = fx x / z + cx, v = fy y / z + cy in the camera frame).

    Args:
        points: (B, N, 3) world points.
        camera: a PinholeCamera (e.g. from make_camera).
        near: points with depth <= near are not visible (their pixels are meaningless: for z <= 0 kornia
            divides by a negative or skips the divide).

    Returns:
        uv (B, N, 2) pixels, depth (B, N) camera-frame z, visible (B, N) bool: in front (depth > near) and inside
        the image ([-0.5, W - 0.5] x [-0.5, H - 0.5]).

    Shape: (B, N, 3) -> (B, N, 2), (B, N), (B, N).

    Example:
        >>> uv, depth, vis = project(joints, cam)
    """
    points, E, K, H, W = _batch(points, camera, "points", 3)
    pc = transform_points(E, points)
    uv = project_points(pc, K)
    depth = pc[..., 2]
    H, W = H[:, None], W[:, None]
    u, v = uv[..., 0], uv[..., 1]
    visible = (depth > near) & (u >= -0.5) & (u <= W - 0.5) & (v >= -0.5) & (v <= H - 0.5)
    return uv, depth, visible


def unproject(uv: torch.Tensor, depth: torch.Tensor, camera: PinholeCamera) -> torch.Tensor:
    """World points at pixels uv and camera-frame depths (the inverse of `project`).

    Shape: uv (B, N, 2), depth (B, N) -> (B, N, 3).

    Example:
        >>> X = unproject(uv, depth, cam)  # == points where visible
    """
    if not torch.is_tensor(depth) or not torch.is_tensor(uv) or depth.shape != uv.shape[:-1]:
        raise ValueError(f"depth must be a (B, N) tensor matching uv (B, N, 2), got {getattr(depth, 'shape', None)} "
                         f"and {getattr(uv, 'shape', None)}.")
    uv, _, K, _, _ = _batch(uv, camera, "uv", 2)
    pc = unproject_points(uv, depth.expand(uv.shape[:-1])[..., None], K[:, None])
    return camera_to_world(pc, camera)


def orbit_eye(target, distance: float, yaw_deg: float, height: float) -> torch.Tensor:
    """A camera position at a horizontal `distance` from `target` in direction yaw (0: along +Z, in front of a
    body facing +Z; 90: along +X), at absolute `height` above the floor (y = height).

    Shape: target (3,) -> (3,).

    Example:
        >>> cam = make_camera(orbit_eye(pelvis, 2.0, 30.0, 1.6), pelvis)
    """
    t = _vec3(target, "target")[0]
    if not (distance > 0 and math.isfinite(distance)):
        raise ValueError(f"distance must be positive metres, got {distance}.")
    a = math.radians(yaw_deg)
    y = torch.as_tensor(float(height), dtype=t.dtype)
    return torch.stack([t[0] + distance * math.sin(a), y, t[2] + distance * math.cos(a)])
