"""Training: loss definition, learning on a fixed batch, exact resume, micro-batching, DDP on gloo."""
from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys

import pytest
import torch

import volsmpl
from volsmpl.nn.config import VolumeConfig
from volsmpl.train.loop import TrainStep, _accumulate, sdf_loss, train
from volsmpl.train.batches import make_batch
from volsmpl.train.config import TrainConfig, lr_at

TINY = VolumeConfig(latent_dim=16, encoder_hidden=16, encoder_blocks=2, n_surface_samples=64, decoder_hidden=16, nbw_rank=2)


def tiny_cfg(**kw):
    kw = {"model": TINY, **kw}
    return TrainConfig(batch_size=2, n_uniform=16, n_surface=16, steps=1000, ckpt_every=2, log_every=1, **kw)


def test_loss_terms():
    cfg = TrainConfig()
    gt = torch.tensor([[0.05, -0.04, 0.1]])
    loss, parts = sdf_loss(gt.clone(), gt, cfg)  # perfect prediction
    assert parts["abs"] == 0 and parts["sign"] == 0
    wrong = -gt
    _, p2 = sdf_loss(wrong, gt, TrainConfig(residual="abs"))
    assert abs(p2["sign"] - 4.0) < 1e-3 and p2["abs"] == 0  # all signs wrong: (±1 ∓ 1)^2 = 4
    _, p2s = sdf_loss(wrong, gt, cfg)  # signed residual: (d~ - d)^2 = (2d)^2
    assert p2s["abs"] == pytest.approx(cfg.abs_weight * (4 * gt.square()).mean().item(), rel=1e-5)
    _, p3 = sdf_loss(gt + 0.01, gt, cfg)
    assert abs(p3["abs"] - cfg.abs_weight * 1e-4) < 1e-6
    # the sign term's gradient reaches wrong signs however far they are (straight-through), none for right ones
    pred = torch.tensor([[0.5, -0.04, 0.1]], requires_grad=True)  # first point: 50 cm on the wrong side
    l, _ = sdf_loss(pred, torch.tensor([[-0.05, -0.04, 0.1]]), TrainConfig(abs_weight=0.0))
    l.backward()
    assert pred.grad[0, 0] > 0 and pred.grad[0, 1] == 0 and pred.grad[0, 2] == 0


