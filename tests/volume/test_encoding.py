"""The encoding cache never answers for another body or other weights: every way of editing the body output or
the weights (autograd in-place ops, `.data`, `.numpy()`, `.detach()` aliases, optimiser steps, load_state_dict)
gives the values of a volume that never cached anything (the reference: a second volume with the same weights,
queried on a copy of the tensors)."""
from __future__ import annotations

from types import SimpleNamespace

import pytest
import torch

import volsmpl
from conftest import random_pose
from volsmpl.volume.fingerprint import fingerprint


@pytest.fixture(scope="module")
def setup(tiny_config):
    torch.manual_seed(3)
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, pretrained=False, config=tiny_config).eval()
    return b, vol


def _reference(vol, tiny_config, out, points):
    """A fresh volume with vol's current weights (no cache), on copies of the output's tensors."""
    ref = volsmpl.attach_volume(volsmpl.create_body(), pretrained=False, config=tiny_config).eval()
    ref.load_state_dict(vol.state_dict())
    ref.net.encoder_bf16 = vol.net.encoder_bf16
    mine = dict(vol.named_buffers())
    with torch.no_grad():
        for name, buf in ref.named_buffers():  # the partition's buffers are not in the state dict
            buf.copy_(mine[name])
    copy = SimpleNamespace(**{n: getattr(out, n).detach().clone() for n in ("vertices", "joints", "full_pose")})
    with torch.no_grad():
        return ref.query(copy, points)


def _fresh_volume(tiny_config, seed):
    """A new body and an untrained volume on it, its weights drawn after torch.manual_seed(seed)."""
    torch.manual_seed(seed)
    b = volsmpl.create_body()
    return b, volsmpl.attach_volume(b, pretrained=False, config=tiny_config).eval()


def _points(out, n=300, seed=0):
    g = torch.Generator().manual_seed(seed)
    v = out.vertices.detach()
    idx = torch.randint(0, v.shape[1], (n,), generator=g)
    return v[:, idx] + 0.03 * torch.randn(v.shape[0], n, 3, generator=g)


def _edit_output(out, how):
    if how == "data":
        out.vertices.data.add_(0.02)
    elif how == "numpy":
        out.vertices.numpy()[..., 1] -= 0.02
    elif how == "detach":
        out.vertices.detach().mul_(1.01)
    elif how == "inplace":
        out.vertices.add_(0.02)
    elif how == "joints_data":  # part frames move, vertices stay
        out.joints.data[:, 1:] += 0.02
    elif how == "pose_numpy":
        out.full_pose.numpy()[:, 3:6] += 0.3


@pytest.mark.parametrize("how", ["data", "numpy", "detach", "inplace", "joints_data", "pose_numpy"])
def test_edited_output_is_re_encoded(setup, tiny_config, how):
    b, vol = setup
    with torch.no_grad():
        out = b(**random_pose(1, seed=21))
    pts = _points(out)
    with torch.no_grad():
        before = vol.query(out, pts)
        _edit_output(out, how)
        after = vol.query(out, pts)
    expect = _reference(vol, tiny_config, out, pts)
    assert not torch.allclose(expect, before, atol=1e-4)  # the edit changes the field
    assert torch.allclose(after, expect, atol=1e-6)


def test_edited_output_with_gradients(setup, tiny_config):
    """An output that carries a graph, edited through .data between two queries."""
    b, vol = setup
    pose = random_pose(1, seed=22)
    pose["body_pose"].requires_grad_(True)
    out = b(**pose)
    pts = _points(out)
    before = vol.query(out, pts).detach()
    out.vertices.data.add_(0.02)
    after = vol.query(out, pts)
    after.sum().backward()  # still differentiable
    expect = _reference(vol, tiny_config, out, pts)
    assert not torch.allclose(expect, before, atol=1e-4)
    assert torch.allclose(after.detach(), expect, atol=1e-6)


