import math

import pytest
import torch

from volsmpl.nn.analytic import box_excess, box_sdf, outside_distance, transform_points, union_box_sdf


def _surface_samples(bmin, bmax, n=60):
    """Dense grid on the 6 faces of an axis-aligned box, (S, 3) float64."""
    t = torch.linspace(0, 1, n, dtype=torch.float64)
    u, v = torch.meshgrid(t, t, indexing="ij")
    u, v = u.reshape(-1), v.reshape(-1)
    pts = []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        for side in (bmin[axis], bmax[axis]):
            p = torch.empty(u.shape[0], 3, dtype=torch.float64)
            p[:, axis] = side
            p[:, a] = bmin[a] + u * (bmax[a] - bmin[a])
            p[:, b] = bmin[b] + v * (bmax[b] - bmin[b])
            pts.append(p)
    return torch.cat(pts)


def test_box_sdf_matches_brute_force():
    g = torch.Generator().manual_seed(0)
    bmin = torch.tensor([-0.3, -0.1, 0.2], dtype=torch.float64)
    bmax = torch.tensor([0.5, 0.4, 0.6], dtype=torch.float64)
    x = torch.rand(400, 3, generator=g, dtype=torch.float64) * 2.0 - 0.8
    d = box_sdf(x, bmin, bmax)
    surf = _surface_samples(bmin, bmax)
    dist = torch.cdist(x, surf).amin(1)
    inside = ((x > bmin) & (x < bmax)).all(-1)
    assert inside.any() and (~inside).any()
    ref = torch.where(inside, -dist, dist)
    # grid spacing 0.8/59 -> sampled distance overestimates by at most half a cell diagonal
    assert (d - ref).abs().max() < 0.8 / 59 * math.sqrt(2) / 2 + 1e-9
    assert (d[inside] < 0).all() and (d[~inside] > 0).all()


def test_box_sdf_closed_form():
    bmin = torch.tensor([-1.0, -2.0, -3.0])
    bmax = torch.tensor([1.0, 2.0, 3.0])
    x = torch.tensor([[0.0, 0.0, 0.0], [0.9, 0.0, 0.0], [3.0, 0.0, 0.0], [2.0, 3.0, 0.0],
                      [2.0, 3.0, 5.0], [1.0, 0.0, 0.0], [0.0, -1.5, 2.9]])
    expected = torch.tensor([-1.0, -0.1, 2.0, math.sqrt(2), math.sqrt(1 + 1 + 4), 0.0, -0.1])
    torch.testing.assert_close(box_sdf(x, bmin, bmax), expected)


def test_box_sdf_gradient_finite():
    x = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.2, 0.0], [3.0, 0.0, 0.0]], requires_grad=True)
    d = box_sdf(x, -torch.ones(3), torch.ones(3))
    (g,) = torch.autograd.grad(d.sum(), x)
    assert torch.isfinite(g).all()
    torch.testing.assert_close(g[2], torch.tensor([1.0, 0.0, 0.0]))


def _random_rigid(B, K, g):
    q = torch.randn(B, K, 4, generator=g, dtype=torch.float64)
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    R = torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                     2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                     2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1).view(B, K, 3, 3)
    T = torch.eye(4, dtype=torch.float64).repeat(B, K, 1, 1)
    T[..., :3, :3] = R
    T[..., :3, 3] = torch.randn(B, K, 3, generator=g, dtype=torch.float64) * 0.3
    return T


def test_union_box_sdf_against_per_box_loop():
    g = torch.Generator().manual_seed(1)
    B, K, N = 2, 4, 300
    G_inv = _random_rigid(B, K, g)
    box_min = -torch.rand(B, K, 3, generator=g, dtype=torch.float64) * 0.3 - 0.05
    box_max = torch.rand(B, K, 3, generator=g, dtype=torch.float64) * 0.3 + 0.05
    x = torch.randn(B, N, 3, generator=g, dtype=torch.float64) * 0.5
    sdf, inside = union_box_sdf(x, G_inv, box_min, box_max)
    assert sdf.shape == (B, N) and inside.shape == (B, K, N) and inside.dtype == torch.bool
    ref = torch.full((B, N), float("inf"), dtype=torch.float64)
    for b in range(B):
        for k in range(K):
            xl = x[b] @ G_inv[b, k, :3, :3].T + G_inv[b, k, :3, 3]
            dk = box_sdf(xl, box_min[b, k], box_max[b, k])
            ref[b] = torch.minimum(ref[b], dk)
            assert torch.equal(inside[b, k], ((xl >= box_min[b, k]) & (xl <= box_max[b, k])).all(-1))
    torch.testing.assert_close(sdf, ref)
    assert inside.any() and (~inside.any(1)).any()
    # outside all boxes the union distance is the exact distance to the union of the boxes
    out = ~inside.any(1)
    assert (sdf[out] > 0).all() and (sdf[~out] <= 0).all()


def _outside_reference(u, half, absent=None):
    """float64 min over boxes of the exact box distance (box_sdf of each box, one at a time)."""
    ref = torch.full(u.shape[:1], float("inf"), dtype=torch.float64)
    for k in range(u.shape[1]):
        dk = box_sdf(u[:, k].double(), -half[:, k].double(), half[:, k].double())
        if absent is not None:
            dk = torch.where(absent[:, k], float("inf"), dk)
        ref = torch.minimum(ref, dk)
    return ref