def test_logistic_sign_term():
    """sign_loss='logistic': sign_weight * mean softplus(-sgn(d) d~ / tau), by hand; an unresolved point (the same
    location labelled inside and outside) has its optimum at a graded value, not at a plateau's 0."""
    cfg = TrainConfig(sign_loss="logistic", sign_tau=0.002, sign_weight=0.5, abs_weight=0.0)
    gt = torch.tensor([[0.01, -0.004, 0.003]], dtype=torch.float64)
    pred = torch.tensor([[0.002, 0.001, -0.006]], dtype=torch.float64)
    _, parts = sdf_loss(pred, gt, cfg)
    by_hand = [math.log1p(math.exp(-y * p / 0.002)) for y, p in ((1, 0.002), (-1, 0.001), (1, -0.006))]
    assert parts["sign"] == pytest.approx(0.5 * sum(by_hand) / 3, rel=1e-9)
    # one location, labelled outside with probability 0.8 (4 of 5 samples): the minimiser is tau * log-odds
    x = torch.zeros(1, 1, dtype=torch.float64, requires_grad=True)
    labels = torch.tensor([[0.001, 0.001, 0.001, 0.001, -0.001]], dtype=torch.float64)
    opt = torch.optim.LBFGS([x], lr=1e-3, max_iter=200, tolerance_grad=1e-12, tolerance_change=1e-15,
                            line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        loss = sdf_loss(x.expand(1, 5), labels, cfg)[0]
        loss.backward()
        return loss
    opt.step(closure)
    assert float(x.detach()) == pytest.approx(0.002 * math.log(4.0), rel=1e-4)
    with pytest.raises(ValueError, match="sign_loss"):
        TrainConfig(sign_loss="hinge")
    with pytest.raises(ValueError, match="sign_tau"):
        TrainConfig(sign_tau=0.0)


def test_wrong_sign_fixed_point_only_with_abs_residual():
    # 3 cm outside, predicted 1 cm inside: eq. 3's literal |d| term cancels the sign term's gradient
    # (tau 1 cm, abs_weight 1e4: -4/tau + 2e4 (|d~| - |d|) sign(d~) = -400 + 400), the signed residual does not
    gt = torch.tensor([[0.03]], dtype=torch.float64)
    grads = {}
    for residual in ("abs", "signed"):
        pred = torch.tensor([[-0.01]], dtype=torch.float64, requires_grad=True)
        sdf_loss(pred, gt, TrainConfig(residual=residual))[0].backward()
        grads[residual] = float(pred.grad)
    assert grads["abs"] == pytest.approx(0.0, abs=1e-9)
    assert grads["signed"] < -100  # descent raises d~ towards the right (positive) side
    with pytest.raises(ValueError, match="residual"):
        TrainConfig.from_dict({"residual": "l1"})


def test_lr_schedule_and_config_roundtrip():
    cfg = TrainConfig(steps=100)
    assert lr_at(cfg, 0) == pytest.approx(1e-4) and lr_at(cfg, 100) == pytest.approx(1e-5)
    assert lr_at(cfg, 50) == pytest.approx(1e-4 * 0.1 ** 0.5)
    d = json.loads(json.dumps(cfg.to_dict()))
    assert TrainConfig.from_dict(d).to_dict() == cfg.to_dict()
    with pytest.raises(ValueError, match="unknown training config"):
        TrainConfig.from_dict({"batchsize": 3})


def test_batch_deterministic_and_ground_truth(body):
    cfg = tiny_cfg()
    part = volsmpl.Partition(body)
    a, b = make_batch(cfg, body, part, 5), make_batch(cfg, body, part, 5)
    assert torch.equal(a["points"], b["points"]) and torch.equal(a["sdf"], b["sdf"])
    assert not torch.equal(a["points"], make_batch(cfg, body, part, 6)["points"])
    K = part.num_parts
    assert a["points"].shape == (2, K * 32, 3)
    # ground truth against the exact generalised winding number sign on a subset
    from volsmpl.geometry.groundtruth import winding_number
    out = body(**a["params"])
    w = winding_number(out.vertices[0], body.faces, a["points"][0, ::8])
    inside = torch.as_tensor(w) > 0.5
    assert ((a["sdf"][0, ::8] < 0) == inside).float().mean() > 0.99


def test_batch_whole_body_surface_block(body):
    """n_body_surface appends area-weighted queries near the whole surface; the part blocks stay as they were."""
    import dataclasses
    cfg = tiny_cfg()
    part = volsmpl.Partition(body)
    a = make_batch(cfg, body, part, 5)
    c = make_batch(dataclasses.replace(cfg, n_body_surface=64, body_surface_sigma=(0.0,)), body, part, 5)
    n = a["points"].shape[1]
    assert c["points"].shape == (2, n + 64, 3) and torch.equal(c["points"][:, :n], a["points"])
    out = body(**c["params"])
    from volsmpl.geometry.groundtruth import mesh_sdf
    d = mesh_sdf(out.vertices[1].detach().numpy(), body.faces, c["points"][1, n:].numpy())
    assert abs(d).max() < 1e-6  # offsets 0: on the surface
    assert torch.allclose(c["sdf"][1, n:], torch.as_tensor(d, dtype=c["sdf"].dtype), atol=1e-6)


def test_micro_batches_give_the_full_batch_gradient(body):
    cfg = tiny_cfg()
    torch.manual_seed(0)
    vol = volsmpl.attach_volume(volsmpl.create_body(), pretrained=False, config=TINY)
    vol.train()
    step = TrainStep(vol, cfg)
    batch = make_batch(cfg, body, vol.partition, 0)
    grads = []
    for micro in (2, 1):
        vol.net.zero_grad()
        _accumulate(step, batch, micro, False)
        grads.append([p.grad.clone() for p in vol.net.parameters()])
    # micro=2 is one pass over both bodies with seed*7919; micro=1 uses other sample seeds per chunk,
    # so compare micro=1 against an explicit two-pass reference with the same seeds instead
    vol.net.zero_grad()
    loss = 0
    for i in range(2):
        sub = {"params": {k: v[i:i + 1] for k, v in batch["params"].items()},
               "posed": {k: v[i:i + 1] for k, v in batch["posed"].items()}, "points": batch["points"][i:i + 1],
               "sdf": batch["sdf"][i:i + 1], "seed": batch["seed"] * 7919 + i}
        l, _ = step(sub)
        (l / 2).backward()
    for g1, p in zip(grads[1], vol.net.parameters()):
        assert torch.allclose(g1, p.grad, atol=1e-6)


def test_learns_fixed_batch(body):
    cfg = tiny_cfg()
    torch.manual_seed(0)
    vol = volsmpl.attach_volume(volsmpl.create_body(), pretrained=False, config=TINY)
    vol.train()
    step = TrainStep(vol, cfg)
    batch = make_batch(cfg, body, vol.partition, 0)
    opt = torch.optim.Adam(vol.net.parameters(), lr=3e-3)
    losses = []
    for _ in range(60):
        opt.zero_grad()
        loss, _ = _accumulate(step, batch, 2, False)
        opt.step()
        losses.append(loss)
    assert sum(losses[-5:]) < 0.8 * sum(losses[:5]), losses[::10]


def test_resume_continues_exactly(tmp_path):
    cfg = tiny_cfg()
    full = train(cfg, tmp_path / "a", max_steps=4, quiet=True)
    train(cfg, tmp_path / "b", max_steps=2, quiet=True)
    resumed = train(cfg, tmp_path / "b", resume=True, max_steps=2, quiet=True)
    assert resumed["losses"] == pytest.approx(full["losses"][2:], rel=1e-5, abs=1e-7)
    assert (tmp_path / "b" / "latest").read_text() == "ckpt-00000004"
    with pytest.raises(FileExistsError, match="--resume"):
        train(cfg, tmp_path / "b", max_steps=1, quiet=True)
    # the checkpoint is a normal volsmpl checkpoint
    vol = volsmpl.attach_volume(volsmpl.create_body(), checkpoint=tmp_path / "b" / "ckpt-00000004" / "model")
    assert vol.meta["training"]["step"] == 4


def test_resume_drops_log_rows_past_the_checkpoint(tmp_path):
    cfg = dataclasses.replace(tiny_cfg(), log_every=1, ckpt_every=2)
    train(cfg, tmp_path / "a", max_steps=2, quiet=True)
    log = tmp_path / "a" / "log.csv"
    # a run that logged steps 3 and 4 and died before its next checkpoint
    log.write_text(log.read_text() + "3,1,1,0,1e-4,1,0\n4,1,1,0,1e-4,1,0\n")
    train(cfg, tmp_path / "a", resume=True, max_steps=2, quiet=True)
    steps = [int(ln.split(",")[0]) for ln in log.read_text().splitlines()[1:]]
    assert steps == [1, 2, 3, 4]
    assert b"\r" not in log.read_bytes()   # one line end throughout: the resumed run's rows as the kept ones


def test_time_budget_is_cumulative_over_resumes(tmp_path):
    cfg = dataclasses.replace(tiny_cfg(), ckpt_every=1000)
    r1 = train(cfg, tmp_path / "a", max_seconds=1e-9, quiet=True)  # any step spends the budget
    assert r1["step"] == 1 and (tmp_path / "a" / "latest").read_text() == "ckpt-00000001"
    meta = json.loads((tmp_path / "a" / "ckpt-00000001" / "model.json").read_text())["meta"]
    spent = meta["training"]["train_seconds"]
    assert spent > 0
    r2 = train(cfg, tmp_path / "a", resume=True, max_seconds=spent * 1.5 + 60, max_steps=2, quiet=True)
    assert r2["step"] == 3  # budget left: runs on (stopped by max_steps)
    meta = json.loads((tmp_path / "a" / "ckpt-00000003" / "model.json").read_text())["meta"]
    assert meta["training"]["train_seconds"] > spent
    r3 = train(cfg, tmp_path / "a", resume=True, max_seconds=spent / 2, quiet=True)  # spent already: no step
    assert r3["losses"] == [] and (tmp_path / "a" / "latest").read_text() == "ckpt-00000003"


@pytest.mark.slow
def test_ddp_two_processes_gloo(tmp_path):
    cfgf = tmp_path / "cfg.json"
    cfgf.write_text(json.dumps(tiny_cfg().to_dict()))
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2", "--standalone", "-m", "volsmpl.cli",  # --standalone: a free port
           "train", "--config", str(cfgf), "--out", str(tmp_path / "ddp"), "--max-steps", "2"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    assert (tmp_path / "ddp" / "latest").exists()
    rows = (tmp_path / "ddp" / "log.csv").read_text().strip().splitlines()
    assert len(rows) == 3  # header + 2 steps, written by rank 0 only


def test_init_from_model_checkpoint(tmp_path):
    """A new run started from a committed model checkpoint continues its weights and step."""
    cfg = tiny_cfg()
    train(cfg, tmp_path / "a", max_steps=2, quiet=True)
    r = train(cfg, tmp_path / "c", init=tmp_path / "a" / "ckpt-00000002" / "model", max_steps=1, quiet=True)
    assert r["step"] == 3
    with pytest.raises(ValueError, match="holds model config"):
        train(tiny_cfg(model=VolumeConfig()), tmp_path / "d", init=tmp_path / "a" / "ckpt-00000002" / "model", quiet=True)


def test_bad_loss_and_sign_options_fail_at_construction():
    with pytest.raises(ValueError, match="residual"):
        TrainConfig(residual="l1")
    with pytest.raises(ValueError, match="gt_sign"):
        TrainConfig(gt_sign="parity")
    with pytest.raises(ValueError, match="pose_mode"):
        TrainConfig(pose_mode="wild")
    with pytest.raises(ValueError, match="extreme_fraction"):
        TrainConfig(pose_mode="mixed", extreme_fraction=1.5)


def test_lr_anneal_start():
    cfg = TrainConfig(steps=300, anneal_start=100, lr=1e-4, lr_final=1e-5)
    assert lr_at(cfg, 0) == lr_at(cfg, 100) == pytest.approx(1e-4)
    assert lr_at(cfg, 200) == pytest.approx(1e-4 * 0.1 ** 0.5) and lr_at(cfg, 300) == pytest.approx(1e-5)
    with pytest.raises(ValueError, match="anneal_start"):
        TrainConfig(steps=100, anneal_start=100)
    with pytest.raises(ValueError, match="ema_decay"):
        TrainConfig(ema_decay=1.0)


def test_weight_ema_matches_hand_average():
    """The average follows avg += (1 - d_n)(w - avg), d_n = min(decay, (1+n)/(10+n)), buffers copied."""
    from volsmpl.train.loop import WeightEMA
    lin = torch.nn.Linear(2, 1)
    w0 = lin.weight.detach().clone()
    ema = WeightEMA(lin, decay=0.5)
    expect = w0.clone()
    for n in range(4):
        with torch.no_grad():
            lin.weight.add_(1.0)
        ema.update(lin)
        d = min(0.5, (1 + n) / (10 + n))
        expect = expect + (1 - d) * (lin.weight.detach() - expect)
    assert torch.allclose(ema.avg["weight"], expect) and not torch.allclose(expect, lin.weight)


def test_ema_checkpoint_publishes_the_average_and_resumes_exactly(tmp_path):
    from safetensors.torch import load_file
    cfg = tiny_cfg(ema_decay=0.9)
    full = train(cfg, tmp_path / "a", max_steps=4, quiet=True)
    train(cfg, tmp_path / "b", max_steps=2, quiet=True)
    resumed = train(cfg, tmp_path / "b", resume=True, max_steps=2, quiet=True)
    assert resumed["losses"] == pytest.approx(full["losses"][2:], rel=1e-5, abs=1e-7)  # optimised from live weights
    a, b = tmp_path / "a" / "ckpt-00000004", tmp_path / "b" / "ckpt-00000004"
    avg_a, avg_b = load_file(str(a / "model.safetensors")), load_file(str(b / "model.safetensors"))
    live = {k: v for f in sorted(a.glob("live-*.safetensors")) for k, v in load_file(str(f)).items()}
    assert live
    assert all(torch.allclose(avg_a[k], avg_b[k], atol=1e-6) for k in avg_a)  # the average resumes too
    assert any(not torch.allclose(avg_a[k], live[k]) for k in avg_a)  # and it is not the live weights
    assert json.loads((b / "model.json").read_text())["meta"]["training"]["ema_updates"] == 4
    with pytest.raises(ValueError, match="ema_decay"):
        train(dataclasses.replace(cfg, ema_decay=0.0), tmp_path / "b", resume=True, max_steps=1, quiet=True)


def test_worker_processes_give_the_serial_batches(tmp_path):
    """Batches made by two DataLoader worker processes are those of the serial loop: same losses."""
    serial = train(tiny_cfg(), tmp_path / "a", max_steps=3, quiet=True)
    workers = train(tiny_cfg(num_workers=2), tmp_path / "b", max_steps=3, quiet=True)
    assert workers["losses"] == pytest.approx(serial["losses"], rel=1e-6, abs=1e-8)
    with pytest.raises(ValueError, match="num_workers"):
        TrainConfig(num_workers=-1)


# ------------------------------------------------------------------ training on any device
def test_torch_ground_truth_batch_matches_open3d(body):
    """gt_backend='torch' gives the open3d batch: same points, exact signs away from the surface, distances to 1e-6 m."""
    pytest.importorskip("open3d")
    cfg = tiny_cfg(gt_backend="open3d")
    part = volsmpl.Partition(body)
    a = make_batch(cfg, body, part, 3)
    b = make_batch(dataclasses.replace(cfg, gt_backend="torch"), body, part, 3)
    assert torch.equal(a["points"], b["points"]) and b["sdf"].dtype == a["sdf"].dtype
    far = a["sdf"].abs() > 1e-3
    assert torch.equal(a["sdf"][far] < 0, b["sdf"][far] < 0)
    assert (a["sdf"].abs() - b["sdf"].abs()).abs().max() < 1e-6
    assert set(b["timing"]) == {"make_s", "gt_s"} and 0 <= b["timing"]["gt_s"] <= b["timing"]["make_s"]


def test_batches_build_without_open3d(body, monkeypatch, tmp_path):
    """With open3d unimportable, 'auto' takes the torch ground truth and training batches (and steps) still run."""
    import sys
    from volsmpl.geometry.groundtruth import resolve_gt_backend
    monkeypatch.setitem(sys.modules, "open3d", None)  # `import open3d` raises ImportError
    assert resolve_gt_backend("auto", "cpu") == "torch"
    with pytest.raises(ImportError, match="gt_backend='torch'"):
        resolve_gt_backend("open3d", "cpu")
    cfg = tiny_cfg()
    batch = make_batch(cfg, body, volsmpl.Partition(body), 2)
    assert batch["sdf"].shape == batch["points"].shape[:2] and torch.isfinite(batch["sdf"]).all()
    assert (batch["sdf"] < 0).any() and (batch["sdf"] > 0).any()
    res = train(cfg, tmp_path / "r", max_steps=2, quiet=True)
    assert res["step"] == 2 and all(math.isfinite(x) for x in res["losses"])


def test_profile_log_has_the_step_breakdown(tmp_path):
    train(tiny_cfg(gt_backend="torch"), tmp_path / "p", max_steps=2, quiet=True)
    rows = [json.loads(x) for x in (tmp_path / "p" / "profile.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [1, 2]
    for r in rows:
        assert r["device"] == "cpu" and 0 <= r["gt_s"] <= r["make_s"] <= r["data_s"] + 1e-3
        assert r["step_s"] == pytest.approx(r["data_s"] + r["fwd_bwd_s"] + r["opt_s"], abs=1e-5)
        assert 0 < r["gt_share"] < 1


def test_batch_on_an_explicit_cpu_device_is_the_default_batch(body):
    from volsmpl.train.batches import batch_stream
    cfg = tiny_cfg()
    part = volsmpl.Partition(body)
    a = next(batch_stream(cfg, body, part, 4, 5))
    b = next(batch_stream(cfg, body, part, 4, 5, device=torch.device("cpu")))
    assert torch.equal(a["points"], b["points"]) and torch.equal(a["sdf"], b["sdf"])
    with pytest.raises(ValueError, match="num_workers=0"):
        batch_stream(dataclasses.replace(cfg, num_workers=1), body, part, 0, 1, device="meta")


@pytest.mark.cuda
def test_batches_stay_on_cuda(body):
    from volsmpl.train.batches import batch_stream
    cfg = tiny_cfg(gt_backend="auto")
    b = next(batch_stream(cfg, body, volsmpl.Partition(body), 0, 1, device="cuda"))
    tensors = [b["points"], b["sdf"], *b["params"].values(), *b["posed"].values()]
    assert all(t.device.type == "cuda" for t in tensors)
    c = next(batch_stream(cfg, body, volsmpl.Partition(body), 0, 1, device="cuda"))
    assert torch.equal(b["points"], c["points"]) and torch.equal(b["sdf"], c["sdf"])  # seeded on the device
    ref = make_batch(dataclasses.replace(cfg, gt_backend="torch"), body, volsmpl.Partition(body), 0)  # CPU
    assert b["sdf"].shape == ref["sdf"].shape


@pytest.mark.cuda
def test_five_training_steps_on_cuda_with_the_torch_ground_truth(tmp_path):
    res = train(tiny_cfg(gt_backend="torch"), tmp_path / "c", max_steps=5, device="cuda", quiet=True)
    assert res["step"] == 5 and all(math.isfinite(x) for x in res["losses"])
    rows = [json.loads(x) for x in (tmp_path / "c" / "profile.jsonl").read_text().splitlines()]
    assert len(rows) == 5 and all(r["device"].startswith("cuda") for r in rows)


def test_cli_set_takes_string_values_and_config_errors_name_the_file(tmp_path, capsys):
    """`--set gt_backend=torch` (README) and `--set gt_sign=fast_winding` ended in 'Expecting value: line 1 column 1
    (char 0)' (a value starting with t or f was parsed as JSON); a bad --config file or --set item gave json's bare
    message without the file or the option. Strings are kept; each problem is one line naming the input."""
    from volsmpl.cli import main

    cfgf = tmp_path / "tiny.json"
    cfgf.write_text(json.dumps(tiny_cfg().to_dict()))
    run = tmp_path / "run"
    assert main(["train", "--config", str(cfgf), "--out", str(run), "--max-steps", "0", "--device", "cpu",
                 "--set", "gt_backend=torch", "gt_sign=fast_winding", "batch_size=3", "surface_sigma=[0.02]"]) == 0
    saved = json.loads((run / "config.json").read_text())
    assert (saved["gt_backend"], saved["gt_sign"], saved["batch_size"], saved["surface_sigma"]) == \
        ("torch", "fast_winding", 3, [0.02])
    capsys.readouterr()
    (tmp_path / "list.json").write_text("[1, 2]")
    (tmp_path / "bad.json").write_text("{bad")
    for argv, words in [(["--config", str(tmp_path / "bad.json")], ["bad.json", "not valid JSON"]),
                        (["--config", str(tmp_path / "list.json")], ["list.json", "JSON list"]),
                        (["--config", str(tmp_path / "none.json")], ["none.json", "cannot read"]),
                        (["--set", "batch_size"], ["--set 'batch_size'", "KEY=VALUE"]),
                        (["--set", "model={bad"], ["--set model", "not valid JSON"])]:
        assert main(["train", "--out", str(tmp_path / "r2"), "--max-steps", "0", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and all(w in err for w in words), err


def test_cli_resume_and_init_take_the_checkpoints_training_config(tmp_path, capsys):
    """A run folder holding only a copied checkpoint folder (mkdir, cp -r ckpt-N, echo ckpt-N > latest) resumes with
    the checkpoint's training config, not the defaults (with which the run would be refused for its model config, or
    go on with the default network, batch 8, 450k steps, ...); `--init CKPT.json` takes the path as given (not
    CKPT.json.json); `--init CKPT --set k=v` trains on the checkpoint's config, not the defaults. All three start
    from the checkpoint's recorded training config (meta.training.train_config), --set on top."""
    import shutil

    from volsmpl.cli import main

    cfg = tiny_cfg()
    train(cfg, tmp_path / "a", max_steps=2, quiet=True)
    b = tmp_path / "b"
    b.mkdir()
    shutil.copytree(tmp_path / "a" / "ckpt-00000002", b / "ckpt-00000002")
    (b / "latest").write_text("ckpt-00000002")
    assert main(["train", "--resume", "--out", str(b), "--max-steps", "1", "--device", "cpu",
                 "--set", "num_threads=1"]) == 0, capsys.readouterr().err
    assert json.loads((b / "config.json").read_text()) == {**cfg.to_dict(), "num_threads": 1}
    assert (b / "latest").read_text() == "ckpt-00000003"
    c = tmp_path / "c"
    assert main(["train", "--init", str(tmp_path / "a" / "ckpt-00000002" / "model.json"), "--out", str(c),
                 "--max-steps", "1", "--device", "cpu", "--set", "lr=5e-5"]) == 0, capsys.readouterr().err
    assert json.loads((c / "config.json").read_text()) == {**cfg.to_dict(), "lr": 5e-5}
    assert (c / "latest").read_text() == "ckpt-00000003"
    # --init beside --resume of a run that has a checkpoint continues the run, and says that --init is not used
    capsys.readouterr()
    assert main(["train", "--init", str(tmp_path / "a" / "ckpt-00000002" / "model"), "--resume", "--out", str(c),
                 "--max-steps", "1", "--device", "cpu"]) == 0
    assert "is not used: --resume continues" in capsys.readouterr().err
    assert (c / "latest").read_text() == "ckpt-00000004"


def test_nothing_to_train_is_said_not_done_step_none(tmp_path, capsys):
    """--init from a checkpoint at the end of its schedule (e.g. the shipped COAP, step 5,735 of 5,735) trained nothing
    and printed 'done: step None loss None' (exit 0); so did --resume of a finished run. The first is refused in one
    line naming the fix, the second says where the run stands."""
    from volsmpl.cli import main

    cfg = dataclasses.replace(tiny_cfg(), steps=2)
    train(cfg, tmp_path / "a", quiet=True)
    with pytest.raises(ValueError, match="is at step 2 and the training config ends at steps=2: nothing to train"):
        train(cfg, tmp_path / "c", init=tmp_path / "a" / "ckpt-00000002" / "model", quiet=True)
    assert main(["train", "--init", str(tmp_path / "a" / "ckpt-00000002" / "model"), "--out", str(tmp_path / "d"),
                 "--device", "cpu"]) == 2
    assert "--set steps=" in capsys.readouterr().err
    assert main(["train", "--resume", "--out", str(tmp_path / "a"), "--device", "cpu"]) == 0
    out = capsys.readouterr().out
    assert "None" not in out and "nothing to train" in out and "step 2" in out


def test_cli_resume_names_the_config_fields_it_changes(tmp_path, capsys):
    """--resume with a --config or --set that differs from the checkpoint's training config continued a different run
    without a word; the changed fields are now named on stderr (the change itself stays allowed: new phases use it)."""
    from volsmpl.cli import main

    cfg = tiny_cfg()
    train(cfg, tmp_path / "a", max_steps=2, quiet=True)
    assert main(["train", "--resume", "--out", str(tmp_path / "a"), "--max-steps", "1", "--device", "cpu",
                 "--set", "lr=5e-5"]) == 0
    err = capsys.readouterr().err
    assert "changed training config" in err and "lr 0.0001 -> 5e-05" in err
    assert main(["train", "--resume", "--out", str(tmp_path / "a"), "--max-steps", "1", "--device", "cpu"]) == 0
    assert "changed" not in capsys.readouterr().err  # the run's own config (now with lr 5e-5): nothing to say
