"""The example of examples/motion/README.md: its command, run through `volsmpl.cli.main` with fewer frames,
iterations and collision frames, gives the walk's bodies in results.json, a mesh file of them in the file's units and
axes, and the figures."""
from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "motion"
FAST = ["--frames", "30", "--iters", "1", "--coll-frames", "4", "--cost-frames", "1", "--cost-repeats", "1"]


def _command(out) -> list[str]:
    """The README's command (the line starting with `volsmpl motion`) as argv for volsmpl.cli.main, its --out
    replaced; the options appended later (FAST) override the README's, as argparse reads the last one."""
    lines = [ln.strip() for ln in (EXAMPLE / "README.md").read_text().splitlines()]
    (line,) = [ln for ln in lines if ln.startswith("volsmpl motion ")]
    argv = shlex.split(line)[1:]
    i = argv.index("--out")
    argv[i + 1] = str(out)
    return argv


FLOOR_MM = 120.0   # the example's floor: z = 120 mm (make_scene.py)


def test_the_example_scene_is_small_and_in_millimetres_z_up():
    path = EXAMPLE / "scene.ply"
    assert path.stat().st_size < 200_000
    lo, hi = trimesh.load(path, process=False).bounds
    assert np.allclose(lo, [-2500, -1800, FLOOR_MM]) and np.allclose(hi, [2500, 1800, FLOOR_MM + 2200])   # mm, z up


def test_the_readme_command_gives_bodies_meshes_and_figures(tmp_path, capsys):
    import volsmpl
    from volsmpl.cli import main

    out = tmp_path / "example"
    argv = _command(out)
    assert argv[0] == "motion" and "examples/motion/scene.ply" in argv
    rc = main([a.replace("examples/motion/scene.ply", str(EXAMPLE / "scene.ply")) for a in argv] + FAST)
    io = capsys.readouterr()
    assert rc == 0, io.err
    assert "up z, floor at 0.12 m along z" in io.out
    d = json.loads((out / "results.json").read_text())
    (rec,) = d["cases"]["volsmpl"]
    b = rec["body"]
    assert b["units"] == "mm" and b["up"] == "z" and b["frames"] == 30
    assert all(len(b[k]) == 30 for k in ("transl", "global_orient", "body_pose", "pelvis"))
    assert np.allclose(b["pelvis"][0][:2], [-1000.0, 0.0], atol=0.1)        # the walk starts at --start (mm, x y)
    assert 800.0 < b["pelvis"][0][2] - FLOOR_MM < 1100.0                      # a pelvis' height above the floor, z up
    # the mesh file: the record's bodies at frames 0, 10, 20, 29 rebuilt through a fresh body, turned by hand into
    # the file's frame (metres Y up -> millimetres z up: (x, y, z) -> 1000 (x, -z, y))
    assert rec["mesh"] == {"path": "meshes/scene_0/volsmpl_walk.ply", "frames": [0, 10, 20, 29]}
    got = np.asarray(trimesh.load(out / rec["mesh"]["path"], process=False).vertices)
    f = rec["mesh"]["frames"]
    with torch.no_grad():
        v = volsmpl.create_body()(betas=torch.tensor([b["betas"]] * len(f)),
                                  global_orient=torch.tensor(b["global_orient"])[f],
                                  body_pose=torch.tensor(b["body_pose"])[f], transl=torch.tensor(b["transl"])[f]).vertices
    v = v.double().numpy()
    want = 1000.0 * np.stack([v[..., 0], -v[..., 2], v[..., 1]], -1)
    assert got.shape == (want.shape[0] * want.shape[1], 3)
    assert np.allclose(got, want.reshape(-1, 3), atol=1e-3)
    soles = got.reshape(want.shape)[..., 2].min(1)
    assert np.all(np.abs(soles - FLOOR_MM) < 15.0)                            # feet on the example's floor
    assert set(d["figures"]) == {"topdown_scene", "strip_scene_0_volsmpl"}
    for name in d["figures"].values():
        assert (out / name).stat().st_size > 10_000
    assert d["config"]["units"] == "mm" and d["config"]["floor_found_m"] == pytest.approx(FLOOR_MM / 1000, abs=0.01)
