"""tools/app_cost.py with the apps' runs replaced by known times: medians over rounds, ratios, refusals."""
import importlib.util
import json
import sys
from pathlib import Path

import pytest

spec = importlib.util.spec_from_file_location("app_cost", Path(__file__).parents[2] / "tools" / "app_cost.py")
tool = importlib.util.module_from_spec(spec)
spec.loader.exec_module(tool)


def run(monkeypatch, *argv):
    monkeypatch.setattr(sys, "argv", ["app_cost.py", *argv])
    return tool.main()


def test_medians_over_rounds_and_ratios_to_the_shipped_model(tmp_path, monkeypatch):
    # round r: shipped 10, 30, 20 ms; r3 25, 60, 35 ms -> medians 20 and 35, ratio 1.75
    times = {"shipped": [10.0, 30.0, 20.0], "r3": [25.0, 60.0, 35.0]}
    calls = []

    def fake(app, setting, threads, workdir):
        calls.append((app, setting))
        r = sum(1 for a, s in calls if (a, s) == (app, setting)) - 1
        return {k: times[setting][r] * (1 + i) for i, k in enumerate(tool.APPS[app][1])}, 0.0

    monkeypatch.setattr(tool, "run_one", fake)
    out = tmp_path / "cost.json"
    argv = ["--apps", "selfpen,motion", "--settings", "shipped,r3", "--rounds", "3", "--base", "shipped", "--out", str(out)]
    assert run(monkeypatch, *argv) == 0
    res = json.loads(out.read_text())
    assert calls[:4] == [("selfpen", "shipped"), ("selfpen", "r3"), ("motion", "shipped"), ("motion", "r3")]
    assert res["median"]["selfpen"] == {"shipped": 20.0, "r3": 35.0}
    assert res["median"]["motion"] == {"shipped": 20.0, "r3": 35.0}        # the first key read is tabulated
    assert res["rounds"][1]["motion"]["r3"] == {"ms_per_frame_fwdbwd": 60.0, "ms_per_iter": 120.0}
    assert res["base"] == "shipped" and res["ratio_to_base"]["selfpen"]["r3"] == pytest.approx(1.75)
    assert res["checkpoints"] == {"shipped": "core/assets/volsmpl_anny",
                                  "r3": "checkpoints/volsmpl_r3/ckpt-00057000/model"}


def test_the_ratios_divide_by_the_base_setting(tmp_path, monkeypatch):
    # shipped 20 ms, r3 50 ms in every round: --base r3 gives shipped 0.4x, r3 1x
    monkeypatch.setattr(tool, "run_one", lambda app, setting, threads, workdir: (
        {k: {"shipped": 20.0, "r3": 50.0}[setting] for k in tool.APPS[app][1]}, 0.0))
    out = tmp_path / "cost.json"
    assert run(monkeypatch, "--apps", "selfpen", "--settings", "shipped,r3", "--rounds", "1", "--base", "r3",
               "--out", str(out)) == 0
    res = json.loads(out.read_text())
    assert res["base"] == "r3"
    assert res["ratio_to_base"]["selfpen"] == {"shipped": pytest.approx(0.4), "r3": pytest.approx(1.0)}


def test_unknown_apps_and_settings_are_refused_in_one_line(tmp_path, monkeypatch):
    with pytest.raises(SystemExit, match="unknown app 'hoii'"):
        run(monkeypatch, "--apps", "hoii", "--out", str(tmp_path / "x.json"))
    with pytest.raises(SystemExit, match="unknown setting 'r9'"):
        run(monkeypatch, "--settings", "shipped,r9", "--out", str(tmp_path / "x.json"))
    with pytest.raises(SystemExit, match="--base 'r3' is not among --settings"):
        run(monkeypatch, "--settings", "shipped,r1", "--base", "r3", "--out", str(tmp_path / "x.json"))
    with pytest.raises(SystemExit, match="--base 's33000' is not among --settings"):
        run(monkeypatch, "--settings", "shipped,r1", "--out", str(tmp_path / "x.json"))
    with pytest.raises(SystemExit, match="--rounds 0: give a number >= 1"):
        run(monkeypatch, "--rounds", "0", "--out", str(tmp_path / "x.json"))
    with pytest.raises(SystemExit, match="--threads -1: give a number >= 1"):
        run(monkeypatch, "--threads", "-1", "--out", str(tmp_path / "x.json"))
