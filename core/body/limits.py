"""Joint limits as differentiable measures of a body pose: each joint's Euler angles in torch, how far they lie
beyond the limits of `volsmpl.body.poses.JOINT_LIMITS`, and the joints a self-contact should move.

The angles are the intrinsic Euler triples of `poses.EULER_ORDER` (XYZ, YXZ for the elbows), the convention of the
pose sampler and of scipy's `Rotation.as_euler('XYZ')`, so a limit reads the same here and there.

    e = euler_angles(body_pose)                      # (B, 23, 3) radians, differentiable
    x = limit_excess(body_pose, lo, hi)              # (B, 23, 3) radians beyond [lo, hi] (0 inside)
    pose = clamp_to_limits(body_pose, lo, hi)        # (B, 69): joints beyond their limits turned back inside
    lo, hi = limits_around(start_pose)               # the limits, widened to hold a start that lies outside them
    bad = violations(body_pose, lo, hi)              # [(joint, axis, angle_deg, lo_deg, hi_deg)] per body
    moving = contact_joints(part_pairs, table)       # (23,) bool: the joints a contact's limbs turn
"""
from __future__ import annotations

import numpy as np
import torch

from .lbs import rodrigues
from .poses import BODY_JOINTS, JOINT_LIMITS

__all__ = [
    "LIMITS",
    "TRUNK_JOINTS",
    "clamp_to_limits",
    "contact_joints",
    "euler_angles",
    "largest_change_deg",
    "limit_excess",
    "limits_around",
    "violations",
]

#: (23, 3, 2) radians: (min, max) per body joint and Euler axis (x, y, z)
LIMITS = torch.tensor(np.array([JOINT_LIMITS[j] for j in BODY_JOINTS]), dtype=torch.float64)
#: joints of the trunk: a contact between limbs (or a limb and the trunk or head) moves the limbs, not these
TRUNK_JOINTS = ("spine1", "spine2", "spine3")
_YXZ = torch.tensor([n.startswith(("left_elbow", "right_elbow")) for n in BODY_JOINTS])


def euler_angles(body_pose: torch.Tensor) -> torch.Tensor:
    """(B, 69) axis-angle -> (B, 23, 3) intrinsic Euler angles (x, y, z) in each joint's EULER_ORDER, differentiable.

    XYZ: R = Rx(a) Ry(b) Rz(c): b = asin(R02), a = atan2(-R12, R22), c = atan2(-R01, R00).
    YXZ: R = Ry(b) Rx(a) Rz(c): a = asin(-R12), b = atan2(R02, R22), c = atan2(R10, R11).

    Example:
        >>> euler_angles(torch.tensor([[0.3, 0.0, 0.0] * 23]))[0, 0].tolist()   # a turn about x alone
        [0.30000001192092896, 0.0, 0.0]
    """
    B = body_pose.shape[0]
    R = rodrigues(body_pose.reshape(-1, 3)).reshape(B, 23, 3, 3)
    eps = 1e-6
    xyz = torch.stack([torch.atan2(-R[..., 1, 2], R[..., 2, 2]),
                       torch.asin(R[..., 0, 2].clamp(-1 + eps, 1 - eps)),
                       torch.atan2(-R[..., 0, 1], R[..., 0, 0])], -1)
    yxz = torch.stack([torch.asin((-R[..., 1, 2]).clamp(-1 + eps, 1 - eps)),
                       torch.atan2(R[..., 0, 2], R[..., 2, 2]),
                       torch.atan2(R[..., 1, 0], R[..., 1, 1])], -1)
    return torch.where(_YXZ.to(body_pose.device)[None, :, None], yxz, xyz)


def _elementary(angle: torch.Tensor, axis: int) -> torch.Tensor:
    """(...,) radians -> (..., 3, 3) rotation about coordinate axis `axis`."""
    c, s = torch.cos(angle), torch.sin(angle)
    o, z = torch.ones_like(angle), torch.zeros_like(angle)
    rows = {0: ((o, z, z), (z, c, -s), (z, s, c)),
            1: ((c, z, s), (z, o, z), (-s, z, c)),
            2: ((c, -s, z), (s, c, z), (z, z, o))}[axis]
    return torch.stack([torch.stack(r, -1) for r in rows], -2)


