"""Device paths: every test here runs on the CPU and, marked `cuda`, again on a GPU when one is present
(`pytest -m cuda` runs only the GPU variants; skipped without a GPU). Also: --device that this machine cannot run
on is refused in one line, and the attached volume moves with its body."""
from __future__ import annotations

import json

import pytest
import torch

import volsmpl
from conftest import random_pose
from volsmpl.cli import main

DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.cuda)]


@pytest.mark.parametrize("device", DEVICES)
def test_query_and_gradients_dense_equal_sparse(tiny_config, device):
    torch.manual_seed(0)
    b = volsmpl.create_body().to(device)
    vol = volsmpl.attach_volume(b, pretrained=False, config=tiny_config)
    assert vol.device.type == device  # attached where the body is
    p = {k: v.to(device).requires_grad_(True) for k, v in random_pose(2, seed=3).items()}
    out = b(**p)
    g = torch.Generator().manual_seed(1)
    idx = torch.randint(0, out.vertices.shape[1], (500,), generator=g)
    pts = (out.vertices.detach()[:, idx] + 0.04 * torch.randn(2, 500, 3, generator=g).to(device)).requires_grad_(True)
    res = {}
    for dense in (False, True):
        d = vol.query(out, pts, dense=dense)
        gp, gx = torch.autograd.grad(d.square().sum(), [p["body_pose"], pts], retain_graph=True)  # encoding cached on out
        res[dense] = (d.detach(), gp, gx)
    for a, e in zip(res[False], res[True]):
        assert a.device.type == device
        assert torch.allclose(a, e, atol=1e-5, rtol=1e-4)
    if device != "cpu":  # the same field on the CPU
        cb = volsmpl.create_body()
        cv = volsmpl.attach_volume(cb, pretrained=False, config=tiny_config)
        cv.load_state_dict(vol.state_dict())
        with torch.no_grad():
            ref = cv.query(cb(**{k: v.detach().cpu() for k, v in p.items()}), pts.detach().cpu())
        assert torch.allclose(res[False][0].cpu(), ref, atol=1e-5)


@pytest.mark.parametrize("device", DEVICES)
def test_selfpen_end_to_end_two_cases(tmp_path, device):
    rc = main(["selfpen", "--model", "volsmpl,coap", "--cases", "forearm_through_torso_left,arm_through_head",
               "--random-init", "--max-iters", "1", "--n-points", "32", "--threads", "1", "--device", device,
               "--out", str(tmp_path), "--render", "0"])
    assert rc == 0
    res = json.loads((tmp_path / "results.json").read_text())
    for m in ("volsmpl", "coap"):
        assert [c["name"] for c in res["cases"][m]] == ["forearm_through_torso_left", "arm_through_head"]
        assert all(c["collisions_before"] > 0 for c in res["cases"][m])


@pytest.mark.parametrize("device", DEVICES)
def test_bench_quick(tmp_path, device):
    out = tmp_path / "bench.json"
    rc = main(["bench", "--device", device, "--points", "1000", "--batch", "1", "--repeats", "1", "--warmup", "1",
               "--threads", "1", "--models", "volsmpl", "--no-bodybody", "--matmul-size", "128",
               "--quick", "--out", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())
    assert res["meta"]["device"].startswith(device)


@pytest.mark.parametrize("device", DEVICES)
def test_volume_moves_with_its_body(tiny_config, device):
    """body.to(...) after attach_volume moves the attached volume too (dtype on the CPU, the device on a GPU)."""
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, pretrained=False, config=tiny_config)
    b.to(torch.float64)
    assert all(t.dtype == torch.float64 for t in [*vol.parameters(), vol.partition.sample_bary])
    b.to(device)
    assert vol.device.type == device and next(vol.parameters()).device.type == device
    p = {k: v.to(device) for k, v in random_pose(1, seed=2, dtype=torch.float64).items()}
    with torch.no_grad():
        out = b(**p)
        d = b.volume.query(out, out.vertices[:, ::100])
    assert d.dtype == torch.float64 and d.device.type == device and torch.isfinite(d).all()
    b.float().cpu()
    assert next(vol.parameters()).dtype == torch.float32 and vol.device.type == "cpu"
    assert len(list(b.parameters())) == 0 and not any(k.startswith("volume") for k in b.state_dict())


@pytest.mark.parametrize("model", ["volsmpl", "mesh"])
def test_moves_for_every_kind(model):
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, pretrained=False, model=model) if model != "mesh" else volsmpl.attach_volume(b, model=model)
    b.double()
    assert vol.partition.sample_bary.dtype == torch.float64


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal on a machine without CUDA")
@pytest.mark.parametrize("command", [["eval"], ["bench", "--quick"], ["selfpen"], ["hoi", "fit"], ["motion"], ["train"]])
def test_device_cuda_without_cuda_is_one_line(tmp_path, capsys, command):
    rc = main([*command, "--device", "cuda", "--out", str(tmp_path / "o")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2 and len(err) == 1 and "CUDA is not available" in err[0] and "--device cpu" in err[0], err


def test_check_device_names():
    from volsmpl.runtime.devices import check_device
    assert check_device("cpu") == torch.device("cpu")
    with pytest.raises(ValueError, match="not a device name"):
        check_device("gpu0")
    with pytest.raises(ValueError, match="cpu or cuda"):
        check_device("meta")
    if torch.cuda.is_available():
        with pytest.raises(ValueError, match="GPU"):
            check_device(f"cuda:{torch.cuda.device_count()}")


@pytest.mark.cuda
@pytest.mark.parametrize("precision", ["full", "bf16"])
@pytest.mark.parametrize("call,most", [("query_encoded", 1), ("query", 3)])
def test_query_host_syncs_on_cuda(precision, call, most):
    """On CUDA a query on an encoding synchronises with the host once (the lean path's read of its pair counts);
    `query` at most three times: the encoding cache's fingerprint, the check that the cached encoding has every
    part a point needs (a subset encoding here), and that one read, which also counts NaN and Inf points (the
    H100 run of 508d1c0 counted 5: two fingerprints and a finiteness check of their own)."""
    import warnings

    body = volsmpl.create_body().cuda()
    vol = volsmpl.attach_volume(body).set_precision(precision)
    with torch.no_grad():
        out = body(body_pose=torch.zeros(1, 69, device="cuda"))
        pts = out.vertices.mean(1, keepdim=True) + 0.4 * (torch.rand(1, 5000, 3, device="cuda") - 0.5)
        vol.query(out, pts)                        # encodes and warms up
        enc = vol.encode(out) if call == "query_encoded" else None   # 'query' keeps the subset encoding
        torch.cuda.synchronize()
        torch.cuda.set_sync_debug_mode("warn")
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                vol.query(out, pts) if call == "query" else vol.query_encoded(enc, pts)
        finally:
            torch.cuda.set_sync_debug_mode("default")
    syncs = [w for w in caught if "synchroniz" in str(w.message)]
    assert len(syncs) <= most, [str(w.message)[:120] for w in syncs]
