"""The motion app's tuning split (volsmpl.apps.motion.tuning, cli.tuned_rows) on hand-made records."""
from __future__ import annotations

import math

import pytest

from volsmpl.apps.motion import summary as C
from volsmpl.apps.motion import tuning as T
from volsmpl.report.sections import tuning_note


def _rec(scene, goal, coll, mem=100.0):
    return {"scene": scene, "metrics": {"goal_dist_m": goal, "collision_cm": coll, "optim_peak_mem_mb": mem,
                                        "collision_obstacles_cm": coll, "collision_frames_pct": 10.0,
                                        "foot_skate_cm": 0.1, "max_depth_cm": 1.0, "jerk_max": 1.0, "path_m": 3.0,
                                        "optim_s": 1.0, "ms_per_iter": 10.0}}


def test_split_every_third_room_tunes():
    names = [f"room{i}" for i in range(15)]
    tune, test = T.split_scenes(names)
    assert tune == ["room0", "room3", "room6", "room9", "room12"]
    assert sorted(tune + test, key=names.index) == names and not set(tune) & set(test)
    assert T.split_scenes(["a", "b"]) == (["a"], ["b"])
    with pytest.raises(ValueError, match="at least 2 rooms"):
        T.split_scenes(["a"])


def test_criterion_sums_goal_and_depth_in_metres():
    recs = [_rec("a", 0.02, 0.3), _rec("b", 0.04, 0.1)]
    assert T.criterion(recs) == pytest.approx(0.03 + 0.2 / 100)
    assert T.criterion([_rec("a", float("nan"), 0.3)]) == math.inf
    assert T.criterion([]) == math.inf


def test_choice_sees_only_tuning_rooms():
    # on the tuning room w = 1 is best; on the test room w = 0.01 would be: the choice must be 1
    records = {("coap", 0.01): [_rec("room0", 0.50, 0.1), _rec("room1", 0.00, 0.0)],
               ("coap", 1.0): [_rec("room0", 0.01, 0.2), _rec("room1", 0.30, 2.0)],
               ("volsmpl", 1.0): [_rec("room0", 0.02, 0.1), _rec("room1", 0.03, 0.2)]}
    choice = T.choose_weights(records, ["room0"])
    assert choice["coap"]["w"] == 1.0 and choice["volsmpl"]["w"] == 1.0
    assert choice["coap"]["scores"][0.01] == pytest.approx(0.50 + 0.001)
    # ties go to the smaller weight
    tie = {("coap", 0.1): [_rec("room0", 0.1, 0.0)], ("coap", 0.01): [_rec("room0", 0.1, 0.0)]}
    assert T.choose_weights(tie, ["room0"])["coap"]["w"] == 0.01


def test_test_rows_average_the_test_rooms_at_the_chosen_weight():
    records = {("coap", 0.01): [_rec("room0", 0.50, 0.1), _rec("room1", 0.00, 0.0), _rec("room2", 0.0, 0.0)],
               ("coap", 1.0): [_rec("room0", 0.01, 0.2), _rec("room1", 0.30, 2.0, mem=300.0),
                               _rec("room2", 0.10, 1.0, mem=200.0)],
               ("volsmpl", 1.0): [_rec("room0", 0.02, 0.1), _rec("room1", 0.03, 0.2), _rec("room2", 0.05, 0.4)]}
    cost = {"mem_per_frame_fwd_mb": 1.0, "mem_per_frame_fwdbwd_mb": 2.0, "ms_per_frame_fwd": 3.0,
            "ms_per_frame_fwdbwd": 4.0, "max_frames_in_budget": 10, "memory_kind": "cpu"}
    summary = {}
    t = C.tuned_rows(summary, records, ["room0", "room1", "room2"], {"coap": cost, "volsmpl": cost},
                     {"coap": "all", "volsmpl": "all"})
    assert t["tune_scenes"] == ["room0"] and t["test_scenes"] == ["room1", "room2"]
    assert t["choice"] == {"coap": 1.0, "volsmpl": 1.0}
    s = summary["coap_test"]
    assert s["w"] == 1.0 and s["n_sequences"] == 2 and s["split"] == "test"
    assert s["goal_dist_m"] == pytest.approx(0.20) and s["collision_cm"] == pytest.approx(1.5)
    assert s["total_mem_mb"] == 300.0
    assert summary["volsmpl_test"]["goal_dist_m"] == pytest.approx(0.04)
    assert C.tuned_rows({}, records, ["room0"], {}, {}) is None
    note = " ".join(tuning_note(t))
    assert "room1, room2" in note and "coap w = 1" in note and "criterion" in note
    assert tuning_note(None) == []


def test_tuned_protocol_summary_rows():
    records = {("coap", 0.01): [_rec("room0", 0.50, 0.1)],
               ("coap", 1.0): [_rec("room0", 0.01, 0.2), _rec("room1", 0.30, 2.0), _rec("room2", 0.10, 1.0)],
               ("volsmpl", 1.0): [_rec("room0", 0.02, 0.1), _rec("room1", 0.03, 0.2), _rec("room2", 0.05, 0.4)]}
    cost = {"mem_per_frame_fwd_mb": 1.0, "mem_per_frame_fwdbwd_mb": 2.0, "ms_per_frame_fwd": 3.0,
            "ms_per_frame_fwdbwd": 4.0, "max_frames_in_budget": 10, "memory_kind": "cpu"}
    choice = T.choose_weights(records, ["room0"])
    summary, t = C.tuned_summary(records, choice, ["room0"], ["room1", "room2"], {"coap": cost, "volsmpl": cost},
                                 {"coap": "all", "volsmpl": "all"}, {"coap": [0.01, 1.0], "volsmpl": [1.0]})
    assert summary["coap"]["w"] == 1.0 and summary["coap"]["n_sequences"] == 2
    assert summary["coap"]["goal_dist_m"] == pytest.approx(0.20)
    assert summary["coap_w0.01"]["n_sequences"] == 1 and summary["coap_w0.01"]["split"] == "tune"
    assert summary["coap_w1.0"]["goal_dist_m"] == pytest.approx(0.01)       # the tuning room only
    assert summary["volsmpl"]["goal_dist_m"] == pytest.approx(0.04) and t["protocol"] == "tuned"
    note = " ".join(tuning_note(t))
    assert "Protocol 'tuned'" in note and "room1, room2" in note
