"""A user's human–object case checked before the fit (units, origin, distance, camera) and a fit judged after it,
on the hand-made ball case with the ball given as a mesh file in known units."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from hoi_cases import ball_case
from volsmpl.apps.hoi.case import case_from_dict, object_mesh
from volsmpl.apps.hoi.plausibility import check_case_data, judge_fit
from volsmpl.cli import main as cli_main
from volsmpl.scene.objects import make_object


def _checked(body, tmp_path, d, scale=1.0, shift=(0.0, 0.0, 0.0), units="m"):
    """check_case_data of case d with the ball template written as a mesh file: vertices x scale + shift, declared
    in `units`; returns the warnings."""
    mesh = make_object("ball", seed=0).mesh.copy()
    mesh.vertices = np.asarray(mesh.vertices) * scale + np.asarray(shift)
    mesh.export(tmp_path / "ball.ply")
    case = case_from_dict({**d, "object": {"category": "ball", "mesh": "ball.ply", "units": units},
                           "contacts": [["right_hand", "any"]]}, tmp_path)
    with torch.no_grad():
        v = body(betas=torch.zeros(1, 10), body_pose=torch.zeros(1, 69)).vertices[0].numpy()
    warnings = []
    check_case_data(case, object_mesh(case)[0], v, warnings.append)
    return warnings


def test_a_case_in_its_true_units_passes(body, tmp_path):
    d = ball_case(body)
    assert _checked(body, tmp_path, d) == []
    assert _checked(body, tmp_path, d, scale=1000.0, units="mm") == []  # the same ball written in millimetres
    assert _checked(body, tmp_path, d, scale=100.0, units="cm") == []


def test_wrong_units_are_refused_naming_the_right_ones(body, tmp_path):
    d = ball_case(body)
    # a millimetre file declared as metres: 1,000x too large; the hint names mm
    with pytest.raises(ValueError, match=r'is the mesh in mm\? set "units": "mm"'):
        _checked(body, tmp_path, d, scale=1000.0, units="m")
    # a metre file declared as millimetres: 1,000x too small; the hint names m
    with pytest.raises(ValueError, match=r'is the mesh in m\? set "units": "m"'):
        _checked(body, tmp_path, d, scale=1.0, units="mm")
    with pytest.raises(ValueError, match=r'"units": "cm"'):
        _checked(body, tmp_path, d, scale=100.0, units="m")
    # 4x the size of a ball (the first-stage scale is 0.8): unusual, not impossible (a warning names it, the fit runs)
    assert any("x a typical ball" in w for w in _checked(body, tmp_path, d, scale=5.0))


def test_an_object_far_from_its_origin_or_from_the_body_is_refused(body, tmp_path):
    d = ball_case(body)
    with pytest.raises(ValueError, match="lies 70 m from its origin.*recentre the mesh"):
        _checked(body, tmp_path, d, shift=(70.0, 0.0, 0.0))
    far = json.loads(json.dumps(d))
    far["init"]["object"]["translation"][2] += 141.0
    with pytest.raises(ValueError, match=r"places the object 14\d\.?\d* m from the body"):
        _checked(body, tmp_path, far)
    near = json.loads(json.dumps(d))
    near["init"]["object"]["translation"][0] += 4.0  # 4 m to the side: 2.5 m from the body (a warning: 1.5-3 m)
    assert any("from the body" in w for w in _checked(body, tmp_path, near))


def test_a_camera_for_another_image_is_refused(body, tmp_path):
    d = ball_case(body)
    other = {**d, "camera": {**d["camera"], "K": [[1800.0, 0, 959.5], [0, 1800.0, 539.5], [0, 0, 1]]}}
    with pytest.raises(ValueError, match=r"principal point \(959.5, 539.5\) lies outside the image"):
        _checked(body, tmp_path, other)
    # the principal point 40 % of the width from the centre, inside the image: a warning (the limit is 10 %)
    off = {**d, "camera": {**d["camera"], "K": [[600.0, 0, 575.5], [0, 600.0, 239.5], [0, 0, 1]]}}
    assert any("far from the image centre" in w for w in _checked(body, tmp_path, off))
    unit = {**d, "keypoints_2d": [[u / 640, v / 480, c] for u, v, c in d["keypoints_2d"]]}  # normalised to [0, 1]
    with pytest.raises(ValueError, match=r"keypoints \(keypoints_2d\) lie within 0.\d+ pixels of one another: normalised \[0, 1\] coordinates\?"):
        _checked(body, tmp_path, unit)
    far_kp = {**d, "keypoints_2d": [[u * 4, v * 4, c] for u, v, c in d["keypoints_2d"]]}
    with pytest.raises(ValueError, match="keypoints_2d lie outside the image"):
        _checked(body, tmp_path, far_kp)


def test_judge_fit_on_hand_made_measures():
    ok = {"collision_pct": 0.0, "gap_cm": 1.0}
    assert judge_fit([10.0, 1.0], [1.0, 2.0], ok, ok) == ("converged", "")
    assert judge_fit([10.0, float("nan")], [1.0], ok, {})[0] == "diverged"
    assert judge_fit([10.0, 1.0], [1.0], ok, ok, stop="diverged")[0] == "diverged"  # the harness's verdict
    assert judge_fit([10.0, 1.0], [1.0], ok, ok, stop="max_iters")[0] == "converged"
    assert judge_fit([10.0, 1.0], [float("inf")], ok, ok)[0] == "diverged"
    assert judge_fit([1.0, 10.5], [1.0], ok, ok)[0] == "diverged"          # > 10x the first loss
    assert judge_fit([1.0, 9.5], [1.0], ok, ok)[0] == "converged"
    lost = {"collision_pct": 0.0, "gap_cm": 277e2}
    why = "the object ends 277.00 m from the body (start 0.01 m)"
    assert judge_fit([1.0, 0.5], [1.0], ok, lost) == ("object_lost", why)
    # 1.2 m off but it started 1.0 m off: not lost, yet farther than at the start
    assert judge_fit([1.0, 0.5], [1.0], {"collision_pct": 0, "gap_cm": 100.0},
                     {"collision_pct": 0, "gap_cm": 120.0})[0] == "worse_than_start"
    inside = {"collision_pct": 12.0, "gap_cm": 0.0}
    assert judge_fit([1.0, 0.5], [1.0], {"collision_pct": 3.0, "gap_cm": 0.0}, inside)[0] == "worse_than_start"
    assert judge_fit([1.0, 0.5], [1.0], {"collision_pct": 11.0, "gap_cm": 0.0}, inside)[0] == "converged"


@pytest.mark.parametrize("extra, message", [
    (["--iters", "0"], "--iters 0: give a finite number >= 1"),
    (["--lr", "nan"], "--lr nan: give a finite number > 0"),
    (["--w-keypoints", "-1"], "--w-keypoints -1: give a finite number >= 0"),
    (["--contact-fraction", "2"], "--contact-fraction 2: give a finite number > 0 and <= 1"),
    (["--threads", "0"], "--threads 0: give a positive number"),
    (["--split", "tune"], "--split does not apply to `volsmpl hoi fit`"),
    (["--cases", "3", "--db", "x"], "--cases, --db do not apply to `volsmpl hoi fit`"),
])
def test_fit_options_that_are_wrong_or_do_not_apply_are_refused(tmp_path, capsys, extra, message):
    args = ["hoi", "fit", "--case", str(tmp_path / "missing.json"), "--model", "mesh", "--out", str(tmp_path / "o")]
    assert cli_main(args + extra) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_a_case_file_that_is_not_json_names_the_file(tmp_path, capsys):
    (tmp_path / "case.json").write_bytes(b"\xff\xfe{not json")
    assert cli_main(["hoi", "fit", "--case", str(tmp_path / "case.json"), "--out", str(tmp_path / "o")]) == 2
    assert f"case file {tmp_path / 'case.json'} (--case) is not UTF-8" in capsys.readouterr().err
    (tmp_path / "case.json").write_text('{"format": ')
    assert cli_main(["hoi", "fit", "--case", str(tmp_path / "case.json"), "--out", str(tmp_path / "o")]) == 2
    assert "(--case) is not valid JSON" in capsys.readouterr().err
