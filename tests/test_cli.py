"""The `volsmpl` command: body info/pose, demo outputs, clear errors with exit code 2."""
from __future__ import annotations

import numpy as np
import trimesh

from volsmpl.cli import main


def test_body_info(capsys):
    assert main(["body", "info"]) == 0
    out = capsys.readouterr().out
    assert "K=16" in out and "fingerprint" in out and "left_forearm" in out


def test_body_pose_writes_mesh(tmp_path, body):
    f = tmp_path / "sit.ply"
    assert main(["body", "pose", "--pose", "sitting", "--out", str(f)]) == 0
    m = trimesh.load(f, process=False)
    assert m.vertices.shape == body.v_template.shape and m.is_watertight


def test_demo_outputs(tmp_path):
    assert main(["demo", "--out", str(tmp_path), "--poses", "t_pose", "squatting"]) == 0
    assert (tmp_path / "poses" / "t_pose.ply").exists() and (tmp_path / "poses" / "squatting.ply").exists()
    import cv2
    img = cv2.imread(str(tmp_path / "parts.png"))
    assert img is not None and img.shape[0] > 100
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 16  # parts coloured, not blank


def test_user_errors_exit_2(tmp_path, capsys):
    assert main(["body", "pose", "--pose", "moonwalk", "--out", str(tmp_path / "x.ply")]) == 2
    assert "unknown pose" in capsys.readouterr().err
    assert main(["body", "info", "--model", str(tmp_path / "missing.npz")]) == 2
    assert "not found" in capsys.readouterr().err


def test_demo_with_checkpoint_writes_sdf_slice(tmp_path):
    import volsmpl
    from volsmpl.io.checkpoint import save_checkpoint
    from volsmpl.nn.config import VolumeConfig
    cfg = VolumeConfig(latent_dim=16, encoder_hidden=16, encoder_blocks=2, n_surface_samples=64, decoder_hidden=16, nbw_rank=2)
    vol = volsmpl.attach_volume(volsmpl.create_body(), pretrained=False, config=cfg)
    save_checkpoint(tmp_path / "m", vol.net.state_dict(), cfg.to_dict(), {"body_fingerprint": vol.fingerprint})
    assert main(["demo", "--out", str(tmp_path / "o"), "--poses", "t_pose", "--checkpoint", str(tmp_path / "m"),
                 "--resolution", "24"]) == 0
    import cv2
    img = cv2.imread(str(tmp_path / "o" / "sdf_slice.png"))
    assert img is not None and (img[..., 1] > 100).any()  # the green true-mesh section is drawn


def test_help_lists_every_subcommand_and_imports_only_the_chosen_one():
    import subprocess
    import sys

    code = ("import sys\nfrom volsmpl.cli import main, SUBCOMMANDS\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m, _ in SUBCOMMANDS.values() if m in sys.modules]\n"
            "print('HEAVY', heavy)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    for name in ("bench", "body", "demo", "eval", "selfpen", "train"):
        assert name in r.stdout
    assert "HEAVY []" in r.stdout
