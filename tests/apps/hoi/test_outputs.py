"""What a human–object run gives a user: the fitted body and object in each case record and as mesh files (rebuilt
here from the records by independent code), mesh files for a user's case always and for a table run only with
--save-meshes, kept by --resume; and case figures that show the object's vertices inside the body."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import trimesh
from hoi_cases import ball_case
from volsmpl.apps.hoi.case import case_from_dict
from volsmpl.cli import main as cli_main
from volsmpl.scene.objects import make_object


def _place(sim: dict, x: np.ndarray) -> np.ndarray:
    """x_cam = s R x + t, written out (the case format's similarity, apps/hoi/case.py)."""
    R, t = np.asarray(sim["rotation"], dtype=np.float64), np.asarray(sim["translation"], dtype=np.float64)
    return float(sim["scale"]) * (np.asarray(x, dtype=np.float64) @ R.T) + t


def _fit(tmp_path, d: dict, out: str, *extra: str) -> dict:
    (tmp_path / "case.json").write_text(json.dumps(d))
    assert cli_main(["hoi", "fit", "--case", str(tmp_path / "case.json"), "--model", "mesh", "--iters", "2",
                     "--render", "0", "--out", str(tmp_path / out), *extra]) == 0
    return json.loads((tmp_path / out / "results.json").read_text())["cases"]["mesh"][0]


def _load(path) -> np.ndarray:
    return np.asarray(trimesh.load(path, process=False).vertices, dtype=np.float64)


def test_records_hold_the_fitted_body_and_object_and_rebuild_the_mesh_files(body, tmp_path):
    from volsmpl.body import create_body

    d = ball_case(body)
    rec = _fit(tmp_path, d, "out")
    b, o = rec["body"], rec["object"]
    # the body: params (body model frame) and its placement into the camera frame, the same as the fit's `human`
    assert b["placement"] == rec["human"] and b["units"] == "m" and "camera" in b["frame"]
    assert np.allclose(b["first_stage"]["translation"], d["init"]["human"]["translation"])
    with torch.no_grad():
        out = create_body()(**{k: torch.tensor([v], dtype=torch.float32) for k, v in b["params"].items()})
    verts = _place(b["placement"], out.vertices[0].double().numpy())
    joints = _place(b["placement"], out.joints[0].double().numpy())
    assert np.allclose(b["pelvis"], joints[0], atol=1e-5)
    assert np.allclose(list(b["joints"].values()), joints, atol=1e-5)
    # the fitted placement differs from the first stage (2 steps moved it) and the files hold the fitted one
    body_file, obj_file = (tmp_path / "out" / rec["meshes"][k] for k in ("body", "object"))
    assert np.allclose(_load(body_file), verts, atol=1e-5)
    assert not np.allclose(_place(d["init"]["human"], out.vertices[0].double().numpy()), verts, atol=1e-4)
    # the object: its similarity, category and the case's first stage beside it; its file the case's ball so placed
    assert o["category"] == "ball" and "camera" in o["frame"]
    assert np.allclose(o["first_stage"]["rotation"], d["init"]["object"]["rotation"])
    assert o["first_stage"]["scale"] == pytest.approx(d["init"]["object"]["scale"])
    assert np.allclose(_load(obj_file), _place(o, make_object("ball", seed=0).mesh.vertices), atol=1e-5)
    assert len(trimesh.load(obj_file, process=False).faces) == len(make_object("ball", seed=0).mesh.faces)


def _database(tmp_path, d: dict):
    """A database folder of one case (the index format of apps/hoi/database.py), in the test split."""
    db = tmp_path / "db"
    db.mkdir()
    (db / f"{d['name']}.json").write_text(json.dumps(d))
    (db / "index.json").write_text(json.dumps({"format": "volsmpl-hoi-database", "db_version": 2, "seed": 0,
                                               "cases": [{"name": d["name"], "kind": "carry_ball",
                                                          "category": "ball", "split": "test"}]}))
    return db


def test_a_table_run_writes_meshes_only_with_save_meshes_and_resume_keeps_them(body, tmp_path, capsys):
    d = ball_case(body)
    args = ["hoi", "--db", str(_database(tmp_path, d)), "--split", "test", "--model", "mesh", "--iters", "2",
            "--render", "0", "--out", str(tmp_path / "t")]
    meshes = tmp_path / "t" / "meshes"
    assert cli_main(args + ["--save-meshes"]) == 0
    rec = json.loads((tmp_path / "t" / "results.json").read_text())["cases"]["mesh"][0]
    files = {k: tmp_path / "t" / p for k, p in rec["meshes"].items()}
    assert set(files) == {"body", "object"} and all(f.is_file() for f in files.values())
    first = {k: _load(f) for k, f in files.items()}
    # a resumed run serves the stored record and still writes its meshes (from the record: the same vertices)
    import shutil
    shutil.rmtree(meshes)
    capsys.readouterr()
    assert cli_main(args + ["--save-meshes", "--resume"]) == 0
    assert "(reused)" in capsys.readouterr().out
    assert all(np.allclose(_load(f), first[k], atol=1e-6) for k, f in files.items())
    # without the flag: no mesh file, and none left behind that the records do not list
    assert cli_main(args + ["--resume"]) == 0
    rec = json.loads((tmp_path / "t" / "results.json").read_text())["cases"]["mesh"][0]
    assert rec["meshes"] == {} and not any(f.exists() for f in files.values())
    # --save-meshes is read by the table run and by fit, refused where nothing is fitted
    assert cli_main(["hoi", "make-db", "--save-meshes", "--db", str(tmp_path / "x")]) == 2
    assert "--save-meshes does not apply to `volsmpl hoi make-db`" in capsys.readouterr().err


def test_a_resumed_fit_rewrites_its_meshes_from_the_record_it_serves(body, tmp_path, capsys):
    """A stale mesh file (another run's, same path) is replaced by the one of the record served."""
    d = ball_case(body)
    rec = _fit(tmp_path, d, "out")
    path = tmp_path / "out" / rec["meshes"]["object"]
    good = _load(path)
    trimesh.creation.box().export(path)  # what an earlier, other run left there
    capsys.readouterr()
    again = _fit(tmp_path, d, "out", "--resume")
    assert "(reused)" in capsys.readouterr().out and again["meshes"] == rec["meshes"]
    assert np.allclose(_load(path), good, atol=1e-6)


# ------------------------------------------------------------------------------------------------ figures
def _red(img: np.ndarray) -> np.ndarray:
    """Pixels of the inside-the-body red (nothing else drawn is red: grey body, blue object, white ground)."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > 150) & (g < 90) & (b < 90)


def _drawn(img: np.ndarray) -> np.ndarray:
    return (img < 245).any(-1)


def _span(mask: np.ndarray) -> tuple[int, int]:
    """(width, height) in pixels of the bounding box of a mask."""
    ys, xs = np.nonzero(mask)
    return int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)


@pytest.fixture(scope="module")
def ball_problem(body):
    import volsmpl
    from volsmpl.apps.hoi.fit import FitConfig, Problem

    case = case_from_dict(ball_case(body))
    return Problem(case, body, volsmpl.attach_volume(body, model="mesh"), FitConfig())


def test_close_up_shows_the_object_inside_the_body_in_red(ball_problem):
    import igl
    from volsmpl.apps.hoi.figures import case_views

    case = ball_problem.cases[0]
    truth = {k: s.to_dict() for k, s in case.truth.items()}
    clear = case_views(ball_problem, truth, 0)
    assert clear.share_inside == 0 and not _red(clear.close_up(240)).any()
    # the ball pushed 6 cm up into the right hand (camera y points down)
    into = {**truth, "object": {**truth["object"],
                                "translation": (np.asarray(truth["object"]["translation"]) - [0, 0.06, 0]).tolist()}}
    views = case_views(ball_problem, into, 0)
    # independent reference: libigl's winding numbers of the placed ball's even vertices in the placed body mesh
    v = _place(truth["human"], ball_problem.body_v[0].double().numpy())
    pts = _place(into["object"], np.asarray(ball_problem.meshes[0].vertices))
    w = igl.winding_number(v, np.asarray(ball_problem.faces, dtype=np.int64), pts)
    share = float((np.abs(w) > 0.5).mean())
    assert share > 0.01 and views.share_inside == pytest.approx(share, abs=0.01)
    close = views.close_up(240)
    red = _red(close)
    assert red.sum() > 150  # large discs, drawn over the body
    # the close-up is framed on the contact: the hand and ball fill it, the red lies inside the frame's middle
    assert _drawn(close).mean() > 0.3
    ys, xs = np.nonzero(red)
    assert 20 < xs.mean() < 220 and 20 < ys.mean() < 220


def test_views_frame_the_body_and_the_side_view_looks_across_the_upright_body(ball_problem):
    """The camera view fills its panel; the side view turns about the body's vertical: a body seen by a camera
    pitched 35 deg still stands upright in it, seen in profile (T-pose arms along the line of sight)."""
    from scipy.spatial.transform import Rotation
    from volsmpl.apps.hoi.figures import case_views

    case = ball_problem.cases[0]
    truth = {k: s.to_dict() for k, s in case.truth.items()}
    views = case_views(ball_problem, truth, 0)
    cam = views.camera_view(case.K, None, 200)
    w, h = _span(_drawn(cam))
    assert max(w, h) > 0.85 * 200  # the body fills the panel (it spans ~40 % of the 640 x 480 image)
    # the whole pair turned by a pitch of the camera about its x axis: the side view must not change
    P = Rotation.from_euler("x", 35, degrees=True).as_matrix()
    tilted = {k: {"scale": s["scale"], "rotation": (P @ np.asarray(s["rotation"])).tolist(),
                  "translation": (P @ np.asarray(s["translation"])).tolist()} for k, s in truth.items()}
    for sim in (truth, tilted):
        side = case_views(ball_problem, sim, 0).side_view(200)
        w, h = _span(_drawn(side))
        assert h > 0.85 * 200 and w / h < 0.4  # upright and in profile: 1.7 m tall, ~0.3 m deep
        w_front, h_front = _span(_drawn(case_views(ball_problem, sim, 0).camera_view(case.K, None, 200)))
    assert w_front / h_front > 0.8  # the camera sees the T-pose from the front: as wide as tall


def test_cli_figure_shows_a_penetrating_first_stage(body, tmp_path):
    import cv2

    d = ball_case(body)
    t = np.asarray(d["truth"]["object"]["translation"]) - [0, 0.06, 0]  # the first stage's ball in the hand
    d = {**d, "init": {"human": d["truth"]["human"], "object": {**d["truth"]["object"], "translation": t.tolist()}}}
    (tmp_path / "case.json").write_text(json.dumps(d))
    assert cli_main(["hoi", "fit", "--case", str(tmp_path / "case.json"), "--model", "mesh", "--iters", "1",
                     "--render", "1", "--out", str(tmp_path / "o"), "--quiet"]) == 0
    img = cv2.cvtColor(cv2.imread(str(tmp_path / "o" / "case_ball_at_hand.png")), cv2.COLOR_BGR2RGB)
    assert _red(img).sum() > 300 and img.shape[0] > 3 * 200 and _drawn(img).mean() > 0.1


def test_progress_bars_over_cases_and_steps_and_quiet_turns_them_off(body, tmp_path, monkeypatch, capsys):
    """On a terminal (here: declared one) a bar runs over the cases and the harness gets the step bar's rule;
    --quiet passes progress=False to the harness and shows no case bar."""
    import volsmpl.apps.hoi.fit as fit_module
    import volsmpl.apps.progress as progress_module

    seen = []
    real = fit_module.optimize

    def spy(*a, **k):
        seen.append((k.get("progress"), k.get("desc")))
        return real(*a, **k)

    monkeypatch.setattr(fit_module, "optimize", spy)
    monkeypatch.setattr(progress_module, "shown", lambda quiet=False: not quiet)
    (tmp_path / "case.json").write_text(json.dumps(ball_case(body)))
    args = ["hoi", "fit", "--case", str(tmp_path / "case.json"), "--model", "mesh", "--iters", "1", "--render", "0"]
    capsys.readouterr()
    assert cli_main(args + ["--out", str(tmp_path / "a")]) == 0
    assert "hoi mesh" in capsys.readouterr().err  # the case bar, named by the kinds
    assert seen == [(None, "ball_at_hand mesh")]  # None: the harness's own rule (a terminal, 50 steps or more)
    assert cli_main(args + ["--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert "hoi mesh" not in capsys.readouterr().err and seen[-1] == (False, "ball_at_hand mesh")
