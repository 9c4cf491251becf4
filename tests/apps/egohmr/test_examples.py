"""The example in examples/egohmr/ run with the command its README gives (two guides, three guided steps, to be
quick): it exits 0 and leaves the recovered bodies in results.json, a mesh file per guide and the figure. The bodies
are checked against the body model and the frame's own transform: the record's params, posed by
`volsmpl.body.create_body()` and turned into the scan's millimetres and z-up axes by hand, give the mesh file's
vertices; world_to_camera maps their pelvis onto the camera-frame pelvis the run regressed; the body sits on the
example's chair."""
from __future__ import annotations

import json
import shlex
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import trimesh

from volsmpl.cli import main

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "egohmr"
FAST = ["--model", "none,mesh", "--guide-steps", "3", "--plain-steps", "1"]
#: the example's chair (make_example.py: SEAT), in the scan's millimetres, z up: (x, -z, y) of the Y-up world
CHAIR_MM = np.array([400.0, 600.0])


def readme_command() -> list[str]:
    """The `volsmpl ...` line of the README's code block, as argv (without 'volsmpl')."""
    text = (EXAMPLE / "README.md").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("volsmpl egohmr"))
    return shlex.split(line)[1:]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    argv = readme_command()
    out = tmp_path_factory.mktemp("egohmr_example") / "out"
    i = argv.index("--out")
    argv[i + 1] = str(out)
    argv = [str(Path.cwd() / a) if a.startswith("examples/") else a for a in argv]
    assert main(argv + FAST) == 0
    return out, json.loads((out / "results.json").read_text())


def test_example_files_are_small_and_what_the_readme_says():
    assert (EXAMPLE / "frame.json").stat().st_size + (EXAMPLE / "room.ply").stat().st_size < 200_000
    argv = readme_command()
    assert argv[:2] == ["egohmr", "sample"] and argv[argv.index("--units") + 1] == "mm"
    assert argv[argv.index("--up") + 1] == "z"
    scan = trimesh.load(EXAMPLE / "room.ply", process=False)
    ext = scan.vertices.max(0) - scan.vertices.min(0)
    assert np.allclose(ext, [5000.0, 4000.0, 2500.0])       # mm, z up: 2.5 m walls around a 5 x 4 m floor


def test_example_writes_bodies_meshes_and_figure(run):
    out, res = run
    assert set(res["cases"]) == {"none", "mesh"} and res["config"]["cube_points"] > 20000
    for g, (rec,) in res["cases"].items():
        body = rec["body"]
        p = body["params"]
        assert [len(p[k]) for k in ("betas", "global_orient", "body_pose", "transl")] == [10, 3, 69, 3]
        assert len(body["joints"]) == 24 and body["units"] == "mm" and body["up"] == "z"
        assert body["frame"].startswith("scene")
        assert rec["mesh"] == f"meshes/frame/{g}_body.ply" and (out / rec["mesh"]).is_file()
    img = cv2.imread(str(out / res["figures"]["frame"]))[:, :, ::-1]
    assert img.shape == (2 * 480, 2 * 640, 3)                # a row per guide: camera view, side view
    frame = json.loads((EXAMPLE / "frame.json").read_text())
    for (u, v), c in zip(frame["keypoints"], frame["conf"]):
        if c > 0.9:                                          # drawn on top, nearly opaque: red at its centre
            r, gr, b = img[int(round(v)), int(round(u))].astype(int)
            assert r > 170 and gr < 90 and b < 90, (u, v, r, gr, b)


def test_record_params_rebuild_the_mesh_file_in_the_scan_frame(run):
    from volsmpl.body import create_body

    out, res = run
    T = np.asarray(json.loads((EXAMPLE / "frame.json").read_text())["world_to_camera"])
    body = create_body()
    for g, (rec,) in res["cases"].items():
        params = {k: torch.tensor([v], dtype=torch.float32) for k, v in rec["body"]["params"].items()}
        with torch.no_grad():
            posed = body(**params)
        v = posed.vertices[0].double().numpy()                 # the room's Y-up world, metres
        z_up_mm = np.stack([v[:, 0], -v[:, 2], v[:, 1]], 1) * 1000.0
        mesh = trimesh.load(out / rec["mesh"], process=False)
        assert np.allclose(mesh.vertices, z_up_mm, atol=0.05)  # within 0.05 mm
        pelvis_world = posed.joints[0, 0].double().numpy()
        assert np.allclose(T[:3, :3] @ pelvis_world + T[:3, 3], rec["pelvis"], atol=1e-4)
        if g == "none":                                      # unguided: the regressed pelvis
            assert np.allclose(rec["pelvis"], res["pelvis"], atol=1e-6)
        j = rec["body"]["pelvis"]
        assert np.allclose(j, [pelvis_world[0] * 1000, -pelvis_world[2] * 1000, pelvis_world[1] * 1000], atol=0.05)
        # the body overlays the scan: its pelvis over the chair, between the seat (416 mm) and 0.8 m
        assert np.linalg.norm(np.asarray(j[:2]) - CHAIR_MM) < 250 and 416 < j[2] < 800, j


@pytest.mark.parametrize("inside_any", [True, False])
def test_user_figure_draws_points_inside_the_body_red_in_both_views(tmp_path, inside_any):
    """A box as the body 3 m ahead of the camera, one scene point inside it and two beside it: the inside one red at
    its pinhole projection (by hand) in the camera view and somewhere in the side view; none red without it."""
    from types import SimpleNamespace

    from volsmpl.apps.egohmr.figures import user_figure

    box = trimesh.creation.box(extents=(0.6, 0.6, 0.6))
    v = np.asarray(box.vertices) + [0.0, 0.0, 3.0]
    joints = np.tile([0.25, 0.25, 2.7], (24, 1))
    points = np.array([[0.1, -0.1, 3.0], [0.5, 0.0, 3.0], [-0.5, 0.1, 3.0]])
    inside = np.array([inside_any, False, False])
    frame = SimpleNamespace(K=np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]), image_size=(480, 640),
                            keypoints=np.zeros((24, 2)), conf=np.zeros(24))
    user_figure(tmp_path / "f.png", frame, {"volsmpl": (v, joints, inside)}, np.asarray(box.faces), points,
                np.diag([1.0, -1.0, -1.0]))
    img = cv2.imread(str(tmp_path / "f.png"))[:, :, ::-1].astype(int)
    assert img.shape == (480, 1280, 3)
    red = (img[..., 0] > 180) & (img[..., 1] < 60) & (img[..., 2] < 60)
    u, w = 500.0 * 0.1 / 3.0 + 319.5, 500.0 * -0.1 / 3.0 + 239.5
    assert red[int(round(w)), int(round(u))] == inside_any
    assert red[:, 640:].any() == inside_any and red[:, :640].any() == inside_any
