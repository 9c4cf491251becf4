"""The egocentric app end to end on two test frames: every guide samples, is scored by the exact tests and the
CLI writes results.json and a figure; a few training steps lower the loss; bad input gets one clear line."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import volsmpl
from volsmpl.apps.egohmr.data import make_frames
from volsmpl.apps.egohmr.evaluate import GuideOptions, prepare, sample_frames, summarize
from volsmpl.apps.egohmr.network import EgoConfig, EgoNet
from volsmpl.apps.egohmr.train import TrainSettings, losses, save_model
from volsmpl.apps.egohmr.diffusion import Schedule
from volsmpl.cli import main

TINY = EgoConfig(width=32, blocks=1, cond_width=16, scene_points=64)


@pytest.fixture(scope="module")
def frames():
    # generated with open3d's and libigl's checks, or their torch paths where they do not import (same frames)
    return make_frames("test", 2)


@pytest.fixture(scope="module")
def tiny_ckpt(tmp_path_factory, body):
    torch.manual_seed(0)
    net = EgoNet(TINY)
    out = tmp_path_factory.mktemp("egockpt")
    opt = torch.optim.Adam(net.parameters())
    save_model(out, net, opt, 0, torch.Generator(), TrainSettings(), body, {})
    return out, net


def test_every_guide_samples_two_frames(body, frames, tiny_ckpt):
    _, net = tiny_ckpt
    prep = prepare(net, body, frames, n_guide=2000)
    assert prep["guide_points"].shape == (2, 2000, 3)
    rows = {}
    for g, a in (("none", 0.0), ("volsmpl", 30.0), ("coap", 0.4), ("mesh", 30.0)):
        vol = None if g == "none" else volsmpl.attach_volume(volsmpl.create_body(), model=g)
        # two guided steps, one with Sigma_t and one plain (the default's ten repeat these two kinds)
        recs = sample_frames(net, body, frames, prep, vol, GuideOptions(scale=a, steps=2, plain_steps=1), batch=2)
        assert len(recs) == 2 and all(np.isfinite(r["mpjpe_mm"]) and np.isfinite(r["collision_ratio"]) for r in recs)
        rows[g] = summarize(recs)
    assert rows["none"]["n_frames"] == 2 and rows["none"]["mpjpe_mm"] > 0


def test_a_few_training_steps_lower_the_loss(body):
    from volsmpl.apps.egohmr.dataset import frame_tensors
    from volsmpl.apps.egohmr.pose import rest_joints

    torch.manual_seed(0)
    net = EgoNet(TINY)
    d = frame_tensors(make_frames("test", 5), n_scene=64)
    d["rest"] = rest_joints(body, d["betas"])
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    s = TrainSettings()
    first = None
    for i in range(60):
        terms = losses(net, body, d, Schedule(50), torch.Generator().manual_seed(i % 3), s)
        loss = sum(terms.values())
        first = loss.item() if first is None else first
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert loss.item() < 0.7 * first


@pytest.mark.slow
def test_cli_sample_writes_results_and_figures(tmp_path, tiny_ckpt):
    ckpt, _ = tiny_ckpt
    out = tmp_path / "out"
    rc = main(["egohmr", "sample", "--model", "none,volsmpl", "--frames", "2", "--checkpoint", str(ckpt),
               "--out", str(out), "--render", "1", "--batch", "2", "--budget-mb", "64", "--guide-steps", "2",
               "--plain-steps", "1"])
    assert rc == 0
    res = json.loads((out / "results.json").read_text())
    assert set(res["summary"]) == {"none", "volsmpl"} and res["paper"]["volsmpl"]["batch"] == 30
    for key in ("mpjpe_mm", "mpjpe_visible_mm", "pa_mpjpe_mm", "collision_ratio", "contact_pct", "s_per_frame",
                "max_batch", "peak_mem_mb", "n_frames"):
        assert key in res["summary"]["volsmpl"], key
    assert len(res["cases"]["volsmpl"]) == 2 and (out / res["figures"][res["cases"]["none"][0]["frame"]]).is_file()
    # each frame judged; the flagged list names exactly the frames whose status is not 'ok'; strict JSON
    from volsmpl.apps.egohmr.status import STATUSES

    recs = [(g, r) for g, rs in res["cases"].items() for r in rs]
    assert all(r["status"] in STATUSES and isinstance(r["status_why"], str) for _, r in recs)
    assert sorted((f["model"], f["case"]) for f in res["flagged"]) == \
        sorted((g, r["frame"]) for g, r in recs if r["status"] != "ok")
    assert res["warnings"] == []
    json.loads((out / "results.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in results.json"))


def test_bad_input_gets_one_line(tmp_path, capsys, tiny_ckpt):
    ckpt, _ = tiny_ckpt
    assert main(["egohmr", "sample", "--model", "volsmpl,foo", "--out", str(tmp_path / "o")]) == 2
    assert "unknown model(s) ['foo']" in capsys.readouterr().err
    assert main(["egohmr", "sample", "--checkpoint", str(tmp_path / "none"), "--out", str(tmp_path / "o")]) == 2
    assert "no egohmr checkpoint" in capsys.readouterr().err
    coap = str(volsmpl.volume.models.model_kind("coap").default_checkpoint)
    assert main(["egohmr", "sample", "--checkpoint", coap, "--frames", "1", "--out", str(tmp_path / "o")]) == 2
    assert "not an egohmr checkpoint" in capsys.readouterr().err
    assert main(["egohmr", "sample", "--scale", "volsmpl=abc", "--checkpoint", str(ckpt), "--out", str(tmp_path / "o")]) == 2
    assert "not a number" in capsys.readouterr().err
    assert main(["egohmr", "sample", "--model", "none,mesh", "--encoder-bf16", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "has none: add volsmpl or coap" in err and "\n" not in err
    assert main(["egohmr", "train", "--encoder-bf16", "--out", str(tmp_path / "o")]) == 2
    assert "applies to sample and tune, not train" in capsys.readouterr().err


def test_encoder_bf16_reaches_the_learned_guides_encoders(tmp_path, tiny_ckpt, encoder_bf16_calls):
    """sample --encoder-bf16: every PointNet call of the learned guides runs under bfloat16 autocast, and the
    result says so; without it none does."""
    ckpt, _ = tiny_ckpt
    seen = encoder_bf16_calls
    for flag in ([], ["--encoder-bf16"]):
        seen.clear()
        out = tmp_path / f"out{len(flag)}"
        # one guided step (plain): every guided step calls the encoders alike, and one keeps the emulated bfloat16
        # of a CPU without it cheap
        assert main(["egohmr", "sample", "--model", "volsmpl,coap", "--frames", "1", "--checkpoint", str(ckpt),
                     "--out", str(out), "--render", "0", "--batch", "1", "--no-max-batch", "--guide-steps", "1",
                     "--plain-steps", "1"] + flag) == 0
        assert seen and all(b == bool(flag) for b in seen)
        assert json.loads((out / "results.json").read_text())["config"]["encoder_bf16"] is bool(flag)


def test_resume_reuses_each_finished_guide_and_samples_again_on_other_settings(tmp_path, tiny_ckpt, capsys, monkeypatch):
    """sample --resume takes a guide's samples from OUT/cases/ when the same settings, frames and weights made them
    (the results equal the first run's), and samples again under another guidance scale."""
    import volsmpl.apps.egohmr.evaluate as E

    ckpt, _ = tiny_ckpt
    out = tmp_path / "out"
    argv = ["egohmr", "sample", "--model", "none,mesh", "--frames", "1", "--checkpoint", str(ckpt), "--out", str(out),
            "--render", "0", "--batch", "1", "--no-max-batch", "--threads", "1"]
    assert main(argv) == 0
    first = json.loads((out / "results.json").read_text())
    calls = []
    real = E.sample_frames
    # a guide's sampling passes its volume (None for 'none') after the inputs; the regressor's scoring does not
    monkeypatch.setattr(E, "sample_frames", lambda *a, **k: calls.append(len(a) > 4) or real(*a, **k))
    capsys.readouterr()
    assert main(argv + ["--resume"]) == 0
    assert capsys.readouterr().out.count("(reused)") == 2
    assert calls == [False]                               # only the regressor's scoring ran
    again = json.loads((out / "results.json").read_text())
    assert again["cases"] == first["cases"] and again["summary"].keys() == first["summary"].keys()
    for g in first["summary"]:
        assert {k: v for k, v in again["summary"][g].items() if k != "s_per_frame"} == \
               {k: v for k, v in first["summary"][g].items() if k != "s_per_frame"}
    assert main(argv + ["--resume", "--scale", "mesh=3"]) == 0
    assert "mesh     a=3" in capsys.readouterr().out and calls.count(True) == 1     # 'none' reused, mesh again


def test_user_frame_of_another_resolution_is_refused(tmp_path):
    """K, image_size and keypoints must describe one image: K for twice the resolution, [W, H] for [H, W] and a
    confident keypoint far outside the image are named; a keypoint out of view with confidence 0 is fine."""
    from volsmpl.apps.egohmr.userframe import load_user_frame

    rng = np.random.default_rng(0)
    H, W = 480, 640
    K = [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]
    kp = np.stack([rng.uniform(100, 460, 24), rng.uniform(50, 430, 24)], 1)
    doc = {"K": K, "image_size": [H, W], "keypoints": kp.tolist(), "conf": [0.9] * 24}

    def load(**change):
        (tmp_path / "f.json").write_text(json.dumps(dict(doc, **change)))
        return load_user_frame(tmp_path / "f.json")

    assert np.allclose(load().keypoints, kp)
    with pytest.raises(ValueError, match=r"principal point \(cx, cy\) = \(639, 479\) lies outside"):
        load(K=[[1000.0, 0, 639.0], [0, 1000.0, 479.0], [0, 0, 1]])
    swapped = kp.copy()
    swapped[0] = [600.0, 200.0]                     # inside a 640-wide image, outside a 480-wide one
    load(keypoints=swapped.tolist())
    with pytest.raises(ValueError, match=r"1 keypoints with a confidence above 0 lie outside the image \[H, W\] = "
                                         r"\[640, 480\] \(joint 0 at \(600, 200\)\)"):
        load(keypoints=swapped.tolist(), image_size=[W, H])
    far = kp.copy()
    far[5] = [-80.0, 100.0]
    with pytest.raises(ValueError, match="joint 5 at"):
        load(keypoints=far.tolist())
    conf = [0.9] * 24
    conf[5] = 0.0
    assert load(keypoints=far.tolist(), conf=conf).keypoints[5].tolist() == [0.0, 0.0]


@pytest.mark.slow
def test_user_frame_and_scan_run_end_to_end(tmp_path, frames, tiny_ckpt):
    """A generated frame written as a user's files: the room scan in world millimetres, the camera as
    world_to_camera; the run must read both and see the same camera-frame scene as the generator."""
    from volsmpl.apps.egohmr.data import scene_mesh
    from volsmpl.apps.egohmr.userframe import camera_points, load_user_frame
    from volsmpl.scene import make_room

    ckpt, _ = tiny_ckpt
    f = frames[0]
    room = make_room(f.room_seed).mesh()
    scan = room.copy()
    scan.apply_scale(1000.0)
    scan.export(tmp_path / "room.ply")
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = f.R, f.t
    doc = {"K": f.K.tolist(), "image_size": list(f.image_size), "keypoints": f.keypoints.tolist(),
           "conf": f.conf.tolist(), "world_to_camera": T.tolist()}
    (tmp_path / "frame.json").write_text(json.dumps(doc))
    uf = load_user_frame(tmp_path / "frame.json")
    cam_mesh = scene_mesh(f)
    assert np.allclose(camera_points(uf, np.asarray(room.vertices)), np.asarray(cam_mesh.vertices), atol=1e-6)
    from volsmpl.scene.scan import to_y_up
    v = np.asarray(room.vertices)
    z_up = np.stack([v[:, 0], -v[:, 2], v[:, 1]], 1)  # the same room as a z-up scan
    assert np.allclose(camera_points(uf, to_y_up(z_up, "z")), np.asarray(cam_mesh.vertices), atol=1e-6)
    out = tmp_path / "out"
    rc = main(["egohmr", "sample", "--frame", str(tmp_path / "frame.json"), "--scene", str(tmp_path / "room.ply"),
               "--units", "mm", "--model", "none,volsmpl", "--checkpoint", str(ckpt), "--out", str(out)])
    assert rc == 0
    res = json.loads((out / "results.json").read_text())
    assert set(res["summary"]) == {"none", "volsmpl"} and (out / "frame_frame.png").is_file()
    assert all(r[0]["status"] in ("ok", "diverged", "past_joint_limits", "penetrating", "far_from_keypoints")
               and r[0]["name"] == "frame" for r in res["cases"].values())
    assert isinstance(res["warnings"], list) and isinstance(res["flagged"], list)
    bad = dict(doc, keypoints=f.keypoints[:17].tolist())
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(ValueError, match="24 SMPL joints"):
        load_user_frame(tmp_path / "bad.json")
    (tmp_path / "nan.json").write_text(json.dumps(dict(doc, conf=[float("nan")] * 24)).replace("NaN", "NaN"))
    with pytest.raises(ValueError, match="NaN"):
        load_user_frame(tmp_path / "nan.json")


@pytest.mark.cuda
@pytest.mark.parametrize("device", ["cpu", "cuda"])
def test_sampling_gives_the_same_poses_on_every_device(body, frames, tiny_ckpt, device):
    """The same noise (drawn by the CPU generator) and network give the same guided samples on CPU and CUDA."""
    if device == "cuda" and not torch.cuda.is_available():
        pytest.skip("no CUDA GPU")
    from volsmpl.apps.egohmr.evaluate import draw

    _, net = tiny_ckpt
    ref = draw(net, body, prepare(net, body, frames, n_guide=500), volsmpl.attach_volume(volsmpl.create_body()),
               GuideOptions(scale=30.0), seed=3)[0]
    dev_net = EgoNet(TINY).to(device)
    dev_net.load_state_dict(net.state_dict())
    dev_body = volsmpl.create_body().to(device)
    d = prepare(dev_net, dev_body, frames, n_guide=500)
    x = draw(dev_net, dev_body, d, volsmpl.attach_volume(volsmpl.create_body()).to(device), GuideOptions(scale=30.0),
             seed=3)[0]
    assert x.device.type == device
    assert torch.allclose(x.cpu(), ref, atol=1e-3)


def test_a_diverged_sample_is_flagged_not_fatal(body, frames, tiny_ckpt):
    """A pose with NaN scores as diverged (no collision ratio, no contact) while the other frames are scored."""
    from volsmpl.apps.table import flag_cases

    _, net = tiny_ckpt
    prep = prepare(net, body, frames, n_guide=500)
    poses = prep["pose_reg"].clone()
    poses[1, 3] = float("nan")
    recs = sample_frames(net, body, frames, prep, batch=2, poses=poses)
    assert recs[0]["status"] != "diverged" and np.isfinite(recs[0]["collision_ratio"])
    assert recs[1]["status"] == "diverged" and np.isnan(recs[1]["collision_ratio"]) and recs[1]["contact"] is False
    assert flag_cases({"none": recs}, "frame", good={"ok"})[-1] == {
        "case": frames[1].name, "model": "none", "status": "diverged",
        "why": "the pose or the posed body holds NaN or Inf"}
    row = summarize(recs)                                 # a row with a diverged frame says so, loudly
    assert row["n_diverged"] == 1 and np.isnan(row["mpjpe_mm"]) and np.isnan(row["collision_ratio"])
    assert summarize(recs[:1])["n_diverged"] == 0 and np.isfinite(summarize(recs[:1])["mpjpe_mm"])


def test_by_activity_takes_each_activitys_frames_alone():
    """Per-activity rows by hand: two sitting frames (MPJPE 50 and 70 mm over 24 joints each, one in contact) and
    one standing frame; each row is the mean over its own frames only."""
    from volsmpl.apps.egohmr.evaluate import by_activity

    def rec(act, err, contact, coll):
        return {"activity": act, "mpjpe_mm": err, "mpjpe_visible_mm": err, "mpjpe_invisible_mm": np.nan,
                "n_visible": 24, "n_invisible": 0, "pa_mpjpe_mm": err / 2, "pelvis_err_mm": 100.0,
                "collision_ratio": coll, "contact": contact, "s_per_frame": 1.0}

    rows = by_activity([rec("sitting", 50.0, True, 0.01), rec("standing", 90.0, False, 0.0),
                        rec("sitting", 70.0, False, 0.03)])
    assert list(rows) == ["sitting", "standing"]
    assert rows["sitting"]["n_frames"] == 2 and rows["sitting"]["mpjpe_mm"] == pytest.approx(60.0)
    assert rows["sitting"]["pa_mpjpe_mm"] == pytest.approx(30.0)
    assert rows["sitting"]["contact_pct"] == pytest.approx(50.0)
    assert rows["sitting"]["collision_ratio"] == pytest.approx(0.02)
    assert rows["standing"]["mpjpe_mm"] == pytest.approx(90.0) and rows["standing"]["contact_pct"] == 0.0
