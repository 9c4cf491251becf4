"""The procedural walking model of the motion app (volsmpl.apps.motion.walk), against independent references:
a fresh body forward pass of the returned parameters, hand-computed jerk and skate values, finite differences."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import volsmpl
from volsmpl.apps.motion import walk as W
from volsmpl.body.model import SMPL_JOINT_NAMES

L_HIP, R_HIP = SMPL_JOINT_NAMES.index("left_hip") - 1, SMPL_JOINT_NAMES.index("right_hip") - 1


@pytest.fixture(scope="module")
def model(body):
    return W.WalkModel(body)


@pytest.fixture(scope="module")
def straight(model):
    """A straight walk at 1.3 m/s, 12 primitives (98 frames), facing +Z."""
    return model(*W.straight_controls(1, 12, speed=1.3))


def _stances(contact: np.ndarray):
    d = np.diff(np.r_[0, contact.astype(int), 0])
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]))


# ------------------------------------------------------------------------------------------------ the cycle
def test_cycle_is_periodic_and_mirrored():
    p = torch.linspace(0, 1, 37, dtype=torch.float64)[:-1] + 0.013
    o0, b0 = W.walk_cycle(p)
    for k in (1.0, 3.0, -2.0):
        o1, b1 = W.walk_cycle(p + k)
        assert torch.allclose(b0, b1, atol=1e-6, rtol=0) and torch.allclose(o0, o1, atol=1e-6, rtol=0)
    # not trivially periodic: the pose changes over the cycle, and the right leg is the left one half a cycle later
    assert (b0 - b0[:1]).abs().max() > 0.3
    _, bh = W.walk_cycle(p + 0.5)
    left_x = b0.reshape(-1, 23, 3)[:, L_HIP, 0]
    right_x = bh.reshape(-1, 23, 3)[:, R_HIP, 0]
    assert torch.allclose(left_x, right_x, atol=1e-4)


def test_cycle_within_joint_limits(straight):
    from volsmpl.body.poses import within_limits
    assert bool(within_limits(straight.body_pose[0], tol=1e-3).all())


# ------------------------------------------------------------------------------------------------ feet
def test_params_reproduce_the_walk(body, straight):
    out = body(**straight.params())
    assert torch.allclose(out.joints.reshape(straight.joints.shape), straight.joints, atol=1e-5)


def test_stance_feet_on_floor_and_locked(body, straight):
    """Measured on a fresh forward pass of the returned parameters: every vertex skinned to a foot (ankle or toes),
    and the feet's joints. Bounds: stance foot within 1 cm of the floor, slide of the ball joint below 2 cm per
    stance, swing foot clear of the floor, nothing below it."""
    out = body(**straight.params())
    T = straight.joints.shape[1]
    V = out.vertices.reshape(T, -1, 3)
    J = out.joints.reshape(T, 24, 3)
    owner = body.lbs_weights.argmax(1)
    contacts = straight.contacts[0].numpy()
    phase = straight.phase[0].numpy()
    assert V[..., 1].min() > -2e-3                                     # nothing sinks into the floor
    for i, (ankle, ball) in enumerate([(7, 10), (8, 11)]):
        foot = (owner == ankle) | (owner == ball)
        height = V[:, foot, 1].amin(1)                                # the foot's lowest point, per frame
        c = contacts[:, i]
        assert c.any() and (~c).any()
        assert height[torch.as_tensor(c)].max() < 0.01
        swing_mid = ~c & (((phase - 0.5 * i) % 1.0 > 0.68) & ((phase - 0.5 * i) % 1.0 < 0.95))
        assert height[torch.as_tensor(swing_mid)].min() > 0.01            # the swinging foot clears the floor
        for a, b in _stances(c):
            xz = J[a:b, ball][:, [0, 2]]
            assert (xz - xz[0]).norm(dim=-1).max() < 0.02, f"foot {i} slides in stance frames {a}..{b}"
    assert W.foot_skate(out.joints.reshape(1, T, 24, 3), straight.contacts).item() < 0.2   # cm per frame


def test_contact_labels_alternate(straight):
    c = straight.contacts[0]
    assert c.any(-1).all()                                # always at least one foot down (walking, not running)
    assert (c.all(-1)).float().mean() < 0.35              # double support is a minority of the frames


# ------------------------------------------------------------------------------------------------ the path
@pytest.mark.parametrize("speed", [1.0, 1.3])
def test_straight_distance_and_heading(model, speed):
    P, heading = 12, 0.7
    w = model(*W.straight_controls(1, P, speed=speed), heading0=torch.tensor([heading]),
              start=torch.tensor([[0.5, -1.0]]))
    T = w.joints.shape[1]
    pel = w.joints[0, :, 0]
    assert torch.allclose(pel[0, [0, 2]], torch.tensor([0.5, -1.0]), atol=1e-5)
    d = pel[-1] - pel[0]
    expected = (T - 1) * speed / 30.0
    assert abs(d[[0, 2]].norm().item() / expected - 1.0) < 0.05
    assert abs(math.atan2(d[0].item(), d[2].item()) - heading) < math.radians(3)
    # stride: ~0.7 m per step at 1.2-1.4 m/s: the phase (cycles = 2 steps) advances by distance / stride
    steps = 2 * (w.phase[0, -1] - w.phase[0, 0]).item()
    assert 0.6 < d[[0, 2]].norm().item() / steps < 0.8


def test_heading_follows_a_turning_path(model):
    P, rate = 12, 0.1
    w = model(torch.full((1, P), rate), torch.full((1, P), 1.3))
    T = w.joints.shape[1]
    assert abs(w.heading[0, -1].item() - (T - 1) * rate / 8) < 1e-5
    pel = w.joints[0, :, 0]
    for t in range(16, T - 16, 16):              # travel direction over one cycle (~32 frames) around frame t
        d = pel[t + 16] - pel[t - 16]
        assert abs(math.atan2(d[0].item(), d[2].item()) - w.heading[0, t].item()) < math.radians(6)


def test_gradients_match_finite_differences():
    """d(last-frame pelvis)/d(path controls) by autograd vs central differences, in float64 (directional)."""
    body64 = volsmpl.create_body().double()
    m = W.WalkModel(body64)
    g = torch.Generator().manual_seed(0)
    h0 = torch.randn(1, 2, generator=g, dtype=torch.float64) * 0.2
    s0 = 1.2 + 0.1 * torch.randn(1, 2, generator=g, dtype=torch.float64)
    dh = torch.randn(1, 2, generator=g, dtype=torch.float64)
    ds = torch.randn(1, 2, generator=g, dtype=torch.float64)
    h, s = h0.clone().requires_grad_(True), s0.clone().requires_grad_(True)
    pel = m(h, s).joints[0, -1, 0]
    eps = 1e-6
    for k in range(3):
        gh, gs = torch.autograd.grad(pel[k], (h, s), retain_graph=True)
        fd_h = (m(h0 + eps * dh, s0).joints[0, -1, 0, k] - m(h0 - eps * dh, s0).joints[0, -1, 0, k]) / (2 * eps)
        fd_s = (m(h0, s0 + eps * ds).joints[0, -1, 0, k] - m(h0, s0 - eps * ds).joints[0, -1, 0, k]) / (2 * eps)
        assert abs((gh * dh).sum().item() - fd_h.item()) < 1e-6 + 1e-5 * abs(fd_h.item())
        assert abs((gs * ds).sum().item() - fd_s.item()) < 1e-6 + 1e-5 * abs(fd_s.item())
    assert gs.abs().sum() > 0.1                  # the speed moves the end point (z: forward)


def test_residuals_are_differentiable_and_prior(model):
    h, s = W.straight_controls(1, 1)
    r = torch.zeros(1, 10, 69, requires_grad=True)
    w = model(h, s, r)
    (w.joints[0, -1, 20] ** 2).sum().backward()   # a wrist
    assert r.grad.abs().sum() > 0
    assert torch.equal(W.pose_prior(torch.zeros(2, 10, 69)), torch.zeros(2))
    x = torch.zeros(1, 3, 69)
    x[0, 1, 0] = 0.1                              # hand value: mean sq. 0.01/3, diffs 0.01 + 0.01 over 2 pairs
    assert torch.allclose(W.pose_prior(x, smooth_weight=10.0), torch.tensor([0.01 / 3 + 10 * 0.02 / 2]))


# ------------------------------------------------------------------------------------------------ helpers
def test_jerk_hand_values():
    T = 8
    t = torch.arange(T, dtype=torch.float64)
    joints = torch.zeros(2, T, 3, 3, dtype=torch.float64)
    joints[0, :, 1, 0] = 0.5 * t ** 3            # third difference 6 * 0.5 = 3 at every frame
    joints[1, 4, 2, 2] = 0.2                     # a spike: third differences -0.2, 0.6, -0.6, 0.2 -> max 0.6
    assert torch.allclose(W.jerk(joints, weight=1.0), torch.tensor([3.0, 0.6], dtype=torch.float64))
    assert torch.allclose(W.jerk(joints), torch.tensor([0.3, 0.06], dtype=torch.float64))   # the objective's 0.1
    joints[0, :, 0, 1] = 0.25 * t ** 2 + 2.0 * t                # quadratic: no jerk, must not change the max
    assert torch.allclose(W.jerk(joints, weight=1.0)[0], torch.tensor(3.0, dtype=torch.float64))


def test_foot_skate_hand_values():
    T = 5
    joints = torch.zeros(1, T, 24, 3)
    joints[0, :, 10, 0] = torch.tensor([0.0, 0.01, 0.02, 0.02, 0.05])   # left ball: slides 1 cm, 1 cm, 0, 3 cm
    joints[0, :, 10, 1] = torch.tensor([0.0, 0.05, 0.0, 0.05, 0.0])     # vertical motion does not count
    joints[0, :, 11, 2] = torch.tensor([0.0, 0.0, 0.0, 0.04, 0.04])     # right ball: 4 cm between frames 2 and 3
    contacts = torch.tensor([[[1, 1], [1, 1], [1, 0], [0, 0], [0, 1]]], dtype=torch.bool)
    # pairs in contact at both ends: left (0,1): 1 cm, (1,2): 1 cm; right (0,1): 0 cm -> 2 cm over 3 pairs
    assert torch.allclose(W.foot_skate(joints, contacts), torch.tensor([2.0 / 3.0]), atol=1e-5)
    assert W.foot_skate(joints, torch.zeros(1, T, 2, dtype=torch.bool)).item() == 0.0


# ------------------------------------------------------------------------------------------------ errors, devices
def test_bad_input_messages(model):
    h, s = W.straight_controls(1, 2)
    with pytest.raises(ValueError, match="frames must be >= 2"):
        model(h, s, frames=1)
    with pytest.raises(ValueError, match="needs .* primitives"):
        model(h, s, frames=40)
    with pytest.raises(ValueError, match="NaN or Inf"):
        model(h, s * float("nan"))
    with pytest.raises(ValueError, match="speed has shape"):
        model(h, s[:, :1])
    with pytest.raises(ValueError, match="pose_residual has shape"):
        model(h, s, torch.zeros(1, 5, 69))
    with pytest.raises(ValueError, match=">= 0"):
        model(h, -s)
    with pytest.raises(ValueError, match="at least 4 frames"):
        W.jerk(torch.zeros(1, 3, 24, 3))
    with pytest.raises(ValueError, match="contacts must be"):
        W.foot_skate(torch.zeros(1, 5, 24, 3), torch.zeros(1, 5, 3))
    with pytest.raises(ValueError, match="frames >= 2"):
        W.num_primitives(1)
    assert W.num_frames(10) == 82 and W.num_primitives(82) == 10 and W.num_primitives(83) == 11


def test_frames_and_batch(model):
    h = torch.tensor([[0.0, 0.3], [0.2, -0.1]])
    s = torch.tensor([[1.3, 1.2], [1.0, 1.4]])
    w = model(h, s, frames=13)
    assert w.body_pose.shape == (2, 13, 69) and w.transl.shape == (2, 13, 3) and w.contacts.shape == (2, 13, 2)
    w1 = model(h[1:], s[1:], frames=13)           # sequences are independent
    assert torch.allclose(w.joints[1], w1.joints[0], atol=1e-5)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu(model, straight):
    mc = W.WalkModel(volsmpl.create_body().cuda())
    wc = mc(*W.straight_controls(1, 12, speed=1.3, device="cuda"))
    assert torch.allclose(wc.joints.cpu(), straight.joints, atol=1e-3)
