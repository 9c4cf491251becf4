"""The selfpen tuning grid: stable grid points only, scoring, combining per-model runs, selection."""
import pytest

from volsmpl.apps.selfpen.optimize import RepairResult, SelfPenConfig
from volsmpl.apps.selfpen.tune import best, combine, grid_configs, score


def test_grid_keeps_only_stable_prior_steps():
    cfgs = grid_configs(SelfPenConfig(max_iters=7), lrs=(1e-3, 0.5), w_selfpens=(1.0,), w_priors=(1.0, 10.0))
    assert [(c.lr, c.w_prior) for c in cfgs] == [(1e-3, 1.0), (1e-3, 10.0), (0.5, 1.0)]  # 0.5 * 10 >= 1 left out
    assert all(c.max_iters == 7 for c in cfgs)
    with pytest.raises(ValueError, match="lr \\* w_prior >= 1"):
        grid_configs(SelfPenConfig(), lrs=(1.0,), w_selfpens=(1.0,), w_priors=(1.0,))


def test_score_fraction_removed_over_cases_with_collisions():
    rs = [RepairResult("a", "resolved", 4, collisions_before=100, collisions_after=25, pose_change_deg=1.0),
          RepairResult("b", "max_iters", 10, collisions_before=10, collisions_after=10, pose_change_deg=3.0),
          RepairResult("c", "no_intersection", 0)]
    s = score(rs)
    assert s["removed"] == pytest.approx((0.75 + 0.0) / 2) and s["iterations"] == 7 and s["cases"] == 2
    assert s["pose_change_deg"] == pytest.approx(2.0) and s["collisions_after"] == pytest.approx(17.5)


def _run(model, removed):
    rows = [{"lr": 0.01, "w_selfpen": ws, "w_prior": 1.0,
             "models": {model: {"removed": r, "pose_change_deg": 1.0 / (1 + i)}}} for i, (ws, r) in enumerate(removed)]
    return {"rows": rows, "cases": ["x", "y"], "checkpoints": {model: "c"}}


def test_combine_and_best_average_over_models():
    a = _run("volsmpl", [(1.0, 0.9), (10.0, 0.5)])
    b = _run("coap", [(1.0, 0.1), (10.0, 0.6)])
    c = combine([a, b])
    assert set(c["rows"][0]["models"]) == {"volsmpl", "coap"} and c["checkpoints"] == {"volsmpl": "c", "coap": "c"}
    assert c["best"]["w_selfpen"] == 10.0  # mean removed (0.9 + 0.1) / 2 = 0.5 < (0.5 + 0.6) / 2 = 0.55
    with pytest.raises(ValueError, match="different cases"):
        combine([a, {**b, "cases": ["x"]}])
    # a grid point only one model ran is kept but cannot be chosen
    extra = _run("coap", [(100.0, 1.0)])
    c = combine([a, b, extra])
    assert [r["w_selfpen"] for r in c["rows"]] == [1.0, 10.0, 100.0] and c["best"]["w_selfpen"] == 10.0
    with pytest.raises(ValueError, match="no grid point was run with every model"):
        combine([_run("volsmpl", [(1.0, 0.5)]), extra])


def test_best_ties_prefer_smaller_pose_change():
    rows = _run("volsmpl", [(1.0, 0.5), (10.0, 0.5)])["rows"]
    assert best(rows)["w_selfpen"] == 10.0  # equal removal, pose change 0.5 < 1.0