def test_outside_distance_matches_per_box_minimum():
    g = torch.Generator().manual_seed(3)
    F, K = 2000, 6
    half = torch.rand(F, K, 3, generator=g) * 0.2 + 0.02
    u = torch.randn(F, K, 3, generator=g) * 0.4
    q, q_max = box_excess(u, half)
    assert torch.equal(q_max <= 0, (u.abs() <= half).all(-1))      # the membership test it gives
    free = ~(q_max <= 0).any(-1)
    assert free.sum() > 500
    u, half, q, q_max = u[free], half[free], q[free], q_max[free]
    d = outside_distance(q, q_max)
    torch.testing.assert_close(d.double(), _outside_reference(u, half), rtol=1e-6, atol=0)
    # absent parts do not count; all absent is +inf
    absent = torch.rand(q_max.shape, generator=g) < 0.5
    absent[0] = True
    da = outside_distance(q, q_max, absent)
    ref = _outside_reference(u, half, absent)
    assert math.isinf(float(da[0])) and math.isinf(float(ref[0]))
    torch.testing.assert_close(da[1:].double(), ref[1:], rtol=1e-6, atol=0)


def test_outside_distance_far_points_and_gradient():
    half = torch.tensor([[[0.1, 0.2, 0.3], [0.5, 0.5, 0.5]]])         # two boxes, centred (u relative to each)
    for s in (0.7, 1.0, 1e19, 1e30, 1e37):  # outside both boxes
        u = torch.tensor([[[s, 0.0, 0.0], [s, 2.0 * s, 0.0]]], requires_grad=True)
        d = outside_distance(*box_excess(u, half))
        ref = _outside_reference(u.detach(), half.expand(1, 2, 3))
        assert torch.isfinite(d).all() and torch.allclose(d.double(), ref, rtol=1e-6)
        (gu,) = torch.autograd.grad(d.sum(), u)
        qp = (u.detach().double().abs() - half.double()).clamp(min=0)[0, 0]  # box 0 is the nearest: unit direction
        assert torch.allclose(gu[0, 0].double(), qp / (qp / s).norm() / s, atol=1e-6)   # away from it and gu[0, 1].abs().max() == 0
    with pytest.raises(ValueError, match="outside_distance expects"):
        outside_distance(torch.zeros(4, 3), torch.zeros(4))


def test_outside_distance_gradient_stays_finite_at_rounding_edges():
    # a point 1e-39 m beyond box 0's face: box 1's ratio 1 / 1e-39 overflows float32 to inf, and its zero gradient
    # became NaN (0 x inf)
    q = torch.tensor([[[1e-39, -0.05, -0.05], [1.0, 1.0, 1.0]],
                      [[0.3, -0.1, 0.4], [0.2, 0.2, -0.5]]], requires_grad=True)
    q_max = q.detach().amax(-1)
    d = outside_distance(q, q_max)
    (g,) = torch.autograd.grad(d.sum(), q)
    assert torch.isfinite(g).all()
    ref = torch.stack([qk.double().clamp(min=0).norm(dim=-1).min() for qk in q.detach()])
    torch.testing.assert_close(d.double(), ref, rtol=1e-6, atol=1e-44)
    torch.testing.assert_close(g[0], torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))     # away from the near face
    torch.testing.assert_close(g[1, 1], torch.tensor([0.2, 0.2, 0.0]) / 0.2 / 2 ** 0.5)    # box 1 is nearer there
    # a point its caller found in no box but whose q, computed in another rounding, puts it on box 0: distance 0
    # (not a norm at 0, whose backward gives NaN), with the other rows' values and gradients unchanged
    q2 = torch.tensor([[[-1e-8, -0.05, 0.0], [0.5, 0.5, 0.5]], [[0.3, -0.1, 0.4], [0.2, 0.2, -0.5]]],
                      requires_grad=True)
    d2 = outside_distance(q2, q2.detach().amax(-1))
    (g2,) = torch.autograd.grad(d2.sum(), q2)
    assert float(d2[0].detach()) == 0.0 and torch.isfinite(g2).all() and float(g2[0].abs().max()) == 0.0
    torch.testing.assert_close(d2[1], d[1])
    torch.testing.assert_close(g2[1], g[1])


def test_rigid_transform_preserves_distance():
    g = torch.Generator().manual_seed(2)
    T = _random_rigid(1, 1, g)
    x = torch.randn(1, 50, 3, generator=g, dtype=torch.float64)
    y = transform_points(T, x)[:, 0]
    torch.testing.assert_close(torch.cdist(x, x), torch.cdist(y, y))


def test_union_box_sdf_shape_errors():
    with pytest.raises(ValueError, match="x must be"):
        union_box_sdf(torch.zeros(5, 3), torch.eye(4).expand(1, 2, 4, 4), torch.zeros(1, 2, 3), torch.ones(1, 2, 3))
    with pytest.raises(ValueError, match="box_min/box_max"):
        union_box_sdf(torch.zeros(1, 5, 3), torch.eye(4).expand(1, 2, 4, 4), torch.zeros(1, 3), torch.ones(1, 3))
