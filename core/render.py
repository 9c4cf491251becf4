"""Headless CPU rendering of meshes to images (OpenCV rasterisation, painter's algorithm, flat shading).

Good enough for demos and debugging pictures; no GPU or display needed.
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
    order = np.argsort(tri[:, :, 2].mean(1))  # far to near
    rgb = (col * shade[:, None] * 255).clip(0, 255).astype(np.uint8)
    pts = np.round(px * 16).astype(np.int32)  # 4 bits of sub-pixel precision
    for i in order:
        if visible[i]:
            cv2.fillConvexPoly(img, pts[i], tuple(int(c) for c in rgb[i]), lineType=cv2.LINE_AA, shift=4)
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
