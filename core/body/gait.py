"""The periodic walk cycle of the motion app's walking model (`walk.WalkModel`): the gait as a function of phase.

What it holds: the hand-designed joint-angle keyframes (hips, knees, ankles, toes, pelvis, spine, arms, head, after
clinical gait curves) and their periodic Catmull-Rom splines (`walk_cycle`, `walk_cycle_quat`), the foot lock's
hand-over between the feet (`anchor_weights`), the stance contact labels (`stance_contacts`), the gait constants
(`STANCE`, `DOUBLE_SUPPORT`, `CONTACT_END`), the foot joints (`FOOT_JOINTS`, `ANKLE_JOINTS`) and the small
quaternion helpers the cycle and the model compose rotations with (`axis_quat`, `quat_mul`, `quat_to_axis_angle`).

Conventions (those of `volsmpl.body`): Y up, SMPL's 24 joints and axis-angle pose; the phase is in cycles (one cycle =
one stride = two steps; left heel strike at phase 0, right heel strike at 0.5, each foot on the ground for
STANCE = 0.62 of the cycle). Every function is a smooth (piecewise) torch function of the phase, any batch shape.

    orient, pose = walk_cycle(torch.linspace(0, 1, 31))     # (31, 3), (31, 69)
"""
from __future__ import annotations

import math

import torch

from volsmpl.body.model import SMPL_JOINT_NAMES

__all__ = ["STANCE", "DOUBLE_SUPPORT", "CONTACT_END", "FOOT_JOINTS", "ANKLE_JOINTS", "walk_cycle", "walk_cycle_quat",
           "anchor_weights", "stance_contacts", "axis_quat", "quat_mul", "quat_to_axis_angle"]

STANCE = 0.62          # fraction of the cycle a foot is on the ground (heel strike at 0, toe off at 0.62)
DOUBLE_SUPPORT = STANCE - 0.5
CONTACT_END = 0.60     # contact labels end here: the toes leave the floor over [0.60, 0.62] (lifting < 1.5 cm)

_J = {n: i for i, n in enumerate(SMPL_JOINT_NAMES)}
FOOT_JOINTS = (_J["left_foot"], _J["right_foot"])      # the balls of the feet: anchors of the foot lock
ANKLE_JOINTS = (_J["left_ankle"], _J["right_ankle"])
_EULER_ORDER = {n: ("YXZ" if n.endswith("elbow") else "XYZ") for n in SMPL_JOINT_NAMES[1:]}  # as volsmpl.body.poses

# ------------------------------------------------------------------------------------------------ the walk cycle
# Keyframes (degrees) uniformly spaced over one cycle, phase 0 = this side's heel strike; periodic Catmull-Rom
# between them. Gait-lab signs (flexion positive), converted to SMPL's Euler signs in walk_cycle. Designed by hand after
# normal-gait curves (Winter, 'Biomechanics and Motor Control of Human Movement'; the hip as the thigh's angle to the
# vertical, pelvis upright), then fitted once on the default body (Adam, 150 steps, through this module: sum of squared
# stance slide of the balls and sole heights in stance, swing clearance >= 2.5 cm, stride 1.4 m, staying near the hand
# design and smooth) and rounded to 0.1 deg. The hip curve is scaled by _STRIDE_GAIN.
_KEYS = {
    # thigh flexion (forward +): peak extension at ~55 %, peak flexion at ~88 %
    "hip_flex": [21.4, 19.7, 16.5, 6.9, -1.4, -7.7, -12.7, -8.4, -0.8, 12.8, 23.8, 27.8],
    # knee flexion: loading-response bump, near-straight mid-stance, 60 deg at ~72 % in swing, straight at heel strike
    "knee_flex": [5.8, 7.7, 8.3, 7.1, 4.8, 5.3, 14.6, 29.5, 48.7, 49.2, 32.2, 13.3],
    # foot pitch to the floor during stance (toe down +): heel strike toe up, flat, heel rise into push-off
    "foot_pitch": [-2.9, -3.0, -2.4, -1.2, 1.7, 8.2, 18.0, 32.2, 38.6, 29.7, 14.7, 2.4],
    # ankle plantarflexion in swing (used where the foot is off the ground)
    "ankle_swing": [-2.3, -0.6, -0.1, 0.2, 1.2, 3.8, 7.3, 7.7, 0.7, -6.9, -7.9, -5.5],
    # stance weight of the foot-pitch rule for the ankle (1 in stance, 0 in mid-swing)
    "stance_rule": [1, 1, 1, 1, 1, 1, 1, 0.9, 0.3, 0, 0, 0.4],
    # toe extension (toes bent up +) during heel rise, so the toes stay on the floor
    "toe_ext": [-0.6, -0.7, -0.7, -0.3, 1.3, 5.2, 11.7, 15.7, 13.2, 7.2, 2.4, 0.1],
    # hip abduction (+ away from the midline): slight adduction in stance keeps the foot under the body
    "hip_abd": [-1.0, -2.8, -4.4, -4.4, -3.3, -1.5, 0.6, 2.0, 2.4, 2.3, 1.6, 0.6],
}
_STRIDE_GAIN = 1.25
_PELVIS_YAW = 5.0     # deg: the forward leg's side of the pelvis leads
_PELVIS_ROLL = 3.0    # deg: the swing side drops
_PELVIS_TILT = 2.0    # deg forward lean, +/- 1 deg at twice the step frequency
_TRUNK_LEAN = 3.0     # deg forward lean of the chest
_THORAX_YAW = 4.0     # deg counter-rotation of the spine (relative to the pelvis: spine total -pelvis - this)
_ARM_SWING = 16.0     # deg shoulder flexion amplitude (counter-phase with the same side's leg)
_ARM_LOWER = 72.0     # deg arms lowered from the T-pose
_ELBOW_FLEX = 22.0    # deg mean elbow flexion (+8 deg when the arm swings forward)


