"""Rotation parametrisations for optimisation: the continuous 6D representation (Zhou et al., CVPR 2019)
and axis-angle, to and from rotation matrices (kornia's conversions; matrix -> axis-angle through kornia's
quaternion, with a gradient that stays finite at the identity).

    R = rotation_6d_to_matrix(r6)          # (..., 6) -> (..., 3, 3), always a rotation
    r6 = matrix_to_rotation_6d(R)          # the first two columns
"""
from __future__ import annotations

import torch
from kornia.geometry.conversions import axis_angle_to_rotation_matrix, rotation_matrix_to_quaternion

__all__ = ["rotation_6d_to_matrix", "matrix_to_rotation_6d", "axis_angle_to_matrix", "matrix_to_axis_angle",
           "axis_angle_to_rotation_6d", "rotation_6d_to_axis_angle"]


def rotation_6d_to_matrix(r6: torch.Tensor) -> torch.Tensor:
    """Gram-Schmidt of the two 3-vectors in r6 into the first two columns of a rotation; the third is their cross.

    Shape: (..., 6) -> (..., 3, 3).
    Example:
        >>> rotation_6d_to_matrix(torch.tensor([1., 0, 0, 0, 1, 0]))
        tensor([[1., 0., 0.],
                [0., 1., 0.],
                [0., 0., 1.]])
    """
    if r6.shape[-1] != 6:
        raise ValueError(f"a 6D rotation has 6 values in its last dimension, got shape {tuple(r6.shape)}")
    a, b = r6[..., :3], r6[..., 3:]
    x = torch.nn.functional.normalize(a, dim=-1)
    y = torch.nn.functional.normalize(b - (x * b).sum(-1, keepdim=True) * x, dim=-1)
    z = torch.linalg.cross(x, y, dim=-1)
    return torch.stack([x, y, z], dim=-1)


def matrix_to_rotation_6d(R: torch.Tensor) -> torch.Tensor:
    """The first two columns of rotation matrices, concatenated. Shape: (..., 3, 3) -> (..., 6)."""
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices must be (..., 3, 3), got shape {tuple(R.shape)}")
    return torch.cat([R[..., :, 0], R[..., :, 1]], dim=-1)


def axis_angle_to_matrix(aa: torch.Tensor) -> torch.Tensor:
    """Axis-angle (rotation vector) to matrix. Shape: (..., 3) -> (..., 3, 3)."""
    if aa.shape[-1] != 3:
        raise ValueError(f"axis-angle rotations have 3 values in the last dimension, got shape {tuple(aa.shape)}")
    return axis_angle_to_rotation_matrix(aa.reshape(-1, 3)).reshape(*aa.shape[:-1], 3, 3)


def matrix_to_axis_angle(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrix to axis-angle, angles in [0, pi], through the unit quaternion (w >= 0); the gradient is
    finite at the identity too (angle 2 atan2(|v|, w) / |v| -> 2 / w there), so poses can be optimised through
    it. Shape: (..., 3, 3) -> (..., 3)."""
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices must be (..., 3, 3), got shape {tuple(R.shape)}")
    q = rotation_matrix_to_quaternion(R.reshape(-1, 3, 3), eps=1e-12)  # (w, x, y, z)
    sign = torch.where(q[:, :1] < 0, -1.0, 1.0).to(q.dtype)
    w, v = q[:, :1] * sign, q[:, 1:] * sign
    n2 = (v * v).sum(-1, keepdim=True)
    small = n2 < 1e-12
    n = torch.where(small, torch.ones_like(n2), n2).sqrt()  # no 0/0 in the branch torch.where leaves out
    k = torch.where(small, 2.0 / w.clamp_min(0.5), 2.0 * torch.atan2(n, w) / n)
    return (v * k).reshape(*R.shape[:-2], 3)


def axis_angle_to_rotation_6d(aa: torch.Tensor) -> torch.Tensor:
    """Shape: (..., 3) -> (..., 6)."""
    return matrix_to_rotation_6d(axis_angle_to_matrix(aa))


def rotation_6d_to_axis_angle(r6: torch.Tensor) -> torch.Tensor:
    """Shape: (..., 6) -> (..., 3)."""
    return matrix_to_axis_angle(rotation_6d_to_matrix(r6))
