"""Pose sampler and named poses for SMPL-format bodies (24 joints, SMPL conventions).

Axes of the rest (T-) pose: +X = the body's left, +Y = up, +Z = forward. Every joint angle is an
(x, y, z) intrinsic Euler triple in the parent's rest frame (radians; composed in EULER_ORDER),
converted to SMPL axis-angle.
Signs (derived from the rest pose, see each limit's comment):
  hips:      x < 0 swings the leg forward; z > 0 abducts the left leg (to +X), z < 0 the right leg.
  knees:     x > 0 flexes (shin backwards).
  spine/neck x > 0 bends forward; y twists; z bends sideways.
  shoulders: left arm lies along +X: z < 0 lowers it, y < 0 swings it forward;
             right arm (along -X): z > 0 lowers it, y > 0 swings it forward.
  elbows:    left y < 0 / right y > 0 flex the forearm forward.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from .model import SMPL_JOINT_NAMES

# (min, max) per Euler axis (x, y, z) for each non-root joint; anatomical ranges, slightly conservative.
JOINT_LIMITS = {
    "left_hip": ((-2.0, 0.5), (-0.6, 0.6), (-0.45, 0.8)),
    "right_hip": ((-2.0, 0.5), (-0.6, 0.6), (-0.8, 0.45)),
    "spine1": ((-0.3, 0.6), (-0.35, 0.35), (-0.3, 0.3)),
    "left_knee": ((0.0, 2.4), (-0.15, 0.15), (-0.1, 0.1)),
    "right_knee": ((0.0, 2.4), (-0.15, 0.15), (-0.1, 0.1)),
    "spine2": ((-0.2, 0.4), (-0.3, 0.3), (-0.25, 0.25)),
    "left_ankle": ((-0.7, 0.5), (-0.3, 0.3), (-0.3, 0.3)),
    "right_ankle": ((-0.7, 0.5), (-0.3, 0.3), (-0.3, 0.3)),
    "spine3": ((-0.2, 0.35), (-0.3, 0.3), (-0.2, 0.2)),
    "left_foot": ((-0.4, 0.5), (-0.1, 0.1), (-0.1, 0.1)),
    "right_foot": ((-0.4, 0.5), (-0.1, 0.1), (-0.1, 0.1)),
    "neck": ((-0.5, 0.7), (-0.7, 0.7), (-0.4, 0.4)),
    "left_collar": ((-0.2, 0.2), (-0.3, 0.3), (-0.2, 0.4)),
    "right_collar": ((-0.2, 0.2), (-0.3, 0.3), (-0.4, 0.2)),
    "head": ((-0.4, 0.5), (-0.6, 0.6), (-0.3, 0.3)),
    "left_shoulder": ((-1.0, 1.0), (-1.5, 0.7), (-1.5, 1.2)),
    "right_shoulder": ((-1.0, 1.0), (-0.7, 1.5), (-1.2, 1.5)),
    "left_elbow": ((-0.8, 0.8), (-2.6, 0.0), (-0.2, 0.2)),
    "right_elbow": ((-0.8, 0.8), (0.0, 2.6), (-0.2, 0.2)),
    "left_wrist": ((-0.5, 0.5), (-0.5, 0.5), (-0.9, 0.9)),
    "right_wrist": ((-0.5, 0.5), (-0.5, 0.5), (-0.9, 0.9)),
    "left_hand": ((-0.2, 0.2), (-0.2, 0.2), (-0.6, 0.6)),
    "right_hand": ((-0.2, 0.2), (-0.2, 0.2), (-0.6, 0.6)),
}
BODY_JOINTS = SMPL_JOINT_NAMES[1:]
_LIMITS = np.array([JOINT_LIMITS[j] for j in BODY_JOINTS])  # (23, 3, 2)
# Composition order per joint: the wide-range axis first, so the middle Euler angle stays inside
# (-pi/2, pi/2) and every rotation has one Euler triple (elbows flex up to 2.6 rad about y).
EULER_ORDER = {j: ("YXZ" if j.endswith("elbow") else "XYZ") for j in BODY_JOINTS}
_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _rotations(euler: np.ndarray, joint: str) -> Rotation:
    order = EULER_ORDER[joint]
    return Rotation.from_euler(order, euler[:, [_AXIS[a] for a in order]])


def euler_to_body_pose(euler: np.ndarray) -> torch.Tensor:
    """(B, 23, 3) Euler angles (x, y, z) per joint, composed in EULER_ORDER -> (B, 69) float32 body_pose."""
    euler = np.asarray(euler, dtype=np.float64)
    rv = np.stack([_rotations(euler[:, j], name).as_rotvec() for j, name in enumerate(BODY_JOINTS)], axis=1)
    return torch.as_tensor(rv.reshape(euler.shape[0], -1), dtype=torch.float32)


def body_pose_to_euler(body_pose: torch.Tensor) -> np.ndarray:
    """(B, 69) axis-angle -> (B, 23, 3) Euler angles (x, y, z), inverse of euler_to_body_pose."""
    rv = body_pose.detach().double().cpu().numpy().reshape(body_pose.shape[0], 23, 3)
    out = np.empty_like(rv)
    for j, name in enumerate(BODY_JOINTS):
        order = EULER_ORDER[name]
        e = Rotation.from_rotvec(rv[:, j]).as_euler(order)
        out[:, j, [_AXIS[a] for a in order]] = e
    return out


POSE_MODES = ("realistic", "extreme", "mixed")


def check_pose_mode(mode: str, extreme_fraction: float, contact_fraction: float = 0.0) -> None:
    """Raise ValueError unless `mode` is one of POSE_MODES and both fractions lie in [0, 1]."""
    if mode not in POSE_MODES:
        raise ValueError(f"pose_mode must be one of {POSE_MODES}, got {mode!r}")
    if not 0.0 <= extreme_fraction <= 1.0:
        raise ValueError(f"extreme_fraction must lie in [0, 1], got {extreme_fraction}")
    if not 0.0 <= contact_fraction <= 1.0:
        raise ValueError(f"contact_fraction must lie in [0, 1], got {contact_fraction}")


def sample_euler(n: int, seed: int | None = None, mode: str = "realistic",
                 extreme_fraction: float = 0.5, contact_fraction: float = 0.0) -> np.ndarray:
    """Random joint angles within JOINT_LIMITS, (n, 23, 3).

    mode 'realistic': per angle, with prob. 0.6 a normal around the neutral angle (0 clipped into the
    limits) with sd 1/4 of the range, else uniform in the range; then clipped to the limits.
    mode 'extreme': uniform over the full range of every angle (validation of hard poses).
    mode 'mixed': per body, with prob. `extreme_fraction` an extreme pose, else a realistic one (the
    realistic bodies are those mode 'realistic' draws from the same seed).
    contact_fraction > 0: afterwards, per body with that probability, a self-contact pose
    (`volsmpl.body.contact_poses`) replaces the mode's draw; from a stream of its own, so that 0 leaves every
    draw above as it was.
    """
    check_pose_mode(mode, extreme_fraction, contact_fraction)
    out = _sample_mode(n, seed, mode, extreme_fraction)
    if contact_fraction > 0:
        from .contact_poses import sample_contact_euler

        ss = np.random.SeedSequence([seed, 0xC0DE]) if seed is not None else np.random.SeedSequence()
        pick = np.random.default_rng(ss).random(n) < contact_fraction
        if pick.any():
            contact = sample_contact_euler(n, seed=int(ss.generate_state(1)[0]))
            out = np.where(pick[:, None, None], contact, out)
    return out


def _sample_mode(n: int, seed, mode: str, extreme_fraction: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = _LIMITS[..., 0], _LIMITS[..., 1]
    uni = rng.uniform(lo, hi, size=(n, *lo.shape))
    if mode == "extreme":
        return uni
    centre = np.clip(0.0, lo, hi)
    gauss = centre + rng.standard_normal((n, *lo.shape)) * (hi - lo) / 4
    pick = rng.random((n, *lo.shape)) < 0.6
    realistic = np.clip(np.where(pick, gauss, uni), lo, hi)
    if mode == "realistic":
        return realistic
    extreme = rng.uniform(lo, hi, size=(n, *lo.shape))  # fresh draws: `uni` already fed the realistic angles
    body_extreme = rng.random(n) < extreme_fraction
    return np.where(body_extreme[:, None, None], extreme, realistic)


def sample_poses(n: int, seed: int | None = None, mode: str = "realistic",
                 extreme_fraction: float = 0.5, contact_fraction: float = 0.0) -> torch.Tensor:
    """(n, 69) random SMPL body poses within per-joint anatomical limits (see sample_euler)."""
    return euler_to_body_pose(sample_euler(n, seed, mode, extreme_fraction, contact_fraction))


def within_limits(body_pose: torch.Tensor, tol: float = 1e-6) -> torch.Tensor:
    """(B, 69) -> (B,) bool: every joint's Euler angles inside JOINT_LIMITS."""
    e = body_pose_to_euler(body_pose)
    ok = (e >= _LIMITS[..., 0] - tol) & (e <= _LIMITS[..., 1] + tol)
    return torch.as_tensor(ok.all(axis=(1, 2)))


