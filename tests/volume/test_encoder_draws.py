"""Encoder draws: several fixed surface sample sets per part, one code per set, z_k their mean.

Checked against references built outside the feature: the partition's sets against its own tight and extended
face lists, the averaged code against the encoder run on each set alone, a volume's query against a dense
decode of the mean code, and the cache against a fresh volume."""
from __future__ import annotations

import json
from dataclasses import replace

import pytest
import torch

from volsmpl.volume.attach import attach_volume
from volsmpl.evaluation import EvalConfig
from volsmpl.nn.coap_net import CoapConfig
from volsmpl.nn.config import VolumeConfig
from volsmpl.nn.pointnet import ResnetPointNet
from volsmpl.body.partition import Partition
from volsmpl.nn.volsmpl_net import PartCode
from volsmpl.train.config import same_weights_config
from conftest import random_pose


def test_each_draw_is_a_full_set_half_tight_half_extended(body):
    n, D = 40, 3
    part = Partition(body, n_samples=n, draws=D)
    assert part.sample_faces.shape == (part.num_parts, D * n)
    for k in range(part.num_parts):
        tight = set(part.tight_face_ids[k].tolist())
        extended = set(part.extended_face_ids[k].tolist())
        for d in range(D):
            block = part.sample_faces[k, d * n:(d + 1) * n].tolist()
            assert all(f in tight for f in block[:n // 2]), (k, d)
            assert all(f in extended for f in block[n // 2:]), (k, d)
    # the sets differ from each other (independent draws), and fresh draws come in as many sets
    assert not torch.equal(part.sample_faces[:, :n], part.sample_faces[:, n:2 * n])
    out = body(**random_pose(2, seed=1))
    fresh = part.surface_points(out.vertices, torch.Generator().manual_seed(0))
    assert fresh.shape == (2, part.num_parts, D * n, 3)


def test_one_draw_is_the_constructors_set_and_set_draws_is_reproducible(body):
    ref = Partition(body, n_samples=40)
    part = Partition(body, n_samples=40, draws=4)
    again = Partition(body, n_samples=40, draws=4)
    assert torch.equal(part.sample_faces, again.sample_faces) and torch.equal(part.sample_bary, again.sample_bary)
    part.set_draws(1)
    assert torch.equal(part.sample_faces, ref.sample_faces) and torch.equal(part.sample_bary, ref.sample_bary)
    for bad in (0, -2, 1.5, True):
        with pytest.raises(ValueError, match="positive number of surface sample sets"):
            part.set_draws(bad)


def test_encode_parts_is_the_mean_of_each_set_encoded_alone():
    torch.manual_seed(0)
    enc = ResnetPointNet(latent_dim=16, hidden=12, n_blocks=2).double()
    B, K, n, D = 2, 3, 25, 4
    pts = torch.randn(B, K, D * n, 3, dtype=torch.float64)
    ref = torch.stack([enc(pts[:, :, d * n:(d + 1) * n].reshape(B * K, n, 3)) for d in range(D)]).mean(0)
    torch.testing.assert_close(enc.encode_parts(pts, D), ref.reshape(B, K, -1))
    torch.testing.assert_close(enc.encode_parts(pts[:, :, :n], 1), enc(pts[:, :, :n].reshape(B * K, n, 3)).reshape(B, K, -1))
    with pytest.raises(ValueError, match="do not split into draws=3"):
        enc.encode_parts(pts, 3)


def _volume(body, draws, kind="volsmpl"):
    torch.manual_seed(0)
    cfg = (VolumeConfig(latent_dim=16, encoder_hidden=16, encoder_blocks=2, n_surface_samples=32, decoder_hidden=16,
                        nbw_rank=2, encoder_draws=draws) if kind == "volsmpl"
           else CoapConfig(latent_dim=16, encoder_hidden=16, encoder_blocks=2, n_surface_samples=32, query_dims=(48,) * 3,
                           query_out=16, decoder_dims=(32,) * 6, encoder_draws=draws))
    return attach_volume(body, pretrained=False, model=kind, config=cfg)


@pytest.mark.parametrize("kind", ["volsmpl", "coap"])
def test_volume_query_decodes_the_mean_code(body, kind):
    vol = _volume(body, 3, kind)
    out = body(**random_pose(1, seed=2))
    near = out.vertices[:, ::40]
    pts = near + 0.01 * torch.randn(near.shape, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        got = vol.query(out, pts)
        enc = vol.encode(out)
        p, n = vol.partition, vol.partition.n_samples
        local = p.to_part_frames(p.surface_points(out.vertices), enc.G)
        if enc.center is not None:
            local = (local - enc.center[:, :, None]) / enc.scale[:, :, None]
        z = torch.stack([vol.net.encoder(local[0, :, d * n:(d + 1) * n]) for d in range(3)]).mean(0)[None]
        one = vol.net.encoder(local[0, :, :n])[None]
        assert not torch.allclose(z, one)   # the mean is not one set's code
        code = (PartCode(z, vol.net.decoder.generate(z, None)) if kind == "volsmpl" else vol.net.fold(z, None))
        dense = vol.query_encoded(replace(enc, code=code, grouped=None), pts, dense=True)
    torch.testing.assert_close(got, dense, atol=1e-5, rtol=1e-5)


def test_set_encoder_draws_is_not_served_from_the_cache(body):
    out = body(**random_pose(1, seed=4))
    pts = out.vertices[:, ::50]
    with torch.no_grad():
        vol = _volume(body, 1)
        one = vol.query(out, pts)
        vol.set_encoder_draws(4)
        four = vol.query(out, pts)     # the same output object: its cached encoding was made with one set
        fresh = _volume(body, 4).query(body(**random_pose(1, seed=4)), pts)
    assert not torch.allclose(one, four)
    torch.testing.assert_close(four, fresh)


def test_mesh_volume_refuses_encoder_draws(body):
    mesh = attach_volume(body, model="mesh")
    with pytest.raises(ValueError, match="has no encoder"):
        mesh.set_encoder_draws(2)
    with pytest.raises(ValueError, match="positive number"):
        EvalConfig(encoder_draws=0)


def test_checkpoints_without_the_key_keep_working_and_draws_do_not_block_init():
    old = VolumeConfig().to_dict()
    old.pop("encoder_draws")
    assert same_weights_config(old, VolumeConfig())                      # written before encoder_draws existed
    assert same_weights_config(old, VolumeConfig(encoder_draws=4))       # a phase with more sets, same weights
    assert not same_weights_config(old, VolumeConfig(latent_dim=64))     # other weights
    assert not same_weights_config(CoapConfig().to_dict(), VolumeConfig())
    assert VolumeConfig.from_dict(old).encoder_draws == 1
    assert json.loads(json.dumps(VolumeConfig(encoder_draws=2).to_dict()))["encoder_draws"] == 2
