"""`volsmpl egohmr` with a user's own data: every option checked against the mode, a user's frame and scene checked
for plausibility before any network, and each sample judged without ground truth. The scenes are hand-made boxes
(a floor, four walls, a bed and a table top), the expectations worked out by hand."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from volsmpl.cli import main

H, W = 480, 640
K = [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]


def _plane(rng, origin, u, v, density=1500.0):
    """Points on the rectangle origin + s u + t v (s, t in [0, 1]), `density` per square metre."""
    origin, u, v = (np.asarray(a, np.float64) for a in (origin, u, v))
    n = int(density * np.linalg.norm(np.cross(u, v)))
    s, t = rng.random((2, n, 1))
    return origin + s * u + t * v


def box_room() -> np.ndarray:
    """A 5 x 4 m room, Y up, floor at y = 0, walls 2.5 m high, no ceiling; a bed top at 0.5 m and a table top at
    0.75 m."""
    rng = np.random.default_rng(0)
    parts = [_plane(rng, [-2.5, 0, -2], [5, 0, 0], [0, 0, 4]),                       # floor
             _plane(rng, [-2.5, 0, -2], [0, 2.5, 0], [0, 0, 4]),                     # walls x = -2.5, 2.5
             _plane(rng, [2.5, 0, -2], [0, 2.5, 0], [0, 0, 4]),
             _plane(rng, [-2.5, 0, -2], [5, 0, 0], [0, 2.5, 0]),                     # walls z = -2, 2
             _plane(rng, [-2.5, 0, 2], [5, 0, 0], [0, 2.5, 0]),
             _plane(rng, [-2.4, 0.5, -1.9], [1.6, 0, 0], [0, 0, 2.0]),               # bed
             _plane(rng, [0.0, 0.75, 0.0], [1.0, 0, 0], [0, 0, 0.8])]                # table
    return np.concatenate(parts)


def frame_doc(**change) -> dict:
    """A frame file's content: a camera at (0.5, 1.6, -1.5) of the Y-up room looking along +z (OpenCV axes: x right,
    y down), 24 confident keypoints inside the image."""
    rng = np.random.default_rng(1)
    kp = np.stack([rng.uniform(100, 540, 24), rng.uniform(50, 430, 24)], 1)
    R = np.diag([-1.0, -1.0, 1.0])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ np.array([0.5, 1.6, -1.5])
    return {"K": K, "image_size": [H, W], "keypoints": kp.tolist(), "conf": [0.9] * 24,
            "world_to_camera": T.tolist(), **change}


class PastTheChecks(Exception):
    """Raised where the work would begin: a run that gets there passed every check."""


@pytest.fixture(autouse=True)
def no_work(monkeypatch):
    """Frames, training and the network stop the run: a check that fails to refuse fails its test at once."""
    import volsmpl.apps.egohmr.data as data
    import volsmpl.apps.egohmr.train as train

    def stop(*a, **k):
        raise PastTheChecks("the work began")
    for mod, name in ((data, "make_frames"), (train, "train"), (train, "load_model")):
        monkeypatch.setattr(mod, name, stop)


@pytest.fixture
def files(tmp_path):
    """write(name, doc or points) -> path: a frame file (.json) or a scene (.npy)."""
    def write(name, content):
        p = tmp_path / name
        if name.endswith(".npy"):
            np.save(p, np.asarray(content))
        else:
            p.write_text(json.dumps(content))
        return str(p)
    return write


def run(argv, capsys) -> tuple[int, str]:
    capsys.readouterr()
    rc = main(["egohmr", *argv])
    err = capsys.readouterr().err.strip()
    return rc, err


def test_scene_in_millimetres_read_as_metres_is_refused_naming_units(files, capsys, tmp_path):
    room = box_room()
    frame = files("f.json", frame_doc())
    rc, err = run(["sample", "--frame", frame, "--scene", files("mm.npy", room * 1000), "--out", str(tmp_path / "o")],
                  capsys)
    assert rc == 2 and "\n" not in err
    assert "spans 5e+03 m with --units m" in err and "give --units mm" in err
    rc, err = run(["sample", "--frame", frame, "--scene", files("m.npy", room), "--units", "mm",
                   "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and "spans 0.005 m with --units mm" in err and "give --units m" in err


def test_scene_turned_z_up_is_refused_without_up_z(files, capsys, tmp_path):
    from types import SimpleNamespace

    from volsmpl.apps.egohmr.user_scene import read_user_inputs
    from volsmpl.apps.egohmr.userframe import camera_points

    room = box_room()
    z_up = np.stack([room[:, 0], -room[:, 2], room[:, 1]], 1)       # the same room, z up
    frame = files("f.json", frame_doc())
    rc, err = run(["sample", "--frame", frame, "--scene", files("z.npy", z_up), "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and "\n" not in err and err.endswith("give --up z")
    rc, err = run(["sample", "--frame", frame, "--scene", files("y.npy", room), "--up", "z",
                   "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and err.endswith("give --up y")
    # with --up z the z-up scan is the Y-up room: accepted without a warning, the camera 1.6 m above its floor
    warnings = []
    args = SimpleNamespace(frame=frame, scene=str(tmp_path / "z.npy"), units="m", up="z", seed=0)
    f, scan, up = read_user_inputs(args, warnings)
    assert warnings == []
    assert np.allclose(camera_points(f, scan.vertices), (room @ np.diag([-1.0, -1.0, 1.0]).T) + [0.5, 1.6, 1.5])
    assert up[1] > math.cos(math.radians(5))                         # the floor faces +y of the Y-up world


def test_floor_estimate_needs_a_room_around_it():
    from volsmpl.scene.floor import floor_up

    room = box_room()
    up, a, other = floor_up(room)
    assert abs(up[1]) > math.cos(math.radians(5)) and other <= 0.1
    wall = room[np.abs(room[:, 2] + 2.0) < 1e-9]                       # one wall alone: floor or wall?
    assert floor_up(wall)[0] is None


def test_camera_matrix_of_another_image_size_is_refused_naming_k(files, capsys, tmp_path):
    from volsmpl.apps.egohmr.user_checks import check_camera
    from volsmpl.apps.egohmr.userframe import load_user_frame

    big = [[1000.0, 0, 1279.5], [0, 1000.0, 959.5], [0, 0, 1]]         # K of a 2560 x 1920 image: cx outside 640
    with pytest.raises(ValueError, match=r"'K': the principal point \(cx, cy\) = \(1279.5, 959.5\) lies outside .*"
                                         r"a camera matrix for another image size\?"):
        load_user_frame(files("big.json", frame_doc(K=big)))
    rc, err = run(["sample", "--frame", str(tmp_path / "big.json"), "--scene", files("s.npy", box_room()),
                   "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and "'K': the principal point" in err
    tiny_f = [[5.0, 0, 319.5], [0, 5.0, 239.5], [0, 0, 1]]             # 2 atan(320 / 5) = 178.2 degrees
    with pytest.raises(ValueError, match=r"'K' has fx = 5 px, a 178.2 degree horizontal field of view .* another "
                                         r"image size\?"):
        check_camera(load_user_frame(files("f5.json", frame_doc(K=tiny_f))), "--frame f5.json")
    tall = [[500.0, 0, 319.5], [0, 1000.0, 239.5], [0, 0, 1]]
    with pytest.raises(ValueError, match=r"'K' has fx = 500 and fy = 1000 px"):
        check_camera(load_user_frame(files("tall.json", frame_doc(K=tall))), "--frame tall.json")
    unit = (np.random.default_rng(2).random((24, 2))).tolist()        # keypoints in [0, 1]: normalised, not pixels
    with pytest.raises(ValueError, match=r"'keypoints' span 0.8\d* px .* normalised \[0, 1\] coordinates\?"):
        check_camera(load_user_frame(files("unit.json", frame_doc(keypoints=unit))), "--frame unit.json")
    warnings = []
    check_camera(load_user_frame(files("ok.json", frame_doc())), "--frame ok.json", warnings)
    assert warnings == []


def test_camera_far_outside_the_scene_is_refused(files, capsys, tmp_path):
    doc = frame_doc()
    T = np.asarray(doc["world_to_camera"])
    T[:3, 3] *= 1000.0                                               # the translation in millimetres
    rc, err = run(["sample", "--frame", files("f.json", dict(doc, world_to_camera=T.tolist())),
                   "--scene", files("s.npy", box_room()), "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and "'world_to_camera' puts the camera" in err and "in metres" in err


@pytest.mark.parametrize("argv, said", [
    (["sample", "--frame", "f.json", "--scene", "s.ply", "--split", "val"],
     "--split does not apply to `volsmpl egohmr sample --frame`"),
    (["sample", "--frame", "f.json", "--scene", "s.ply", "--frames", "3", "--batch", "2"],
     "--batch, --frames do not apply to `volsmpl egohmr sample --frame`"),
    (["sample", "--frame", "f.json", "--scene", "s.ply", "--resume"], "--resume does not apply"),
    (["sample", "--steps", "5"], "--steps does not apply to `volsmpl egohmr sample`"),
    (["sample", "--factors", "1,2"], "--factors does not apply to `volsmpl egohmr sample`"),
    (["sample", "--scene", "s.ply", "--units", "mm"],
     "--scene, --units describe the scene of a user's frame: add --frame"),
    (["sample", "--up", "z"], "--up describes the scene of a user's frame"),
    (["sample", "--spacing", "0.02"], "--spacing describes the scene of a user's frame"),
    (["tune", "--save-meshes"], "--save-meshes does not apply to `volsmpl egohmr tune`"),
    (["sample", "--frame", "f.json"], "--frame needs the frame's scene: add --scene"),
    (["tune", "--scale", "volsmpl=3"], "--scale does not apply to `volsmpl egohmr tune`"),
    (["tune", "--model", "none"], "tune sweeps the guides' scales"),
    (["train", "--tuned", "t.json", "--guide-steps", "3"],
     "--guide-steps, --tuned do not apply to `volsmpl egohmr train`"),
    (["make-data", "--budget-mb", "100"], "--budget-mb does not apply to `volsmpl egohmr make-data`"),
    (["make-data", "--threads", "0"], "--threads 0: give a positive number"),
    (["sample", "--model", "none", "--plain-factor", "0.01"], "--plain-factor sets the guidance, but --model none"),
    (["sample", "--no-max-batch", "--budget-mb", "64"], "which --no-max-batch skips"),
])
def test_options_the_mode_does_not_read_are_refused(argv, said, capsys, tmp_path):
    rc, err = run(argv, capsys)
    assert rc == 2 and said in err and "\n" not in err


@pytest.mark.parametrize("argv, said", [
    (["--scale", "volsmpl=-30"], "--scale volsmpl -30: give a finite number >= 0"),
    (["--scale", "mesh=nan"], "--scale mesh nan: give a finite number >= 0"),
    (["--scale", "coap=1", "--model", "none,volsmpl"], "coap is not in --model none,volsmpl"),
    (["--budget-mb", "-5"], "--budget-mb -5: give a finite number > 0"),
    (["--budget-mb", "inf"], "--budget-mb inf: give a finite number > 0"),
    (["--guide-steps", "0"], "--guide-steps 0: give a finite number >= 1"),
    (["--plain-steps", "11"], "--plain-steps 11: give a finite number >= 0 and <= 10"),
    (["--plain-factor", "-1"], "--plain-factor -1: give a finite number >= 0"),
    (["--frames", "0"], "--frames 0: give a finite number >= 1"),
    (["--batch", "0"], "--batch 0: give a finite number >= 1"),
    (["--frame", "f.json", "--scene", "s.ply", "--spacing", "0.2"],
     "--spacing 0.2: give a finite number >= 0.005 and <= 0.0894427"),
    (["--frame", "f.json", "--scene", "s.ply", "--spacing", "0.001"], "--spacing 0.001: give a finite number >= 0.005"),
])
def test_numbers_out_of_range_are_refused(argv, said, capsys, tmp_path):
    rc, err = run(["sample", *argv, "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and said in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_factors_steps_and_tuned_files_are_checked(files, capsys, tmp_path):
    out = ["--out", str(tmp_path / "o")]
    rc, err = run(["tune", "--factors", "1,-2", *out], capsys)
    assert rc == 2 and err.endswith("--factors -2: give a finite number >= 0 (factors of the paper's scales, "
                                    "comma-separated; 0: the pose unguided)")
    assert "--steps 0: give a finite number >= 1" in run(["train", "--steps", "0", *out], capsys)[1]
    no_best = files("rows.json", {"rows": []})
    rc, err = run(["sample", "--tuned", no_best, *out], capsys)
    assert rc == 2 and f"the tuning file {no_best} (--tuned) has no 'best' scales" in err
    part = files("part.json", {"best": {"volsmpl": 9.0}})
    rc, err = run(["sample", "--model", "none,volsmpl,coap", "--tuned", part, *out], capsys)
    assert rc == 2 and f"the tuning file {part} (--tuned) has no best scale for coap" in err and "--scale coap=A" in err
    rc, err = run(["sample", "--model", "none,volsmpl,coap", "--tuned", part, "--scale", "coap=0.4", *out], capsys)
    assert rc == 1 and "PastTheChecks" in err                   # with coap's scale given, the tuned file serves
    bad = files("bad.json", {"best": {"volsmpl": -3}})
    rc, err = run(["sample", "--model", "volsmpl", "--tuned", bad, *out], capsys)
    assert rc == 2 and f"the tuning file {bad} (--tuned): best scale of volsmpl -3: give a finite number >= 0" in err
    (tmp_path / "text.json").write_text("best: 3")
    rc, err = run(["sample", "--tuned", str(tmp_path / "text.json"), *out], capsys)
    assert rc == 2 and f"the tuning file {tmp_path / 'text.json'} (--tuned) is not valid JSON" in err


def test_an_out_folder_of_another_app_is_refused(capsys, tmp_path):
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "results.json").write_text(json.dumps({"app": "hoi"}))
    rc, err = run(["sample", "--frames", "1", "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and "holds the results of `volsmpl hoi`" in err
    assert json.loads((tmp_path / "o" / "results.json").read_text()) == {"app": "hoi"}


# ------------------------------------------------------------------------------------------------ the status judge
def test_judge_of_hand_made_records():
    from volsmpl.apps.egohmr.status import judge

    ok = {"finite": True, "joint_limit_excess_deg": 5.0, "joint_limit_at": "neck x", "deep_ratio": 0.001,
          "reproj_err": 0.05}
    assert judge(ok) == ("ok", "")
    assert judge(dict(ok, finite=False))[0] == "diverged"
    status, why = judge(dict(ok, joint_limit_excess_deg=25.0, joint_limit_at="left_knee x"))
    assert status == "past_joint_limits" and why.startswith("left_knee x lies 25 degrees outside its limit")
    assert judge(dict(ok, joint_limit_excess_deg=14.0))[0] == "ok"
    assert judge(dict(ok, deep_ratio=0.01)) == ("penetrating", "1.00 % of the scene points around the body lie "
                                                               "more than 5 cm inside it (limit 0.5 %)")
    assert judge(dict(ok, reproj_err=0.25))[0] == "far_from_keypoints"
    assert judge(dict(ok, reproj_err=0.12))[0] == "ok"
    status, why = judge(dict(ok, deep_ratio=0.01, reproj_err=0.25))        # the first applies; why names both
    assert status == "penetrating" and "inside it" in why and "0.250" in why
    assert judge(dict(ok, reproj_err=float("nan")))[0] == "ok"             # no confident keypoint: not judged


def test_joint_limit_excess_of_hand_made_poses():
    from volsmpl.apps.egohmr.status import limit_excess

    pose = torch.zeros(3, 69)
    pose[1, 9:12] = torch.tensor([2.9, 0.0, 0.0])      # left knee (body joint 3) flexed 2.9 rad; its limit is 2.4
    pose[2, 0:3] = torch.tensor([0.0, 0.0, -0.65])    # left hip abducted to z = -0.65; its limit is -0.45
    ex, where = limit_excess(pose)
    assert ex[0] == 0.0 and where[1] == "left_knee x" and where[2] == "left_hip z"
    assert ex[1] == pytest.approx(math.degrees(0.5), abs=1e-3)
    assert ex[2] == pytest.approx(math.degrees(0.2), abs=1e-3)


def test_reprojection_error_of_hand_made_joints():
    from volsmpl.apps.egohmr.status import REPROJ_CAP, reprojection_error

    joints = torch.zeros(2, 24, 3)
    joints[..., 2] = 2.0
    joints[0, 0] = torch.tensor([0.1, 0.2, 2.0])      # projects to (0.05, 0.1)
    joints[0, 1] = torch.tensor([0.0, 0.0, 2.0])      # projects to (0, 0)
    joints[0, 2] = torch.tensor([0.0, 0.0, -1.0])     # behind the camera
    kp = torch.zeros(2, 24, 3)
    kp[0, 0] = torch.tensor([0.05, 0.13, 0.9])        # 0.03 away
    kp[0, 1] = torch.tensor([0.04, 0.0, 0.5])         # 0.04 away
    kp[0, 2] = torch.tensor([0.0, 0.0, 0.8])          # counts REPROJ_CAP
    kp[0, 3] = torch.tensor([0.9, 0.9, 0.0])          # not detected: not counted
    err = reprojection_error(joints, kp)
    assert err[0] == pytest.approx((0.03 + 0.04 + REPROJ_CAP) / 3, abs=1e-6)
    assert math.isnan(err[1])                         # no keypoint with a confidence above 0


def test_deep_ratio_and_diverged_pose_of_a_hand_made_body():
    import trimesh

    from volsmpl.apps.egohmr.pose import identity_pose
    from volsmpl.apps.egohmr.status import judge, measure, deep_ratio

    cube = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    v = torch.as_tensor(cube.vertices, dtype=torch.float64)[None]
    pts = torch.tensor([[[0.0, 0.0, 0.0], [0.0, 0.0, 0.48], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0]]], dtype=torch.float64)
    inside = torch.tensor([[True, True, False, False]])
    # the centre is 0.5 m inside, (0, 0, 0.48) 2 cm: one of four points deeper than 5 cm
    assert deep_ratio(v, cube.faces, pts, inside)[0] == pytest.approx(0.25)
    x = identity_pose(1)
    x[0, 7] = float("nan")
    joints = torch.zeros(1, 24, 3)
    rec = measure(x, joints, v.float(), cube.faces, torch.zeros(1, 24, 3), pts.float(), inside)[0]
    assert rec["finite"] is False and judge(rec)[0] == "diverged"


def test_a_principal_point_off_the_centre_is_warned_about():
    """A 640 x 480 camera (cx 320, cy 240) with image_size given as [W, H] = [640, 480] read as [H, W]: cx lies
    80 px = 17 % of the 480 px width from the centre (limit 10 %): a warning naming image_size; the true [480, 640]:
    none."""
    from types import SimpleNamespace

    import numpy as np

    from volsmpl.apps.egohmr.user_checks import check_camera

    K = np.array([[500.0, 0, 320.0], [0, 500.0, 240.0], [0, 0, 1]])
    kp = np.stack([np.linspace(200, 300, 22), np.linspace(100, 400, 22)], 1)

    def warnings_of(size):
        frame = SimpleNamespace(K=K, image_size=size, conf=np.ones(22), keypoints=kp)
        out = []
        check_camera(frame, "--frame f.json", out)
        return out

    assert warnings_of((480, 640)) == []
    assert any("principal point (320, 240) lies far from the centre (240, 320)" in w and "[W, H]" in w
               for w in warnings_of((640, 480)))


def test_a_room_in_a_corner_of_a_large_floor_shows_its_floor_from_the_camera():
    """The room of `box_room` in a corner of a 20 x 20 m open floor: the centre of the points' box lies outside the
    room, so with the normals turned towards it the room's opposite walls face the same way (no clear floor); turned
    towards the camera centre inside the room they face each other, and the floor faces up (the y axis)."""
    from volsmpl.scene.floor import floor_up

    room = box_room()
    rng = np.random.default_rng(3)
    out = np.stack([rng.uniform(-2.5, 17.5, 40000), np.zeros(40000), rng.uniform(-2.0, 18.0, 40000)], 1)
    scene = np.concatenate([room, out[~((out[:, 0] < 2.5) & (out[:, 2] < 2.0))]])
    assert floor_up(scene)[0] is None
    up, _, walls = floor_up(scene, towards=[0.5, 1.6, -1.5])
    assert up is not None and abs(up[1]) > math.cos(math.radians(2)) and walls <= 0.1
