"""Learned passes at every N-th encoding, their correction carried between (volsmpl.volume.carried_passes,
`Volume.set_pass_interval`).

Checked against the model's own two plain paths, composed by hand: the encoder's codes (the network's passes
removed) and the passes' codes (a fresh encoding outside any scope). An encoding between passes must equal its
encoder's codes plus the correction (passes' code - encoder's code) of the last encoding that ran the passes; its
gradient must be the encoder's alone."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

import volsmpl.volume.learned as learned
from volsmpl.body.model import create_body
from volsmpl.evaluation.validation_set import validation_bodies
from volsmpl.optim.harness import optimize
from volsmpl.volume.attach import attach_volume
from volsmpl.volume.carried_passes import CarriedPasses
from volsmpl.volume.warm_codes import WARM_MAX_CHANGE

R3 = Path(__file__).resolve().parents[2] / "checkpoints" / "volsmpl_r3" / "ckpt-00057000" / "model"


@pytest.fixture(scope="module")
def setup():
    """volsmpl_r3 (two learned passes), and validation body 0's parameters."""
    body = create_body()
    vol = attach_volume(body, checkpoint=str(R3))
    vol.requires_grad_(False)
    return body, vol, {k: v[:1] for k, v in validation_bodies(1).items()}


def posed(body, params, shift: float):
    """Body 0 with its left arm's joints turned by `shift` rad per coordinate."""
    pose = params["body_pose"].clone()
    pose[:, 45:54] += shift
    with torch.no_grad():
        return body(**{**params, "body_pose": pose})


def encoder_z(vol, out):
    """The encoder's codes of `out`: a fresh encoding with the network's passes removed."""
    refiner, vol.net.refiner = vol.net.refiner, None
    try:
        return vol.encode(out, fresh=True).code.z.detach()
    finally:
        vol.net.refiner = refiner


def passes_z(vol, out):
    """The passes' codes of `out`: a fresh encoding outside any scope."""
    return vol.encode(out, fresh=True).code.z.detach()


