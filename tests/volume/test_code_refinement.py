"""Test-time code refinement (volsmpl.volume.code_refinement, `Volume.set_code_refinement`).

Checked against references outside the feature: the fitting points' targets against the exact signed distance of
the posed mesh, the refined model against exact ground truth (it must be closer than the encoder's codes), a
refinement of some parts against the refinement of all, point gradients against finite differences, and the
cache against a fresh volume."""
from __future__ import annotations

import pytest
import torch

from volsmpl.volume.attach import attach_volume
from volsmpl.body.model import create_body
from volsmpl.volume.code_refinement import check_refine_steps, refine_codes, refinement_points
from volsmpl.evaluation import EvalConfig
from volsmpl.geometry.groundtruth import mesh_sdf
from volsmpl.evaluation.metrics import compute_metrics
from volsmpl.evaluation.validation_set import query_points, validation_bodies


@pytest.fixture(scope="module")
def shipped():
    """A fresh default body with the shipped VolumetricSMPL's encoder codes (no learned passes: the refinement
    starts from the encoder's codes), and validation body 0's output."""
    body = create_body()
    vol = attach_volume(body).set_passes(0)
    params = {k: v[:1] for k, v in validation_bodies(1).items()}
    with torch.no_grad():
        out = body(**params)
    return body, vol, params, out


def test_fitting_points_lie_at_their_targets_from_the_posed_mesh(shipped):
    body, vol, _, out = shipped
    enc = vol.encode(out)
    xin, t, scale = refinement_points(vol.partition, out.vertices, enc.G, enc.center, enc.scale)
    K = vol.num_parts
    assert xin.shape[:2] == (1, K) and t.shape == xin.shape[:3] and xin.shape[2] == vol.partition.n_samples
    local = xin * scale[:, :, None] + enc.center[:, :, None]
    world = vol.partition.uncanonicalize(local, enc.G).reshape(-1, 3)
    exact = torch.as_tensor(mesh_sdf(out.vertices[0].double().numpy(), body.faces, world.double().numpy(),
                                     sign="winding")).float()
    t = t.reshape(-1)
    err = (exact - t).abs()
    # first order: exact at most points; a flipped normal or a misplaced offset would make err ~ 2 |t| (~5 mm)
    assert float((err < 2e-4).float().mean()) > 0.9, float(err.median())
    clear = t.abs() > 1e-3
    assert float((torch.sign(exact[clear]) == torch.sign(t[clear])).float().mean()) > 0.97
    # antithetic pairs: +t and -t about the same surface samples
    n = xin.shape[2] // 2
    assert torch.equal(t.view(1, K, -1)[..., :n], -t.view(1, K, -1)[..., n:])


def test_refined_codes_are_closer_to_the_exact_distance(shipped):
    body, vol, params, out = shipped
    pts, surf = query_points(out.vertices, body.faces, 6000, seed=11)
    gt = torch.as_tensor(mesh_sdf(out.vertices[0].double().numpy(), body.faces, pts[0].double().numpy(),
                                  sign="winding")).float()[None]
    res = {}
    for steps in (0, 20):
        vol.set_code_refinement(steps)
        with torch.no_grad():
            pred = vol.query(out, pts)
        res[steps] = {k: float(v) for k, v in compute_metrics(pred, gt, surf).items()}
    vol.set_code_refinement(0)
    assert res[20]["iou_surf"] > res[0]["iou_surf"] + 0.015, res
    assert res[20]["mse_sdf_surf"] < 0.8 * res[0]["mse_sdf_surf"], res


def test_refining_some_parts_gives_the_codes_of_refining_all(shipped):
    body, _, params, out = shipped
    a, b = attach_volume(create_body()).set_passes(0), attach_volume(create_body()).set_passes(0)
    a.set_code_refinement(8)
    b.set_code_refinement(8)
    with torch.no_grad():
        enc = a.encode(out)                                   # every part
        tip = a.partition.vertex_labels[out.vertices[0, :, 0].argmax()]     # the part at an extremity (a hand)
        pts = out.vertices[:, a.partition.vertex_labels == tip][:, :30] + 0.003
        full = a.query_encoded(enc, pts)
        part = b.query(out, pts)                              # encodes only the parts whose boxes hold pts
    sub = out._volsmpl_encoding[1]
    assert sub.parts is not None and len(sub.parts) < a.num_parts
    assert torch.allclose(part, full, atol=1e-5, rtol=0), (part - full).abs().max()


def test_point_gradients_match_finite_differences_with_refinement():
    body = create_body().double()
    vol = attach_volume(body).set_passes(0).double()
    vol.set_code_refinement(4)
    params = {k: v[:1].double() for k, v in validation_bodies(1).items()}
    with torch.no_grad():
        out = body(**params)
    pts = (out.vertices[:, ::700][:, :12] + 0.004).clone().requires_grad_(True)
    val = vol.query(out, pts)
    (grad,) = torch.autograd.grad(val.sum(), pts)
    eps = 1e-6
    fd = torch.zeros_like(pts)
    with torch.no_grad():
        for i in range(3):
            d = torch.zeros_like(pts)
            d[..., i] = eps
            fd[..., i] = (vol.query(out, pts + d) - vol.query(out, pts - d)) / (2 * eps)
    assert torch.allclose(grad, fd, atol=1e-5, rtol=1e-4), (grad - fd).abs().max()