@pytest.mark.parametrize("how", ["data", "numpy", "no_grad_inplace", "load_state_dict", "buffer"])
def test_weight_edits_invalidate(tiny_config, how):
    b, vol = _fresh_volume(tiny_config, 4)
    p = random_pose(1, seed=23)
    with torch.no_grad():
        out = b(**p)
    pts = _points(out)
    with torch.no_grad():
        before = vol.query(out, pts)
        params = list(vol.net.parameters())
        if how == "data":
            for q in params:
                q.data.mul_(1.1)
        elif how == "numpy":
            for q in params:
                q.detach().numpy()[...] *= 1.1
        elif how == "no_grad_inplace":
            for q in params:
                q.mul_(1.1)
        elif how == "load_state_dict":
            other = volsmpl.attach_volume(volsmpl.create_body(), pretrained=False, config=tiny_config)
            vol.net.load_state_dict(other.net.state_dict())
        elif how == "buffer":  # the encoder's fixed surface samples (a partition buffer): all on one face per part
            faces = vol.partition.sample_faces
            faces.data.copy_(faces[:, :1].expand_as(faces))
        same_object = vol.query(out, pts)
        equal_new_output = vol.query(b(**p), pts)  # the value-reuse path (equal constant output)
    expect = _reference(vol, tiny_config, out, pts)
    assert not torch.allclose(expect, before, atol=1e-4)
    assert torch.allclose(same_object, expect, atol=1e-6)
    assert torch.allclose(equal_new_output, expect, atol=1e-6)


def test_encoder_arithmetic_switch_re_encodes(tiny_config):
    """Switching the encoder to bfloat16 (`net.encoder_bf16`, as training runs it) and back changes the codes
    without changing a tensor: the cache must not serve the codes made the other way (as a key without it would),
    neither on the same output nor on an equal new one."""
    b, vol = _fresh_volume(tiny_config, 7)
    p = random_pose(1, seed=26)
    with torch.no_grad():
        out = b(**p)
        pts = _points(out, 2000)
        full = vol.query(out, pts)
        for bf16 in (True, False):
            vol.net.encoder_bf16 = bf16
            same_object, equal_new_output = vol.query(out, pts), vol.query(b(**p), pts)
            expect = _reference(vol, tiny_config, out, pts)
            assert torch.equal(same_object, expect) and torch.equal(equal_new_output, expect)
            assert bf16 == (not torch.equal(expect, full))   # bfloat16 codes do change the field


def test_selfpen_and_parts_follow_edits(setup, tiny_config):
    """query_parts and selfpen_loss read the same cache."""
    b, vol = setup
    with torch.no_grad():
        out = b(**random_pose(1, seed=24))
    pts = _points(out)
    with torch.no_grad():
        parts_before = vol.query_parts(out, pts)
        out.vertices.data.add_(0.02)
        parts_after = vol.query_parts(out, pts)
    copy = SimpleNamespace(**{n: getattr(out, n).clone() for n in ("vertices", "joints", "full_pose")})
    with torch.no_grad():
        assert torch.allclose(parts_after, vol.query_parts(copy, pts), atol=1e-6)
        assert not torch.allclose(parts_after, parts_before, atol=1e-4)
        g = torch.Generator().manual_seed(0)
        loss = vol.selfpen_loss(out, generator=g)
        out.vertices.data.mul_(0.0).add_(copy.vertices * 1.05)
        loss2 = vol.selfpen_loss(out, generator=torch.Generator().manual_seed(0))
        copy.vertices.mul_(1.05)
        assert torch.allclose(loss2, vol.selfpen_loss(copy, generator=torch.Generator().manual_seed(0)), atol=1e-6)
    del loss


