"""The human–object app end to end on a hand-made case (a ball at the right hand), for every model kind."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import volsmpl
from volsmpl.apps.hoi.case import FORMAT, VERSION, case_from_dict, case_to_dict, load_case
from volsmpl.apps.hoi.fit import FitConfig, Problem, fit_case
from volsmpl.body.fingerprint import fingerprint_of_model
from volsmpl.cli import main as cli_main
from volsmpl.scene.objects import make_object

R_CAM = np.diag([1.0, -1.0, -1.0])  # body Y-up, facing +Z -> camera y down, facing the camera


def _rot(axis_angle):
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(axis_angle).as_matrix()


def ball_case(body, human_factor=1.2, object_factor=0.8, object_rot=(0.0, 0.35, 0.0)) -> dict:
    """A ball touching the right hand of a standing body 3 m in front of the camera; first-stage estimates scaled
    about the camera centre (the depth-scale ambiguity) and the ball turned by `object_rot`."""
    with torch.no_grad():
        out = body(betas=torch.zeros(1, 10), body_pose=torch.zeros(1, 69))
    joints = out.joints[0, :24].numpy().astype(np.float64)
    tmpl = make_object("ball", seed=0)
    radius = tmpl.mesh.extents[1] / 2
    hand = joints[21]  # right wrist
    centre = hand + np.array([-0.05, -radius - 0.04, 0.0])  # below the hand: the palm side when the arm hangs
    v = out.vertices[0].numpy()
    # move the ball down until it clears the body by 5 mm (exact distances of its vertices)
    from volsmpl.mesh_distance import mesh_signed_distance
    faces = torch.as_tensor(np.asarray(body.faces))
    for _ in range(100):
        verts = tmpl.mesh.vertices - [0, radius, 0] + centre
        d = mesh_signed_distance(torch.as_tensor(v, dtype=torch.float64), faces, torch.as_tensor(verts))
        if float(d.min()) > 0.005:
            break
        centre = centre + np.array([0.0, -0.005, 0.0])
    t_h = np.array([0.0, 0.2, 3.0])
    truth_h = {"scale": 1.0, "rotation": R_CAM, "translation": t_h}
    obj_t = R_CAM @ (centre - [0, radius, 0]) + t_h
    truth_o = {"scale": 1.0, "rotation": R_CAM, "translation": obj_t}
    K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])

    def proj(x):
        return np.stack([600 * x[:, 0] / x[:, 2] + 319.5, 600 * x[:, 1] / x[:, 2] + 239.5], -1)

    j_cam = joints @ R_CAM.T + t_h
    kp = np.concatenate([proj(j_cam), np.full((24, 1), 0.9)], 1)
    o_cam = tmpl.mesh.vertices @ R_CAM.T + obj_t
    sil = proj(o_cam)[:: max(1, len(o_cam) // 300)]
    sim = lambda s, R, t: {"scale": s, "rotation": np.asarray(R).tolist(), "translation": list(t)}  # noqa: E731
    return {
        "format": FORMAT, "version": VERSION, "name": "ball_at_hand",
        "body": {"fingerprint": fingerprint_of_model(body), "betas": [0.0] * 10, "global_orient": [0.0] * 3,
                 "body_pose": [0.0] * 69, "transl": [0.0] * 3},
        "object": {"category": "ball", "template_seed": 0},
        "camera": {"K": K.tolist(), "image_size": [480, 640]},
        "keypoints_2d": kp.tolist(), "silhouette": sil.tolist(), "contacts": [["right_hand", "grasp"]],
        "init": {"human": sim(human_factor, R_CAM, t_h * human_factor),
                 "object": sim(object_factor, _rot(object_rot) @ R_CAM, obj_t * object_factor)},
        "truth": {k: sim(v["scale"], v["rotation"], v["translation"]) for k, v in (("human", truth_h), ("object", truth_o))},
    }


def test_case_round_trips_and_bad_cases_are_named(body, tmp_path):
    d = ball_case(body)
    c = case_from_dict(d)
    assert json.dumps(case_to_dict(c), sort_keys=True) == json.dumps(case_to_dict(case_from_dict(case_to_dict(c))), sort_keys=True)
    with pytest.raises(ValueError, match="unknown object category 'kettle'"):
        case_from_dict({**d, "object": {"category": "kettle", "template_seed": 0}})
    vol = volsmpl.attach_volume(body, model="mesh")
    with pytest.raises(ValueError, match="not a body part"):
        Problem(case_from_dict({**d, "contacts": [["tail", "grasp"]]}), body, vol, FitConfig())
    with pytest.raises(ValueError, match="not a region of the object"):
        Problem(case_from_dict({**d, "contacts": [["right_hand", "handle"]]}), body, vol, FitConfig())
    with pytest.raises(ValueError, match="was made for body"):
        Problem(case_from_dict({**d, "body": {**d["body"], "fingerprint": "0123456789abcdef"}}), body, vol, FitConfig())
    bad = {**d, "init": {**d["init"], "object": {**d["init"]["object"], "scale": float("nan")}}}
    with pytest.raises(ValueError, match="init.object"):
        case_from_dict(bad)
    # a user's mesh file in millimetres, not centred: loads; an empty one is refused with the fix
    import trimesh
    m = trimesh.creation.icosphere(radius=110.0)
    m.apply_translation([500.0, 0, 0])
    m.export(tmp_path / "ball_mm.ply")
    user = {**d, "object": {"category": "ball", "mesh": "ball_mm.ply", "units": "mm"}, "contacts": [["right_hand", "any"]]}
    (tmp_path / "user.json").write_text(json.dumps(user))
    prob = Problem(load_case(tmp_path / "user.json"), body, vol, FitConfig())
    assert prob.mesh.extents.max() == pytest.approx(0.22, rel=1e-2)
    (tmp_path / "empty.ply").write_text("ply\nformat ascii 1.0\nelement vertex 0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n")
    (tmp_path / "empty.json").write_text(json.dumps({**user, "object": {"category": "ball", "mesh": "empty.ply"}}))
    with pytest.raises(ValueError, match="no triangles"):
        Problem(load_case(tmp_path / "empty.json"), body, vol, FitConfig())


@pytest.mark.parametrize("kind", ["volsmpl", "coap", "mesh"])
def test_one_case_end_to_end_lowers_the_loss_and_the_errors(body, kind):
    case = case_from_dict(ball_case(body))
    vol = volsmpl.attach_volume(body, model=kind)
    r = fit_case(case, body, vol, FitConfig(iters=150))
    assert r.iterations == 150 and r.loss[-1] < r.loss[0]
    # the first stage's errors (scales 1.2 / 0.8, ball turned 20 deg) shrink
    assert r.after["scale_err_pct"] < r.before["scale_err_pct"]
    assert r.after["human_scale_err_pct"] < r.before["human_scale_err_pct"]
    assert r.after["obj_trans_err_cm"] < r.before["obj_trans_err_cm"]
    assert r.ms_per_iter > 0 and r.peak_mem_mb >= 0


def test_cli_fit_writes_results_and_figures(body, tmp_path, capsys):
    (tmp_path / "case.json").write_text(json.dumps(ball_case(body)))
    rc = cli_main(["hoi", "fit", "--case", str(tmp_path / "case.json"), "--model", "volsmpl,mesh", "--iters", "5",
                   "--out", str(tmp_path / "out"), "--render", "1"])
    assert rc == 0
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    assert set(res["summary"]) == {"volsmpl", "mesh"} and res["paper"]["volsmpl"]["iter_ms"] == 4.28
    assert res["summary"]["volsmpl"]["n_cases"] == 1 and (tmp_path / "out" / "case_ball_at_hand.png").is_file()
    assert cli_main(["hoi", "fit", "--out", str(tmp_path / "o2")]) == 2
    assert "needs --case" in capsys.readouterr().err


def test_resume_keeps_matching_records_and_refuses_other_settings(tmp_path):
    import json

    from volsmpl.apps.hoi.cli import resumed

    key = {"config": {"iters": 1000, "lr": 0.002}, "models": ["volsmpl", "mesh"], "split": "test", "seed": 0}
    rec = {"name": "sit_chair_0052", "ms_per_iter": 50.0}
    path = tmp_path / "results.json"
    assert resumed(path, key, key["models"]) == {"volsmpl": [], "mesh": []}  # nothing yet: start afresh
    path.write_text(json.dumps({**key, "cases": {"volsmpl": [rec], "mesh": []}}))
    got = resumed(path, key, key["models"])
    assert [r.name for r in got["volsmpl"]] == ["sit_chair_0052"] and got["mesh"] == []
    with pytest.raises(ValueError, match="config"):
        resumed(path, {**key, "config": {"iters": 10, "lr": 0.002}}, key["models"])
    path.write_text("{")
    with pytest.raises(ValueError, match="not valid JSON"):
        resumed(path, key, key["models"])
