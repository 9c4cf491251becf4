import json
import math

import pytest
import torch

from volsmpl.nn.coap_net import CoapCode, CoapConfig, CoapNet
from volsmpl.nn.config import VolumeConfig
from volsmpl.nn.nbw import count_parameters


def _tiny_cfg(**kw):
    args = dict(latent_dim=6, encoder_hidden=8, encoder_blocks=1, n_surface_samples=16,
                query_dims=(24, 20, 24), query_skip=(2,), query_out=7,
                decoder_dims=(16, 18, 16), decoder_skip=(2,))
    args.update(kw)
    return CoapConfig(**args)


def _tiny(K=3, dtype=torch.float64, seed=0, **kw):
    torch.manual_seed(seed)
    net = CoapNet(K, _tiny_cfg(**kw)).to(dtype)
    with torch.no_grad():  # non-trivial biases everywhere (defaults zero some of them)
        for lin in list(net.query_layers) + list(net.decoder_layers):
            lin.bias.normal_(0.0, 0.3)
    return net


def _naive(net, x, z, inside=None):
    """Reference: COAP's ImplicitNet on explicitly concatenated inputs (no folding).

    x (B, K, N, 3), z (B, K, L), inside (B, K, N) or None (= 1) -> (B, K, N) occupancy."""
    B, K, N, _ = x.shape
    beta = net.config.softplus_beta
    act = torch.relu if beta == 0 else (lambda t: torch.nn.functional.softplus(t, beta=beta))
    flag = torch.ones(B, K, N, 1, dtype=x.dtype) if inside is None else inside.to(x.dtype)[..., None]
    onehot = torch.eye(K, dtype=x.dtype)[None, :, None, :].expand(B, K, N, K)
    u = torch.cat([x, flag, onehot, z[:, :, None, :].expand(B, K, N, z.shape[-1])], -1)

    def mlp(layers, skips, inp):
        h = inp
        for l, lin in enumerate(layers):
            if l in skips:
                h = torch.cat([h, inp], -1) / math.sqrt(2)
            h = h @ lin.weight.T + lin.bias
            if l < len(layers) - 1:
                h = act(h)
        return h

    q = mlp(net.query_layers, net.config.query_skip, u)
    o = mlp(net.decoder_layers, net.config.decoder_skip, torch.cat([x, q], -1))
    return torch.sigmoid(-o[..., 0])


def _random_pairs(B, K, N, M, seed=0, bodies=None):
    g = torch.Generator().manual_seed(seed)
    b = torch.randint(0, B, (M,), generator=g) if bodies is None else \
        torch.tensor(bodies)[torch.randint(0, len(bodies), (M,), generator=g)]
    return b, torch.randint(0, K, (M,), generator=g), torch.randint(0, N, (M,), generator=g)


def test_shapes_and_layer_layout():
    net = CoapNet(16)
    assert net.kind == "coap" and net.output == "occupancy" and net.encoder_bf16 is False
    assert net.num_parts == 16 and isinstance(net.config, CoapConfig)
    # COAP's IGR layout: the layer before a skip outputs width - input size.
    assert [(l.in_features, l.out_features) for l in net.query_layers] == [(148, 256), (256, 108), (256, 256), (256, 128)]
    assert [(l.in_features, l.out_features) for l in net.decoder_layers] == \
        [(131, 256), (256, 256), (256, 125), (256, 256), (256, 256), (256, 256), (256, 1)]
    torch.manual_seed(0)
    code = net.encode(torch.randn(2, 16, 50, 3) * 0.1)
    assert isinstance(code, CoapCode) and code.z.shape == (2, 16, 128)
    assert [b.shape for b in code.biases] == [(2, 16, 256), (2, 16, 256)]
    with torch.no_grad():
        assert net.decode_dense(torch.randn(2, 16, 7, 3), code).shape == (2, 16, 7)
        out = net.decode_pairs(torch.randn(5, 3), torch.tensor([0, 1, 1, 0, 1]), torch.tensor([0, 3, 15, 2, 2]), code)
    assert out.shape == (5,)