def _pose(**joints) -> dict:
    return joints


# Named poses: joint -> (x, y, z) Euler radians; joints left out stay at the T-pose.
NAMED_POSES = {
    "t_pose": _pose(),
    "a_pose": _pose(left_shoulder=(0, 0, -0.75), right_shoulder=(0, 0, 0.75)),
    "arms_down": _pose(left_shoulder=(0, 0, -1.35), right_shoulder=(0, 0, 1.35)),
    "arms_up": _pose(left_shoulder=(0, 0, 1.2), right_shoulder=(0, 0, -1.2), left_collar=(0, 0, 0.3), right_collar=(0, 0, -0.3)),
    "sitting": _pose(left_hip=(-1.55, 0, 0.1), right_hip=(-1.55, 0, -0.1), left_knee=(1.55, 0, 0), right_knee=(1.55, 0, 0),
                     left_shoulder=(0, -0.3, -1.2), right_shoulder=(0, 0.3, 1.2), left_elbow=(0, -0.8, 0), right_elbow=(0, 0.8, 0)),
    "squatting": _pose(left_hip=(-1.9, 0, 0.35), right_hip=(-1.9, 0, -0.35), left_knee=(2.3, 0, 0), right_knee=(2.3, 0, 0),
                       left_ankle=(-0.5, 0, 0), right_ankle=(-0.5, 0, 0), spine1=(0.35, 0, 0),
                       left_shoulder=(0, -1.2, -0.6), right_shoulder=(0, 1.2, 0.6)),
    "reaching": _pose(right_shoulder=(0, 1.3, -0.5), right_elbow=(0, 0.2, 0), spine2=(0.2, -0.2, 0),
                      left_shoulder=(0, 0, -1.3)),
    "arms_crossed": _pose(left_shoulder=(0, -1.1, -1.0), right_shoulder=(0, 1.1, 1.0), left_elbow=(0, -1.9, 0),
                          right_elbow=(0, 1.9, 0)),
    "lunge": _pose(left_hip=(-1.3, 0, 0.1), left_knee=(1.4, 0, 0), right_hip=(0.45, 0, -0.1), right_knee=(0.7, 0, 0),
                   left_shoulder=(0, 0, -1.3), right_shoulder=(0, 0, 1.3)),
    "walking": _pose(left_hip=(-0.45, 0, 0), right_hip=(0.3, 0, 0), right_knee=(0.4, 0, 0), left_knee=(0.15, 0, 0),
                     left_shoulder=(0, 0.35, -1.3), right_shoulder=(0, 0.35, 1.3), left_elbow=(0, -0.3, 0),
                     right_elbow=(0, 0.5, 0)),
    "hands_on_hips": _pose(left_shoulder=(0, 0.35, -0.9), right_shoulder=(0, -0.35, 0.9), left_elbow=(0, -1.6, 0),
                           right_elbow=(0, 1.6, 0)),
    "kneeling": _pose(left_hip=(-1.5, 0, 0.05), left_knee=(1.6, 0, 0), right_hip=(0.0, 0, -0.05), right_knee=(1.6, 0, 0),
                      right_ankle=(0.5, 0, 0), left_shoulder=(0, 0, -1.3), right_shoulder=(0, 0, 1.3)),
}


def named_pose(name: str) -> torch.Tensor:
    """(1, 69) body_pose of a named pose (see NAMED_POSES)."""
    if name not in NAMED_POSES:
        raise ValueError(f"unknown pose {name!r}; named poses are {sorted(NAMED_POSES)}")
    e = np.zeros((1, 23, 3))
    for joint, angles in NAMED_POSES[name].items():
        e[0, BODY_JOINTS.index(joint)] = angles
    return euler_to_body_pose(e)
