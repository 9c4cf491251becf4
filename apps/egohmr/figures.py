"""Figures of the egocentric app: per frame, the camera view with the keypoints and the ground truth, then one
panel per guide with its sample, scene points inside the sampled body in red (exact winding-number test).

    frame_figure(path, frame, scene, gt_vertices, samples, faces, points)
"""
from __future__ import annotations

import numpy as np
import torch

BODY_GT = (0.55, 0.75, 0.55)
BODY_SAMPLE = (0.35, 0.55, 0.9)


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


__all__ = ["frame_figure", "camera_of"]
