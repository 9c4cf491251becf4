"""The learned passes a volume runs (`Volume.set_passes`, every app's and the evaluation's `--passes`).

Checked against models built apart from the setting: the first P passes of `volsmpl_r3` against a network of P
passes holding those passes' weights; no passes against step 50,000's model, whose encoder and decoders `volsmpl_r3`
keeps unchanged; carried passes against the model of one pass."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from volsmpl.body.model import create_body
from volsmpl.evaluation.config import EvalConfig
from volsmpl.evaluation.validation_set import validation_bodies
from volsmpl.io.checkpoint import load_checkpoint
from volsmpl.nn.config import VolumeConfig
from volsmpl.volume.attach import attach_volume

CKPTS = Path(__file__).resolve().parents[2] / "checkpoints"
R3 = CKPTS / "volsmpl_r3" / "ckpt-00057000" / "model"
STEP_50K = CKPTS / "volsmpl_b8q" / "ckpt-00050000" / "model"


def first_passes(body, passes: int):
    """volsmpl_r3's network cut to its first `passes` passes: a network built with refiner_iters = passes that
    loads r3's weights of those passes (and nothing of the others)."""
    state, cfg, _ = load_checkpoint(R3)
    keep = {k: v for k, v in state.items()
            if not k.startswith("refiner.") or int(k.split(".")[2]) < passes}
    vol = attach_volume(body, pretrained=False, config=VolumeConfig.from_dict({**cfg, "refiner_iters": passes}))
    vol.net.load_state_dict(keep)
    return vol.requires_grad_(False)


@pytest.fixture(scope="module")
def setup():
    body = create_body()
    vol = attach_volume(body, checkpoint=str(R3))
    with torch.no_grad():
        out = body(**{k: v[:2] for k, v in validation_bodies(2).items()})
    return body, vol, out


def codes(vol, out, fresh: bool = True):
    with torch.no_grad():
        return vol.encode(out, fresh=fresh).code.z


def test_the_first_passes_are_the_model_of_those_passes(setup):
    body, vol, out = setup
    assert vol.active_passes == 2
    full = codes(vol, out)
    try:
        vol.set_passes(1)
        one = codes(vol, out)
        assert vol.active_passes == 1
        assert torch.allclose(one, codes(first_passes(body, 1), out), atol=1e-6, rtol=1e-6)
        assert (one - full).norm() > 0.01 * full.norm()          # the second pass is not vacuous (2.8 %)
        vol.set_passes(0)
        none = codes(vol, out)
        plain = attach_volume(body, checkpoint=str(STEP_50K))
        assert plain.net.refiner is None
        assert torch.allclose(none, codes(plain, out), atol=1e-6, rtol=1e-6)
        vol.set_passes(2)
        assert torch.allclose(codes(vol, out), full, atol=1e-6, rtol=1e-6)
    finally:
        vol.set_passes(None)


def test_a_cached_encoding_is_not_served_after_the_passes_change(setup):
    body, vol, out = setup
    full = codes(vol, out, fresh=False)                          # cached on the output
    try:
        vol.set_passes(1)
        assert torch.allclose(codes(vol, out, fresh=False), codes(first_passes(body, 1), out), atol=1e-6)
    finally:
        vol.set_passes(None)
    assert torch.equal(codes(vol, out, fresh=False), full)


def test_carried_passes_are_the_chosen_passes(setup):
    body, vol, out = setup
    vol.set_passes(1).set_pass_interval(3)
    try:
        with torch.no_grad(), vol.warm_start() as carried:
            first = codes(vol, out, fresh=True)
            again = codes(vol, out, fresh=True)
    finally:
        vol.set_pass_interval(1).set_passes(None)
    ref = codes(first_passes(body, 1), out)
    assert carried.passed == carried.encoded // 2 == 2 * vol.num_parts    # the first encoding ran the pass
    assert torch.allclose(first, ref, atol=1e-5) and torch.allclose(again, ref, atol=1e-5)


def test_each_body_of_a_batch_gets_the_codes_it_gets_alone():
    """The passes read each (body, part) alone: a batch's codes are each body's alone, in either order. In float64,
    where the rounding the passes' gradient features amplify (3e-5 in float32) stays at 1e-15."""
    body = create_body().double()
    vol = attach_volume(body, checkpoint=str(R3))
    params = {k: v.double() for k, v in validation_bodies(2).items()}
    with torch.no_grad():
        both = codes(vol, body(**params))
        for i in (0, 1):
            alone = body(**{k: v[i:i + 1] for k, v in params.items()})
            assert torch.allclose(both[i:i + 1], codes(vol, alone), atol=1e-10, rtol=0)
        swapped = body(**{k: v[[1, 0]] for k, v in params.items()})
        assert torch.allclose(codes(vol, swapped), both[[1, 0]], atol=1e-10, rtol=0)


def test_the_errors(setup):
    body, vol, _ = setup
    for bad, words in ((3, "this model has 2 learned code-refinement passes; give --passes 0..2"),
                       (-1, "give an integer >= 0"), (True, "give an integer >= 0"), (1.0, "give an integer >= 0")):
        with pytest.raises(ValueError, match="passes") as e:
            vol.set_passes(bad)
        assert words in str(e.value) and "\n" not in str(e.value)
    assert vol.passes is None
    vol.set_pass_interval(4)
    try:
        with pytest.raises(ValueError, match="--passes 0 runs no learned passes"):
            vol.set_passes(0)
    finally:
        vol.set_pass_interval(1)
    vol.set_passes(0)
    try:
        with pytest.raises(ValueError, match="the learned passes are turned off"):
            vol.set_pass_interval(4)
    finally:
        vol.set_passes(None)
    plain = attach_volume(body, checkpoint=str(STEP_50K))        # no passes: only 0 or all (none)
    assert plain.active_passes == 0 and plain.set_passes(0).active_passes == 0
    with pytest.raises(ValueError, match="has 0 learned code-refinement passes; give --passes 0, or a checkpoint"):
        plain.set_passes(1)
    coap = attach_volume(body, model="coap")
    with pytest.raises(ValueError, match="has 0 learned code-refinement passes; drop the setting"):
        coap.set_passes(1)
    mesh = attach_volume(body, model="mesh")
    assert mesh.active_passes == 0 and mesh.set_passes(None) is mesh and mesh.set_passes(0) is mesh
    with pytest.raises(ValueError, match="the mesh volume has no learned code-refinement passes"):
        mesh.set_passes(2)
    with pytest.raises(ValueError, match="--passes -2: give an integer >= 0"):
        EvalConfig(passes=-2)
