"""volsmpl.body.limits: Euler angles against scipy, the hard bound's projection, the wrap at half a turn, the joints
a contact turns (hand-listed)."""
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation
from volsmpl.body.limits import (
    LIMITS,
    clamp_to_limits,
    contact_joints,
    euler_angles,
    largest_change_deg,
    limit_excess,
    limits_around,
    violations,
)
from volsmpl.body.poses import BODY_JOINTS, EULER_ORDER


def _scipy_euler(pose: np.ndarray) -> np.ndarray:
    """(69,) -> (23, 3) (x, y, z) by scipy's intrinsic Euler angles in each joint's order."""
    out = np.zeros((23, 3))
    for j, name in enumerate(BODY_JOINTS):
        order = EULER_ORDER[name]
        out[j, ["XYZ".index(a) for a in order]] = Rotation.from_rotvec(pose.reshape(23, 3)[j]).as_euler(order)
    return out


def test_euler_angles_match_scipy():
    pose = np.random.default_rng(0).normal(scale=0.8, size=(3, 69))
    e = euler_angles(torch.tensor(pose)).numpy()
    for b in range(3):
        assert np.allclose(e[b], _scipy_euler(pose[b]), atol=1e-7)


def test_clamp_turns_only_the_joints_beyond_their_limits_to_the_clamped_angles():
    pose = torch.tensor(np.random.default_rng(1).normal(scale=1.0, size=(4, 69)))
    lo, hi = LIMITS[..., 0], LIMITS[..., 1]
    out = clamp_to_limits(pose, lo, hi)
    for b in range(4):
        e0 = _scipy_euler(pose[b].numpy())
        e1 = _scipy_euler(out[b].numpy())
        L, H = lo.numpy(), hi.numpy()
        circ = lambda a: np.abs((a + np.pi) % (2 * np.pi) - np.pi)
        within = (e0 >= L) & (e0 <= H)
        # outside: the bound nearer on the circle (an angle of -3.1 rad is nearer 0.6 than -0.3 the other way round)
        want = np.where(within, e0, np.where(circ(e0 - L) <= circ(e0 - H), L, H))
        inside = within.all(1)
        assert np.allclose(e1[~inside], want[~inside], atol=1e-6)
        assert torch.equal(out[b].reshape(23, 3)[torch.tensor(inside)], pose[b].reshape(23, 3)[torch.tensor(inside)])
    assert float(limit_excess(out, lo, hi).max()) < 1e-9


def test_an_angle_past_half_a_turn_is_the_same_turn():
    """A shoulder whose start lies at x = -179 deg (widened limit) turned to x = -181 deg: scipy reads it as +179,
    1 deg beyond the widened limit, not 122 deg beyond the upper one (57)."""
    j = BODY_JOINTS.index("left_shoulder")

    def pose_x(deg):
        p = np.zeros(69)
        p[3 * j:3 * j + 3] = Rotation.from_euler("XYZ", [np.radians(deg), 0, 0]).as_rotvec()
        return torch.tensor(p)

    lo, hi = limits_around(pose_x(-179.0))
    assert np.degrees(float(lo[j, 0])) == pytest.approx(-179.0)
    x = limit_excess(pose_x(-181.0)[None], lo, hi)[0, j, 0]
    assert np.degrees(float(x)) == pytest.approx(2.0, abs=1e-6)
    back = clamp_to_limits(pose_x(-181.0)[None], lo, hi)[0]
    assert largest_change_deg(pose_x(-179.0), back)[0] == pytest.approx(0.0, abs=1e-5)
    assert violations(pose_x(-181.0), lo, hi)[0][:2] == ("left_shoulder", "x")
    assert violations(pose_x(-179.0), lo, hi) == []


def test_contact_joints_of_an_arm_against_the_chest_and_a_hand_against_a_thigh():
    from volsmpl.body import Partition, create_body

    body = create_body()
    table = Partition(body).table
    parts = list(table.part_names)
    parents = body.parents.numpy()

    def moved(a, b):
        m = contact_joints([(parts.index(a), parts.index(b))], table, parents)
        return {BODY_JOINTS[j] for j in np.flatnonzero(m)}

    assert moved("left_forearm", "chest") == {"left_collar", "left_shoulder", "left_elbow"}
    assert moved("right_hand", "left_thigh") == {"right_collar", "right_shoulder", "right_elbow", "right_wrist",
                                                 "right_hand", "left_hip"}
    assert moved("head", "left_forearm") == {"neck", "head", "left_collar", "left_shoulder", "left_elbow"}
    assert moved("pelvis", "chest") == {"spine1", "spine2", "spine3"}   # two trunk parts: the trunk moves
