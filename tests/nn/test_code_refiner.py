"""The learned code refinement (volsmpl.nn.code_refiner; VolumeConfig.refiner_iters).

Checked against references outside the feature: the refinement losses by hand; the gradient the refiner reads
against central differences of the part's loss computed from every part's dense decoder; an untrained refiner
against the model without one; a refinement of some parts against the refinement of all; training only the refiner
against the weights it must leave as they were."""
from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import pytest
import torch

from volsmpl.body.model import create_body
from volsmpl.evaluation.validation_set import validation_bodies
from volsmpl.geometry.boxes import part_normalization
from volsmpl.io.checkpoint import load_checkpoint
from volsmpl.nn.code_refiner import LearnedCodeRefiner, refinement_losses
from volsmpl.nn.config import VolumeConfig
from volsmpl.volume.attach import attach_volume
from volsmpl.volume.code_refinement import refinement_points
from volsmpl.volume.models import model_kind
from volsmpl.train.config import TrainConfig, adds_refiner
from volsmpl.train.loop import train

TINY = VolumeConfig(latent_dim=16, encoder_hidden=16, encoder_blocks=2, n_surface_samples=64, decoder_hidden=16,
                    nbw_rank=2, normalize_parts=True)


def with_refiner(body, iters: int = 1, seed: int | None = None):
    """The shipped VolumetricSMPL's encoder and decoders with a new refiner of `iters` passes: untrained (seed None: the identity), or
    with its heads' last layers drawn small from `seed` (a refiner that changes the codes)."""
    state, cfg, _ = load_checkpoint(model_kind("volsmpl").default_checkpoint)
    state = {k: v for k, v in state.items() if not k.startswith("refiner.")}   # a shipped model's own passes
    torch.manual_seed(0 if seed is None else seed)                      # the refiner's initial weights
    vol = attach_volume(body, pretrained=False, config=VolumeConfig.from_dict({**cfg, "refiner_iters": iters}))
    missing, unexpected = vol.net.load_state_dict(state, strict=False)
    assert not unexpected and all(k.startswith("refiner.") for k in missing)
    if seed is not None:
        g = torch.Generator().manual_seed(seed)
        for h in vol.net.refiner.head:
            with torch.no_grad():
                h[-1].weight.copy_(torch.randn(h[-1].weight.shape, generator=g) * 0.02)
    vol.requires_grad_(False)
    return vol


@pytest.fixture(scope="module")
def posed():
    body = create_body()
    with torch.no_grad():
        out = body(**{k: v[:1] for k, v in validation_bodies(1).items()})
    return body, out


def test_refinement_losses_by_hand():
    t = torch.tensor([[[0.002, -0.001]]], dtype=torch.float64)
    d = torch.tensor([[[0.003, 0.0005]]], dtype=torch.float64)
    sdf = [0.25 * math.log1p(math.exp(-(1 * 0.003) / 1e-3)) + 1e4 * 0.001 ** 2,
           0.25 * math.log1p(math.exp(-(-1 * 0.0005) / 1e-3)) + 1e4 * 0.0015 ** 2]
    assert float(refinement_losses("sdf", d, t)) == pytest.approx(sum(sdf) / 2, rel=1e-12)
    occ = torch.tensor([[[0.9, 0.25]]], dtype=torch.float64)           # labels: outside (0), inside (1)
    assert float(refinement_losses("occupancy", occ, t)) == pytest.approx((-math.log(0.1) - math.log(0.25)) / 2)
    with pytest.raises(ValueError, match="neither 'sdf' nor 'occupancy'"):
        refinement_losses("udf", d, t)


