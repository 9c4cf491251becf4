"""Headless CPU rendering of meshes to images (OpenCV rasterisation, painter's algorithm, flat shading).

Good enough for demos and debugging pictures; no GPU or display needed.

- `render_mesh`: one mesh, orthographic, rotated by yaw/pitch.
- `render_scene`: several meshes with their own colours (a body in a room, a hand on a cup) and optional points
  drawn as dots (e.g. penetrating scene points in red), orthographic, in one depth order.
- `render_camera_view`: the same through a perspective `kornia` PinholeCamera (`volsmpl.scene.camera`), with
  near-plane clipping, and projected keypoints drawn by OpenCV (`draw_keypoints`).
All share one rasteriser (`_paint`: triangles and dots filled far to near). Painter's ordering needs triangles
that are small against the gaps between objects: `render_scene`/`render_camera_view` split triangles longer than
`max_edge` first (floors and walls are two triangles per face).
"""
from __future__ import annotations

import colorsys

import cv2
import numpy as np


def part_palette(k: int) -> np.ndarray:
    """k distinct RGB colours in [0, 1], (k, 3)."""
    return np.array([colorsys.hsv_to_rgb((i * 0.618034) % 1.0, 0.65, 0.95) for i in range(k)])


def _view_rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    return Rx @ Ry


def render_mesh(vertices: np.ndarray, faces: np.ndarray, face_colors: np.ndarray | None = None, size: int = 512,
                yaw: float = 0.0, pitch: float = 0.0, extent: float | None = None,
                background=(255, 255, 255)) -> np.ndarray:
    """Orthographic view of a mesh (camera looks along -Z of the rotated frame: the body's front at yaw 0).

    Args:
        vertices (V, 3) Y-up metres; faces (F, 3); face_colors (F, 3) RGB in [0, 1] (default grey);
        yaw/pitch: view rotation in degrees; extent: metres spanned by the image (default: fit the mesh),
        to share one scale between images. The mesh is centred. Returns an (size, size, 3) uint8 RGB image.
    """
    v = np.asarray(vertices, dtype=np.float64) @ _view_rotation(yaw, pitch).T
    f = np.asarray(faces)
    col = np.full((len(f), 3), 0.75) if face_colors is None else np.asarray(face_colors, dtype=np.float64)
    tri = v[f]  # (F, 3, 3)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    light = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])
    shade = 0.35 + 0.65 * np.clip(n @ light, 0, 1)
    visible = n[:, 2] > 0
    lo, hi = v[:, :2].min(0), v[:, :2].max(0)
    scale = 0.9 * size / (max(hi - lo) if extent is None else extent)
    centre = 0.5 * (lo + hi)
    px = (tri[..., :2] - centre) * scale
    px[..., 0] += size / 2
    px[..., 1] = size / 2 - px[..., 1]
    img = np.empty((size, size, 3), np.uint8)
    img[:] = background
    rgb = (col * shade[:, None] * 255).clip(0, 255).astype(np.uint8)
    _paint(img, px, tri[:, :, 2].mean(1), rgb, visible)
    return img


def _paint(img: np.ndarray, polys, near_key: np.ndarray, rgb: np.ndarray, visible: np.ndarray | None = None,
           dots: np.ndarray | None = None, dot_key: np.ndarray | None = None, dot_rgb: np.ndarray | None = None,
           dot_radius: int = 2) -> np.ndarray:
    """The shared rasteriser: fill convex polygons and dots into img (in place), far to near.

    Args:
        polys: (F, k, 2) pixel coordinates (x right, y down; integer = pixel centre), or a list of (k_i, 2) arrays.
        near_key: (F,) nearness (larger = nearer): primitives are drawn in ascending order (painter's algorithm).
        rgb: (F, 3) uint8 colours; visible: (F,) bool (default all).
        dots, dot_key, dot_rgb: optional (P, 2) pixel centres, (P,) nearness and (P, 3) uint8 colours of dots
            interleaved with the polygons in the same order.
    """
    n = len(near_key)
    key = near_key if dots is None else np.concatenate([near_key, dot_key])
    order = np.argsort(key)  # far to near
    pts = (np.round(polys * 16).astype(np.int32) if isinstance(polys, np.ndarray)
           else [np.round(p * 16).astype(np.int32) for p in polys])  # 4 bits of sub-pixel precision
    dpts = None if dots is None else np.round(dots * 16).astype(np.int32)
    for i in order:
        if i < n:
            if visible is None or visible[i]:
                cv2.fillConvexPoly(img, pts[i], tuple(int(c) for c in rgb[i]), lineType=cv2.LINE_AA, shift=4)
        else:
            j = i - n
            cv2.circle(img, (int(dpts[j, 0]), int(dpts[j, 1])), dot_radius * 16, tuple(int(c) for c in dot_rgb[j]),
                       thickness=-1, lineType=cv2.LINE_AA, shift=4)
    return img


