"""`volsmpl hoi make-case` on hand-made inputs, against independent references: joints projected by hand, a sphere's
mask placed where it was drawn, PnP back to a known placement, regions against brute-force distances, face normals
and the template's own regions; every error a user can cause is one line, before the work."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch
import trimesh
import volsmpl
from scipy.spatial.transform import Rotation
from volsmpl.apps.hoi.case import case_from_dict, case_to_dict, load_case, object_mesh
from volsmpl.cli import main as cli_main

F, CX, CY, SIZE = 600.0, 300.0, 250.0, (480, 640)
POSE = {"betas": [0.0] * 10, "global_orient": [np.pi, 0.0, 0.0], "body_pose": [0.0] * 69, "transl": [0.1, 0.2, 3.0]}


def _write(tmp_path, name, obj) -> str:
    p = tmp_path / name
    p.write_text(json.dumps(obj))
    return str(p)


def _posed(body, pose):
    with torch.no_grad():
        return body(**{k: torch.tensor(v, dtype=torch.float32)[None] for k, v in pose.items()})


def _make(tmp_path, *extra, out="case.json") -> dict:
    rc = cli_main(["hoi", "make-case", *extra, "--out", str(tmp_path / out)])
    assert rc == 0
    return json.loads((tmp_path / out).read_text())


@pytest.fixture
def box_inputs(tmp_path, body):
    """A 10 cm box (in cm) 6 cm to the side of the right hand of a T-posed body 3 m in front of the camera."""
    out = _posed(body, POSE)
    labels = volsmpl.Partition(body).vertex_labels.numpy()
    hand = out.vertices[0].numpy()[labels == list(volsmpl.Partition(body).table.part_names).index("right_hand")]
    box = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    box.export(tmp_path / "box.ply")
    centre = hand.mean(0) + np.array([0.0, 0.0, -0.08])  # towards the camera
    pose = {"rotation": np.eye(3).tolist(), "translation": centre.tolist()}
    return {"box": str(tmp_path / "box.ply"), "body": _write(tmp_path, "pose.json", POSE), "hand": hand,
            "object_pose": _write(tmp_path, "object_pose.json", pose), "centre": centre, "mesh": box}


def test_body_keypoints_silhouette_and_regions_against_references(tmp_path, body, box_inputs):
    b = box_inputs
    (tmp_path / "top.txt").write_text("# the top's four vertices\n" + "\n".join(
        str(i) for i in np.nonzero(b["mesh"].vertices[:, 2] > 0)[0]) + "\n")
    (tmp_path / "two.json").write_text("[0, 3]")
    d = _make(tmp_path, "--object", b["box"], "--units", "cm", "--category", "box", "--size-m", "0.1",
              "--body", b["body"], "--image-size", "480,640", "--focal", "600", "--principal", "300,250",
              "--object-pose", b["object_pose"],
              "--contact", "right_hand:auto", "--contact", "left_hand:vertices=" + str(tmp_path / "top.txt"),
              "--contact", "chest:faces=" + str(tmp_path / "two.json"), "--contact", "belly:any")
    case = case_from_dict(d, tmp_path)
    assert d["version"] == 2 and d["object"]["mesh"] == "box.ply" and d["object"]["units"] == "cm"
    # the body in its own frame (global_orient and transl 0), its rotation about x by pi in init.human
    assert case.body["transl"].abs().max() == 0 and case.body["global_orient"].abs().max() == 0
    assert np.allclose(case.init["human"].rotation, np.diag([1.0, -1.0, -1.0])) and case.init["human"].scale == 1.0
    # keypoints: the posed body's joints projected by hand; confidence 1 in the image (the feet are below it)
    j = _posed(body, POSE).joints[0, :24].double().numpy()
    uv = np.stack([F * j[:, 0] / j[:, 2] + CX, F * j[:, 1] / j[:, 2] + CY], axis=1)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= 640) & (uv[:, 1] >= 0) & (uv[:, 1] <= 480)
    assert np.abs(case.keypoints_2d[:, :2] - uv).max() < 1e-3 and 20 <= inside.sum() < 24
    assert case.keypoints_2d[:, 2].tolist() == inside.astype(float).tolist()
    assert case.init["object"].scale == pytest.approx(1.0) and case.size_m == 0.1  # the box's own size: 10 cm
    # no mask: the silhouette is the placed box's projection, a convex polygon: its area in pixels
    v = b["mesh"].vertices * 0.01 + b["centre"]
    hull = cv2.convexHull(np.stack([F * v[:, 0] / v[:, 2] + CX, F * v[:, 1] / v[:, 2] + CY], 1).astype(np.float32))
    area = cv2.contourArea(hull)
    assert len(case.silhouette) == pytest.approx(area, rel=0.15) and "no mask" in case.meta["silhouette"]
    assert cv2.pointPolygonTest(hull, tuple(map(float, case.silhouette.mean(0))), False) > 0
    # regions: vertex selection -> the two top triangles (normals +z); faces as given; auto by brute force
    mesh, regions = object_mesh(case)
    assert dict(case.contacts) == {"right_hand": "near_right_hand", "left_hand": "top", "chest": "two",
                                   "belly": "any"}
    assert regions["top"].tolist() == np.nonzero(mesh.face_normals[:, 2] > 0.99)[0].tolist()
    assert regions["two"].tolist() == [0, 3]
    tris = v[b["mesh"].faces]  # the placed box's triangles (camera frame)
    hand = b["hand"]
    pts = np.repeat(hand, len(tris), axis=0)
    q = trimesh.triangles.closest_point(np.tile(tris, (len(hand), 1, 1)), pts)
    dist = np.linalg.norm(q - pts, axis=1).reshape(len(hand), len(tris)).min(axis=0)
    want = np.nonzero(dist <= dist.min() + 0.02)[0]
    assert 0 < len(want) < len(tris) and regions["near_right_hand"].tolist() == want.tolist()


def test_mask_placement_pnp_and_a_named_template_region(tmp_path, body):
    """A sphere's mask drawn at a known place puts the sphere there (upright, at the depth of its size); keypoints
    of the default body placed by a known similarity give that similarity back (PnP); a cup template in mm keeps
    its own 'handle' triangles."""
    from volsmpl.body.poses import named_pose
    from volsmpl.scene.objects import make_object

    trimesh.creation.icosphere(4, radius=1.0).export(tmp_path / "orb.ply")
    z0, u0, v0 = 2.5, 380, 200
    mask = np.zeros(SIZE, np.uint8)
    cv2.circle(mask, (u0, v0), int(F * 0.1 / z0), 255, -1)  # radius 24 px: a 0.2 m sphere at 2.5 m
    cv2.imwrite(str(tmp_path / "mask.png"), mask)
    R = Rotation.from_euler("xyz", [180, 20, 5], degrees=True).as_matrix()
    t = np.array([-0.2, 0.1, 3.2])
    with torch.no_grad():
        j = body(betas=torch.zeros(1, 10), body_pose=named_pose("arms_down")).joints[0, :24].double().numpy() @ R.T + t
    kp = np.concatenate([F * j[:, :1] / j[:, 2:] + CX, F * j[:, 1:2] / j[:, 2:] + CY, np.ones((24, 1))], axis=1)
    kp[3, 2] = 0.0  # one joint not detected
    d = _make(tmp_path, "--object", str(tmp_path / "orb.ply"), "--category", "orb", "--size-m", "0.2",
              "--keypoints", _write(tmp_path, "kp.json", kp.tolist()), "--focal", "600", "--principal", "300,250",
              "--mask", str(tmp_path / "mask.png"), "--contact", "right_hand:any")
    case = case_from_dict(d, tmp_path)
    o = case.init["object"]
    assert o.scale == pytest.approx(0.1) and np.allclose(o.rotation, np.diag([1.0, -1.0, -1.0]))
    assert o.translation[2] == pytest.approx(z0, rel=0.03)
    assert (o.translation[0] / o.translation[2] * F + CX, o.translation[1] / o.translation[2] * F + CY) == (
        pytest.approx(u0, abs=0.5), pytest.approx(v0, abs=0.5))
    vv, uu = np.nonzero(mask)
    assert sorted(map(tuple, case.silhouette.tolist())) == sorted(zip(uu.tolist(), vv.tolist()))
    assert case.image_size == SIZE and case.size_m == 0.2 and case.category == "orb"
    h = case.init["human"]
    assert np.abs(h.rotation - R).max() < 1e-4 and np.abs(h.translation - t).max() < 1e-3
    assert case.keypoints_2d.tolist() == kp.tolist()
    # a mesh file of the cup template itself, in mm: 'handle' moves over triangle for triangle
    tmpl = make_object("cup")
    trimesh.Trimesh(tmpl.mesh.vertices * 1000, tmpl.mesh.faces, process=False).export(tmp_path / "cup.obj")
    d = _make(tmp_path, "--object", str(tmp_path / "cup.obj"), "--units", "mm", "--category", "cup",
              "--keypoints", str(tmp_path / "kp.json"), "--focal", "600", "--mask", str(tmp_path / "mask.png"),
              "--contact", "right_hand:handle", out="cup.json")
    assert d["object"]["regions"]["handle"] == tmpl.regions["handle"].tolist()


def test_case_format_reads_version_1_and_checks_regions(tmp_path):
    """A case without version-2 fields is written as version 1 (the database's files unchanged); size_m and regions
    are checked; a region naming a triangle the mesh lacks is refused when the mesh is read."""
    trimesh.creation.box().export(tmp_path / "box.ply")
    sim = {"scale": 1.0, "rotation": np.eye(3).tolist(), "translation": [0.0, 0.0, 3.0]}
    d = {"format": "volsmpl-hoi-case", "version": 1, "name": "v1",
         "body": {"betas": [0.0] * 10, "global_orient": [0.0] * 3, "body_pose": [0.0] * 69, "transl": [0.0] * 3},
         "object": {"category": "box", "mesh": "box.ply"}, "camera": {"K": np.eye(3).tolist(), "image_size": [4, 4]},
         "keypoints_2d": [[0.0, 0.0, 1.0]] * 24, "silhouette": [[1.0, 1.0]], "contacts": [],
         "init": {"human": sim, "object": sim}}
    assert case_to_dict(case_from_dict(d))["version"] == 1
    v2 = {**d, "version": 2,
          "object": {"category": "tray", "mesh": "box.ply", "size_m": 0.4, "regions": {"r": [11, 2]}}}
    c = case_from_dict(v2, tmp_path)
    assert c.regions["r"].tolist() == [2, 11] and case_to_dict(c)["version"] == 2
    for obj, msg in [({"category": "tray", "mesh": "box.ply"}, "unknown object category 'tray'"),
                     ({"category": "tray", "mesh": "box.ply", "size_m": -1}, "'size_m' -1 must be a finite length"),
                     ({"category": "box", "template_seed": 0, "size_m": 0.3}, "'size_m' goes with a mesh file"),
                     ({"category": "box", "mesh": "box.ply", "regions": {"any": [0]}}, "reserved"),
                     ({"category": "box", "mesh": "box.ply", "regions": {"r": [0.5]}}, "triangle ids")]:
        with pytest.raises(ValueError, match=msg):
            case_from_dict({**v2, "object": obj})
    with pytest.raises(ValueError, match="names triangle 12, the mesh .* has 12"):
        object_mesh(case_from_dict({**v2, "object": {**v2["object"], "regions": {"r": [12]}}}, tmp_path))


def _errors(tmp_path):
    """(arguments, the message's words, whether the body may be made first) of the errors a user can cause."""
    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(tmp_path / "box.ply")
    cv2.imwrite(str(tmp_path / "empty.png"), np.zeros((48, 64), np.uint8))
    cv2.imwrite(str(tmp_path / "m.png"), np.full((48, 64), 255, np.uint8))
    body = _write(tmp_path, "pose.json", POSE)
    pose = _write(tmp_path, "op.json", {"rotation": np.eye(3).tolist(), "translation": [0, 0, 3]})
    (tmp_path / "sel.txt").write_text("0\n99\n")
    ok = {"--object": str(tmp_path / "box.ply"), "--category": "box", "--body": body, "--image-size": "48,64",
          "--focal": "60", "--object-pose": pose, "--contact": "right_hand:any", "--out": str(tmp_path / "c.json")}
    cases = [({"--object": str(tmp_path / "nope.obj")}, "--object .*nope.obj: no such file"),
             ({"--units": "inch"}, "--units 'inch': give the mesh file's units, m, cm or mm"),
             ({"--size-m": "-2"}, "--size-m -2: give the object's largest extent in metres, a finite number > 0"),
             ({"--size-m": "nan"}, "--size-m 'nan': give a number"),
             ({"--category": "kettle"}, ("--category 'kettle' is not a template \\(cup, bottle, .*\\): give its size "
                                         "too, --size-m")),
             ({"--mask": str(tmp_path / "empty.png"), "--image-size": None}, "mask .*empty.png: no object pixel"),
             ({"--mask": str(tmp_path / "m.png"), "--image-size": "480,640"}, "the mask is 48 x 64 pixels"),
             ({"--body": _write(tmp_path, "b.json", {**POSE, "body_pose": [0.0] * 60})},
              "'body_pose' must be 69 finite numbers, got 60"),
             ({"--body": None, "--keypoints": _write(tmp_path, "k.json", [[0, 0, 1]] * 23)},
              "give 24 x \\[u, v, confidence\\].*got shape \\(23, 3\\)"),
             ({"--contact": "right_hand"}, "give PART:REGION"),
             ({"--contact": "right_hand:spout"},
              "no region 'spout' \\(the box template's regions: top, grasp, bottom\\)"),
             ({"--contact": "right_hand:faces=" + str(tmp_path / "sel.txt")}, "id 99 but the mesh has 12 triangles"),
             ({"--focal": None}, "the camera is missing"),
             ({"--focal": "0"}, "--focal 0: give the focal length in pixels, > 0"),
             ({"--object-pose": None}, "give the object's first-stage placement"),
             ({"--out": str(tmp_path / "c.txt")}, "ending in .json"),
             ({"--category": "teddy", "--size-m": "0.3", "--contact": "right_hand:hug"},
              "'teddy' is not a template, it has no named regions")]
    out = []
    for change, msg in cases:
        args = {**ok, **change}
        out.append(([x for k, v in args.items() if v is not None for x in (k, v)], msg, False))
    bad_part = {**ok, "--contact": "tail:any"}
    out.append(([x for kv in bad_part.items() for x in kv], "'tail' is not a body part; parts: pelvis, left_thigh",
                True))
    return out


def test_every_user_error_is_one_line_before_the_work(tmp_path, capsys, monkeypatch):
    from volsmpl.apps.hoi import make_case

    for argv, msg, body_first in _errors(tmp_path):
        if not body_first:  # refused before the body is made (and before any region or placement work)
            monkeypatch.setattr(volsmpl, "create_body", lambda *a, m=msg, **k: pytest.fail(f"work started: {m}"))
        monkeypatch.setattr(make_case, "auto_region", lambda *a, m=msg, **k: pytest.fail(f"work started: {m}"))
        rc = cli_main(["hoi", "make-case", *argv])
        err = capsys.readouterr().err.strip()
        assert rc == 2 and len(err.splitlines()) == 1, (msg, err)
        assert err.startswith("volsmpl hoi: error: ") and __import__("re").search(msg, err), (msg, err)
        monkeypatch.undo()
        assert not (tmp_path / "c.json").exists()
    # an option of make-case given to fit is refused, not ignored
    assert cli_main(["hoi", "fit", "--case", "x.json", "--mask", "m.png"]) == 2
    assert "--mask does not apply to `volsmpl hoi fit`" in capsys.readouterr().err


def test_a_case_of_any_category_with_its_size_fits(tmp_path, body, box_inputs):
    """A category that is no template (a tray) with its size: the scale prior is size_m over the mesh's extent, and
    the joint stage runs on it."""
    from volsmpl.apps.hoi.fit import FitConfig, Problem, fit_case

    b = box_inputs
    _make(tmp_path, "--object", b["box"], "--units", "cm", "--category", "tray", "--size-m", "0.3", "--body",
          b["body"], "--image-size", "480,640", "--focal", "600", "--object-pose", b["object_pose"],
          "--contact", "right_hand:auto")
    case = load_case(tmp_path / "case.json")
    vol = volsmpl.attach_volume(body, model="mesh")
    prob = Problem(case, body, vol, FitConfig(iters=2))
    assert float(prob.prior_object[0]) == pytest.approx(0.3 / 0.1, rel=1e-5)
    r = fit_case(case, body, vol, FitConfig(iters=2), prob)
    assert r.iterations == 2 and np.isfinite(r.loss).all()
    # and from the command line: the case's checks read its size, not the templates' table
    assert cli_main(["hoi", "fit", "--case", str(tmp_path / "case.json"), "--model", "mesh", "--iters", "2",
                     "--render", "0", "--quiet", "--out", str(tmp_path / "fit")]) == 0