def test_parameter_count_and_flops():
    net = CoapNet(16)
    enc = count_parameters(net.encoder)
    q = (148 * 256 + 256) + (256 * 108 + 108) + (256 * 256 + 256) + (256 * 128 + 128)
    d = (131 * 256 + 256) + 4 * (256 * 256 + 256) + (256 * 125 + 125) + (256 + 1)
    assert net.num_parameters() == enc + q + d == 840170
    # folded: layer 0 reads x only, the skip layer reads [h (108), x]; decoder unchanged.
    macs = 3 * 256 + 256 * 108 + (108 + 3) * 256 + 256 * 128
    macs += 131 * 256 + 4 * 256 * 256 + 256 * 125 + 256
    assert net.flops_per_pair() == 2 * macs == 835072


@pytest.mark.parametrize("beta", [100.0, 0.0])
@pytest.mark.parametrize("use_inside", [False, True])
def test_folded_equals_naive_concat(beta, use_inside):
    net = _tiny(K=4, softplus_beta=beta)
    torch.manual_seed(1)
    z = torch.randn(2, 4, 6, dtype=torch.float64)
    x = torch.randn(2, 4, 30, 3, dtype=torch.float64) * 0.5
    inside = torch.rand(2, 4, 30) > 0.5 if use_inside else None
    ref = _naive(net, x, z, inside)
    out = net.decode_dense(x, net.fold(z), inside=inside)
    torch.testing.assert_close(out, ref)
    if use_inside:  # the flag is an input that matters
        assert not torch.allclose(out, net.decode_dense(x, net.fold(z)))


def test_folded_equals_naive_default_config_float32():
    torch.manual_seed(0)
    net = CoapNet(16)
    surf = torch.randn(1, 16, 64, 3) * 0.1
    x = torch.randn(1, 16, 40, 3) * 0.2
    inside = torch.rand(1, 16, 40) > 0.3
    with torch.no_grad():
        code = net.encode(surf)
        torch.testing.assert_close(code.z, net.encoder(surf.reshape(16, 64, 3)).reshape(1, 16, -1))
        ref = _naive(net, x, code.z, inside)
        out = net.decode_dense(x, code, inside=inside)
    torch.testing.assert_close(out, ref, atol=1e-5, rtol=1e-5)


def test_pairs_equal_dense_incl_body_without_pairs_and_tiling():
    net = _tiny(K=5)
    torch.manual_seed(2)
    code = net.fold(torch.randn(3, 5, 6, dtype=torch.float64))
    x = torch.randn(3, 5, 40, 3, dtype=torch.float64) * 0.6
    dense = net.decode_dense(x, code)
    torch.testing.assert_close(dense, _naive(net, x, code.z))  # flag 1 folded like the pairs path
    b, k, n = _random_pairs(3, 5, 40, 300, bodies=[0, 2])   # body 1 has no pairs
    torch.testing.assert_close(net.decode_pairs(x[b, k, n], b, k, code), dense[b, k, n])
    net.TILE_ROWS = 64                                      # no-grad tiled path
    with torch.no_grad():
        torch.testing.assert_close(net.decode_pairs(x[b, k, n], b, k, code), dense[b, k, n])
        torch.testing.assert_close(net.decode_dense(x, code), dense)


def test_pairs_empty_and_bad_indices():
    net = _tiny(K=3)
    code = net.fold(torch.randn(2, 3, 6, dtype=torch.float64))
    e = torch.zeros(0, dtype=torch.long)
    out = net.decode_pairs(torch.zeros(0, 3, dtype=torch.float64), e, e, code)
    assert out.shape == (0,) and out.dtype == torch.float64
    with pytest.raises(IndexError, match="must lie in"):
        net.decode_pairs(torch.zeros(1, 3, dtype=torch.float64), torch.tensor([2]), torch.tensor([0]), code)
    with pytest.raises(ValueError, match=r"\(M, 3\)"):
        net.decode_pairs(torch.zeros(4, dtype=torch.float64), e, e, code)
    with pytest.raises(TypeError, match="CoapCode"):
        net.decode_pairs(torch.zeros(1, 3, dtype=torch.float64), torch.tensor([0]), torch.tensor([0]), code.z)
    with pytest.raises(ValueError, match="inside of shape"):
        net.decode_dense(torch.zeros(2, 3, 4, 3, dtype=torch.float64), code, inside=torch.ones(2, 3, 5, dtype=torch.bool))


