"""Code refinement carried along an optimisation (volsmpl.volume.warm_codes, `Volume.set_code_refinement(warm=True)`).

Checked against references outside the feature: torch.optim.Adam run on the part codes with the refinement loss
(what T warm encodings of a body that does not move must equal), the same Adam from the encoder's codes where a
body jumped, per-part Adam runs where only some parts were encoded, and the optimisation harness's scope."""
from __future__ import annotations

import pytest
import torch

from volsmpl.body.model import create_body
from volsmpl.evaluation.validation_set import validation_bodies
from volsmpl.nn.code_refiner import decode_targets, refinement_losses
from volsmpl.optim.harness import optimize
from volsmpl.volume.attach import attach_volume
from volsmpl.volume.code_refinement import REFINE_LR, refinement_points
from volsmpl.volume.warm_codes import WARM_MAX_CHANGE, WARM_WARMUP, WarmCodes


@pytest.fixture(scope="module")
def setup():
    """The shipped VolumetricSMPL's encoder codes (no learned passes) set to warm refinement (1 step), and
    validation bodies 0-2's outputs."""
    body = create_body()
    vol = attach_volume(body).set_passes(0).set_code_refinement(1, warm=True)
    params = validation_bodies(3)
    with torch.no_grad():
        outs = [body(**{k: v[i:i + 1] for k, v in params.items()}) for i in range(3)]
        both = body(**{k: v[:2] for k, v in params.items()})
    return body, vol, outs, both


def encoder_state(vol, out):
    """The encoder's codes of `out` (no refinement) and the refinement points, from a plain volume's encoding."""
    steps, warm = vol.refine_steps, vol.refine_warm
    vol.set_code_refinement(0)
    try:
        enc = vol.encode(out, fresh=True)
    finally:
        vol.set_code_refinement(steps, warm=warm)
    xin, target, sc = refinement_points(vol.partition, out.vertices, enc.G, enc.center, enc.scale)
    return enc.code.z.detach(), xin, target, sc


def adam_reference(net, z0, xin, target, sc, steps, parts=None):
    """`steps` steps of torch.optim.Adam on the summed per-part refinement losses, the i-th (from 1) at the step
    size REFINE_LR * min(1, i / WARM_WARMUP)."""
    var = z0.clone().requires_grad_(True)
    opt = torch.optim.Adam([var], lr=REFINE_LR)
    for i in range(1, steps + 1):
        opt.param_groups[0]["lr"] = REFINE_LR * min(1.0, i / WARM_WARMUP)
        opt.zero_grad()
        refinement_losses(net.output, decode_targets(net, var, xin, sc, parts), target).sum().backward()
        opt.step()
    return var.detach()


def warm_codes(vol, out):
    return vol.encode(out, fresh=True).code.z.detach()


def test_encodings_of_a_body_that_stays_continue_one_adam_run(setup):
    _, vol, outs, _ = setup
    z0, xin, target, sc = encoder_state(vol, outs[0])
    with torch.no_grad(), vol.warm_start() as warm:
        for _ in range(5):
            z = warm_codes(vol, outs[0])
    ref = adam_reference(vol.net, z0, xin, target, sc, 5)
    assert warm.encoded == 5 * vol.num_parts and warm.restarted == 0
    assert torch.allclose(z, ref, atol=1e-5, rtol=1e-4), (z - ref).abs().max()
    assert (z - z0).norm() > 10 * (z - ref).norm()          # five steps moved the codes well beyond the tolerance
    assert vol.warm is None                                 # the scope closed


def test_keys_follow_the_bodies_not_their_order(setup):
    body, vol, outs, both = setup
    with torch.no_grad():
        swapped = body(**{k: v[[1, 0]] for k, v in validation_bodies(2).items()})
    with torch.no_grad(), vol.warm_start():
        for _ in range(3):
            ref = warm_codes(vol, both)
    with torch.no_grad(), vol.warm_start():
        for _ in range(2):
            warm_codes(vol, both)
        with vol.warm_keys(torch.tensor([1, 0])):
            z = warm_codes(vol, swapped)
    # equal but for the rare coordinate whose gradient is at rounding level, where Adam's normalised step takes
    # the sign of the rounding (a few of 4,096 here)
    off = (z - ref[[1, 0]]).abs() > 1e-5
    assert off.float().mean() < 0.01, off.float().mean()


