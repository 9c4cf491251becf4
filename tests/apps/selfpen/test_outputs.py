"""What `volsmpl selfpen` gives a user to take away: the repaired body and its starting parameters in each case
record, the before / after mesh files (a user's case file always, the shipped table with --save-meshes, a resumed
run from its records), and the figure's red colliding triangles.

The repair is replaced by a stand-in that returns a known pose, so that every file can be checked against the
default body posed independently (volsmpl.body.create_body) and against the exact triangle counter."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import trimesh
from volsmpl.apps.selfpen import cli as selfpen_cli
from volsmpl.apps.selfpen.cases import CASES_FILE
from volsmpl.apps.selfpen.optimize import RepairResult
from volsmpl.apps.selfpen.triangles import body_collisions
from volsmpl.body import create_body
from volsmpl.cli import main as cli_main

SHIPPED = "hands_through_thighs"  # both arms pressed down, hands inside the thighs


@pytest.fixture(scope="module")
def reference():
    return create_body()


def _shipped(name: str = SHIPPED) -> dict:
    """A shipped case as the file gives it (read as plain JSON)."""
    return next(c for c in json.loads(CASES_FILE.read_text())["cases"] if c["name"] == name)


def _repaired_pose(case_pose) -> list:
    """The stand-in's 'repair': every joint rotation halved (a pose unlike the case's, known to the test)."""
    return [0.5 * float(x) for x in case_pose]


def _stand_in(pose_of=_repaired_pose, calls=None):
    def repair(body, volume, case, cfg, keep_meshes=False, **kw):
        if calls is not None:
            calls.append(case.name)
        return RepairResult(name=case.name, status="resolved", iterations=1, collisions_before=7, collisions_after=0,
                            step_ms=[1.0], total_s=0.01, body_pose=pose_of(case.body_pose.tolist()))
    return repair


def _user_file(tmp_path, name="my body") -> tuple[str, dict]:
    d = {**_shipped(), "name": name}
    path = tmp_path / "mine.json"
    path.write_text(json.dumps({"cases": [d]}))
    return str(path), d


def _posed(reference, betas, global_orient, body_pose):
    with torch.no_grad():
        out = reference(betas=torch.tensor([betas]), global_orient=torch.tensor([global_orient]),
                        body_pose=torch.tensor([body_pose]))
    return out.vertices[0].double().numpy(), out.joints[0].double().numpy()


def _ply(path) -> np.ndarray:
    return np.asarray(trimesh.load(path, process=False).vertices, np.float64)


def test_a_users_case_gives_its_repaired_body_and_meshes_in_the_record(tmp_path, monkeypatch, reference):
    monkeypatch.setattr(selfpen_cli, "repair_case", _stand_in())
    case_file, d = _user_file(tmp_path)
    out = tmp_path / "o"
    assert cli_main(["selfpen", "--model", "mesh", "--case-file", case_file, "--out", str(out), "--render", "0"]) == 0
    (rec,) = json.loads((out / "results.json").read_text())["cases"]["mesh"]
    want = _repaired_pose(d["body_pose"])
    params = rec["body"]["params"]
    assert params["body_pose"] == pytest.approx(want, abs=1e-6) and params["betas"] == pytest.approx(d["betas"], abs=1e-6)
    assert rec["start_params"]["body_pose"] == pytest.approx(d["body_pose"], abs=1e-6)
    assert rec["start_params"]["transl"] == [0.0, 0.0, 0.0] and rec["body"]["units"] == "m" and rec["body"]["up"] == "y"
    v_after, j_after = _posed(reference, params["betas"], params["global_orient"], params["body_pose"])
    assert rec["body"]["joints"]["pelvis"] == pytest.approx(j_after[0].tolist(), abs=1e-5)
    assert set(rec["meshes"]) == {"before", "after"}
    assert rec["meshes"]["after"].endswith("/mesh_after.ply") and not rec["meshes"]["after"].startswith("/")
    after, before = _ply(out / rec["meshes"]["after"]), _ply(out / rec["meshes"]["before"])
    np.testing.assert_allclose(after, v_after, atol=1e-5)   # the record's params rebuild the after mesh
    v_case, _ = _posed(reference, d["betas"], d["global_orient"], d["body_pose"])
    np.testing.assert_allclose(before, v_case, atol=1e-5)   # the before mesh is the case file's pose
    assert np.abs(after - before).max() > 0.01              # and the repair moved the body


def test_the_shipped_table_writes_meshes_only_with_save_meshes(tmp_path, monkeypatch):
    monkeypatch.setattr(selfpen_cli, "repair_case", _stand_in())
    out = tmp_path / "o"
    argv = ["selfpen", "--model", "mesh", "--cases", SHIPPED, "--out", str(out), "--render", "0"]
    assert cli_main(argv) == 0
    (rec,) = json.loads((out / "results.json").read_text())["cases"]["mesh"]
    assert not (out / "meshes").exists() and rec["meshes"] == {} and len(rec["body"]["params"]["body_pose"]) == 69
    assert cli_main(argv + ["--save-meshes"]) == 0
    (rec,) = json.loads((out / "results.json").read_text())["cases"]["mesh"]
    assert rec["meshes"] == {"before": f"meshes/{SHIPPED}/mesh_before.ply", "after": f"meshes/{SHIPPED}/mesh_after.ply"}
    assert all((out / p).is_file() for p in rec["meshes"].values())


def test_a_resumed_run_makes_its_meshes_again_from_the_record(tmp_path, monkeypatch, capsys, reference):
    """The second run reuses the record (no repair); a removed before mesh and an after mesh replaced by another body
    are written again from the record's parameters."""
    monkeypatch.setattr(selfpen_cli, "repair_case", _stand_in())
    case_file, d = _user_file(tmp_path)
    out = tmp_path / "o"
    argv = ["selfpen", "--model", "mesh", "--case-file", case_file, "--out", str(out), "--render", "0"]
    assert cli_main(argv) == 0
    (rec,) = json.loads((out / "results.json").read_text())["cases"]["mesh"]
    (out / rec["meshes"]["before"]).unlink()
    stale = trimesh.creation.box()
    stale.export(out / rec["meshes"]["after"])
    calls = []
    monkeypatch.setattr(selfpen_cli, "repair_case", _stand_in(pose_of=lambda p: [0.0] * 69, calls=calls))
    capsys.readouterr()
    assert cli_main(argv + ["--resume"]) == 0
    assert calls == [] and "(reused)" in capsys.readouterr().out
    (again,) = json.loads((out / "results.json").read_text())["cases"]["mesh"]
    assert again["body"] == rec["body"] and again["meshes"] == rec["meshes"]
    v_after, _ = _posed(reference, d["betas"], d["global_orient"], _repaired_pose(d["body_pose"]))
    np.testing.assert_allclose(_ply(out / again["meshes"]["after"]), v_after, atol=1e-5)
    v_case, _ = _posed(reference, d["betas"], d["global_orient"], d["body_pose"])
    np.testing.assert_allclose(_ply(out / again["meshes"]["before"]), v_case, atol=1e-5)