def clamp_to_limits(body_pose: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """The pose with every joint whose Euler angles lie beyond [lo, hi] turned to its nearest angles inside (each
    angle clamped, composed back in its EULER_ORDER); joints inside are returned untouched. The projection of a hard
    joint-limit bound (volsmpl.optim.Variable.project). Shape: (B, 69), (23, 3), (23, 3) -> (B, 69)."""
    from kornia.geometry.conversions import rotation_matrix_to_axis_angle

    B = body_pose.shape[0]
    e = euler_angles(body_pose)
    lo, hi = lo.to(e), hi.to(e)
    e = _near_range(e, lo, hi)
    out_of = ((e < lo) | (e > hi)).any(-1)                         # (B, 23)
    if not bool(out_of.any()):
        return body_pose
    c = torch.minimum(torch.maximum(e, lo), hi)
    Rx, Ry, Rz = (_elementary(c[..., i], i) for i in range(3))
    R = torch.where(_YXZ.to(e.device)[None, :, None, None], Ry @ Rx @ Rz, Rx @ Ry @ Rz)
    aa = rotation_matrix_to_axis_angle(R.reshape(-1, 3, 3)).reshape(B, 23, 3).to(body_pose.dtype)
    pose = body_pose.reshape(B, 23, 3)
    return torch.where(out_of[..., None], aa, pose).reshape(B, 69)


def limits_around(start_pose=None) -> tuple[torch.Tensor, torch.Tensor]:
    """(lo, hi) (23, 3) radians: JOINT_LIMITS, widened per angle to hold the start pose's angle where the start lies
    outside (a repair may not move a joint farther out than it began, nor must it pull it in)."""
    lo, hi = LIMITS[..., 0].clone(), LIMITS[..., 1].clone()
    if start_pose is not None:
        e = euler_angles(torch.as_tensor(start_pose, dtype=torch.float64).reshape(1, 69))[0]
        lo, hi = torch.minimum(lo, e), torch.maximum(hi, e)
    return lo, hi


def _near_range(e: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Euler angles turned by whole turns to lie within half a turn of their range's middle: an angle of 179 deg
    and one of -181 deg are the same turn, and the range [-180, 57] holds the second."""
    mid = 0.5 * (lo + hi)
    return mid + torch.remainder(e - mid + np.pi, 2 * np.pi) - np.pi


def limit_excess(body_pose: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Radians beyond [lo, hi] per joint and axis, 0 inside. Shape: (B, 69), (23, 3), (23, 3) -> (B, 23, 3)."""
    e = euler_angles(body_pose)
    lo, hi = lo.to(e), hi.to(e)
    e = _near_range(e, lo, hi)
    return torch.relu(e - hi) + torch.relu(lo - e)


def violations(body_pose, lo=None, hi=None, tol_deg: float = 0.5) -> list:
    """The angles of one pose (69,) beyond [lo, hi] (default JOINT_LIMITS) by more than tol_deg:
    [(joint, axis, angle_deg, lo_deg, hi_deg)]."""
    if lo is None or hi is None:
        lo, hi = LIMITS[..., 0], LIMITS[..., 1]
    pose = torch.as_tensor(body_pose, dtype=torch.float64).reshape(1, 69)
    e = _near_range(euler_angles(pose)[0], lo, hi)
    over = limit_excess(pose, lo, hi)[0] > np.radians(tol_deg)
    deg = lambda t: float(np.degrees(float(t)))
    return [(BODY_JOINTS[j], "xyz"[a], deg(e[j, a]), deg(lo[j, a]), deg(hi[j, a]))
            for j, a in torch.nonzero(over).tolist()]


def joint_changes_deg(pose0, pose1) -> np.ndarray:
    """The geodesic rotation change (degrees) of each joint between two axis-angle poses. Shape: (J*3,) -> (J,)."""
    from scipy.spatial.transform import Rotation

    a = Rotation.from_rotvec(np.asarray(pose0, np.float64).reshape(-1, 3))
    b = Rotation.from_rotvec(np.asarray(pose1, np.float64).reshape(-1, 3))
    return np.degrees((a.inv() * b).magnitude())


def largest_change_deg(pose0, pose1) -> tuple[float, str]:
    """(degrees, joint): the largest geodesic rotation change over the 23 body joints between two (69,) poses."""
    d = joint_changes_deg(pose0, pose1)
    j = int(d.argmax())
    return float(d[j]), BODY_JOINTS[j]


def contact_joints(part_pairs, table, parents) -> np.ndarray:
    """(23,) bool over the body joints: the joints that turn the limbs (and head) of the colliding parts: for each
    part of each pair, the joints on its kinematic chain from its own joint up to the root (and the joints merged
    into a limb's or the head's part: head, toes, hands), less the trunk (TRUNK_JOINTS, the pelvis). A pair of two trunk parts moves their chains' trunk joints instead.

    part_pairs: iterable of (part a, part b) indices of `table` (volsmpl.body.part_table.PartTable); parents: (J,)
    the body's kinematic parents (-1 at the root)."""
    names = BODY_JOINTS
    trunk = {names.index(j) + 1 for j in TRUNK_JOINTS}

    def chain(part: int) -> list:
        j, out = int(table.part_joints[part]), []
        if j not in trunk:   # a limb's or the head's own merged joints (head, toes, hands) turn it too
            out += [int(m) for m in np.flatnonzero(np.asarray(table.joint_to_part) == part) if m != j and m < 24]
        while j > 0:
            out.append(j)
            j = int(parents[j])
        return out

    moving = np.zeros(len(names), bool)
    for a, b in part_pairs:
        joints = chain(a) + chain(b)
        limbs = [j for j in joints if j not in trunk]
        for j in (limbs or joints):
            moving[j - 1] = True
    return moving