def test_an_untrained_refiner_leaves_the_model_as_it_is(posed):
    body, out = posed
    plain = attach_volume(create_body()).set_passes(0)
    vol = with_refiner(create_body(), iters=2)
    pts = out.vertices[:, ::40] + 0.004 * torch.randn(1, out.vertices[:, ::40].shape[1], 3, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        assert torch.equal(vol.query(out, pts), plain.query(out, pts))


def test_the_refiner_reads_the_gradient_of_each_parts_loss(posed):
    """A refiner whose one pass is set by hand to z <- z - eta g / |g| (g the gradient it reads) moves each code
    along the steepest descent of the part's loss: by central differences of that loss, computed from the part's
    dense decoder in float64 (no code shared with the refiner's pair decoding), the loss falls along the step at
    the rate |g| and does not change along directions orthogonal to it."""
    body, out = posed
    vol = with_refiner(create_body()).double()
    net, ref = vol.net, vol.net.refiner
    L = net.config.latent_dim
    h = ref.head[0]
    off = L + ref.point[0].latent_dim + ref.num_parts                    # [z, summary, one-hot] precede g / |g|
    eta = 0.05
    with torch.no_grad():
        for lin in h:
            if isinstance(lin, torch.nn.Linear):
                lin.weight.zero_()
                lin.bias.zero_()
        eye = torch.eye(L, dtype=torch.float64)
        h[0].weight[:L, off:off + L] = eye            # relu(u), relu(-u) of u = g / |g|
        h[0].weight[L:2 * L, off:off + L] = -eye
        h[2].weight[:2 * L, :2 * L] = torch.eye(2 * L, dtype=torch.float64)
        h[4].weight[:, :L] = -eta * eye
        h[4].weight[:, L:2 * L] = eta * eye
    v = out.vertices.double()
    with torch.no_grad():
        G, bmin, bmax = vol._frames(SimpleNamespace(vertices=v, joints=out.joints.double(),
                                                    full_pose=out.full_pose.double()))
        center, scale = part_normalization(bmin, bmax)
        p = vol.partition
        local = (p.to_part_frames(p.surface_points(v), G) - center[:, :, None]) / scale[:, :, None]
        z = net.encode_z(local)
        xin, t, sc = refinement_points(p, v, G, center, scale)
        z1 = ref(net, z, xin, t, sc)
    step = (z1 - z)[0]                                                   # (K, L)

    def part_loss(k, zk):
        one = torch.tensor([k])
        d = net.decode_dense(xin[:, k:k + 1], net.code_from_z(zk[None, None], one))[0, 0] * sc[0, k]
        tk = t[0, k]
        sign = torch.log1p(torch.exp(-torch.sign(tk) * d / 1e-3))
        return float((0.25 * sign + 1e4 * (d - tk) ** 2).mean())

    gen = torch.Generator().manual_seed(1)
    for k in (0, 7):
        def slope(u):
            with torch.no_grad():
                return (part_loss(k, z[0, k] + 1e-5 * u) - part_loss(k, z[0, k] - 1e-5 * u)) / 2e-5
        along = step[k] / step[k].norm()
        assert float(step[k].norm()) == pytest.approx(eta, rel=1e-9)
        down = slope(along)
        assert down < 0
        for _ in range(3):
            u = torch.randn(L, generator=gen, dtype=torch.float64)
            u = u - (u @ along) * along
            assert abs(slope(u / u.norm())) < 1e-3 * abs(down), (k, slope(u / u.norm()), down)


def test_refining_some_parts_gives_the_codes_of_refining_all(posed):
    body, out = posed
    a, b = with_refiner(create_body(), seed=3), with_refiner(create_body(), seed=3)
    with torch.no_grad():
        enc = a.encode(out)
        tip = a.partition.vertex_labels[out.vertices[0, :, 0].argmax()]
        pts = out.vertices[:, a.partition.vertex_labels == tip][:, :30] + 0.003
        full = a.query_encoded(enc, pts)
        part = b.query(out, pts)                              # encodes only the parts whose boxes hold pts
    sub = out._volsmpl_encoding[1]
    assert sub.parts is not None and len(sub.parts) < a.num_parts
    assert not torch.equal(enc.code.z, a.net.encode_z(                    # the refiner changed the codes
        (a.partition.to_part_frames(a.partition.surface_points(out.vertices), enc.G) - enc.center[:, :, None])
        / enc.scale[:, :, None]))
    assert torch.allclose(part, full, atol=1e-6), float((part - full).abs().max())


def test_training_only_the_refiner_leaves_the_encoder_and_decoders(tmp_path):
    base = TrainConfig(batch_size=2, n_uniform=16, n_surface=16, steps=1000, ckpt_every=2, log_every=1, model=TINY)
    train(base, tmp_path / "a", max_steps=2, quiet=True)
    src = tmp_path / "a" / "ckpt-00000002" / "model"
    cfg = dataclasses.replace(base, model=dataclasses.replace(TINY, refiner_iters=1, refiner_hidden=8,
                                                              refiner_blocks=1), train_weights="refiner", lr=1e-2)
    r = train(cfg, tmp_path / "r", init=src, max_steps=3, quiet=True)
    assert r["step"] == 5
    before, _, _ = load_checkpoint(src)
    after, held, _ = load_checkpoint(tmp_path / "r" / "ckpt-00000005" / "model")
    assert held["refiner_iters"] == 1
    for k, v in before.items():
        assert torch.equal(after[k], v), k
    head = [k for k in after if k.startswith("refiner.head.0.4.")]
    assert head and any(after[k].abs().max() > 0 for k in head)    # the zero-initialised last layer trained
    # a second pass added to that checkpoint: the first pass loads, the second starts as the identity
    two = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, refiner_iters=2))
    r = train(two, tmp_path / "r2", init=tmp_path / "r" / "ckpt-00000005" / "model", max_steps=1, quiet=True)
    assert r["step"] == 6
    grown, _, _ = load_checkpoint(tmp_path / "r2" / "ckpt-00000006" / "model")
    assert any(k.startswith("refiner.head.1.") for k in grown)
    for k, v in before.items():
        assert torch.equal(grown[k], v), k


def test_refiner_options_fail_in_one_line():
    with pytest.raises(ValueError, match="refiner_iters must be a non-negative integer"):
        VolumeConfig(refiner_iters=-1)
    with pytest.raises(ValueError, match="set model.refiner_iters >= 1"):
        TrainConfig(train_weights="refiner")
    with pytest.raises(ValueError, match="train_weights must be 'all' or 'refiner'"):
        TrainConfig(train_weights="decoder")
    with pytest.raises(ValueError, match="iters >= 1"):
        LearnedCodeRefiner(16, iters=0)
    held = VolumeConfig().to_dict()
    assert adds_refiner(held, VolumeConfig(refiner_iters=2))
    assert not adds_refiner(held, VolumeConfig())                                   # nothing added
    assert not adds_refiner(held, VolumeConfig(refiner_iters=2, latent_dim=64))     # other weights
    one = VolumeConfig(refiner_iters=1).to_dict()
    assert adds_refiner(one, VolumeConfig(refiner_iters=2))                          # a second pass
    assert not adds_refiner(one, VolumeConfig(refiner_iters=1))
    assert not adds_refiner(one, VolumeConfig(refiner_iters=2, refiner_hidden=32))  # the first pass's width changed
