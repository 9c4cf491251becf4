"""A user's scan of any size for `volsmpl motion --scene` (volsmpl.apps.motion.user_scene): the corridor a walk can
reach, its points at a spacing in metres (a small obstacle on the line gets its share of points), the floor found
among stray points; and the generated rooms' meshes written only with --save-meshes, from the stored record."""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from volsmpl.apps.motion import user_scene as U


def _temple(path, lantern_mm=((0.0, 0.0),), size_mm: float = 60_000.0) -> None:
    """A size x size floor (two triangles, z = 0, millimetres, z up) with 20 cm cube lanterns hanging 0.8-1.0 m
    above it at the given (x, y) positions: a temple's hall, reduced to what the test needs."""
    h = size_mm / 2
    floor = trimesh.Trimesh([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    parts = [floor] + [trimesh.creation.box(bounds=[[x - 100, y - 100, 800], [x + 100, y + 100, 1000]])
                       for x, y in lantern_mm]
    trimesh.util.concatenate(parts).export(path)


def test_the_corridor_is_the_reach_ellipse_box_widened_by_the_body():
    """An 80-frame walk reaches 2.2 m/s x 79 / 30 s = 5.793 m; ending within 0.5 m of the goal, its pelvis stays in
    the ellipse |p - s| + |p - g| <= 6.293 m. For s, g 3 m apart along x: semi-axes 3.147 m along the line and
    sqrt(3.147^2 - 1.5^2) = 2.766 m across, widened by 0.6 + 0.4 m. Turned 45 degrees, each half extent is
    sqrt((3.147^2 + 2.766^2) / 2) = 2.962 m (+ 1.0 m)."""
    a = (2.2 * 79 / 30 + 0.5) / 2
    b = np.sqrt(a * a - 1.5 ** 2)
    lo, hi = U.corridor([1.0, 2.0], [4.0, 2.0], 80)
    assert np.allclose(lo, [2.5 - a - 1.0, 2.0 - b - 1.0], atol=1e-9)
    assert np.allclose(hi, [2.5 + a + 1.0, 2.0 + b + 1.0], atol=1e-9)
    r = 3.0 / np.sqrt(2)
    lo, hi = U.corridor([0.0, 0.0], [r, r], 80)
    half = np.sqrt((a * a + b * b) / 2) + 1.0
    assert np.allclose(hi - lo, [2 * half, 2 * half], atol=1e-9) and np.allclose((lo + hi) / 2, [r / 2, r / 2])


def test_a_small_obstacle_on_the_line_of_a_large_scan_gets_its_points(tmp_path, capsys):
    """A 60 x 60 m hall (mm, z up) with a 20 cm lantern dead on the line between start and goal 3 m apart: at the
    default 5 cm spacing the lantern's 0.24 m^2 get 0.24 / 0.05^2 = 96 points (a 16,384-point cloud of the whole
    hall gave it 16,384 x 0.24 / 3,600 = 1); the floor inside the corridor one per 5 cm x 5 cm; a second lantern
    30 m away is left out."""
    path = tmp_path / "hall.ply"
    _temple(path, [(1500.0, 0.0), (30_000.0, 20_000.0)])
    sc = U.load_user_scene(path, (0, 0), (3000, 0), 80, up="z", units="mm")
    out = capsys.readouterr().out
    assert "up z, floor at 0.00 m along z" in out and "5 cm apart" in out
    P = sc.points
    lantern = P[(np.abs(P[:, 0] - 1.5) <= 0.1001) & (np.abs(P[:, 2]) <= 0.1001) & (P[:, 1] > 0.79)]
    assert len(lantern) == pytest.approx(0.24 / U.DEFAULT_SPACING_M ** 2, rel=0.25)
    assert (P[:, 1] > 0.79).sum() == len(lantern)          # the far lantern is outside the corridor
    lo, hi = U.corridor([0.0, 0.0], [3.0, 0.0], 80)
    area = float(np.prod(hi - lo))
    assert sc.floor.sum() == pytest.approx(area / U.DEFAULT_SPACING_M ** 2, rel=0.05)
    assert np.allclose(sc.pairs[0][0], [0.0, 0.0]) and np.allclose(sc.pairs[0][1], [3.0, 0.0])


def test_a_corridor_needing_too_many_points_names_a_spacing_that_fits(tmp_path, monkeypatch):
    path = tmp_path / "hall.ply"
    _temple(path)
    monkeypatch.setattr(U, "MAX_POINTS", 5000)
    with pytest.raises(ValueError, match=r"hall\.ply: .* give --spacing ([\d.]+) or more \(metres\)") as e:
        U.load_user_scene(path, (-1500, 0), (1500, 0), 80, up="z", units="mm")
    fit = float(str(e.value).split("--spacing ")[1].split(" ")[0])
    sc = U.load_user_scene(path, (-1500, 0), (1500, 0), 80, up="z", units="mm", spacing=fit)
    assert len(sc.points) <= 5000


def test_start_and_goal_outside_the_scene_are_refused_naming_the_corridor(tmp_path):
    """A 10 x 10 m hall (mm, z up) and a walk 20 m east of it: one line naming the corridor in the file's axes."""
    path = tmp_path / "hall.ply"
    _temple(path, size_mm=10_000.0)
    with pytest.raises(ValueError, match=r"hall\.ply: no scene points around --start and --goal \(the corridor x "
                                         r"17\.\d\.\.23\.\d, y -3\.\d\.\.3\.\d m\); pick positions inside the "
                                         r"scene") as e:
        U.load_user_scene(path, (20_000, 0), (21_000, 0), 50, up="z", units="mm")
    assert "\n" not in str(e.value)


def test_the_floor_is_found_among_stray_points_below_it(tmp_path, capsys):
    """A z-up cloud in metres: a floor at z = 0.30 m (5 cm grid), a 1 x 1 x 1 m block, and 1,500 stray points
    0.3-1.0 m under the floor (a scanner's noise): the 1st height percentile lies among the strays, the floor found
    at 0.30 m, the floor points at y = 0 and the block's top at 1 m above them."""
    rng = np.random.default_rng(0)
    g = np.arange(-4.0, 4.0001, 0.05)
    X, Y = np.meshgrid(g, g)
    floor = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 0.30)], 1)
    s = np.arange(0.0, 1.0001, 0.05)
    A, B = np.meshgrid(s, s)
    top = np.stack([A.ravel() + 1.0, B.ravel() - 0.5, np.full(A.size, 1.30)], 1)
    stray = np.stack([rng.uniform(-4, 4, 1500), rng.uniform(-4, 4, 1500), rng.uniform(-0.7, 0.0, 1500)], 1)
    pts = np.concatenate([floor, top, stray])
    assert np.percentile(pts[:, 2], 1) < 0.0     # where a low percentile would put the floor
    np.save(tmp_path / "scan.npy", pts)
    sc = U.load_user_scene(tmp_path / "scan.npy", (-2.0, 0.0), (0.5, 2.0), 80, up="z", units="m")
    assert sc.lift == pytest.approx(0.30, abs=0.01)
    assert "floor at 0.30 m along z" in capsys.readouterr().out
    assert np.abs(sc.points[sc.floor, 1]).max() < 0.03
    assert sc.points[:, 1].max() == pytest.approx(1.0, abs=0.03)
    assert sc.points[:, 1].min() > -0.1 - 1e-6       # the strays under the floor are left out


