"""Training-state folders: files of at most 16 MiB, sha256-checked on resume, older folders still read, and a run
that continues exactly from a state written in shards (and on another device, where one is available)."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest
import torch

import volsmpl
import volsmpl.volume.models
from volsmpl.train import state as ts
from volsmpl.nn.config import VolumeConfig
from volsmpl.train.loop import WeightEMA, train
from volsmpl.train.config import TrainConfig

ROOT = Path(__file__).resolve().parents[2]

TINY = VolumeConfig(latent_dim=16, encoder_hidden=16, encoder_blocks=2, n_surface_samples=64, decoder_hidden=16, nbw_rank=2)


def tiny_cfg(**kw):
    kw = {"model": TINY, **kw}
    return TrainConfig(batch_size=2, n_uniform=16, n_surface=16, steps=1000, ckpt_every=2, log_every=1, **kw)


def test_shards_respect_the_limit_and_keep_every_tensor():
    tensors = {f"t{i}": torch.zeros(n) for i, n in enumerate([10, 30, 25, 5, 60, 1])}  # float32: 4 bytes each
    groups = ts.shard_tensors(tensors, limit=160)
    assert sorted(k for g in groups for k in g) == sorted(tensors)
    for g in groups:
        assert sum(tensors[k].numel() * 4 for k in g) <= 160 or len(g) == 1
    assert len(groups) == 4  # t0+t1 (160), t2+t3 (120), t4 (240 alone: above the limit), t5


@pytest.mark.parametrize("model_json", [volsmpl.volume.models.ASSETS / "volsmpl_anny.json",
                                        ROOT / "checkpoints" / "volsmpl_r3" / "ckpt-00057000" / "model.json"])
def test_full_size_state_files_stay_within_16_mib(tmp_path, model_json):
    """The shipped VolumetricSMPL configuration, and the one with two learned passes (its model file 16.71 MB), with
    a weight average and Adam's moments: every file <= 16 MiB, and reading the folder back restores the weights and
    moments bit for bit."""
    cfg_json = json.loads(open(model_json).read())
    cfg = TrainConfig.from_dict({**cfg_json["meta"]["training"]["train_config"], "keep_ckpts": 1})
    body = volsmpl.create_body()
    vol = volsmpl.attach_volume(body, pretrained=False, model=cfg.model_kind, config=cfg.model)
    opt = torch.optim.Adam(vol.net.parameters(), lr=1e-4)
    for p in vol.net.parameters():
        p.grad = torch.randn_like(p)
    opt.step()
    ema = WeightEMA(vol.net, 0.9)
    with torch.no_grad():
        for p in vol.net.parameters():
            p.add_(0.01)
    d = ts.save_training_state(tmp_path, 7, vol, opt, cfg, {"loss": 1.0, "train_seconds": 3.0}, ema)
    sizes = {f.name: f.stat().st_size for f in d.iterdir()}
    assert max(sizes.values()) <= ts.SHARD_BYTES, sizes
    assert sum(n.startswith("optimizer-") for n in sizes) >= 2  # Adam's 2 x 14 MB moments do not fit one file
    assert ts.latest_checkpoint(tmp_path) == d

    vol2 = volsmpl.attach_volume(body, pretrained=False, model=cfg.model_kind, config=cfg.model)
    got = ts.read_training_state(d, vol2, cfg)
    assert got["step"] == 7 and got["train_seconds"] == 3.0
    for k, v in vol.net.state_dict().items():
        assert torch.equal(vol2.net.state_dict()[k], v)
        assert torch.equal(got["ema_state"][k], ema.avg[k])
    opt2 = torch.optim.Adam(vol2.net.parameters(), lr=1e-4)
    ts.load_optimizer(opt2, *got["optimizer"])
    for p, q in zip(vol.net.parameters(), vol2.net.parameters()):
        for key in ("exp_avg", "exp_avg_sq", "step"):
            assert torch.equal(opt.state[p][key], opt2.state[q][key])


def test_resume_from_many_small_shards_continues_exactly(tmp_path, monkeypatch):
    cfg = tiny_cfg(ema_decay=0.9)
    full = train(cfg, tmp_path / "a", max_steps=4, quiet=True)
    monkeypatch.setattr(ts, "SHARD_BYTES", 4000)
    train(cfg, tmp_path / "b", max_steps=2, quiet=True)
    d = tmp_path / "b" / "ckpt-00000002"
    assert len(list(d.glob("optimizer-*"))) > 3 and len(list(d.glob("live-*"))) > 1
    resumed = train(cfg, tmp_path / "b", resume=True, max_steps=2, quiet=True)
    assert resumed["losses"] == pytest.approx(full["losses"][2:], rel=1e-5, abs=1e-7)


def test_damaged_or_missing_file_is_refused_with_the_fix(tmp_path):
    cfg = tiny_cfg()
    train(cfg, tmp_path / "a", max_steps=4, quiet=True)
    d = tmp_path / "a" / "ckpt-00000004"
    shard = sorted(d.glob("optimizer-*"))[0]
    raw = bytearray(shard.read_bytes())
    raw[-1] ^= 0xFF
    shard.write_bytes(bytes(raw))
    with pytest.raises(ts.TrainStateError, match=r"optimizer-00-of-01.*sha256.*ckpt-00000002"):
        train(cfg, tmp_path / "a", resume=True, max_steps=1, quiet=True)
    shard.unlink()
    with pytest.raises(ts.TrainStateError, match="missing"):
        train(cfg, tmp_path / "a", resume=True, max_steps=1, quiet=True)


def test_folder_written_before_state_json_still_resumes(tmp_path):
    """The layout of volsmpl before the split (optimizer.safetensors + optimizer.json without parameter ids,
    live.safetensors) continues exactly."""
    from safetensors.torch import load_file, save_file
    cfg = tiny_cfg(ema_decay=0.9)
    full = train(cfg, tmp_path / "a", max_steps=4, quiet=True)
    train(cfg, tmp_path / "b", max_steps=2, quiet=True)
    d = tmp_path / "b" / "ckpt-00000002"
    doc = json.loads((d / "state.json").read_text())
    opt = {k: v for f in doc["optimizer"]["files"] for k, v in load_file(str(d / f)).items()}
    live = {k: v for f in doc["live"] for k, v in load_file(str(d / f)).items()}
    save_file(opt, str(d / "optimizer.safetensors"))
    save_file(live, str(d / "live.safetensors"))
    groups = [{k: v for k, v in g.items() if k != "params"} for g in doc["optimizer"]["param_groups"]]
    (d / "optimizer.json").write_text(json.dumps({"param_groups": groups, "step": 2}))
    for f in doc["optimizer"]["files"] + doc["live"] + ["state.json"]:
        (d / f).unlink()
    resumed = train(cfg, tmp_path / "b", resume=True, max_steps=2, quiet=True)
    assert resumed["losses"] == pytest.approx(full["losses"][2:], rel=1e-5, abs=1e-7)
    assert (tmp_path / "b" / "ckpt-00000004" / "state.json").exists()  # written in the new layout from then on


def test_profile_cut_short_by_a_kill_is_repaired_on_resume(tmp_path):
    cfg = tiny_cfg()
    train(cfg, tmp_path / "a", max_steps=2, quiet=True)
    prof = tmp_path / "a" / "profile.jsonl"
    prof.write_text(prof.read_text() + json.dumps({"step": 3, "step_s": 1.0}) + "\n" + '{"step": 4, "ste')
    train(cfg, tmp_path / "a", resume=True, max_steps=1, quiet=True)
    steps = [json.loads(x)["step"] for x in prof.read_text().splitlines()]
    assert steps == [1, 2, 3]  # the rows of the killed run past its checkpoint and the half line are gone


@pytest.mark.cuda
def test_a_run_moves_between_cpu_and_cuda(tmp_path):
    """Written on the CPU, continued on CUDA (Adam's moments follow the weights there), then back on the CPU."""
    cfg = tiny_cfg(gt_backend="torch")
    train(cfg, tmp_path / "a", max_steps=2, quiet=True)
    r = train(cfg, tmp_path / "a", resume=True, max_steps=2, device="cuda", quiet=True)
    assert r["step"] == 4 and all(math.isfinite(x) for x in r["losses"])
    r = train(cfg, tmp_path / "a", resume=True, max_steps=2, device="cpu", quiet=True)
    assert r["step"] == 6 and all(math.isfinite(x) for x in r["losses"])
    shutil.rmtree(tmp_path / "a")


def test_pruning_keeps_the_newest_and_the_milestones(body, tmp_path):
    """keep_ckpts newest folders survive, and with keep_every those at multiples of it (a phase's end stays
    evaluable after the next phase resumed from it); without keep_every only the newest."""
    vol = volsmpl.attach_volume(body, pretrained=False, config=TINY)
    opt = torch.optim.Adam(vol.net.parameters(), lr=1e-4)
    for keep_every, left in ((4, [4, 8, 10]), (0, [10])):
        out = tmp_path / f"every{keep_every}"
        cfg = tiny_cfg(keep_ckpts=1, keep_every=keep_every)
        for step in (2, 4, 6, 8, 10):
            ts.save_training_state(out, step, vol, opt, cfg, {"loss": 1.0, "train_seconds": 1.0})
        assert sorted(int(p.name.split("-")[1]) for p in out.glob("ckpt-*")) == left
        assert ts.latest_checkpoint(out).name == "ckpt-00000010"
    with pytest.raises(ValueError, match="keep_every"):
        tiny_cfg(keep_every=-1)
