"""Figures of the egocentric app.

- A generated frame (`frame_figure`): the camera view with the keypoints and the ground truth, then one panel per
  guide with its sample, scene points inside the sampled body in red (exact winding-number test).
- A user's frame (`user_figure`): one row per guide: the camera view (the image's camera, scaled to at most
  FIGURE_SIDE pixels) with the input 2D keypoints drawn by their confidence (radius and opacity grow with it; 0: not
  drawn), the recovered body and its joints (blue), and the scene points within NEAR_M of the body (grey; those
  inside it red, drawn on top); then a side view (orthographic, up as in the scene, looking across the camera's
  line of sight) of the same.

    frame_figure(path, frame, scene, gt_vertices, samples, faces, points)
    user_figure(path, frame, {"volsmpl": (vertices, joints, inside)}, faces, points, up_rotation)
"""
from __future__ import annotations

import numpy as np
import torch

BODY_GT = (0.55, 0.75, 0.55)
BODY_SAMPLE = (0.35, 0.55, 0.9)
#: the longer side (pixels) of a user frame's camera view; larger images are drawn scaled down
FIGURE_SIDE = 640
#: scene points farther than this (m) from the recovered body are not drawn; at most NEAR_GREY of the others
NEAR_M, NEAR_GREY = 0.4, 5000
INSIDE_RGB, POINT_GREY, KEYPOINT_RGB, JOINT_RGB = (230, 20, 20), (0.55, 0.55, 0.55), (220, 30, 30), (30, 60, 200)


def camera_of(K: np.ndarray, image_size) -> "object":
    """A kornia pinhole camera at the origin looking down +z (the frame's camera coordinates)."""
    from kornia.geometry.camera import PinholeCamera

    H, W = int(image_size[0]), int(image_size[1])
    Km = torch.eye(4, dtype=torch.float64)[None]
    Km[0, :3, :3] = torch.as_tensor(np.asarray(K, np.float64))
    return PinholeCamera(Km, torch.eye(4, dtype=torch.float64)[None], torch.tensor([float(H)]), torch.tensor([float(W)]))


def _panel(scene, camera, body_vertices, faces, color, points=None, keypoints=None, title=""):
    from volsmpl.viz.render import render_camera_view

    meshes = [(np.asarray(scene.vertices), np.asarray(scene.faces), (0.78, 0.76, 0.72))]
    if body_vertices is not None:
        meshes.append((np.asarray(body_vertices), faces, color))
    red = None if points is None or len(points) == 0 else np.tile([[0.9, 0.1, 0.1]], (len(points), 1))
    img = render_camera_view(meshes, camera, points=points if red is not None else None, point_colors=red,
                             point_radius=2, keypoints=keypoints)
    return img, title


def frame_figure(path, frame, scene, gt_vertices, samples: dict, faces: np.ndarray, inside: dict) -> None:
    """Write one frame's grid: the ground truth with the 2D keypoints' 3D joints, then each guide's sample.

    samples: guide -> sampled vertices (V, 3) camera frame; inside: guide -> scene points inside that sample (M, 3).
    """
    from volsmpl.viz.render import grid, save_png

    cam = camera_of(frame.K, frame.image_size)
    panels = [_panel(scene, cam, gt_vertices, faces, BODY_GT, keypoints=np.asarray(frame.joints),
                     title=f"{frame.name} {frame.activity}: ground truth")]
    for g, v in samples.items():
        pts = inside.get(g)
        panels.append(_panel(scene, cam, v, faces, BODY_SAMPLE, points=pts,
                             title=f"{'no guidance' if g == 'none' else 'guided by ' + g}: "
                                   f"{0 if pts is None else len(pts)} scene points inside"))
    imgs, labels = zip(*panels)
    save_png(path, grid(list(imgs), list(labels), cols=min(len(imgs), 3)))


def draw_confident_keypoints(img: np.ndarray, uv: np.ndarray, conf: np.ndarray, color=KEYPOINT_RGB) -> np.ndarray:
    """2D keypoints (N, 2) (pixels) drawn in place by their confidence (N,): radius 2 + 5 conf pixels, opacity
    0.25 + 0.75 conf; confidence 0 (not detected) is not drawn. Returns img."""
    import cv2

    for i in np.flatnonzero(np.asarray(conf) > 0):
        c = float(conf[i])
        over = img.copy()
        p = (int(round(uv[i, 0] * 16)), int(round(uv[i, 1] * 16)))
        cv2.circle(over, p, int(round((2 + 5 * c) * 16)), tuple(int(v) for v in color), -1, cv2.LINE_AA, shift=4)
        a = 0.25 + 0.75 * c
        img[:] = cv2.addWeighted(over, a, img, 1 - a, 0)
    return img