def _run(out, *extra):
    from volsmpl.cli import main

    argv = ["motion", "--model", "mesh", "--scenes", "1", "--sequences", "1", "--frames", "10", "--iters", "1",
            "--cost-frames", "1", "--cost-repeats", "1", "--render", "0", "--threads", "2", "--out", str(out)]
    assert main(argv + list(extra)) == 0
    return json.loads((out / "results.json").read_text())


def test_generated_rooms_write_meshes_only_with_save_meshes_and_from_the_record(tmp_path, capsys):
    """A table run writes no bodies into results.json and no mesh files; --resume --save-meshes reuses the stored
    walk and writes its mesh from the record (a stale file in its place is replaced); the mesh's vertices are the
    record's bodies rebuilt through a fresh volsmpl.body.create_body() (metres, Y up: the rooms' own frame)."""
    import torch
    import volsmpl

    out = tmp_path / "rooms"
    d = _run(out)
    (first,) = d["cases"]["mesh"]
    assert "body" not in first and "mesh" not in first and not (out / "meshes").exists()
    mesh = out / "meshes" / f"{first['scene']}_0" / "mesh_walk.ply"
    mesh.parent.mkdir(parents=True)
    mesh.write_bytes(b"stale")
    capsys.readouterr()
    d = _run(out, "--resume", "--save-meshes")
    assert "(reused)" in capsys.readouterr().out
    (rec,) = d["cases"]["mesh"]
    assert rec["metrics"] == first["metrics"]
    assert rec["mesh"] == {"path": f"meshes/{rec['scene']}_0/mesh_walk.ply", "frames": [0, 9]}
    got = np.asarray(trimesh.load(mesh, process=False).vertices)
    b = rec["body"]
    body = volsmpl.create_body()
    with torch.no_grad():
        ref = body(betas=torch.tensor([b["betas"]] * 2), global_orient=torch.tensor(b["global_orient"])[[0, 9]],
                   body_pose=torch.tensor(b["body_pose"])[[0, 9]], transl=torch.tensor(b["transl"])[[0, 9]]).vertices
    assert got.shape == (2 * ref.shape[1], 3)
    assert np.allclose(got, ref.reshape(-1, 3).double().numpy(), atol=1e-5)
    assert b["units"] == "m" and b["up"] == "y" and len(b["transl"]) == 10