def test_two_volumes_never_share(tiny_config):
    """One output queried by two volumes with different weights: each answers with its own weights."""
    b = volsmpl.create_body()
    torch.manual_seed(5)
    v1 = volsmpl.attach_volume(b, pretrained=False, config=tiny_config).eval()
    torch.manual_seed(6)
    v2 = volsmpl.attach_volume(volsmpl.create_body(), pretrained=False, config=tiny_config).eval()
    with torch.no_grad():
        out = b(**random_pose(1, seed=25))
        pts = _points(out)
        a1, a2 = v1.query(out, pts), v2.query(out, pts)
        assert torch.equal(v1.query(out, pts), a1) and torch.equal(v2.query(out, pts), a2)
    assert torch.allclose(a2, _reference(v2, tiny_config, out, pts), atol=1e-6)


def test_fingerprint_detects_single_bit_and_swaps():
    x = torch.randn(1001)
    base = fingerprint([x])
    for i in (0, 500, 1000):
        y = x.clone()
        y.view(torch.int32)[i] ^= 1  # the lowest mantissa bit
        assert fingerprint([y]) != base
    y = x.clone()
    y[[3, 7]] = y[[7, 3]]
    assert fingerprint([y]) != base
    assert fingerprint([x.double()]) != base and fingerprint([x.reshape(7, 143)]) != base
    assert fingerprint([x[1:]]) == fingerprint([x[1:].clone()])  # unaligned views read like copies


@pytest.mark.parametrize("frozen", [False, True])
@pytest.mark.parametrize("loss", ["query", "collision_loss", "selfpen_loss"])
def test_encoding_made_without_graph_is_not_served_to_a_gradient(tiny_config, loss, frozen):
    """An output queried under torch.no_grad() (a logged value) and then in a loss: the loss's pose and weight
    gradients are those of an output never queried before (before: the cached graph-free encoding answered, the
    pose gradient was None and collision_loss's exactly 0 against a maximum of ~7; frozen weights or not)."""
    torch.manual_seed(3)
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, pretrained=False, config=tiny_config).eval().requires_grad_(not frozen)
    p = {k: v.clone().requires_grad_() for k, v in random_pose(2, scale=0.8, seed=8).items()}
    pts = _points(b(**p), 500)

    def value(out):
        if loss == "selfpen_loss":
            return vol.selfpen_loss(out, generator=torch.Generator().manual_seed(0)).sum()
        return getattr(vol, loss)(out, pts).square().sum()

    wrt = [p["body_pose"], *(w for w in vol.parameters() if w.requires_grad)]
    ref_val = value(b(**p))
    ref = torch.autograd.grad(ref_val, wrt, allow_unused=True)
    out = b(**p)
    with torch.no_grad():
        vol.query(out, pts)
        vol.selfpen_loss(out, generator=torch.Generator().manual_seed(0))
    val = value(out)
    got = torch.autograd.grad(val, wrt, allow_unused=True)
    assert torch.allclose(val, ref_val)
    assert ref[0].abs().max() > 0
    for r, g in zip(ref, got):
        assert (r is None) == (g is None)
        if r is not None:
            assert torch.allclose(g, r, atol=1e-6 + 1e-5 * float(r.abs().max())), float((g - r).abs().max())


def test_fingerprint_only_when_a_cached_encoding_could_answer(setup, monkeypatch):
    """The cache's fingerprint (a pass over 3.6 M weights and a host read) is taken only when an encoding could be
    served: never for the new output of a body that moves (every optimisation step's `selfpen_loss`), and still for
    an output that carries an encoding, whose edit must then be caught (test_edited_output_is_re_encoded)."""
    b, vol = setup
    calls = []
    original = vol.cache_key
    monkeypatch.setattr(vol, "cache_key", lambda out: calls.append(1) or original(out))
    pose = random_pose(1, seed=31)["body_pose"].requires_grad_()
    out = b(body_pose=pose)
    vol.selfpen_loss(out, n_points=50, generator=torch.Generator().manual_seed(0))
    assert calls == []
    vol.query(out, _points(out, 50))          # encodes and caches on `out`
    calls.clear()
    vol.selfpen_loss(out, n_points=50, generator=torch.Generator().manual_seed(0))
    assert calls == [1]
