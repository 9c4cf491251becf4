"""Rotation conversions against kornia's and by round trips; gradients finite at the identity."""
from __future__ import annotations

import math

import torch

from volsmpl.geometry.rotations import (axis_angle_to_matrix, matrix_to_axis_angle, rotation_6d_to_axis_angle,
                               rotation_6d_to_matrix)


def test_matrix_to_axis_angle_round_trip():
    g = torch.Generator().manual_seed(0)
    d = torch.nn.functional.normalize(torch.randn(2000, 3, generator=g, dtype=torch.float64), dim=-1)
    ang = torch.rand(2000, 1, generator=g, dtype=torch.float64) * (math.pi - 1e-3)
    aa = d * ang
    back = matrix_to_axis_angle(axis_angle_to_matrix(aa))
    assert torch.allclose(back, aa, atol=1e-9)
    small = aa * 1e-7
    assert torch.allclose(matrix_to_axis_angle(axis_angle_to_matrix(small)), small, atol=1e-12)


def test_gradient_is_finite_at_the_identity_and_matches_finite_differences():
    x = torch.tensor([[1.0, 0, 0, 0, 1, 0]], dtype=torch.float64, requires_grad=True)
    a = rotation_6d_to_axis_angle(x)
    (g,) = torch.autograd.grad((a * torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)).sum(), x)
    assert torch.isfinite(g).all() and g.abs().sum() > 0
    x = torch.randn(6, 6, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda y: matrix_to_axis_angle(rotation_6d_to_matrix(y)), (x,))
    eye = torch.tensor([[1.0, 0, 0, 0, 1, 0]], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda y: matrix_to_axis_angle(rotation_6d_to_matrix(y)), (eye,))
