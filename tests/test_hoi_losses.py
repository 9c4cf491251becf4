"""Loss terms of the human–object app on hand-made configurations, against exact references."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import volsmpl
from volsmpl.apps.hoi.losses import (contact_terms, keypoint_term, penetration, scale_prior, silhouette_term,
                                     to_body_frame, to_camera)
from volsmpl.groundtruth import mesh_sdf
from volsmpl.rotations import axis_angle_to_matrix


@pytest.fixture(scope="module")
def posed(body):
    with torch.no_grad():
        out = body(betas=torch.zeros(1, 10), body_pose=torch.zeros(1, 69))
    return out


def _thigh_points(body, out, depth: float, n: int = 50):
    """Points `depth` metres inside (depth > 0) or outside (< 0) the left thigh, along the inward vertex normals."""
    import trimesh
    p = volsmpl.Partition(body)
    ids = np.nonzero(p.vertex_labels.numpy() == list(p.table.part_names).index("left_thigh"))[0][::5][:n]
    v = out.vertices[0].numpy()
    nrm = trimesh.Trimesh(v, np.asarray(body.faces), process=False).vertex_normals[ids]
    return torch.as_tensor(v[ids] - depth * nrm, dtype=torch.float32)[None]


def test_contact_is_zero_when_touching_and_grows_with_the_gap():
    g = torch.Generator().manual_seed(0)
    q = torch.rand(1, 40, 3, generator=g) * torch.tensor([0.2, 0.0, 0.2])  # a patch of the plane y = 0
    up = torch.tensor([0.0, 1.0, 0.0]).expand(1, 40, 3)
    mask = torch.ones(1, 40, dtype=torch.bool)
    c, n, _ = contact_terms(q.clone(), -up, q, up, mask)
    assert float(c) == pytest.approx(0.0, abs=1e-9) and float(n) == pytest.approx(0.0, abs=1e-7)  # touching, opposite
    c2, n2, facing = contact_terms(q + torch.tensor([0.0, 0.03, 0.0]), -up, q, up, mask)
    assert bool(facing.all()) and float(c2) == pytest.approx(0.03 ** 2, rel=1e-5)  # mean squared gap of 3 cm
    _, n3, _ = contact_terms(q + torch.tensor([0.0, 0.03, 0.0]), up, q, up, mask)
    assert float(n3) == pytest.approx(2.0, abs=1e-6)  # same direction: 1 + cos = 2


def test_contact_uses_only_region_points_facing_the_part():
    part = torch.tensor([[[0.0, 1.0, 0.0]]])
    n_part = torch.tensor([[[0.0, -1.0, 0.0]]])
    # two region points: one below the part facing up (towards it), one nearer but facing away
    q = torch.tensor([[[0.0, 0.9, 0.0], [0.0, 1.02, 0.0]]])
    nq = torch.tensor([[[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]])
    c, _, facing = contact_terms(part, n_part, q, nq, torch.ones(1, 2, dtype=torch.bool))
    assert facing.tolist() == [[True, False]] and float(c) == pytest.approx(0.01, rel=1e-5)


@pytest.mark.parametrize("kind", ["mesh", "volsmpl"])
def test_penetration_zero_apart_positive_inside_with_outward_gradient(body, posed, kind):
    vol = volsmpl.attach_volume(body, model=kind)
    eye, zero, one = torch.eye(3)[None], torch.zeros(1, 3), torch.ones(1)
    outside = _thigh_points(body, posed, -0.03)
    mask = torch.ones(outside.shape[:2], dtype=torch.bool)
    assert mask.shape[1] == 50
    assert float(penetration(vol, posed, outside, mask, one, eye, zero)) == 0.0
    inside = _thigh_points(body, posed, 0.015)
    t = torch.zeros(1, 3, requires_grad=True)
    pen = penetration(vol, posed, inside + t[:, None], mask, one, eye, zero)
    assert float(pen) > 0.005
    (g,) = torch.autograd.grad(pen.sum(), t)
    # the thigh's outward direction at these points: from the thigh's axis to the points
    centre = inside[0].mean(dim=0)
    outward = torch.nn.functional.normalize(inside[0] - centre, dim=-1).mean(dim=0)
    step = -g[0] / g[0].norm() * 0.01
    assert float(penetration(vol, posed, inside + step, mask, one, eye, zero)) < float(pen)
    assert g[0].norm() > 0 and torch.isfinite(outward).all()


def test_penetration_reads_the_body_frame_of_the_current_human_similarity(body, posed):
    """The object vertices enter the model in the frame the body was encoded in: the term at (s, R, t) equals the
    exact penetration depth into the body mesh placed by (s, R, t), divided by s (the paper's f(v / s_h))."""
    vol = volsmpl.attach_volume(body, model="mesh")
    s, R, t = torch.tensor([1.3]), axis_angle_to_matrix(torch.tensor([[0.3, -1.1, 0.4]])), torch.tensor([[0.2, -0.1, 2.5]])
    inside_body = _thigh_points(body, posed, 0.012)
    v_cam = to_camera(inside_body, s, R, t)
    assert torch.allclose(to_body_frame(v_cam, s, R, t), inside_body, atol=1e-6)
    mask = torch.ones(v_cam.shape[:2], dtype=torch.bool)
    ours = penetration(vol, posed, v_cam, mask, s, R, t)
    placed = to_camera(posed.vertices, s, R, t)[0]
    ref = mesh_sdf(placed.double(), body.faces, v_cam[0].double(), sign="winding")
    assert float(ours) == pytest.approx(float(torch.relu(-ref).mean() / 1.3), rel=1e-4)


def test_scale_prior_and_keypoints_by_hand():
    assert torch.allclose(scale_prior(torch.tensor([1.2, 0.7]), 1.0), torch.tensor([0.2, 0.3]))
    K = torch.tensor([[[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]])
    X = torch.tensor([[[0.1, -0.2, 2.0], [0.0, 0.0, 4.0]]])
    uv = torch.stack([500 * X[0, :, 0] / X[0, :, 2] + 320, 500 * X[0, :, 1] / X[0, :, 2] + 240], dim=-1)
    kp = torch.cat([uv + torch.tensor([[5.0, 0.0], [0.0, 0.0]]), torch.tensor([[1.0], [1.0]])], dim=-1)[None]
    assert float(keypoint_term(X, kp, K)) == pytest.approx((5.0 / 500) ** 2 / 2, rel=1e-5)
    kp[0, 0, 2] = 0.0  # an unseen joint does not count
    assert float(keypoint_term(X, kp, K)) == pytest.approx(0.0, abs=1e-10)


def test_silhouette_zero_on_the_mask_and_positive_off_it():
    K = torch.tensor([[[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]])
    X = torch.tensor([[[0.1, -0.2, 2.0], [0.0, 0.0, 4.0], [-0.1, 0.1, 3.0]]])
    uv = torch.stack([500 * X[0, :, 0] / X[0, :, 2] + 320, 500 * X[0, :, 1] / X[0, :, 2] + 240], dim=-1)[None]
    m3, m2 = torch.ones(1, 3, dtype=torch.bool), torch.ones(1, 3, dtype=torch.bool)
    assert float(silhouette_term(X, m3, uv, m2, K)) == pytest.approx(0.0, abs=1e-10)
    shifted = X + torch.tensor([0.05, 0.0, 0.0])
    assert float(silhouette_term(shifted, m3, uv, m2, K)) > 0
