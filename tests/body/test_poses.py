"""Pose sampler and named poses: inside the anatomical limits, reproducible, and the signs mean what they say."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from volsmpl.body.poses import NAMED_POSES, JOINT_LIMITS, named_pose, sample_euler, sample_poses, within_limits


def test_samples_within_limits_and_reproducible():
    p = sample_poses(200, seed=0)
    assert p.shape == (200, 69)
    assert within_limits(p).all()
    assert torch.equal(p, sample_poses(200, seed=0))
    assert not torch.equal(p, sample_poses(200, seed=1))
    assert within_limits(sample_poses(100, seed=2, mode="extreme")).all()


def test_realistic_is_concentrated_and_not_uniform():
    r, e = sample_euler(4000, seed=0), sample_euler(4000, seed=0, mode="extreme")
    assert np.abs(r).mean() < 0.8 * np.abs(e).mean()  # realistic poses sit nearer the neutral pose
    for axis in range(3):
        lo = np.array([JOINT_LIMITS[j][axis][0] for j in JOINT_LIMITS])
        assert (e[..., axis].min(0) < lo + 0.1 * (np.array([JOINT_LIMITS[j][axis][1] for j in JOINT_LIMITS]) - lo) + 1e-9).all()


def test_mixed_mode_draws_whole_bodies_from_either_sampler():
    n = 4000
    r, e = sample_euler(n, seed=5), sample_euler(n, seed=5, mode="extreme")
    assert np.array_equal(sample_euler(n, seed=5, mode="mixed", extreme_fraction=0.0), r)
    m = sample_euler(n, seed=5, mode="mixed", extreme_fraction=0.3)
    same = (m == r).reshape(n, -1).all(1)   # body kept its realistic angles
    changed = (m != r).reshape(n, -1).all(1)  # body replaced whole (fresh uniform angles differ everywhere)
    assert (same | changed).all()
    assert abs(changed.mean() - 0.3) < 3 * (0.3 * 0.7 / n) ** 0.5
    # the replaced bodies follow the extreme (uniform) law: same mean |angle| as mode 'extreme' within noise
    assert np.abs(np.abs(m[changed]).mean() - np.abs(e).mean()) < 0.02
    assert within_limits(sample_poses(50, seed=1, mode="mixed", extreme_fraction=1.0)).all()
    with pytest.raises(ValueError, match="mode must be one of"):
        sample_euler(2, mode="wild")
    with pytest.raises(ValueError, match="extreme_fraction"):
        sample_euler(2, mode="mixed", extreme_fraction=-0.1)


def test_out_of_limits_detected():
    p = torch.zeros(1, 69)
    p[0, 3 * 3] = -1.0  # left knee bent the wrong way (x < 0)
    assert not within_limits(p)[0]


def test_named_poses_valid():
    for name in NAMED_POSES:
        p = named_pose(name)
        assert p.shape == (1, 69) and torch.isfinite(p).all()
    with pytest.raises(ValueError, match="unknown pose"):
        named_pose("moonwalk")


def test_sign_conventions(body):
    """Hip flexion brings the knee forward (+Z), left shoulder z<0 lowers the left arm, knee flexion moves the ankle back."""
    rest = body()
    sit = body(body_pose=named_pose("sitting"))
    J = {n: i for i, n in enumerate(body.joint_names)}
    assert sit.joints[0, J["left_knee"], 2] - sit.joints[0, J["left_hip"], 2] > 0.25
    a = body(body_pose=named_pose("a_pose"))
    assert a.joints[0, J["left_wrist"], 1] < rest.joints[0, J["left_wrist"], 1] - 0.2
    assert a.joints[0, J["left_wrist"], 0] > 0.2  # still on the left side
    reach = body(body_pose=named_pose("reaching"))
    assert reach.joints[0, J["right_wrist"], 2] > rest.joints[0, J["right_wrist"], 2] + 0.3
    walk = body(body_pose=named_pose("walking"))
    assert walk.joints[0, J["right_ankle"], 2] < walk.joints[0, J["right_knee"], 2]