def _catmull_rom(keys: torch.Tensor, phase: torch.Tensor) -> torch.Tensor:
    """Periodic Catmull-Rom spline through N uniformly spaced keys (period 1). keys (N,), phase (...) -> (...)."""
    n = keys.shape[0]
    u = (phase - torch.floor(phase)) * n
    i = torch.floor(u).long().clamp(0, n - 1)
    t = u - i.to(u.dtype)
    p0, p1, p2, p3 = (keys[(i + k) % n] for k in (-1, 0, 1, 2))
    t2, t3 = t * t, t * t * t
    return 0.5 * (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t2 + (3 * p1 - p0 - 3 * p2 + p3) * t3)


def axis_quat(angle: torch.Tensor, axis: int) -> torch.Tensor:
    """(...) angles about a coordinate axis -> (..., 4) quaternions (w, x, y, z)."""
    h = 0.5 * angle
    q = [torch.cos(h)] + [torch.zeros_like(h)] * 3
    q[1 + axis] = torch.sin(h)
    return torch.stack(q, dim=-1)


def quat_mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], dim=-1)


def quat_to_axis_angle(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) unit quaternions -> (..., 3) axis-angle, smooth through the identity (gradients included)."""
    q = torch.where(q[..., :1] < 0, -q, q)
    w, v = q[..., 0], q[..., 1:]
    n2 = (v * v).sum(-1)
    small = n2 < 1e-12
    n = torch.sqrt(torch.where(small, torch.ones_like(n2), n2))
    factor = torch.where(small, 2.0 / w * (1.0 - n2 / (3.0 * w * w)), 2.0 * torch.atan2(n, w) / n)
    return v * factor[..., None]


def _euler_to_axis_angle(euler: dict, order: str, like: torch.Tensor) -> torch.Tensor:
    """{'x','y','z': (...) radians or None} composed intrinsically in `order` (as scipy's upper case) -> (..., 3)."""
    q = None
    for a in order:
        ang = euler.get(a.lower())
        if ang is None:
            continue
        qa = axis_quat(ang, "XYZ".index(a))
        q = qa if q is None else quat_mul(q, qa)
    if q is None:
        return torch.zeros(*like.shape, 3, dtype=like.dtype, device=like.device)
    return quat_to_axis_angle(q)


def _curve(name: str, phase: torch.Tensor) -> torch.Tensor:
    keys = torch.as_tensor(_KEYS[name], dtype=phase.dtype, device=phase.device)
    return _catmull_rom(keys, phase)


def walk_cycle_quat(phase: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """walk_cycle with the pelvis rotation as a quaternion (w, x, y, z): (...) -> (..., 4), (..., 69)."""
    if not torch.is_tensor(phase) or not phase.is_floating_point():
        raise ValueError(f"phase must be a floating-point tensor, got {type(phase).__name__}"
                         + (f" of {phase.dtype}" if torch.is_tensor(phase) else ""))
    if not torch.isfinite(phase).all():
        raise ValueError("phase contains NaN or Inf.")
    deg = math.pi / 180.0
    two_pi = 2 * math.pi
    angles: dict[str, dict[str, torch.Tensor]] = {}
    pelvis_tilt_x = (_PELVIS_TILT + 1.0 * torch.cos(2 * two_pi * phase)) * deg
    for side, shift, mirror in (("left", 0.0, 1.0), ("right", 0.5, -1.0)):
        p = phase - shift
        hip = _curve("hip_flex", p) * _STRIDE_GAIN
        knee = _curve("knee_flex", p)
        # SMPL x-rotations of the leg chain add up in the sagittal plane: hip x = -flexion, knee x = +flexion,
        # ankle/toe x = plantarflexion; the foot's pitch to the floor is pelvis_x + hip_x + knee_x + ankle_x.
        hip_x, knee_x = -hip * deg, knee * deg
        pitch = _curve("foot_pitch", p) * deg
        rule = _curve("stance_rule", p).clamp(0.0, 1.0)
        ankle_x = rule * (pitch - pelvis_tilt_x - hip_x - knee_x) + (1 - rule) * _curve("ankle_swing", p) * deg
        angles[f"{side}_hip"] = {"x": hip_x, "z": mirror * _curve("hip_abd", p) * deg}
        angles[f"{side}_knee"] = {"x": knee_x}
        angles[f"{side}_ankle"] = {"x": ankle_x}
        angles[f"{side}_foot"] = {"x": -_curve("toe_ext", p) * deg}
        # arms: this side's arm swings forward (x < 0) while this side's leg is back (phase 0.5)
        swing = torch.cos(two_pi * p)
        angles[f"{side}_shoulder"] = {"x": _ARM_SWING * swing * deg, "z": torch.full_like(phase, -mirror * _ARM_LOWER * deg)}
        angles[f"{side}_elbow"] = {"y": -mirror * (_ELBOW_FLEX - 8.0 * swing) * deg}
    c = torch.cos(two_pi * phase)
    pelvis_yaw = -_PELVIS_YAW * c * deg                     # left side of the pelvis forward at left heel strike
    pelvis_roll = _PELVIS_ROLL * torch.sin(two_pi * (phase + 0.1)) * deg   # the swing side drops
    thorax_yaw = _THORAX_YAW * c * deg                      # the chest counter-rotates against the pelvis
    for j in ("spine1", "spine2", "spine3"):   # the spine undoes the pelvis tilt and roll (3 joints), leans forward
        angles[j] = {"x": (_TRUNK_LEAN * deg - pelvis_tilt_x) / 3.0, "y": (thorax_yaw - pelvis_yaw) / 3.0, "z": -pelvis_roll / 3.0}
    angles["neck"] = {"y": -0.5 * thorax_yaw}               # the head keeps looking along the path
    angles["head"] = {"y": -0.5 * thorax_yaw}
    pose = []
    for name in SMPL_JOINT_NAMES[1:]:
        pose.append(_euler_to_axis_angle(angles.get(name, {}), _EULER_ORDER[name], phase))
    body_pose = torch.cat(pose, dim=-1)
    q = quat_mul(quat_mul(axis_quat(pelvis_yaw, 1), axis_quat(pelvis_tilt_x, 0)), axis_quat(pelvis_roll, 2))
    return q, body_pose


def walk_cycle(phase: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The periodic walk cycle: pelvis rotation (without heading) and body_pose at a gait phase (cycles).

    Periodic with period 1 (phase p and p + 1 give the same pose), smooth in the phase (C1 keyframe splines).
    Left heel strike at 0, right heel strike at 0.5.

    Shape: phase (...) -> (pelvis_orient (..., 3), body_pose (..., 69)), axis-angle.
    Example:
        >>> orient, pose = walk_cycle(torch.linspace(0, 1, 31))     # (31, 3), (31, 69)
    """
    q, body_pose = walk_cycle_quat(phase)
    return quat_to_axis_angle(q), body_pose


def _smoothstep(x: torch.Tensor) -> torch.Tensor:
    x = x.clamp(0.0, 1.0)
    return x * x * (3 - 2 * x)


def anchor_weights(phase: torch.Tensor) -> torch.Tensor:
    """Weights (left, right) of the feet in the foot lock: 1 for the only foot down, a smooth hand-over from the
    trailing to the leading foot during double support (phase [0, 0.12] and [0.5, 0.62]). They sum to 1.

    Shape: phase (...) -> (..., 2).
    Example:
        >>> anchor_weights(torch.tensor([0.3, 0.8]))   # tensor([[1., 0.], [0., 1.]])
    """
    p = phase - torch.floor(phase)
    left = torch.where(p < 0.5, _smoothstep(p / DOUBLE_SUPPORT), 1.0 - _smoothstep((p - 0.5) / DOUBLE_SUPPORT))
    return torch.stack([left, 1.0 - left], dim=-1)


def stance_contacts(phase: torch.Tensor) -> torch.Tensor:
    """Foot contact labels (left, right): the foot's stance interval of the cycle, heel strike to CONTACT_END
    (left [0, 0.60), right [0.5, 1.10) mod 1). Shape: (...) -> (..., 2) bool."""
    p = phase - torch.floor(phase)
    q = (phase - 0.5) - torch.floor(phase - 0.5)
    return torch.stack([p < CONTACT_END, q < CONTACT_END], dim=-1)
