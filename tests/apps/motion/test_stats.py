"""Paired differences of the motion table (volsmpl.apps.motion.stats) on hand-made records: values by hand, the
confidence interval against the normal-theory interval, and the rows a results.json compares."""
from __future__ import annotations

import json

import numpy as np
import pytest

from volsmpl.apps.motion import stats as S


def _rec(model, w, scene, seq, **metrics):
    base = {"collision_cm": 0.0, "collision_frames_pct": 0.0, "goal_dist_m": 0.0, "foot_skate_cm": 0.0}
    return {"model": model, "w": w, "scene": scene, "sequence": seq, "metrics": {**base, **metrics}}


def test_pairs_match_sequences_not_list_order():
    a = [_rec("volsmpl", 1.0, "r", k, collision_cm=v) for k, v in enumerate([1.0, 2.0, 3.0])]
    b = [_rec("coap", 0.1, "other", 0, collision_cm=9.0)]            # walked by b only: not compared
    b += [_rec("coap", 0.1, "r", k, collision_cm=v) for k, v in enumerate([0.0, 1.0, 2.0])][::-1]
    t = S.paired_differences({"volsmpl": a, "coap": b}, n_resamples=200)
    (p,) = t["pairs"]
    m = p["metrics"]["collision_cm"]
    assert (p["a"], p["b"], p["n"]) == ("volsmpl", "coap", 3)
    assert m["mean_a"] == pytest.approx(2.0) and m["mean_b"] == pytest.approx(1.0)
    # paired by sequence every difference is +1 (in list order they would be -1, +1, +3)
    assert m["mean_diff"] == pytest.approx(1.0) and m["ci"] == pytest.approx([1.0, 1.0])
    assert (m["a_lower"], m["equal"], m["a_higher"]) == (0.0, 0.0, 1.0)
    c = [_rec("mesh", 1.0, "r", k, collision_cm=v) for k, v in enumerate([1.0, 0.0, 5.0])]
    m = S.paired_differences({"volsmpl": a, "mesh": c}, n_resamples=200)["pairs"][0]["metrics"]["collision_cm"]
    assert (m["a_lower"], m["equal"], m["a_higher"]) == pytest.approx((1 / 3, 1 / 3, 1 / 3))
    assert m["mean_diff"] == pytest.approx(0.0) and m["ci"][0] <= m["mean_diff"] <= m["ci"][1]


def test_pairs_refuse_disjoint_runs_and_missing_metrics():
    a = [_rec("volsmpl", 1.0, "r", k) for k in range(3)]
    with pytest.raises(ValueError, match="share 0 sequences"):
        S.paired_differences({"volsmpl": a, "coap": [_rec("coap", 0.1, "s", k) for k in range(3)]})
    bad = [_rec("coap", 0.1, "r", k, goal_dist_m=float("inf")) for k in range(3)]
    with pytest.raises(ValueError, match="goal_dist_m"):
        S.paired_differences({"volsmpl": a, "coap": bad})


def test_compared_runs_tuned_protocol_takes_the_choice_on_test_rooms():
    cases = ([_rec("coap", w, s, k) for w in (0.01, 0.1) for s in ("t0", "x1") for k in range(2)]
             + [_rec("volsmpl", 1.0, s, k) for s in ("t0", "x1") for k in range(2)])
    result = {"cases": cases, "config": {"models": ["volsmpl", "coap"], "weights": {"volsmpl": [1.0],
                                                                                    "coap": [0.01, 0.1]}},
              "tuning": {"choice": {"volsmpl": 1.0, "coap": 0.01}, "test_scenes": ["x1"], "tune_scenes": ["t0"]}}
    runs = S.compared_runs(result)
    assert list(runs) == ["volsmpl", "coap (w 0.01)"]
    assert all(r["scene"] == "x1" for recs in runs.values() for r in recs)
    assert {r["w"] for r in runs["coap (w 0.01)"]} == {0.01}
    result["tuning"] = None        # the paper's protocol: Table 5's COAP row (w = 0.1) on every room
    runs = S.compared_runs(result)
    assert {r["w"] for r in runs["coap (w 0.1)"]} == {0.1} and len(runs["coap (w 0.1)"]) == 4


@pytest.mark.parametrize("coap_ws", [(0.01, 0.1, 1.0), (0.01, 1.0)])
def test_summary_and_paired_rows_are_the_same_runs(coap_ws):
    """The paper's protocol: summary.coap (Table 5's row) and the paired table's COAP row are the same weight, w =
    0.1 when swept, else the first; a model with one weight is compared at it."""
    from volsmpl.apps.motion.summary import compared_weight, paper_summary
    weights = {"volsmpl": [1.0], "coap": list(coap_ws)}
    keys = ("goal_dist_m", "collision_obstacles_cm", "collision_frames_pct", "foot_skate_cm", "max_depth_cm",
            "jerk_max", "path_m", "optim_s", "ms_per_iter")
    records = {(m, w): [{"scene": "r", "metrics": {"collision_cm": 10 * w, "optim_peak_mem_mb": 1.0,
                                                   **dict.fromkeys(keys, 0.0)}}]
               for m, ws in weights.items() for w in ws}
    cost = {"mem_per_frame_fwd_mb": 1.0, "mem_per_frame_fwdbwd_mb": 1.0, "ms_per_frame_fwd": 1.0,
            "ms_per_frame_fwdbwd": 1.0, "memory_kind": "rss"}
    summary = paper_summary(records, {m: cost for m in weights}, {m: 1 for m in weights}, weights)
    expect = 0.1 if 0.1 in coap_ws else coap_ws[0]
    assert compared_weight("coap", coap_ws) == expect and summary["coap"]["w"] == expect
    assert summary["coap"]["collision_cm"] == pytest.approx(10 * expect) and summary["volsmpl"]["w"] == 1.0
    cases = [_rec(m, w, "r", 0) for m, ws in weights.items() for w in ws]
    runs = S.compared_runs({"cases": cases, "config": {"models": ["volsmpl", "coap"], "weights": weights}})
    assert {r["w"] for r in runs[f"coap (w {expect:g})"]} == {expect}
    assert compared_weight("coap", coap_ws, {"coap": 1.0}) == 1.0      # a choice on tuning rooms wins


def test_cli_errors_are_one_line(tmp_path, capsys):
    bad = tmp_path / "r.json"
    bad.write_text("{}")
    assert S.main([str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "results.json of volsmpl motion" in err
    bad.write_text("not json")
    assert S.main([str(bad)]) == 2
    assert "is not JSON" in capsys.readouterr().err
    good = tmp_path / "g.json"
    cases = [_rec(m, 1.0, "r", k, collision_cm=float(k + (m == "mesh"))) for m in ("volsmpl", "mesh") for k in range(4)]
    good.write_text(json.dumps({"cases": cases, "config": {"models": ["volsmpl", "mesh"]}}))
    assert S.main([str(good), "--out", str(tmp_path / "p.json"), "--resamples", "200"]) == 0
    table = json.loads((tmp_path / "p.json").read_text())
    assert table["pairs"][0]["metrics"]["collision_cm"]["mean_diff"] == pytest.approx(-1.0)
    assert "git_commit" in table["meta"] and table["source"]["results"] == str(good)
