"""Pretrained volumes are attached frozen (no weight gradients, no graph over the weights); gradients still reach
poses, shapes and points, and match those of the same volume unfrozen; unfreezing is explicit."""
from __future__ import annotations

import pytest
import torch

import volsmpl
from conftest import random_pose


@pytest.fixture(scope="module")
def saved(tmp_path_factory, tiny_config):
    """A checkpoint of a random tiny volume (the pretrained path without the shipped weights)."""
    from volsmpl.io.checkpoint import save_checkpoint
    torch.manual_seed(7)
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, pretrained=False, config=tiny_config)
    path = tmp_path_factory.mktemp("ck") / "model"
    save_checkpoint(path, vol.net.state_dict(), tiny_config.to_dict(), {"body_fingerprint": vol.fingerprint})
    return path


def _grads(vol, body, seed=0):
    p = {k: v.clone().requires_grad_(True) for k, v in random_pose(1, seed=seed).items()}
    out = body(**p)
    g = torch.Generator().manual_seed(seed)
    pts = (out.vertices.detach()[:, ::40] + 0.03 * torch.randn(1, 334, 3, generator=g)).requires_grad_(True)
    vol.query(out, pts).sum().backward()
    return [p["body_pose"].grad, p["betas"].grad, p["transl"].grad, pts.grad]


def test_pretrained_is_frozen_and_gradients_reach_inputs(saved):
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, checkpoint=saved)
    assert not any(p.requires_grad for p in vol.parameters())
    frozen = _grads(vol, b)
    assert all(p.grad is None for p in vol.parameters())
    b2 = volsmpl.create_body()
    ref = volsmpl.attach_volume(b2, checkpoint=saved, trainable=True)  # same weights, requiring gradients
    assert all(p.requires_grad for p in ref.net.parameters())
    expect = _grads(ref, b2)
    for a, e in zip(frozen, expect):
        assert a is not None and a.abs().sum() > 0
        assert torch.allclose(a, e, atol=1e-6, rtol=1e-5)
    assert all(p.grad is not None for p in ref.net.parameters())


def test_query_builds_no_graph_over_weights(saved):
    """The output's graph reaches no weight: autograd.grad w.r.t. a weight of a frozen volume is refused."""
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, checkpoint=saved)
    out = b(**random_pose(1, seed=1))
    pts = out.vertices.detach()[:, ::50].clone().requires_grad_(True)
    d = vol.query(out, pts)
    w = next(vol.net.parameters())
    with pytest.raises(RuntimeError):
        torch.autograd.grad(d.sum(), w)


def test_unfreeze_explicitly_and_random_volumes_train(saved, tiny_config):
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, checkpoint=saved)
    vol.requires_grad_(True)
    _grads(vol, b)
    assert all(p.grad is not None for p in vol.net.parameters())
    rnd = volsmpl.attach_volume(volsmpl.create_body(), pretrained=False, config=tiny_config)
    assert all(p.requires_grad for p in rnd.net.parameters())  # the start of training
    frozen_rnd = volsmpl.attach_volume(volsmpl.create_body(), pretrained=False, config=tiny_config, trainable=False)
    assert not any(p.requires_grad for p in frozen_rnd.parameters())
