"""`volsmpl selfpen` with a user's options and runs: numbers out of range and options of the other action refused
in one line before any work, results kept case by case when a run is stopped, a repair that makes things worse
listed under 'flagged', and one writer per output folder."""
from __future__ import annotations

import json

import pytest

from volsmpl.apps.selfpen import cli as selfpen_cli
from volsmpl.apps.selfpen.optimize import RepairResult
from volsmpl.cli import main as cli_main


@pytest.mark.parametrize("extra, message", [
    (["--w-prior", "nan"], "--w-prior nan: give a finite number >= 0"),
    (["--max-step", "nan"], "--max-step nan: give a finite number >= 0"),
    (["--lr", "-1"], "--lr -1: give a finite number > 0"),
    (["--tau", "0"], "--tau 0: give a finite number > 0"),
    (["--max-iters", "0"], "--max-iters 0: give a finite number >= 1"),
    (["--n-points", "0"], "--n-points 0: give a finite number >= 1"),
    (["--patience", "-1"], "--patience -1: give a finite number >= 0"),
    (["--stall-rtol", "nan"], "--stall-rtol nan: give a finite number >= 0"),
    (["--threads", "0"], "--threads 0: give a positive number"),
    (["--grid-lr", "1e-3"], "--grid-lr does not apply to `volsmpl selfpen run`"),
    (["--combine", "a.json"], "--combine does not apply to `volsmpl selfpen run`"),
])
def test_wrong_options_are_refused_in_one_line(tmp_path, capsys, extra, message):
    # the case file does not exist: an option not checked would end there instead, at once
    assert cli_main(["selfpen", "--model", "mesh", "--case-file", str(tmp_path / "none.json"),
                     "--out", str(tmp_path / "o")] + extra) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()  # refused before anything was made


def test_tune_refuses_the_run_options(tmp_path, capsys):
    assert cli_main(["selfpen", "tune", "--model", "volsmpl", "--w-prior", "10", "--case-file",
                     str(tmp_path / "none.json"), "--out", str(tmp_path)]) == 2
    assert "--w-prior does not apply to `volsmpl selfpen tune`" in capsys.readouterr().err


def _fake(collisions_after: int):
    def repair(body, volume, case, cfg, keep_meshes=False):
        if case.name == "stop_here":
            raise KeyboardInterrupt
        return RepairResult(name=case.name, status="resolved", iterations=3, collisions_before=10,
                            collisions_after=collisions_after, step_ms=[1.0, 1.0, 1.0], total_s=0.1)
    return repair


def _case_file(tmp_path, names):
    cases = [{"name": n, "betas": [0.0] * 10, "global_orient": [0.0] * 3, "body_pose": [0.0] * 69} for n in names]
    (tmp_path / "cases.json").write_text(json.dumps({"cases": cases}))
    return str(tmp_path / "cases.json")


def test_a_stopped_run_keeps_its_finished_cases(tmp_path, monkeypatch):
    """Ctrl-C during the second case: results.json holds the first (written after every case)."""
    monkeypatch.setattr(selfpen_cli, "repair_case", _fake(collisions_after=0))
    out = tmp_path / "o"
    args = ["selfpen", "--model", "mesh", "--case-file", _case_file(tmp_path, ["first", "stop_here"]),
            "--out", str(out), "--render", "0"]
    assert cli_main(args) == 130
    res = json.loads((out / "results.json").read_text())
    assert [r["name"] for r in res["cases"]["mesh"]] == ["first"] and res["app"] == "selfpen"


def test_a_repair_that_makes_it_worse_is_flagged(tmp_path, monkeypatch, capsys):
    """The fake repair ends with 25 colliding pairs from 10: status 'worse_than_start' (optimize.repair_case sets it
    from the counts; here the record carries it), listed under 'flagged' and printed."""
    def worse(body, volume, case, cfg, keep_meshes=False):
        r = _fake(collisions_after=25)(body, volume, case, cfg)
        r.status, r.status_why = "worse_than_start", "colliding triangle pairs 10 -> 25"
        return r

    monkeypatch.setattr(selfpen_cli, "repair_case", worse)
    out = tmp_path / "o"
    assert cli_main(["selfpen", "--model", "mesh", "--case-file", _case_file(tmp_path, ["wide"]), "--out", str(out),
                     "--render", "0"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["flagged"] == [{"case": "wide", "model": "mesh", "status": "worse_than_start",
                               "why": "colliding triangle pairs 10 -> 25"}]
    assert "flagged: wide mesh: worse_than_start" in capsys.readouterr().out


def test_an_output_folder_of_another_app_or_in_use_is_refused(tmp_path, monkeypatch, capsys):
    import fcntl

    monkeypatch.setattr(selfpen_cli, "repair_case", _fake(collisions_after=0))
    args = ["selfpen", "--model", "mesh", "--case-file", _case_file(tmp_path, ["a"]), "--render", "0"]
    other = tmp_path / "hoi_run"
    other.mkdir()
    (other / "results.json").write_text(json.dumps({"app": "hoi", "cases": {}}))
    assert cli_main(args + ["--out", str(other)]) == 2
    assert "holds the results of `volsmpl hoi`" in capsys.readouterr().err
    assert json.loads((other / "results.json").read_text())["app"] == "hoi"  # kept
    busy = tmp_path / "busy"
    busy.mkdir()
    with open(busy / ".lock", "a+") as fh:  # another process's lock (flock: per open file)
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        assert cli_main(args + ["--out", str(busy)]) == 2
        assert "is being written by another volsmpl selfpen run" in capsys.readouterr().err
    assert cli_main(args + ["--out", str(busy)]) == 0  # released: runs


def test_a_pose_in_degrees_or_betas_of_another_scale_are_refused(tmp_path):
    """Axis-angle in radians turns a joint by at most 2 pi; 90 (degrees) is refused naming the field and the fix.
    Shape coefficients in standard deviations: 30 is refused, 5 (an extreme but real body) accepted."""
    from volsmpl.apps.selfpen.cases import load_cases

    def case(**over):
        d = {"name": "c", "betas": [0.0] * 10, "global_orient": [0.0] * 3, "body_pose": [0.0] * 69, **over}
        (tmp_path / "c.json").write_text(json.dumps({"cases": [d]}))
        return tmp_path / "c.json"

    pose = [0.0] * 69
    pose[47] = 90.0  # joint 15, about z: a right angle written in degrees
    with pytest.raises(ValueError, match=r"'body_pose' turns joint 15 by 90 rad .*is it in degrees\?"):
        load_cases(case(body_pose=pose))
    pose[47] = 6.0  # 6 rad < 2 pi: a real (if odd) rotation
    assert load_cases(case(body_pose=pose))[0].name == "c"
    with pytest.raises(ValueError, match=r"'betas' reaches 30; shape coefficients are in standard deviations"):
        load_cases(case(betas=[30.0] + [0.0] * 9))
    assert load_cases(case(betas=[5.0] * 10))[0].name == "c"


def test_a_negative_seed_is_refused(tmp_path, capsys):
    assert cli_main(["selfpen", "--model", "mesh", "--sampler-seed", "-1", "--case-file", str(tmp_path / "none.json"),
                     "--out", str(tmp_path / "o")]) == 2
    assert "--sampler-seed -1: give a finite number >= 0" in capsys.readouterr().err
