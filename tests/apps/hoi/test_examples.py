"""examples/hoi: the commands its README gives (make-case, then fit with few iterations) run on its files and write
what the README says: a valid case naming the mesh beside it, with the mask's pixels and the grasp region, and a
fit's results.json."""
from __future__ import annotations

import json
import re
import shlex
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from volsmpl.apps.hoi.case import load_case, object_mesh
from volsmpl.cli import main as cli_main

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "hoi"


def _readme_commands() -> list[list[str]]:
    """The README's `volsmpl hoi ...` commands (backslash continuations joined) as arguments, in order."""
    text = re.sub(r"\\\n\s*", " ", (EXAMPLE / "README.md").read_text())
    return [shlex.split(ln.strip())[1:] for ln in text.splitlines() if ln.strip().startswith("volsmpl hoi ")]


@pytest.mark.needs_checkpoint
def test_the_readme_commands_make_the_case_and_fit_it(tmp_path, monkeypatch, capsys):
    make, fit = _readme_commands()
    assert make[:2] == ["hoi", "make-case"] and fit[:2] == ["hoi", "fit"]
    for f in ("mug.obj", "pose.json", "camera.json", "mask.png", "object_pose.json"):
        shutil.copy(EXAMPLE / f, tmp_path / f)
    monkeypatch.chdir(tmp_path)  # the README runs in the example's folder
    assert cli_main(make) == 0
    line = capsys.readouterr().out.strip()
    assert len(line.splitlines()) == 1 and line.startswith("wrote mug_case.json: cup mug.obj")
    case = load_case(tmp_path / "mug_case.json")
    assert case.mesh_path == "mug.obj" and case.units == "mm" and case.contacts == [("left_hand", "grasp")]
    mesh, regions = object_mesh(case)
    assert mesh.extents.max() == pytest.approx(0.12, rel=1e-6) and 0 < len(regions["grasp"]) < len(mesh.faces)
    v, u = np.nonzero(cv2.imread("mask.png", cv2.IMREAD_GRAYSCALE) > 127)
    assert sorted(map(tuple, case.silhouette.astype(int).tolist())) == sorted(zip(u.tolist(), v.tolist()))
    fit = [*fit[: fit.index("--iters") + 1], "3", *fit[fit.index("--iters") + 2:]]
    assert cli_main([*fit, "--render", "0"]) == 0
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    rec = res["cases"]["volsmpl"][0]
    assert rec["name"] == "mug_case" and rec["iterations"] == 3 and np.isfinite(rec["loss"]).all()
