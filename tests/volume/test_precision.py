"""Reduced-precision decoding (Volume.set_precision: 'bf16', 'tf32') against the full-precision query."""
from __future__ import annotations

import pytest
import torch

import volsmpl
from volsmpl.body.poses import sample_poses
from volsmpl.evaluation import EvalConfig, evaluate_volume


@pytest.fixture(scope="module")
def setup():
    body = volsmpl.create_body()
    vol = volsmpl.attach_volume(body)
    out = body(body_pose=sample_poses(2, seed=3))
    g = torch.Generator().manual_seed(0)
    pts = out.vertices.detach().mean(1, keepdim=True) + (torch.rand(2, 6000, 3, generator=g) - 0.5) * torch.tensor([1.0, 1.9, 0.6])
    return body, vol, out, pts


def test_bf16_close_to_full_but_not_equal(setup):
    body, vol, out, pts = setup
    with torch.no_grad():
        full = vol.query(out, pts)
        vol.set_precision("bf16")
        try:
            low = vol.query(out, pts)
        finally:
            vol.set_precision("full")
    diff = (low - full).abs()
    assert diff.max() > 0                       # the mode is active (bfloat16 rounds the layers' inputs)
    assert diff.max() < 3e-3 and diff.median() < 2e-4      # metres
    assert ((low < 0) == (full < 0)).float().mean() > 0.995


def test_bf16_gradients_follow_full(setup):
    body, vol, out, pts = setup
    grads = {}
    for prec in ("full", "bf16"):
        vol.set_precision(prec)
        x = pts[:, :2000].clone().requires_grad_(True)
        vol.query(out, x).sum().backward()
        grads[prec] = x.grad.reshape(-1, 3)
    vol.set_precision("full")
    cos = torch.nn.functional.cosine_similarity(grads["full"], grads["bf16"], dim=1)
    moved = grads["full"].norm(dim=1) > 0.5     # points inside some box (the analytic box SDF has unit gradients too)
    assert cos[moved].median() > 0.99


def test_modes_that_cannot_run_are_refused(setup):
    body, vol, out, pts = setup
    with pytest.raises(ValueError, match="precision must be one of"):
        vol.set_precision("fp8")
    if not torch.cuda.is_available():
        vol.set_precision("tf32")
        try:
            with pytest.raises(ValueError, match="CUDA"):
                vol.query(out, pts[:, :10])
        finally:
            vol.set_precision("full")
    coap = volsmpl.attach_volume(volsmpl.create_body(), model="coap")
    with pytest.raises(ValueError, match="grouped decoder"):
        coap.set_precision("bf16")
    mesh = volsmpl.attach_volume(volsmpl.create_body(), model="mesh")
    with pytest.raises(ValueError, match="full precision only"):
        mesh.set_precision("bf16")
    assert mesh.set_precision("full") is mesh


def test_tf32_evaluation_off_cuda_is_refused_before_any_work(capsys):
    from volsmpl.cli import main
    with pytest.raises(ValueError, match="CUDA"):
        EvalConfig(precision="tf32")
    assert main(["eval", "--precision", "tf32", "--n-bodies", "1", "--points", "100"]) == 2
    assert "--device cuda" in capsys.readouterr().err


def test_evaluation_in_bf16_restores_the_volume(setup):
    body, vol, out, pts = setup
    cfg = EvalConfig(n_bodies=1, n_points=4000, use_cache=False)
    full = evaluate_volume(vol, body, cfg)
    low = evaluate_volume(vol, body, cfg, precision="bf16")
    assert vol.precision == "full" and low.config["precision"] == "bf16"
    assert abs(low.metrics["iou_mean"] - full.metrics["iou_mean"]) < 0.01
    assert full.metrics["mse_sdf"] is not None and "output" not in full.extra     # an SDF keeps its distance columns
    assert abs(low.metrics["mse_sdf"] - full.metrics["mse_sdf"]) < 0.1 * full.metrics["mse_sdf"]


@pytest.mark.cuda
def test_tf32_on_cuda_close_to_full(setup):
    body, vol, out, pts = setup
    vol_c, out_c = vol.to("cuda"), body.to("cuda")(body_pose=sample_poses(2, seed=3).cuda())
    p = pts.cuda()
    m = torch.backends.cuda.matmul
    before = m.fp32_precision if hasattr(m, "fp32_precision") else m.allow_tf32
    with torch.no_grad():
        full = vol_c.query(out_c, p)
        vol_c.set_precision("tf32")
        low = vol_c.query(out_c, p)
        vol_c.set_precision("full")
    assert (low - full).abs().max() < 3e-3
    assert (m.fp32_precision if hasattr(m, "fp32_precision") else m.allow_tf32) == before   # restored after the query
    vol.to("cpu"); body.to("cpu")
