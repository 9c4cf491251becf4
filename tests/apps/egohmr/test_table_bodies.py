"""`volsmpl egohmr sample` on the generated split (a tiny network, one frame): each record holds its body, compact,
in the camera frame; mesh files only with --save-meshes, made from the record also when --resume reuses it, and none
left from an earlier run; a bar per batch and per denoising step on a terminal, none with --quiet. The mesh files
are checked against the record's params posed by `volsmpl.body.create_body()`."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import trimesh

from volsmpl.apps.egohmr.network import EgoConfig, EgoNet
from volsmpl.cli import main

TINY = EgoConfig(width=32, blocks=1, cond_width=16, scene_points=64)


@pytest.fixture(scope="module")
def tiny_ckpt(tmp_path_factory, body):
    from volsmpl.apps.egohmr.train import TrainSettings, save_model

    torch.manual_seed(0)
    net = EgoNet(TINY)
    out = tmp_path_factory.mktemp("egockpt")
    save_model(out, net, torch.optim.Adam(net.parameters()), 0, torch.Generator(), TrainSettings(), body, {})
    return out


def _argv(ckpt, out, *extra):
    return ["egohmr", "sample", "--model", "none,mesh", "--frames", "1", "--checkpoint", str(ckpt), "--out", str(out),
            "--render", "0", "--batch", "1", "--no-max-batch", "--threads", "1", "--guide-steps", "2",
            "--plain-steps", "1", *extra]


def test_meshes_only_with_save_meshes_made_from_the_record(tmp_path, tiny_ckpt, capsys):
    from volsmpl.body import create_body

    out = tmp_path / "out"
    assert main(_argv(tiny_ckpt, out)) == 0
    first = json.loads((out / "results.json").read_text())
    assert not (out / "meshes").exists()
    assert first["config"]["bodies"].startswith("camera")
    for g in ("none", "mesh"):
        (rec,) = first["cases"][g]
        assert "mesh" not in rec and len(rec["body"]["joints"]) == 24
        assert [len(rec["body"]["params"][k]) for k in ("betas", "global_orient", "body_pose", "transl")] == \
               [10, 3, 69, 3]
    capsys.readouterr()
    assert main(_argv(tiny_ckpt, out, "--resume", "--save-meshes")) == 0
    assert capsys.readouterr().out.count("(reused)") == 2         # the records reused, their meshes made
    res = json.loads((out / "results.json").read_text())
    body = create_body()
    files = {}
    for g in ("none", "mesh"):
        (rec,) = res["cases"][g]
        assert rec["body"] == first["cases"][g][0]["body"]
        params = {k: torch.tensor([v]) for k, v in rec["body"]["params"].items()}
        with torch.no_grad():
            posed = body(**params)
        files[g] = out / rec["mesh"]
        v = trimesh.load(files[g], process=False).vertices
        # params kept to 4 decimals, joints to the millimetre: the mesh within 2 mm of the params' body
        assert np.abs(v - posed.vertices[0].numpy()).max() < 2e-3
        assert np.abs(np.asarray(rec["body"]["joints"]) - posed.joints[0, :24].numpy()).max() < 2e-3
    good = files["mesh"].read_bytes()
    trimesh.creation.box().export(files["mesh"])                   # a stale file in its place
    assert main(_argv(tiny_ckpt, out, "--resume", "--save-meshes")) == 0
    assert files["mesh"].read_bytes() == good                      # made again from the reused record
    assert main(_argv(tiny_ckpt, out, "--resume")) == 0
    assert not (out / "meshes").exists()                           # none left that results.json does not describe


def test_bars_per_batch_and_denoising_step_on_a_terminal_only(tmp_path, tiny_ckpt, capsys, monkeypatch):
    import volsmpl.apps.progress as progress

    monkeypatch.setattr(progress, "shown", lambda quiet=False: not quiet)   # as on a terminal
    capsys.readouterr()
    assert main(_argv(tiny_ckpt, tmp_path / "a")) == 0
    err = capsys.readouterr().err
    assert "egohmr none" in err and "egohmr mesh: denoising" in err and "egohmr regressor" in err
    assert main(_argv(tiny_ckpt, tmp_path / "b", "--quiet")) == 0
    assert "egohmr" not in capsys.readouterr().err