def test_the_passes_run_at_every_nth_encoding_and_their_correction_is_carried(setup):
    body, vol, params = setup
    outs = [posed(body, params, 0.002 * i) for i in range(7)]
    vol.set_pass_interval(3)
    try:
        with torch.no_grad(), vol.warm_start() as carried:
            got = [passes_z(vol, o) for o in outs]
    finally:
        vol.set_pass_interval(1)
    assert isinstance(carried, CarriedPasses) and vol.carried is None
    K = vol.num_parts
    assert carried.encoded == 7 * K and carried.passed == 3 * K and carried.restarted == 0
    for i, out in enumerate(outs):
        j = 3 * (i // 3)                                       # the last encoding that ran the passes
        ref = encoder_z(vol, out) + (passes_z(vol, outs[j]) - encoder_z(vol, outs[j]))
        assert torch.allclose(got[i], ref, atol=1e-5, rtol=1e-5), (i, (got[i] - ref).abs().max())
    # the rule is not vacuous: the correction is large, and a carried one differs from the passes made anew
    fresh = passes_z(vol, outs[2])
    assert (fresh - encoder_z(vol, outs[2])).norm() > 20 * (got[2] - fresh).norm() > 0


def test_a_jump_passes_the_parts_that_jumped_anew(setup):
    body, vol, params = setup
    still, moved = posed(body, params, 0.0), posed(body, params, 0.8)
    za, zb = encoder_z(vol, still), encoder_z(vol, moved)
    jumped = ((zb - za).norm(dim=-1) / za.norm(dim=-1))[0] > WARM_MAX_CHANGE
    assert jumped.any() and (~jumped).any()                    # the arm's parts jumped, the others did not
    vol.set_pass_interval(10)
    try:
        with torch.no_grad(), vol.warm_start() as carried:
            passes_z(vol, still)
            passes_z(vol, still)
            z = passes_z(vol, moved)
    finally:
        vol.set_pass_interval(1)
    assert carried.restarted == 1 and carried.passed == vol.num_parts + int(jumped.sum())
    assert torch.allclose(z[:, jumped], passes_z(vol, moved)[:, jumped], atol=1e-4, rtol=1e-4)
    kept = zb + passes_z(vol, still) - za                      # the still body's correction, carried
    assert torch.allclose(z[:, ~jumped], kept[:, ~jumped], atol=1e-4, rtol=1e-4)


def test_only_the_body_that_jumped_is_passed_anew(setup):
    body, vol, _ = setup
    params = validation_bodies(2)
    pose = params["body_pose"].clone()
    pose[1, 45:54] += 0.8                                      # body 1's left arm turned; body 0 stays
    with torch.no_grad():
        before, after = body(**params), body(**{**params, "body_pose": pose})
    za, zb = encoder_z(vol, before), encoder_z(vol, after)
    jumped = ((zb - za).norm(dim=-1) / za.norm(dim=-1)) > WARM_MAX_CHANGE          # (2, K)
    assert not jumped[0].any() and jumped[1].any()
    vol.set_pass_interval(10)
    try:
        with torch.no_grad(), vol.warm_start() as carried:
            passes_z(vol, before)
            z = passes_z(vol, after)
    finally:
        vol.set_pass_interval(1)
    K = vol.num_parts
    assert carried.passed == 2 * K + int(jumped[1].sum()) and carried.restarted == 1 and carried.encoded == 4 * K
    fresh, kept = passes_z(vol, after), zb + passes_z(vol, before) - za
    assert torch.allclose(z[jumped], fresh[jumped], atol=1e-4, rtol=1e-4)
    assert torch.allclose(z[~jumped], kept[~jumped], atol=1e-4, rtol=1e-4)


def test_each_body_key_carries_its_own_correction(setup):
    body, vol, _ = setup
    params = validation_bodies(2)
    with torch.no_grad():
        both = body(**params)
        swapped = body(**{k: v[[1, 0]] for k, v in params.items()})
    vol.set_pass_interval(4)
    try:
        with torch.no_grad(), vol.warm_start() as carried:
            passes_z(vol, both)
            with vol.warm_keys(torch.tensor([1, 0])):
                z = passes_z(vol, swapped)
        with torch.no_grad(), vol.warm_start() as unkeyed:     # without the keys the rows' codes jump: passes anew
            passes_z(vol, both)
            passes_z(vol, swapped)
    finally:
        vol.set_pass_interval(1)
    assert carried.passed == 2 * vol.num_parts and carried.restarted == 0   # the second encoding carried
    ref = passes_z(vol, swapped)
    assert torch.allclose(z, ref, atol=1e-4, rtol=1e-4), (z - ref).abs().max()
    assert unkeyed.passed > 2 * vol.num_parts and unkeyed.restarted == 2


def test_a_carried_encoding_takes_the_encoders_gradient_and_makes_no_refinement_points(setup, monkeypatch):
    body, vol, params = setup
    made = []
    real = learned.refinement_points
    monkeypatch.setattr(learned, "refinement_points", lambda *a, **k: made.append(1) or real(*a, **k))

    def grad_of_codes(carry: bool):
        pose = params["body_pose"].clone().requires_grad_(True)
        out = body(**{**params, "body_pose": pose})
        w = torch.linspace(-1, 1, 128, dtype=pose.dtype)
        if carry:
            passes_z(vol, posed(body, params, 0.0))            # the scope's first encoding runs the passes
            z = vol.encode(out, fresh=True).code.z
        else:
            refiner, vol.net.refiner = vol.net.refiner, None
            try:
                z = vol.encode(out, fresh=True).code.z
            finally:
                vol.net.refiner = refiner
        (g,) = torch.autograd.grad((z * w).sum(), pose)
        return g

    vol.set_pass_interval(2)
    try:
        with vol.warm_start():
            carried = grad_of_codes(True)
    finally:
        vol.set_pass_interval(1)
    assert len(made) == 1                                      # the passes' encoding only
    plain = grad_of_codes(False)
    assert plain.abs().max() > 0
    assert torch.allclose(carried, plain, atol=1e-6, rtol=1e-5)


def test_the_harness_opens_one_scope_per_run(setup):
    body, vol, params = setup
    seen = []

    def term(s):
        seen.append(vol.carried)
        return vol.collision_loss(s.out, s.out.vertices[:, ::500].detach() - 0.01, reduction="none").sum(-1)

    vol.set_pass_interval(2)
    try:
        optimize({"body_pose": params["body_pose"].clone()}, {"pen": term},
                 prepare=lambda s: {"out": body(body_pose=s.body_pose)}, max_iters=3, frozen=[vol], lr=1e-3)
    finally:
        vol.set_pass_interval(1)
    assert vol.carried is None and len(seen) == 4 and all(c is seen[0] and c is not None for c in seen)
    assert seen[0].encoded >= 4 * 1 and seen[0].passed < seen[0].encoded


def test_an_encoding_from_outside_the_scope_is_not_served_inside(setup):
    body, vol, params = setup
    out = posed(body, params, 0.0)
    pts = out.vertices[:, ::300] + 0.002
    vol.set_pass_interval(3)
    try:
        with torch.no_grad():
            vol.query(out, pts)                                # cached outside, with the passes
            with vol.warm_start() as carried:
                vol.query(out, pts)
                assert carried.encoded > 0                     # encoded anew inside the scope
    finally:
        vol.set_pass_interval(1)


def test_interval_one_opens_no_scope(setup):
    _, vol, _ = setup
    with vol.warm_start() as state:
        assert state is None and vol.carried is None


def test_the_errors(setup):
    _, vol, _ = setup
    shipped = attach_volume(create_body())
    if shipped.net.refiner is None:
        with pytest.raises(ValueError, match="no learned code-refinement passes"):
            shipped.set_pass_interval(2)
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="give an integer >= 1"):
            vol.set_pass_interval(bad)
    vol.set_pass_interval(2)
    try:
        with pytest.raises(ValueError, match="set the learned passes' interval"):
            vol.set_code_refinement(1, warm=True)
    finally:
        vol.set_pass_interval(1)
    vol.set_code_refinement(1, warm=True)
    try:
        with pytest.raises(ValueError, match="use one of them"):
            vol.set_pass_interval(2)
    finally:
        vol.set_code_refinement(0)
    with pytest.raises(ValueError, match="max_change"):
        CarriedPasses(16, every=2, max_change=0)


def test_kinds_without_passes_refuse_an_interval_and_open_empty_scopes():
    body = create_body()
    mesh, coap = attach_volume(body, model="mesh"), attach_volume(body, model="coap")
    for vol, words in ((mesh, "has no learned code-refinement passes"), (coap, "no learned code-refinement passes")):
        assert vol.set_pass_interval(1) is vol
        with pytest.raises(ValueError, match=words):
            vol.set_pass_interval(2)
        with vol.warm_start() as state, vol.warm_keys([0]):
            assert state is None
