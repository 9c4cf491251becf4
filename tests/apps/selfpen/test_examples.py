"""examples/selfpen: the command its README gives runs on my_bodies.json (with few iterations) and writes what the
README says: results.json with each body's repaired and starting parameters, the mesh files and the figures."""
from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from volsmpl.body import create_body
from volsmpl.cli import main as cli_main

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "selfpen"


def _readme_command() -> list[str]:
    """The README's `volsmpl selfpen ...` line as arguments (without the program name)."""
    lines = [ln.strip() for ln in (EXAMPLE / "README.md").read_text().splitlines()
             if ln.strip().startswith("volsmpl selfpen --case-file")]
    assert len(lines) == 1, lines
    return shlex.split(lines[0])[1:]


@pytest.mark.needs_checkpoint
def test_the_readme_command_repairs_the_example_bodies(tmp_path, monkeypatch):
    argv = _readme_command()
    assert argv[argv.index("--case-file") + 1] == "examples/selfpen/my_bodies.json"
    argv[argv.index("--out") + 1] = str(tmp_path / "out")
    monkeypatch.chdir(EXAMPLE.parents[1])   # the README runs from the repository root
    assert cli_main(argv + ["--max-iters", "1", "--n-points", "64", "--threads", "1"]) == 0
    out = tmp_path / "out"
    res = json.loads((out / "results.json").read_text())
    bodies = json.loads((EXAMPLE / "my_bodies.json").read_text())["cases"]
    recs = res["cases"]["volsmpl"]
    assert [r["name"] for r in recs] == [b["name"] for b in bodies] and len(bodies) >= 2
    reference = create_body()
    for b, r in zip(bodies, recs):
        assert r["collisions_before"] > 0                                   # the example bodies do self-intersect
        assert r["start_params"]["body_pose"] == pytest.approx(b["body_pose"], abs=1e-6)
        assert r["body"]["params"]["betas"] == pytest.approx(b["betas"], abs=1e-6)
        assert len(r["body"]["params"]["body_pose"]) == 69 and "pelvis" in r["body"]["joints"]
        assert r["meshes"] == {"before": f"meshes/{b['name']}/volsmpl_before.ply",
                               "after": f"meshes/{b['name']}/volsmpl_after.ply"}
        p = r["body"]["params"]
        with torch.no_grad():
            v = reference(betas=torch.tensor([p["betas"]]), global_orient=torch.tensor([p["global_orient"]]),
                          body_pose=torch.tensor([p["body_pose"]])).vertices[0].numpy()
        after = np.asarray(trimesh.load(out / r["meshes"]["after"], process=False).vertices)
        np.testing.assert_allclose(after, v, atol=1e-5)
        assert (out / r["meshes"]["before"]).is_file()
    assert sorted(res["figures"].values()) == sorted(f"render_{b['name']}.png" for b in bodies)
    assert all((out / f).stat().st_size > 1000 for f in res["figures"].values())
