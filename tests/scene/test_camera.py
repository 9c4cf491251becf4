"""Pinhole cameras: intrinsics, look-at, projection against a hand-written pinhole model, back-projection,
visibility, batching and gradients."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from volsmpl.scene.camera import (camera_center, intrinsics_from_fov, look_at, make_camera, orbit_eye, project,
                                  unproject, world_to_camera)


def _manual(points: np.ndarray, eye, target, H, W, fov):
    """Independent numpy pinhole: OpenCV axes from eye/target/up, u = fx x / z + cx."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0, 1, 0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pc = (points - eye) @ np.stack([x, y, z]).T
    f = (W / 2) / math.tan(math.radians(fov) / 2)
    return np.stack([f * pc[:, 0] / pc[:, 2] + (W - 1) / 2, f * pc[:, 1] / pc[:, 2] + (H - 1) / 2], 1), pc[:, 2]


def test_intrinsics():
    K = intrinsics_from_fov((480, 640), 90.0)
    assert K.shape == (1, 3, 3)
    assert K[0, 0, 0].item() == pytest.approx(320.0) and K[0, 1, 1].item() == pytest.approx(320.0)
    assert K[0, 0, 2].item() == 319.5 and K[0, 1, 2].item() == 239.5
    Kv = intrinsics_from_fov((480, 640), torch.tensor([60.0, 90.0]), axis="vertical")
    assert Kv.shape == (2, 3, 3) and Kv[0, 0, 0].item() == pytest.approx(240 / math.tan(math.radians(30)), rel=1e-6)
    with pytest.raises(ValueError, match="fov_deg"):
        intrinsics_from_fov((480, 640), 180.0)


