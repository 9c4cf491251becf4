"""Pose sampler, self-contact poses and named poses for SMPL-format bodies (24 joints, SMPL conventions).

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
    (`sample_contact_euler`, below) replaces the mode's draw; from a stream of its own, so that 0 leaves every
    draw above as it was.
    """
    check_pose_mode(mode, extreme_fraction, contact_fraction)
    out = _sample_mode(n, seed, mode, extreme_fraction)
    if contact_fraction > 0:
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


# ---------------------------------------------------------------------------------------------------- self-contact poses
# Random self-contact poses for training: limbs drawn from families of joint ranges that bring parts together.
#
# Uniform joint angles (`poses.sample_euler`'s 'realistic' and 'extreme') rarely put a hand on the chest, a
# thigh against the belly or one leg across the other; those are the poses the self-penetration and interaction
# apps work on, and the ones where a trained volume errs most. Here each body draws, independently per arm and
# for the legs, one family of angle ranges (left side written; the right side mirrors it, (x, -y, -z), as
# JOINT_LIMITS does), uniform inside the family's ranges and clipped to JOINT_LIMITS; the joints a family leaves
# out keep a realistic draw, and half the bodies bend the spine forward. Families (`ARM_FAMILIES`,
# `LEG_FAMILIES`): arms across the torso, hands on hips or thighs, upper arm against the flank, hand to the head,
# or free; legs in a deep squat, seated, seated cross-legged, crossed while standing, sitting on the heels, or
# free. The ranges are broad families, not the validation split's poses (`volsmpl.evaluation.contact_split`): those are
# scored on their own bodies and query points, which training never sees.
#
#     e = sample_contact_euler(8, seed=0)      # (8, 23, 3) Euler angles, poses.euler_to_body_pose(e) -> (8, 69)

#: family -> (probability, {left joint: ((x lo, hi) | None, (y lo, hi) | None, (z lo, hi) | None)}); None: realistic
ARM_FAMILIES = {
    "across_torso": (0.30, {"left_shoulder": ((-0.3, 0.3), (-1.5, -0.6), (-1.3, -0.5)),
                            "left_elbow": (None, (-2.6, -1.5), None)}),
    "hand_on_hip_or_thigh": (0.25, {"left_shoulder": (None, (-0.8, 0.5), (-1.4, -0.8)),
                                    "left_elbow": (None, (-1.8, -0.2), None)}),
    "arm_against_flank": (0.15, {"left_shoulder": (None, (-0.3, 0.3), (-1.5, -1.3)),
                                 "left_elbow": (None, (-0.6, 0.0), None)}),
    "hand_to_head": (0.10, {"left_shoulder": (None, (-1.2, -0.2), (0.0, 1.0)),
                            "left_elbow": (None, (-2.6, -1.8), None)}),
    "free": (0.20, {}),
}
LEG_FAMILIES = {
    "deep_squat": (0.20, {"left_hip": ((-2.0, -1.4), None, (0.0, 0.4)), "left_knee": ((1.9, 2.4), None, None),
                          "left_ankle": ((-0.7, 0.5), None, None)}),
    "seated": (0.20, {"left_hip": ((-1.7, -1.3), None, None), "left_knee": ((1.2, 2.0), None, None)}),
    "cross_legged": (0.15, {"left_hip": ((-1.7, -1.3), (0.3, 0.6), (0.4, 0.8)), "left_knee": ((2.0, 2.4), None, None)}),
    "crossed_standing": (0.15, {"left_hip": ((-0.4, 0.1), None, (-0.45, -0.2))}),
    "on_heels": (0.10, {"left_hip": ((-0.6, 0.0), None, None), "left_knee": ((2.2, 2.4), None, None),
                        "left_ankle": ((0.2, 0.5), None, None)}),
    "free": (0.20, {}),
}
_SAME_LEGS = 0.7     # probability that both legs take the same family (each its own angles)
_SPINE_BEND = (0.5, "spine1", (0.0, 0.6))   # probability, joint, forward-bend range of its x angle


def mirror(joint: str) -> str:
    """The other side's joint name ('left_hip' <-> 'right_hip'); central joints map to themselves."""
    if joint.startswith("left_"):
        return "right_" + joint[5:]
    if joint.startswith("right_"):
        return "left_" + joint[6:]
    return joint


def _draw_family(families: dict, rng: np.random.Generator) -> str:
    names = list(families)
    p = np.array([families[n][0] for n in names])
    return names[rng.choice(len(names), p=p / p.sum())]


def _apply(e: np.ndarray, ranges: dict, right: bool, rng: np.random.Generator) -> None:
    """Overwrite the angles `ranges` sets (left-side ranges; mirrored for the right side) with uniform draws."""
    for joint, axes in ranges.items():
        j = BODY_JOINTS.index(mirror(joint) if right else joint)
        for a, r in enumerate(axes):
            if r is None:
                continue
            v = rng.uniform(*r)
            e[j, a] = -v if (right and a > 0) else v


def sample_contact_euler(n: int, seed: int | None = None) -> np.ndarray:
    """Self-contact-seeking joint angles (the section's comment above), (n, 23, 3), within JOINT_LIMITS; body i depends only
    on (seed, i)."""
    if not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"sample_contact_euler needs n >= 0 bodies, got {n!r}")
    out = np.empty((n, len(BODY_JOINTS), 3))
    base = np.random.SeedSequence(seed) if seed is not None else np.random.SeedSequence()
    limits = np.array([JOINT_LIMITS[j] for j in BODY_JOINTS])      # (23, 3, 2)
    for i, child in enumerate(base.spawn(n)):
        rng = np.random.default_rng(child)
        e = sample_euler(1, seed=int(rng.integers(2 ** 63)), mode="realistic")[0]
        for right in (False, True):
            _apply(e, ARM_FAMILIES[_draw_family(ARM_FAMILIES, rng)][1], right, rng)
        legs = _draw_family(LEG_FAMILIES, rng)
        other = legs if rng.random() < _SAME_LEGS else _draw_family(LEG_FAMILIES, rng)
        _apply(e, LEG_FAMILIES[legs][1], False, rng)
        _apply(e, LEG_FAMILIES[other][1], True, rng)
        p, joint, r = _SPINE_BEND
        if rng.random() < p:
            e[BODY_JOINTS.index(joint), 0] = rng.uniform(*r)
        out[i] = np.clip(e, limits[..., 0], limits[..., 1])
    return out


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