def test_changing_the_setting_re_encodes(shipped):
    body, _, params, _ = shipped
    vol = attach_volume(body).set_passes(0)
    with torch.no_grad():
        out = body(**params)
    pts = out.vertices[:, ::300] + 0.003
    with torch.no_grad():
        plain = vol.query(out, pts)
        vol.set_code_refinement(6)
        refined = vol.query(out, pts)                         # the cached plain encoding must not answer
        fresh = attach_volume(create_body()).set_passes(0).set_code_refinement(6).query(out, pts)
    assert torch.allclose(refined, fresh, atol=1e-6, rtol=0)
    assert not torch.allclose(refined, plain, atol=1e-5, rtol=0)


def test_zero_steps_and_the_errors():
    z = torch.randn(1, 3, 8)
    assert refine_codes(None, z, None, torch.zeros(1, 3, 4), None, None, 0) is z
    for bad in (-1, 1.5, True, "3"):
        with pytest.raises(ValueError, match="integer >= 0"):
            check_refine_steps(bad)
    with pytest.raises(ValueError, match="--refine-steps -2"):
        EvalConfig(refine_steps=-2)
    mesh = attach_volume(create_body(), model="mesh")
    with pytest.raises(ValueError, match="no part codes"):
        mesh.set_code_refinement(4)


def test_coap_refinement_fits_its_occupancy():
    body = create_body()
    vol = attach_volume(body, model="coap")
    params = {k: v[:1] for k, v in validation_bodies(1).items()}
    with torch.no_grad():
        out = body(**params)
    pts, surf = query_points(out.vertices, body.faces, 4000, seed=12)
    gt = torch.as_tensor(mesh_sdf(out.vertices[0].double().numpy(), body.faces, pts[0].double().numpy(),
                                  sign="winding")).float()[None]
    ious = []
    for steps in (0, 20):
        vol.set_code_refinement(steps)
        with torch.no_grad():
            occ = vol.query(out, pts)
        ious.append(float(compute_metrics(vol.level - occ, gt, surf)["iou_surf"]))
    assert ious[1] > ious[0] + 0.01, ious


@pytest.mark.cuda
def test_cuda_refinement_matches_the_cpu(shipped):
    body, _, params, out = shipped
    pts = out.vertices[:, ::200] + 0.003
    cpu = attach_volume(create_body()).set_passes(0).set_code_refinement(10)
    with torch.no_grad():
        ref = cpu.query(out, pts)
    gbody = create_body().to("cuda")
    gvol = attach_volume(gbody).set_passes(0).set_code_refinement(10)
    with torch.no_grad():
        gout = gbody(**{k: v.to("cuda") for k, v in params.items()})
        got = gvol.query(gout, pts.to("cuda")).cpu()
    # float32 on another device: the ten steps round otherwise; a wrong device path would be off by millimetres
    assert torch.allclose(got, ref, atol=2e-4, rtol=0), (got - ref).abs().max()


def test_refinement_is_adams_steps_on_the_warmed_up_cosine_schedule(shipped):
    """refine_codes against torch.optim.Adam with the step size REFINE_LR * min(1, i / REFINE_WARMUP) * the cosine
    decay 0.5 (1 + cos(pi (i - 1) / R)) at the i-th of R steps."""
    import math

    from volsmpl.nn.code_refiner import decode_targets, refinement_losses
    from volsmpl.volume.code_refinement import REFINE_LR, REFINE_WARMUP

    _, vol, _, out = shipped
    steps = vol.refine_steps
    vol.set_code_refinement(0)
    enc = vol.encode(out, fresh=True)
    vol.set_code_refinement(steps)
    z0 = enc.code.z.detach()
    xin, target, sc = refinement_points(vol.partition, out.vertices, enc.G, enc.center, enc.scale)
    R = 12
    ours = refine_codes(vol.net, z0, xin, target, sc, None, R)
    var = z0.clone().requires_grad_(True)
    opt = torch.optim.Adam([var], lr=REFINE_LR)
    for i in range(1, R + 1):
        opt.param_groups[0]["lr"] = REFINE_LR * min(1.0, i / REFINE_WARMUP) * 0.5 * (1 + math.cos(math.pi * (i - 1) / R))
        opt.zero_grad()
        refinement_losses(vol.net.output, decode_targets(vol.net, var, xin, sc, None), target).sum().backward()
        opt.step()
    off = (ours - var.detach()).abs() > 1e-5     # but for coordinates whose gradient is at rounding level
    assert off.float().mean() < 0.01 and (ours - z0).norm() > 10 * (ours - var.detach()).norm()