def test_a_body_that_jumped_starts_afresh(setup):
    body, vol, outs, _ = setup
    params = {k: v[:1] for k, v in validation_bodies(1).items()}
    pose = params["body_pose"].clone()
    pose[:, 45:54] += 0.8                                    # the left shoulder, elbow... turned: an arm jumps
    with torch.no_grad():
        moved = body(**{**params, "body_pose": pose})
    za, *_ = encoder_state(vol, outs[0])
    zb, xin, target, sc = encoder_state(vol, moved)
    change = (zb - za).norm(dim=-1) / za.norm(dim=-1)       # (1, K): how far each part's encoder code moved
    jumped = change[0] > WARM_MAX_CHANGE
    assert jumped.any() and (~jumped).any(), change         # both kinds of part occur between these two bodies
    with torch.no_grad(), vol.warm_start() as warm:
        for _ in range(3):
            carried = warm_codes(vol, outs[0]) - za
        z = warm_codes(vol, moved)
    assert warm.restarted == int(jumped.sum())
    fresh = adam_reference(vol.net, zb, xin, target, sc, 1)
    assert torch.allclose(z[:, jumped], fresh[:, jumped], atol=1e-5, rtol=1e-4)
    # the parts that stayed started from the carried correction, not from the encoder's codes
    assert not torch.allclose(z[:, ~jumped], fresh[:, ~jumped], atol=1e-4, rtol=0)
    assert ((z - zb)[:, ~jumped] - carried[:, ~jumped]).norm() < (z - zb)[:, ~jumped].norm()


def test_refining_some_parts_keeps_the_others_state(setup):
    _, vol, outs, _ = setup
    z0, xin, target, sc = encoder_state(vol, outs[1])
    some = torch.tensor([2, 5])
    warm = WarmCodes(vol.num_parts, steps=1)
    for _ in range(3):
        warm.refine(vol.net, z0[:, some], xin[:, some], target[:, some], None if sc is None else sc[:, some], some)
    z = warm.refine(vol.net, z0, xin, target, sc, None)
    four = adam_reference(vol.net, z0[:, some], xin[:, some], target[:, some], None if sc is None else sc[:, some],
                          4, some)
    rest = torch.ones(vol.num_parts, dtype=torch.bool)
    rest[some] = False
    one = adam_reference(vol.net, z0, xin, target, sc, 1)
    assert torch.allclose(z[:, some], four, atol=1e-5, rtol=1e-4)
    assert torch.allclose(z[:, rest], one[:, rest], atol=1e-5, rtol=1e-4)


def test_the_harness_opens_one_scope_per_run(setup):
    body, vol, outs, _ = setup
    seen = []
    pose = validation_bodies(1)["body_pose"]

    def term(s):
        seen.append(vol.warm)
        return vol.collision_loss(s.out, s.out.vertices[:, ::500].detach() - 0.01, reduction="none").sum(-1)

    optimize({"body_pose": pose.clone()}, {"pen": term}, prepare=lambda s: {"out": body(body_pose=s.body_pose)},
             max_iters=3, frozen=[vol], lr=1e-3)
    assert vol.warm is None and len(seen) == 4 and all(w is seen[0] and w is not None for w in seen)
    assert seen[0].encoded >= 4                              # every evaluation's encoding went through the scope
    vol.set_code_refinement(1)                               # cold: no scope
    try:
        seen.clear()
        optimize({"body_pose": pose.clone()}, {"pen": term}, prepare=lambda s: {"out": body(body_pose=s.body_pose)},
                 max_iters=1, frozen=[vol], lr=1e-3)
        assert seen == [None, None]
    finally:
        vol.set_code_refinement(1, warm=True)


def test_an_encoding_from_outside_the_scope_is_not_served_inside(setup):
    _, vol, outs, _ = setup
    pts = outs[0].vertices[:, ::300] + 0.002
    with torch.no_grad():
        outside = vol.query(outs[0], pts)                  # cached, refined cold by one step
        with vol.warm_start() as warm:
            vol.query(outs[0], pts)
            assert warm.encoded == vol.num_parts           # encoded anew inside the scope
            vol.query(outs[0], pts)
            assert warm.encoded == vol.num_parts           # the scope's own encoding of the same output is served
        after = vol.query(outs[0], pts)
    assert torch.allclose(outside, after, atol=1e-6, rtol=0)


def test_the_errors():
    body = create_body()
    vol = attach_volume(body)
    with pytest.raises(ValueError, match="steps >= 1"):
        vol.set_code_refinement(0, warm=True)
    with pytest.raises(ValueError, match="steps >= 1"):
        WarmCodes(16, steps=0)
    with pytest.raises(ValueError, match="max_change"):
        WarmCodes(16, max_change=0)
    with pytest.raises(ValueError, match="warmup"):
        WarmCodes(16, warmup=-1)
    warm = WarmCodes(16)
    with pytest.raises(ValueError, match="distinct integer ids"):
        with warm.keys([3, 3]):
            pass
    with vol.set_code_refinement(1, warm=True).warm_start(), vol.warm_keys([0, 1, 2]):
        with torch.no_grad(), pytest.raises(ValueError, match="named 3 bodies but the encoded output has 1"):
            vol.encode(body(), fresh=True)
    with vol.set_code_refinement(2).warm_start() as state:    # cold setting: no scope
        assert state is None and vol.warm is None
