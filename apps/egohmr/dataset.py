"""Frames (apps/egohmr/data.py) as the tensors the network trains and samples on.

    kp = keypoint_input(frame)                         # (24, 3): (x, y) normalised by the intrinsics, confidence
    d = frame_tensors(frames, body)                    # dict of stacked tensors, scene crops around the true pelvis
    crops = scene_crops(frames, centres, n=1024)       # (B, n, 3) scene points relative to `centres`

Keypoints enter the network as ((u - cx) / fx, (v - cy) / fy, conf), 0 where conf is 0 (not detected), so the
network sees the viewing rays, independent of the image size and focal length.
"""
from __future__ import annotations

import numpy as np
import torch

from .pose import pose_vector


def keypoint_input(frame) -> np.ndarray:
    """(24, 3) float32 network input of a frame's 2D keypoints (module docstring)."""
    K, kp, conf = np.asarray(frame.K, np.float64), np.asarray(frame.keypoints, np.float64), np.asarray(frame.conf)
    xy = np.stack([(kp[:, 0] - K[0, 2]) / K[0, 0], (kp[:, 1] - K[1, 2]) / K[1, 1]], axis=-1)
    xy = np.where(conf[:, None] > 0, xy, 0.0)
    return np.concatenate([xy, conf[:, None]], axis=-1).astype(np.float32)


def scene_crops(frames, centres, n: int, size: float = 2.0, seed: int = 0) -> torch.Tensor:
    """Scene points in the `size` cube around each centre, relative to it. Shape: centres (B, 3) -> (B, n, 3)."""
    from .data import scene_points

    c = np.asarray(torch.as_tensor(centres).detach().cpu(), np.float64)
    return torch.stack([torch.as_tensor(scene_points(f, c[i], n=n, size=size, seed=seed + i) - c[i], dtype=torch.float32)
                        for i, f in enumerate(frames)])


def frame_tensors(frames, n_scene: int = 1024, size: float = 2.0, seed: int = 0) -> dict:
    """Stacked tensors of frames: kp (B, 24, 3), pose (B, 144), pelvis (B, 3), betas (B, 10), joints (B, 24, 3),
    visible (B, 24) bool, scene (B, n_scene, 3) around the true pelvis (relative to it)."""
    if not frames:
        raise ValueError("no frames given")
    kp = torch.as_tensor(np.stack([keypoint_input(f) for f in frames]))
    go = torch.as_tensor(np.stack([f.global_orient for f in frames]), dtype=torch.float32)
    bp = torch.as_tensor(np.stack([f.body_pose for f in frames]), dtype=torch.float32)
    joints = torch.as_tensor(np.stack([f.joints for f in frames]), dtype=torch.float32)
    out = {"kp": kp, "pose": pose_vector(go, bp), "pelvis": joints[:, 0].clone(), "joints": joints,
           "betas": torch.as_tensor(np.stack([f.betas for f in frames]), dtype=torch.float32),
           "visible": torch.as_tensor(np.stack([f.visible for f in frames]), dtype=torch.bool)}
    if n_scene:
        out["scene"] = scene_crops(frames, out["pelvis"], n_scene, size, seed)
    return out


__all__ = ["keypoint_input", "scene_crops", "frame_tensors"]
