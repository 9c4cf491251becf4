"""Repairs within the anatomy: the tuned repair moves only the joints of the limbs in contact, keeps every joint
within its limits, and reports a repair beyond them; checked with scipy's Euler angles and geodesic changes."""
import numpy as np
import pytest
import volsmpl
from scipy.spatial.transform import Rotation
from volsmpl.apps.selfpen import cases as C
from volsmpl.apps.selfpen.optimize import SelfPenConfig, repair_case
from volsmpl.body.poses import BODY_JOINTS, EULER_ORDER, JOINT_LIMITS

STILL = ("spine1", "spine2", "spine3", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
         "right_ankle", "left_foot", "right_foot")


def _changes_deg(p0, p1) -> dict:
    a = Rotation.from_rotvec(np.asarray(p0, np.float64).reshape(23, 3))
    b = Rotation.from_rotvec(np.asarray(p1, np.float64).reshape(23, 3))
    return dict(zip(BODY_JOINTS, np.degrees((a.inv() * b).magnitude())))


def _beyond(start, pose, tol_deg=0.5) -> list:
    """Angles of `pose` beyond JOINT_LIMITS widened to the start's, by scipy's Euler angles (turns taken nearest
    the range)."""
    out = []
    for j, name in enumerate(BODY_JOINTS):
        order = EULER_ORDER[name]
        idx = ["XYZ".index(a) for a in order]
        e0 = np.zeros(3)
        e1 = np.zeros(3)
        e0[idx] = Rotation.from_rotvec(np.asarray(start, float).reshape(23, 3)[j]).as_euler(order)
        e1[idx] = Rotation.from_rotvec(np.asarray(pose, float).reshape(23, 3)[j]).as_euler(order)
        for a in range(3):
            lo, hi = JOINT_LIMITS[name][a]
            lo, hi = min(lo, e0[a]), max(hi, e0[a])
            mid = (lo + hi) / 2
            x = mid + (e1[a] - mid + np.pi) % (2 * np.pi) - np.pi
            if x < lo - np.radians(tol_deg) or x > hi + np.radians(tol_deg):
                out.append((name, "xyz"[a]))
    return out


@pytest.mark.needs_checkpoint
def test_an_arm_cross_is_repaired_by_the_arms_alone_within_the_limits(body):
    vol = volsmpl.attach_volume(body)
    case = C.load_cases(names=["arms_crossed_deep"])[0]
    r = repair_case(body, vol, case, SelfPenConfig())
    assert r.collidable_after < r.collidable_before
    d = _changes_deg(case.body_pose, r.body_pose)
    assert max(d[j] for j in STILL) < 1e-3                          # spine and legs untouched
    assert max(d.values()) == pytest.approx(r.max_change_deg, abs=1e-3)
    assert _beyond(case.body_pose, r.body_pose) == [] and r.limits_after == []
    assert r.status in ("resolved", "stalled", "max_iters")


@pytest.mark.needs_checkpoint
def test_without_the_bounds_the_spine_folds_and_the_repair_is_flagged(body):
    """The same case with every joint free and no limits (the objective before the bounds): the spine turns by
    tens of degrees, and the record says so (largest change, still joints, limits)."""
    vol = volsmpl.attach_volume(body)
    case = C.load_cases(names=["arms_crossed_deep"])[0]
    r = repair_case(body, vol, case, SelfPenConfig(hold=False, limits=False))
    d = _changes_deg(case.body_pose, r.body_pose)
    spine = max(d[j] for j in ("spine1", "spine2", "spine3"))
    assert spine > 10.0
    assert r.still_change_deg == pytest.approx(max(d[j] for j in STILL + ("neck", "head")), abs=1e-3)
    beyond = _beyond(case.body_pose, r.body_pose)
    assert [tuple(v[:2]) for v in r.limits_after] == beyond
    assert (r.status == "outside_limits") == bool(beyond)