def grid(images: list[np.ndarray], labels: list[str] | None = None, cols: int = 4) -> np.ndarray:
    """Tile equally sized RGB images into a grid, with optional captions."""
    h, w = images[0].shape[:2]
    rows = (len(images) + cols - 1) // cols
    out = np.full((rows * h, cols * w, 3), 255, np.uint8)
    for i, im in enumerate(images):
        r, c = divmod(i, cols)
        tile = im.copy()
        if labels:
            cv2.putText(tile, labels[i], (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (20, 20, 20), 2, cv2.LINE_AA)
        out[r * h:(r + 1) * h, c * w:(c + 1) * w] = tile
    return out


def save_png(path, rgb: np.ndarray) -> None:
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise RuntimeError(f"could not write {path}")


# ------------------------------------------------------------------------------------------------ scenes
def _gather(meshes, max_edge: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[(vertices, faces, rgb)] -> triangles (F, 3, 3), colours (F, 3) in [0, 1]; split long edges if max_edge."""
    if not isinstance(meshes, (list, tuple)) or len(meshes) == 0:
        raise ValueError("meshes must be a non-empty list of (vertices, faces, rgb) tuples.")
    tris, cols = [], []
    for k, item in enumerate(meshes):
        if len(item) != 3:
            raise ValueError(f"meshes[{k}] must be (vertices, faces, rgb), got {len(item)} entries.")
        v, f, c = np.asarray(item[0], dtype=np.float64), np.asarray(item[1], dtype=np.int64), np.asarray(item[2], float)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"meshes[{k}]: vertices must be (V, 3) and faces (F, 3), got {v.shape} and {f.shape}.")
        if not np.isfinite(v).all():
            raise ValueError(f"meshes[{k}]: vertices contain NaN/inf.")
        c = np.broadcast_to(c, (len(f), 3)) if c.shape == (3,) else c
        if c.shape != (len(f), 3):
            raise ValueError(f"meshes[{k}]: rgb must be (3,) or (F, 3) in [0, 1], got {c.shape}.")
        if max_edge is not None and len(f):
            import trimesh
            v, f, idx = trimesh.remesh.subdivide_to_size(v, f, max_edge, max_iter=12, return_index=True)
            c = c[idx]
        tris.append(v[f])
        cols.append(c)
    return np.concatenate(tris), np.concatenate(cols)


def _dots(points, point_colors) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    c = np.asarray((0.15, 0.3, 0.8) if point_colors is None else point_colors, dtype=np.float64)
    c = np.broadcast_to(c, (len(p), 3)) if c.shape == (3,) else c
    if c.shape != (len(p), 3):
        raise ValueError(f"point_colors must be (3,) or (P, 3) in [0, 1] for {len(p)} points, got {c.shape}.")
    return p, (c * 255).clip(0, 255).astype(np.uint8)


def render_scene(meshes, size: int = 512, yaw: float = 0.0, pitch: float = 0.0, extent: float | None = None,
                 center=None, points=None, point_colors=None, point_radius: int = 2, background=(255, 255, 255),
                 max_edge: float | str | None = "auto") -> np.ndarray:
    """Orthographic view of several meshes, each with its own colour, and optional points as dots.

    Same camera as render_mesh (view rotated by yaw/pitch, looking along -Z of the rotated frame).

    Args:
        meshes: [(vertices (V, 3), faces (F, 3), rgb (3,) or (F, 3) in [0, 1])], world frame (Y up, metres).
        extent: metres spanned by the image (default: fit everything); center: (3,) world point at the image
            centre (default: the centre of the projected bounding box).
        points: optional (P, 3) points drawn as dots of radius point_radius pixels; point_colors (3,) or (P, 3)
            in [0, 1], e.g. red where a body penetrates the scene: np.where(inside[:, None], (1, 0, 0), (.3, .3, .3)).
        max_edge: split triangles longer than this (metres) so that painter's ordering holds between large
            faces (floors, walls) and objects; 'auto': 1/30 of the scene's size; None: no splitting.

    Shape: -> (size, size, 3) uint8 RGB.

    Example:
        >>> img = render_scene(room.render_meshes() + [(body_v, body_f, (0.9, 0.6, 0.5))], 512, yaw=30, pitch=35)
    """
    tri, col = _gather(meshes, None)
    if max_edge == "auto":
        max_edge = float(np.ptp(tri.reshape(-1, 3), axis=0).max()) / 30 or None
    if max_edge is not None:
        tri, col = _gather(meshes, max_edge)
    R = _view_rotation(yaw, pitch)
    tri = tri @ R.T
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    light = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])
    rgb = (col * (0.35 + 0.65 * np.clip(n @ light, 0, 1))[:, None] * 255).clip(0, 255).astype(np.uint8)
    allv = tri.reshape(-1, 3)
    dots = dot_rgb = None
    if points is not None:
        dots, dot_rgb = _dots(points, point_colors)
        dots = dots @ R.T
        allv = np.concatenate([allv, dots])
    lo, hi = allv[:, :2].min(0), allv[:, :2].max(0)
    scale = 0.9 * size / (max(hi - lo) if extent is None else extent)
    c2 = 0.5 * (lo + hi) if center is None else (R @ np.asarray(center, dtype=np.float64).reshape(3))[:2]

    def to_px(xy):
        px = (xy - c2) * scale
        px[..., 0] += size / 2
        px[..., 1] = size / 2 - px[..., 1]
        return px

    img = np.empty((size, size, 3), np.uint8)
    img[:] = background
    _paint(img, to_px(tri[..., :2]), tri[:, :, 2].mean(1), rgb, n[:, 2] > 0,
           None if dots is None else to_px(dots[:, :2]), None if dots is None else dots[:, 2], dot_rgb, point_radius)
    return img


def _clip_near(tri: np.ndarray, near: float) -> list[np.ndarray]:
    """Clip camera-frame triangles (T, 3, 3) against the plane z = near (Sutherland-Hodgman): 3- or 4-gons."""
    out = []
    for t in tri:
        poly = []
        for a, b in zip(t, np.roll(t, -1, axis=0)):
            ina, inb = a[2] >= near, b[2] >= near
            if ina:
                poly.append(a)
            if ina != inb:
                s = (near - a[2]) / (b[2] - a[2])
                poly.append(a + s * (b - a))
        out.append(np.array(poly))
    return out


def draw_keypoints(img: np.ndarray, uv, visible=None, color=(255, 0, 0), radius: int = 4, labels=None) -> np.ndarray:
    """Draw 2D keypoints (pixels, integer = pixel centre) on an RGB uint8 image in place with OpenCV.

    Args: uv (N, 2) array or tensor; visible (N,) bool (default all); color RGB 0-255 (one, or (N, 3));
    labels: optional N strings written next to the points. Returns img.
    """
    uv = np.asarray(uv.detach().cpu() if hasattr(uv, "detach") else uv, dtype=np.float64).reshape(-1, 2)
    vis = np.ones(len(uv), bool) if visible is None else np.asarray(
        visible.detach().cpu() if hasattr(visible, "detach") else visible, bool).reshape(-1)
    cols = np.broadcast_to(np.asarray(color), (len(uv), 3))
    for i in np.flatnonzero(vis & np.isfinite(uv).all(1)):
        p = (int(round(uv[i, 0] * 16)), int(round(uv[i, 1] * 16)))
        c = tuple(int(x) for x in cols[i])
        cv2.circle(img, p, radius * 16, c, thickness=-1, lineType=cv2.LINE_AA, shift=4)
        if labels is not None:
            cv2.putText(img, str(labels[i]), (p[0] // 16 + radius + 2, p[1] // 16 - radius), cv2.FONT_HERSHEY_SIMPLEX,
                        0.4, c, 1, cv2.LINE_AA)
    return img


def render_camera_view(meshes, camera, points=None, point_colors=None, point_radius: int = 2, keypoints=None,
                       keypoint_color=(255, 0, 0), keypoint_labels=None, near: float = 0.05,
                       background=(255, 255, 255), max_edge: float | None = 0.25) -> np.ndarray:
    """Perspective view of several meshes through a pinhole camera (kornia PinholeCamera, e.g. from
    `volsmpl.scene.camera.make_camera`; its first batch element), with optional dots and keypoints.

    Triangles facing away from the camera are culled, those crossing the near plane are clipped at z = near;
    keypoints (K, 3) world are projected with the camera and drawn on top with OpenCV (those in view only).

    Args:
        meshes: [(vertices (V, 3), faces (F, 3), rgb (3,) or (F, 3) in [0, 1])], world frame.
        points, point_colors: as in render_scene (depth-ordered with the triangles).
        max_edge: split longer triangles (metres) for painter's ordering; None: no splitting.

    Shape: -> (H, W, 3) uint8 RGB, H and W from the camera.

    Example:
        >>> cam = make_camera(room.sample_viewpoint(pelvis), pelvis, (480, 640), 60)
        >>> img = render_camera_view(room.render_meshes() + [(v, f, (0.9, 0.6, 0.5))], cam, keypoints=joints)
    """
    import torch

    from volsmpl.scene.camera import project, world_to_camera

    H, W = int(camera.height[0]), int(camera.width[0])
    E = camera.extrinsics[:1].detach().double().cpu()
    K = camera.intrinsics[0, :3, :3].detach().double().cpu().numpy()
    cam0 = type(camera)(camera.intrinsics[:1].detach().double().cpu(), E, camera.height[:1].double().cpu(),
                        camera.width[:1].double().cpu())
    tri, col = _gather(meshes, max_edge)
    tri = world_to_camera(torch.as_tensor(tri.reshape(1, -1, 3)), cam0)[0].numpy().reshape(-1, 3, 3)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    keep = (np.einsum("fi,fi->f", n, -tri.mean(1)) > 0) & (tri[:, :, 2] >= near).any(1)
    tri, col, n = tri[keep], col[keep], n[keep]
    light = np.array([0.3, -0.4, -1.0]) / np.linalg.norm([0.3, -0.4, -1.0])  # from upper right of the camera
    rgb = (col * (0.35 + 0.65 * np.clip(n @ light, 0, 1))[:, None] * 255).clip(0, 255).astype(np.uint8)
    straddle = (tri[:, :, 2] < near).any(1)
    polys = list(tri)
    for i, p in zip(np.flatnonzero(straddle), _clip_near(tri[straddle], near)):
        polys[i] = p
    polys = [K[:2, :2].diagonal() * p[:, :2] / p[:, 2:3] + K[:2, 2] for p in polys]
    img = np.empty((H, W, 3), np.uint8)
    img[:] = background
    dots = dkey = drgb = None
    if points is not None:
        p, drgb = _dots(points, point_colors)
        uv, depth, vis = project(torch.as_tensor(p)[None], cam0, near)
        vis = vis[0].numpy()
        dots, dkey, drgb = uv[0].numpy()[vis], -depth[0].numpy()[vis], drgb[vis]
    _paint(img, polys, -tri[:, :, 2].mean(1), rgb, None, dots, dkey, drgb, point_radius)
    if keypoints is not None:
        kp = torch.as_tensor(np.asarray(keypoints.detach().cpu() if hasattr(keypoints, "detach") else keypoints,
                                        dtype=np.float64).reshape(1, -1, 3))
        uv, _, vis = project(kp, cam0, near)
        draw_keypoints(img, uv[0].numpy(), vis[0].numpy(), keypoint_color, 4, keypoint_labels)
    return img


# ------------------------------------------------------------------------------------------------ framing
def scene_view(points, yaw: float = 0.0, pitch: float = 0.0) -> np.ndarray:
    """World points (Y up) in the view frame of `render_scene` / `render_mesh` at yaw/pitch: x right, y up, z towards
    the viewer (larger = nearer). Frame a view on what matters from these (their x, y bounds give `center` and
    `extent`). Shape: (P, 3) -> (P, 3) float64."""
    return np.asarray(points, dtype=np.float64).reshape(-1, 3) @ _view_rotation(yaw, pitch).T


def scene_pixels(points, size: int, yaw: float, pitch: float, extent: float, center) -> np.ndarray:
    """Pixel coordinates (x right, y down; integer = pixel centre) of world points in `render_scene`'s image of
    the same size, yaw, pitch, extent and center (given explicitly, as render_scene then frames it), e.g. to draw
    marks on top of the meshes. Shape: (P, 3) -> (P, 2) float64."""
    R = _view_rotation(yaw, pitch)
    xy = scene_view(points, yaw, pitch)[:, :2] - (R @ np.asarray(center, dtype=np.float64).reshape(3))[:2]
    px = xy * (0.9 * size / extent)
    px[:, 0] += size / 2
    px[:, 1] = size / 2 - px[:, 1]
    return px