def test_outputs_are_probabilities():
    torch.manual_seed(0)
    net = CoapNet(4)
    with torch.no_grad():
        code = net.encode(torch.randn(2, 4, 32, 3) * 0.1)
        x = torch.cat([torch.randn(2, 4, 50, 3) * 0.1, torch.randn(2, 4, 50, 3) * 100.0], 2)
        out = net.decode_dense(x, code)
    assert torch.isfinite(out).all() and (out >= 0).all() and (out <= 1).all()
    # geometric init (radius 1): occupancy > 0.5 near the origin, < 0.5 far away, as in COAP.
    assert (out[..., :50] > 0.5).float().mean() > 0.9 and (out[..., 50:] < 0.5).all()


def test_gradcheck_x_and_z():
    net = _tiny(K=3)
    torch.manual_seed(3)
    z = torch.randn(2, 3, 6, dtype=torch.float64, requires_grad=True)
    b, k = torch.tensor([0, 1, 1, 0, 1]), torch.tensor([2, 0, 2, 1, 1])
    x = (torch.randn(5, 3, dtype=torch.float64) * 0.3).requires_grad_()
    assert torch.autograd.gradcheck(lambda x, z: net.decode_pairs(x, b, k, net.fold(z)), (x, z))
    xd = (torch.randn(2, 3, 4, 3, dtype=torch.float64) * 0.3).requires_grad_()
    inside = torch.rand(2, 3, 4) > 0.5
    assert torch.autograd.gradcheck(lambda x, z: net.decode_dense(x, net.fold(z), inside=inside), (xd, z))


def test_encode_autocast_bf16_flag():
    torch.manual_seed(0)
    net = _tiny(K=2, dtype=torch.float32)
    surf = torch.randn(1, 2, 16, 3)
    net.encoder_bf16 = True
    code = net.encode(surf)
    assert code.z.dtype == torch.float32
    torch.testing.assert_close(code.z, net.encoder(surf.reshape(2, 16, 3)).reshape(1, 2, -1), atol=0.1, rtol=0.1)


def test_config_round_trip_and_errors():
    cfg = CoapConfig(query_dims=(300, 280, 256), decoder_skip=(2, 4), softplus_beta=0)
    d = json.loads(json.dumps(cfg.to_dict()))
    assert d["model"] == "coap"
    assert CoapConfig.from_dict(d) == cfg
    assert CoapConfig.from_dict({}) == CoapConfig()
    with pytest.raises(ValueError, match="unknown CoapConfig key"):
        CoapConfig.from_dict({**d, "nbw_rank": 80})
    with pytest.raises(ValueError, match="unknown CoapConfig key"):
        CoapConfig.from_dict(VolumeConfig().to_dict())
    with pytest.raises(ValueError, match="model must be 'coap'"):
        CoapConfig(model="volsmpl")
    with pytest.raises(ValueError, match="out of range"):
        CoapConfig(query_skip=(4,))
    with pytest.raises(ValueError, match="needs width"):
        CoapNet(200)  # 3 + 1 + 200 + 128 input columns exceed the 256-wide skip layer
    # a net rebuilt from the saved config has the same architecture
    net = CoapNet(5, CoapConfig.from_dict(CoapConfig().to_dict()))
    assert net.num_parameters() == CoapNet(5).num_parameters()


def test_part_subset_code_equals_naive_concat():
    """A code folded for a part subset keeps each part's own one-hot column (naive reference on all parts)."""
    net = _tiny(K=4)
    torch.manual_seed(3)
    z = torch.randn(2, 4, 6, dtype=torch.float64)
    x = torch.randn(2, 4, 12, 3, dtype=torch.float64) * 0.5
    parts = torch.tensor([0, 2, 3])
    code = net.fold(z[:, parts], parts)
    torch.testing.assert_close(net.decode_dense(x[:, parts], code), _naive(net, x, z)[:, parts])
    with pytest.raises(ValueError, match="K=3"):
        net.fold(z, parts)
    with pytest.raises(ValueError, match=r"latents are for K=3 parts, expected 2 \(the part subset\)"):
        net.decode_dense(x[:, parts], code._replace(parts=torch.tensor([0, 2])))
    with pytest.raises(ValueError, match=r"for K=3 parts, expected 4 \(this network\)"):
        net.decode_dense(x[:, parts], code._replace(parts=None))
    with pytest.raises(ValueError, match="strictly increasing"):
        net.fold(z[:, :2], torch.tensor([0, 4]))