def _red(img: np.ndarray) -> np.ndarray:
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > 150) & (g < 90) & (b < 90)


def _grey(img: np.ndarray) -> np.ndarray:
    im = img.astype(int)
    return (np.abs(im - im[..., :1]) < 12).all(-1) & (im[..., 0] > 60) & (im[..., 0] < 230)


def test_the_figure_shows_the_colliding_triangles_in_red(tmp_path, monkeypatch, reference):
    """The stand-in 'repairs' to the T-pose: the exact counter finds colliding triangle pairs before and none after;
    the figure's before column (left half) has red pixels, the after column none, and both hold the grey body."""
    import cv2

    d = _shipped()
    assert len(body_collisions(reference, d["betas"], d["global_orient"], d["body_pose"])["pairs"]) > 0
    assert len(body_collisions(reference, d["betas"], d["global_orient"], [0.0] * 69)["pairs"]) == 0
    monkeypatch.setattr(selfpen_cli, "repair_case", _stand_in(pose_of=lambda p: [0.0] * 69))
    out = tmp_path / "o"
    assert cli_main(["selfpen", "--model", "mesh", "--cases", SHIPPED, "--out", str(out), "--render", "1"]) == 0
    assert json.loads((out / "results.json").read_text())["figures"] == {SHIPPED: f"render_{SHIPPED}.png"}
    img = cv2.cvtColor(cv2.imread(str(out / f"render_{SHIPPED}.png")), cv2.COLOR_BGR2RGB)
    half = img.shape[1] // 2
    before, after = img[:, :half], img[:, half:]
    assert _red(before).sum() > 200 and _red(after).sum() == 0
    assert _grey(before).sum() > 5000 and _grey(after).sum() > 5000


def test_progress_bars_on_a_terminal_and_none_with_quiet(tmp_path, monkeypatch, capsys):
    """On a terminal the run shows a bar over its cases and leaves the per-step bar to the optimiser's own rule;
    --quiet shows no bar and turns the per-step bar off."""
    import sys

    seen = []

    def repair(body, volume, case, cfg, keep_meshes=False, **kw):
        seen.append(kw)
        return _stand_in()(body, volume, case, cfg, keep_meshes)

    monkeypatch.setattr(selfpen_cli, "repair_case", repair)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    argv = ["selfpen", "--model", "mesh", "--cases", SHIPPED, "--render", "0"]
    assert cli_main(argv + ["--out", str(tmp_path / "a")]) == 0
    assert "selfpen mesh" in capsys.readouterr().err and seen == [{}]
    assert cli_main(argv + ["--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert capsys.readouterr().err == "" and seen[1] == {"progress": False}