def _dots_on_top(img: np.ndarray, px: np.ndarray, color=INSIDE_RGB, radius: int = 2) -> np.ndarray:
    import cv2

    for u, v in np.round(px * 16).astype(np.int64):
        cv2.circle(img, (int(u), int(v)), radius * 16, color, -1, cv2.LINE_AA, shift=4)
    return img


def side_yaw(up_rotation: np.ndarray) -> float:
    """The yaw (degrees, volsmpl.viz.render's convention) of a view looking across the camera's line of sight: the
    camera's forward axis (0, 0, 1) turned by `up_rotation` (camera -> a Y-up frame), made horizontal, turned 90
    degrees about the vertical."""
    f = np.asarray(up_rotation, np.float64) @ np.array([0.0, 0.0, 1.0])
    f = np.array([f[0], 0.0, f[2]])
    f = f / np.linalg.norm(f) if np.linalg.norm(f) > 1e-6 else np.array([0.0, 0.0, 1.0])
    d = np.cross([0.0, 1.0, 0.0], f)                       # towards the viewer
    return float(np.degrees(np.arctan2(-d[0], d[2])))


def user_figure(path, frame, samples: dict, faces: np.ndarray, points: np.ndarray, up_rotation: np.ndarray) -> None:
    """Write a user frame's figure (module docstring). samples: guide -> (vertices (V, 3), joints (24, 3), inside
    (N,) bool over `points`), camera frame; points (N, 3): the scene points around the body, camera frame;
    up_rotation (3, 3): camera -> a Y-up frame (R^T of world_to_camera, or a flip of y and z)."""
    from scipy.spatial import cKDTree

    from volsmpl.viz.render import grid, render_camera_view, render_scene, save_png, scene_pixels

    from .evaluate import GUIDE_CUBE

    H0, W0 = frame.image_size
    s = min(1.0, FIGURE_SIDE / max(H0, W0))
    K = np.asarray(frame.K, np.float64).copy()
    K[:2] *= s
    H, W = int(round(H0 * s)), int(round(W0 * s))
    cam = camera_of(K, (H, W))
    M = np.asarray(up_rotation, np.float64)
    yaw, pitch, size = side_yaw(M), 10.0, min(H, W)
    rng = np.random.default_rng(0)
    imgs, labels = [], []
    for g, (v, joints, inside) in samples.items():
        near = cKDTree(v).query(points, k=1, distance_upper_bound=NEAR_M)[0] < np.inf
        grey = np.flatnonzero(near & ~inside)
        grey = grey if len(grey) <= NEAR_GREY else rng.choice(grey, NEAR_GREY, replace=False)
        red = points[inside]
        name = "no guidance" if g == "none" else f"guided by {g}"
        img = render_camera_view([(v, faces, BODY_SAMPLE)], cam, points=points[grey], point_colors=POINT_GREY,
                                 point_radius=1, keypoints=joints, keypoint_color=JOINT_RGB)
        ahead = red[red[:, 2] > 0.05]
        _dots_on_top(img, (ahead[:, :2] / ahead[:, 2:3]) * K[[0, 1], [0, 1]] + K[:2, 2])
        draw_confident_keypoints(img, frame.keypoints * s, frame.conf)
        imgs.append(img)
        labels.append(f"{name}: camera view, {len(red)} points inside")
        centre = joints[0] @ M.T
        side = render_scene([(v @ M.T, faces, BODY_SAMPLE)], size, yaw=yaw, pitch=pitch, extent=1.1 * GUIDE_CUBE,
                            center=centre, points=points[grey] @ M.T, point_colors=POINT_GREY, point_radius=1)
        _dots_on_top(side, scene_pixels(red @ M.T, size, yaw, pitch, 1.1 * GUIDE_CUBE, centre))
        pad = np.full((H, W, 3), 255, np.uint8)
        pad[(H - size) // 2:(H - size) // 2 + size, (W - size) // 2:(W - size) // 2 + size] = side
        imgs.append(pad)
        labels.append(f"{name}: side view")
    save_png(path, grid(imgs, labels, cols=2))


__all__ = ["frame_figure", "camera_of", "user_figure", "draw_confident_keypoints", "side_yaw"]