def test_look_at_frame():
    E = look_at([1.0, 1.6, 2.0], [0.0, 1.0, 0.0])[0].double()
    R = E[:3, :3]
    assert torch.allclose(R @ R.T, torch.eye(3, dtype=R.dtype), atol=1e-6)
    assert torch.det(R).item() == pytest.approx(1, abs=1e-6)
    cam = make_camera([1.0, 1.6, 2.0], [0.0, 1.0, 0.0])
    assert torch.allclose(camera_center(cam)[0], torch.tensor([1.0, 1.6, 2.0]), atol=1e-6)
    # camera y is down: a point above the target appears higher (smaller v); the target is at the centre
    uv, d, vis = project(torch.tensor([[[0.0, 1.0, 0.0], [0.0, 1.5, 0.0]]]), cam)
    assert torch.allclose(uv[0, 0], torch.tensor([319.5, 239.5]), atol=1e-3)
    assert uv[0, 1, 1] < uv[0, 0, 1] and vis.all() and (d > 0).all()
    with pytest.raises(ValueError, match="parallel"):
        look_at([0, 2, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="coincide"):
        look_at([0, 1, 0], [0, 1, 0])


def test_project_matches_manual_and_unproject_inverts():
    rng = np.random.default_rng(0)
    eye, target, H, W, fov = [0.5, 1.7, 2.2], [0.0, 0.9, 0.0], 480, 640, 65.0
    pts = rng.uniform([-1, 0, -1], [1, 2, 1], (500, 3))
    cam = make_camera(torch.tensor(eye, dtype=torch.float64), torch.tensor(target, dtype=torch.float64), (H, W), fov)
    uv, depth, vis = project(torch.as_tensor(pts)[None], cam)
    ref_uv, ref_z = _manual(pts, eye, target, H, W, fov)
    assert np.abs(uv[0].numpy() - ref_uv).max() < 1e-8 and np.abs(depth[0].numpy() - ref_z).max() < 1e-12
    ref_vis = ((ref_z > 1e-3) & (ref_uv[:, 0] >= -0.5) & (ref_uv[:, 0] <= W - 0.5)
               & (ref_uv[:, 1] >= -0.5) & (ref_uv[:, 1] <= H - 0.5))
    assert np.array_equal(vis[0].numpy(), ref_vis)
    back = unproject(uv, depth, cam)
    assert torch.allclose(back[0], torch.as_tensor(pts), atol=1e-9)
    assert torch.allclose(world_to_camera(back, cam)[..., 2], depth)


def test_visibility_behind_and_outside():
    cam = make_camera([0.0, 1.0, 2.0], [0.0, 1.0, 0.0], (100, 200), 60.0)
    pts = torch.tensor([[[0.0, 1.0, 3.0],   # behind the camera
                         [0.0, 1.0, 2.0],   # at the camera
                         [50.0, 1.0, 0.0],  # far to the side
                         [0.1, 1.0, 0.0]]])  # in view
    _, depth, vis = project(pts, cam)
    assert vis[0].tolist() == [False, False, False, True] and depth[0, 0] < 0


def test_batched_and_differentiable():
    eyes = torch.tensor([[0.0, 1.6, 2.0], [2.0, 1.5, 0.0]], dtype=torch.float64, requires_grad=True)
    targets = torch.tensor([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64)
    pts = torch.tensor([[[0.1, 1.1, 0.2], [-0.2, 0.8, 0.1]]] * 2, dtype=torch.float64, requires_grad=True)
    cam = make_camera(eyes, targets, (240, 320), 60.0)
    uv, depth, vis = project(pts, cam)
    assert uv.shape == (2, 2, 2) and vis.all()
    for b in range(2):
        ref, _ = _manual(pts[b].detach().numpy(), eyes[b].detach().numpy(), targets[b].numpy(), 240, 320, 60.0)
        assert np.abs(uv[b].detach().numpy() - ref).max() < 1e-8
    torch.autograd.gradcheck(lambda p: project(p, make_camera(eyes.detach(), targets, (240, 320), 60.0))[0], (pts,))
    torch.autograd.gradcheck(lambda e: project(pts.detach(), make_camera(e, targets, (240, 320), 60.0))[0], (eyes,))


def test_orbit_eye():
    e = orbit_eye([1.0, 0.9, -1.0], 2.0, 90.0, 1.6)
    assert torch.allclose(e, torch.tensor([3.0, 1.6, -1.0]), atol=1e-6)


def test_batch_broadcast_and_errors():
    two = make_camera(torch.tensor([[0.0, 1.6, 2.0], [1.0, 1.5, 2.0]]), torch.tensor([[0.0, 1.0, 0.0]] * 2))
    one = make_camera([0.0, 1.6, 2.0], [0.0, 1.0, 0.0])
    p1 = torch.rand(1, 4, 3)
    uv, d, _ = project(p1, two)  # one point set seen by two cameras
    assert uv.shape == (2, 4, 2) and torch.allclose(unproject(uv, d, two), p1.expand(2, 4, 3), atol=1e-5)
    assert torch.allclose(uv[0], project(p1, one)[0][0])
    p3 = torch.rand(3, 4, 3)
    uv, d, _ = project(p3, one)  # one camera, three point sets
    assert uv.shape == (3, 4, 2) and torch.allclose(unproject(uv, d, one), p3, atol=1e-5)
    with pytest.raises(ValueError, match="batch 3 but the camera has 2"):
        project(p3, two)
    with pytest.raises(ValueError, match=r"\(B, N, 3\)"):
        project(torch.rand(4, 3), one)


def test_one_eye_for_several_targets_and_mismatched_counts():
    """look_at / make_camera take eye and target as (3,) or (B, 3): one eye with two targets stopped in a torch
    broadcasting error ('The expanded size of the tensor (1) must match ...'); now two cameras, each the one
    made alone, and 2 eyes with 3 targets are refused in one line."""
    eye, targets = [0.5, 1.6, 2.0], [[0.0, 1.0, 0.0], [1.0, 0.8, -0.5]]
    E = look_at(eye, targets)
    assert E.shape == (2, 4, 4)
    for b in range(2):
        assert torch.allclose(E[b], look_at(eye, targets[b])[0])
    cam = make_camera(eye, targets, (480, 640), 60.0)
    pts = np.random.default_rng(1).uniform([-1, 0, -1], [1, 2, 1], (20, 3))
    uv, depth, _ = project(torch.as_tensor(pts, dtype=torch.float32)[None], cam)
    for b in range(2):
        ref_uv, ref_d = _manual(pts, eye, targets[b], 480, 640, 60.0)
        assert np.allclose(uv[b].numpy(), ref_uv, atol=1e-2) and np.allclose(depth[b].numpy(), ref_d, atol=1e-5)
    with pytest.raises(ValueError, match="eye has 2 positions and target 3"):
        look_at([eye, eye], targets + [[0.0, 0.5, 0.0]])
