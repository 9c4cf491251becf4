import pytest
import torch

from volsmpl.nn.config import VolumeConfig
from volsmpl.nn.grouped import grouped_supported
from volsmpl.nn.nbw import NBWDecoder, count_parameters
from volsmpl.nn.pairs import group_pairs
from volsmpl.nn.pointnet import ResnetPointNet
from volsmpl.nn.posenc import positional_encoding


def _tiny(K=3, dtype=torch.float64, share=False, seed=0, **kw):
    torch.manual_seed(seed)
    args = dict(latent_dim=5, hidden=8, n_layers=5, skip_layers=(2,), pe_levels=2, rank=2,
                shape_init_std=0.3, share_shapes=share)
    args.update(kw)
    return NBWDecoder(K, **args).to(dtype)


def _naive_decoder(model, full_weights, x_local, z):
    """Reference: per point concatenate z_k to the input (no folding), explicit skip concat."""
    B, K, N, _ = x_local.shape
    p = positional_encoding(x_local, model.pe_levels)
    u = torch.cat([p, z[:, :, None, :].expand(B, K, N, z.shape[-1])], -1)   # decoder input [gamma(x), z]
    h = u
    for l, W in enumerate(full_weights):
        if l in model.skip_layers:
            h = torch.cat([h, u], -1)
        h = torch.einsum("bkoi,bkni->bkno", W, h) + model.base_bias[l]
        if l < model.n_layers - 1:
            h = torch.relu(h)
    return h[..., 0]


@pytest.mark.parametrize("share", [False, True])
def test_blended_weights_explicit_loop(share):
    m = _tiny(K=3, share=share)
    z = torch.randn(2, 3, 5, dtype=torch.float64)
    full = m.blended_weights(z)
    for l in range(m.n_layers):
        assert full[l].shape == (2, 3, m.out_dims[l], m.in_dims[l])
        for b in range(2):
            for k in range(3):
                v = z[b, k] @ m.blend[l].weight.T + m.blend[l].bias
                W = m.base_weight[l].clone()
                for r in range(m.rank):
                    W = W + v[r] * m.shape_weight[l][0 if share else k, r]
                torch.testing.assert_close(full[l][b, k], W)


def test_rank_zero_is_base_mlp():
    m = _tiny(rank=0)
    z = torch.randn(2, 3, 5, dtype=torch.float64)
    for l, W in enumerate(m.blended_weights(z)):
        torch.testing.assert_close(W, m.base_weight[l].expand_as(W))


def test_folded_bias_equals_naive_concat():
    m = _tiny(K=4)
    z = torch.randn(2, 4, 5, dtype=torch.float64)
    x = torch.randn(2, 4, 30, 3, dtype=torch.float64) * 0.5
    ref = _naive_decoder(m, m.blended_weights(z), x, z)
    gen = m.generate(z)
    assert gen.weights[0].shape == (2, 4, 8, 15)            # latent columns folded away
    assert gen.weights[2].shape == (2, 4, 8, 8 + 15)
    torch.testing.assert_close(m.decode_dense(x, gen), ref)


def test_folded_bias_default_config_float32():
    cfg = VolumeConfig()
    torch.manual_seed(0)
    m = NBWDecoder.from_config(cfg, n_parts=2, shape_init_std=0.02)
    z = torch.randn(1, 2, 128)
    x = torch.randn(1, 2, 50, 3) * 0.3
    with torch.no_grad():
        ref = _naive_decoder(m, m.blended_weights(z), x, z)
        out = m.decode_dense(x, m.generate(z))
    torch.testing.assert_close(out, ref, atol=1e-5, rtol=1e-5)


def _pairs_vs_dense(m, z, x, bi, pi, chunk=None, atol=1e-5):
    """decode_pairs must equal decode_dense gathered at the same (body, part, point) pairs,
    in value and in gradient w.r.t. x and z."""
    B, K = z.shape[:2]
    M = x.shape[0]
    z1 = z.clone().requires_grad_()
    x1 = x.clone().requires_grad_()
    y = m.decode_pairs(x1, bi, pi, m.generate(z1), chunk=chunk)
    # dense reference: put every pair's point in slot (b, k, n) of a dense tensor
    z2 = z.clone().requires_grad_()
    x2 = x.clone().requires_grad_()
    dense_x = torch.zeros(B, K, M, 3, dtype=x.dtype)
    idx = torch.arange(M)
    dense_x = dense_x.index_put((bi, pi, idx), x2)
    d = m.decode_dense(dense_x, m.generate(z2))[bi, pi, idx]
    torch.testing.assert_close(y, d, atol=atol, rtol=atol)
    w = torch.randn(M, dtype=x.dtype)
    gx1, gz1 = torch.autograd.grad((y * w).sum(), (x1, z1))
    gx2, gz2 = torch.autograd.grad((d * w).sum(), (x2, z2))
    torch.testing.assert_close(gx1, gx2, atol=atol, rtol=atol)
    torch.testing.assert_close(gz1, gz2, atol=atol, rtol=atol)
    return y


@pytest.mark.parametrize("chunk", [None, 1, 3, 16, 1000])
def test_decode_pairs_matches_dense(chunk):
    m = _tiny(K=4)
    g = torch.Generator().manual_seed(0)
    B, M = 3, 200
    z = torch.randn(B, 4, 5, dtype=torch.float64, generator=g)
    x = torch.randn(M, 3, dtype=torch.float64, generator=g) * 0.5
    bi = torch.randint(0, B, (M,), generator=g)
    bi[bi == 1] = 2                                   # body 1 has no pairs
    pi = torch.randint(0, 3, (M,), generator=g)       # part 3 empty in every body
    _pairs_vs_dense(m, z, x, bi, pi, chunk=chunk, atol=1e-10)


def test_decode_pairs_all_in_one_part_float32():
    cfg = VolumeConfig()
    torch.manual_seed(1)
    m = NBWDecoder.from_config(cfg, n_parts=4, shape_init_std=0.02)
    z = torch.randn(2, 4, 128)
    x = torch.randn(700, 3) * 0.3
    bi = torch.ones(700, dtype=torch.long)
    pi = torch.full((700,), 2, dtype=torch.long)
    _pairs_vs_dense(m, z, x, bi, pi, atol=1e-5)


def test_decode_pairs_float32_random_pairs_default_config():
    cfg = VolumeConfig()
    torch.manual_seed(2)
    m = NBWDecoder.from_config(cfg, n_parts=5, shape_init_std=0.02)
    z = torch.randn(2, 5, 128)
    M = 600
    x = torch.randn(M, 3) * 0.3
    _pairs_vs_dense(m, z, x, torch.randint(0, 2, (M,)), torch.randint(0, 5, (M,)), atol=1e-5)


def test_decode_pairs_nograd_tiled_path_equals_grad_path(monkeypatch):
    m = _tiny(K=3)
    g = torch.Generator().manual_seed(3)
    z = torch.randn(2, 3, 5, dtype=torch.float64, generator=g)
    x = torch.randn(500, 3, dtype=torch.float64, generator=g)
    bi = torch.randint(0, 2, (500,), generator=g)
    pi = torch.randint(0, 3, (500,), generator=g)
    with torch.no_grad():
        gen = m.generate(z)
        monkeypatch.setattr(NBWDecoder, "TILE_ROWS", 40)   # many tiles
        y_tiled = m.decode_pairs(x, bi, pi, gen, chunk=16)
    xg = x.clone().requires_grad_()
    y_grad = m.decode_pairs(xg, bi, pi, m.generate(z), chunk=16)
    torch.testing.assert_close(y_tiled, y_grad.detach())


def test_decode_pairs_on_a_gpu_runs_untiled_with_operator_calls_independent_of_b(monkeypatch):
    """On a GPU the no-grad path has no cache tiles: one batched matmul per layer whatever B (operator calls
    counted by the profiler), values equal to the CPU's tiled path."""
    from volsmpl.bench.jobs import profile_query

    m = _tiny(K=3)
    assert m.tile_rows("cpu") == NBWDecoder.TILE_ROWS and m.tile_rows("cuda") is None
    monkeypatch.setattr(NBWDecoder, "TILE_ROWS", 40)

    def calls(B, tiles):
        g = torch.Generator().manual_seed(B)
        z = torch.randn(B, 3, 5, dtype=torch.float64, generator=g)
        x = torch.randn(300 * B, 3, dtype=torch.float64, generator=g)
        bi = torch.arange(B).repeat_interleave(300)
        pi = torch.randint(0, 3, (300 * B,), generator=g)
        with torch.no_grad():
            gen = m.generate(z)
            monkeypatch.setattr(NBWDecoder, "tile_rows", lambda self, d: 40 if tiles else None)
            y = m.decode_pairs(x, bi, pi, gen, chunk=16)
            n = profile_query(lambda: m.decode_pairs(x, bi, pi, gen, chunk=16), runs=1)["ops_per_query"]
            monkeypatch.setattr(NBWDecoder, "tile_rows", lambda self, d: 40)
            torch.testing.assert_close(y, m.decode_pairs(x, bi, pi, gen, chunk=16))
        return n

    assert calls(1, tiles=False) == calls(8, tiles=False)
    assert calls(8, tiles=True) > calls(1, tiles=True)  # the CPU's tiles: the count grows with the pairs


def test_decode_pairs_gradcheck():
    m = _tiny(K=3)
    g = torch.Generator().manual_seed(4)
    B, M = 2, 10
    z = torch.randn(B, 3, 5, dtype=torch.float64, generator=g, requires_grad=True)
    x = torch.randn(M, 3, dtype=torch.float64, generator=g, requires_grad=True)
    bi = torch.randint(0, B, (M,), generator=g)
    pi = torch.randint(0, 3, (M,), generator=g)
    assert torch.autograd.gradcheck(lambda x, z: m.decode_pairs(x, bi, pi, m.generate(z), chunk=4), (x, z))


def test_decode_pairs_empty():
    m = _tiny(K=3)
    gen = m.generate(torch.randn(1, 3, 5, dtype=torch.float64))
    y = m.decode_pairs(torch.zeros(0, 3, dtype=torch.float64), torch.zeros(0, dtype=torch.long),
                       torch.zeros(0, dtype=torch.long), gen)
    assert y.shape == (0,)


def test_group_pairs_layout():
    g = torch.tensor([2, 0, 2, 2, 5, 0, 2])
    lay = group_pairs(g, 6, 2)
    # groups 0 (2 pairs -> 1 chunk), 2 (4 -> 2 chunks), 5 (1 -> 1 chunk)
    assert lay.chunk_group.tolist() == [0, 2, 2, 5]
    assert len(set(lay.slot.tolist())) == 7
    assert torch.equal(lay.src[lay.slot], torch.arange(7))
    assert torch.equal(lay.chunk_group[torch.div(lay.slot, 2, rounding_mode="floor")], g)


def test_errors_are_clear():
    m = _tiny(K=3)
    with pytest.raises(ValueError, match=r"\(B, K=3, 5\)"):
        m.generate(torch.randn(1, 4, 5, dtype=torch.float64))
    gen = m.generate(torch.randn(2, 3, 5, dtype=torch.float64))
    x = torch.zeros(4, 3, dtype=torch.float64)
    with pytest.raises(IndexError, match="must lie in"):
        m.decode_pairs(x, torch.tensor([0, 1, 2, 0]), torch.zeros(4, dtype=torch.long), gen)
    with pytest.raises(ValueError, match=r"\(M=4,\)"):
        m.decode_pairs(x, torch.zeros(3, dtype=torch.long), torch.zeros(4, dtype=torch.long), gen)
    with pytest.raises(ValueError, match="K=3"):
        m.decode_dense(torch.zeros(2, 2, 5, 3, dtype=torch.float64), gen)
    with pytest.raises(ValueError, match="skip layer"):
        NBWDecoder(3, n_layers=3, skip_layers=(3,))


def test_parameter_count_formula():
    cfg = VolumeConfig()
    for K in (15, 16):
        with torch.device("meta"):                          # shapes only, no memory or init cost
            dec = NBWDecoder.from_config(cfg, n_parts=K)
        d_in = 15 + 128
        ins = [d_in, 64, 64, 64 + d_in, 64, 64, 64]
        outs = [64] * 6 + [1]
        per_layer = sum(o * i + o + K * 80 * o * i + 128 * 80 + 80 for o, i in zip(outs, ins))
        assert count_parameters(dec) == per_layer
    enc = ResnetPointNet.from_config(cfg)
    expected_enc = (3 * 256 + 256) + 4 * (256 * 128 + 128 + 128 * 128 + 128 + 256 * 128) + 128 * 128 + 128
    assert count_parameters(enc) == expected_enc
    assert count_parameters(enc, enc) == expected_enc      # shared modules counted once


def test_flops_per_pair():
    m = NBWDecoder.from_config(VolumeConfig(), n_parts=1)
    assert m.flops_per_pair() == 2 * (64 * 15 + 4 * 64 * 64 + 64 * 79 + 64)


@pytest.mark.parametrize("share", [False, True])
def test_part_subset_decodes_like_the_naive_decoder(share):
    """Weights generated for a part subset decode each subset part exactly like the naive reference."""
    m = _tiny(K=4, share=share)
    z = torch.randn(2, 4, 5, dtype=torch.float64)
    parts = torch.tensor([1, 3])
    gen = m.generate(z[:, parts], parts)
    assert gen.batch_shape == (2, 2) and torch.equal(gen.parts, parts)
    x = torch.randn(2, 2, 7, 3, dtype=torch.float64)
    full = m.blended_weights(z)
    ref = _naive_decoder(m, [W[:, parts] for W in full], x, z[:, parts])
    torch.testing.assert_close(m.decode_dense(x, gen), ref)
    with pytest.raises(ValueError, match="strictly increasing"):
        m.generate(z[:, :2], torch.tensor([3, 1]))
    with pytest.raises(ValueError, match="K=2"):
        m.generate(z, parts)
    # weights whose part count disagrees with their subset (or with the decoder) are refused at decoding
    bad = gen._replace(parts=torch.tensor([0, 1, 3]))
    with pytest.raises(ValueError, match=r"generated weights are for K=2 parts, expected 3 \(the part subset\)"):
        m.decode_dense(x, bad)
    with pytest.raises(ValueError, match=r"for K=2 parts, expected 4 \(this decoder\)"):
        m.decode_dense(x, gen._replace(parts=None))


# ------------------------------------------------------------------ grouped decoding (volsmpl.nn.grouped)
def _grouped_vs_dense(m, z, x, bi, pi, atol):
    """decode_grouped on the pairs sorted by group equals decode_dense at the same pairs, values and gradients."""
    B, K = z.shape[:2]
    M = x.shape[0]
    order = torch.argsort(bi * K + pi, stable=True)
    xs, bs, ps = x[order], bi[order], pi[order]
    offs = torch.cumsum(torch.bincount(bs * K + ps, minlength=B * K), 0).to(torch.int32)
    z1, x1 = z.clone().requires_grad_(), xs.clone().requires_grad_()
    y = m.decode_grouped(x1, offs, m.generate(z1))
    z2, x2 = z.clone().requires_grad_(), xs.clone().requires_grad_()
    idx = torch.arange(M)
    dense_x = torch.zeros(B, K, M, 3, dtype=x.dtype).index_put((bs, ps, idx), x2)
    d = m.decode_dense(dense_x, m.generate(z2))[bs, ps, idx]
    torch.testing.assert_close(y, d, atol=atol, rtol=atol)
    w = torch.randn(M, dtype=x.dtype)
    gy = torch.autograd.grad((y * w).sum(), (x1, z1), retain_graph=True)
    for a, b in zip(gy, torch.autograd.grad((d * w).sum(), (x2, z2))):
        torch.testing.assert_close(a, b, atol=atol, rtol=atol)
    y.sum().backward()  # an expanded (stride 0) output gradient is accepted too


@pytest.mark.skipif(not grouped_supported(torch.float32), reason="no grouped_mm in this torch")
@pytest.mark.parametrize("hidden, skip", [(8, (2,)), (64, (3,))])
def test_decode_grouped_matches_dense_with_empty_groups(hidden, skip):
    m = _tiny(K=4, dtype=torch.float32, hidden=hidden, n_layers=7 if hidden == 64 else 5, skip_layers=skip)
    g = torch.Generator().manual_seed(3)
    B, M = 3, 300
    z = torch.randn(B, 4, 5, generator=g)
    x = torch.randn(M, 3, generator=g) * 0.5
    bi = torch.randint(0, B, (M,), generator=g)
    bi[bi == 1] = 2                                   # body 1 has no pairs
    pi = torch.randint(0, 3, (M,), generator=g)       # part 3 empty in every body
    _grouped_vs_dense(m, z, x, bi, pi, atol=1e-5)


def test_decode_grouped_refuses_bad_input():
    m = _tiny(K=2, dtype=torch.float32)
    gen = m.generate(torch.randn(1, 2, 5))
    with pytest.raises(ValueError, match="offs"):
        m.decode_grouped(torch.zeros(4, 3), torch.tensor([2, 4]), gen)           # int64 offsets
    with pytest.raises(ValueError, match="x_local"):
        m.decode_grouped(torch.zeros(4, 2), torch.tensor([2, 4], dtype=torch.int32), gen)
    with pytest.raises(TypeError, match="decode_pairs"):
        m.double().decode_grouped(torch.zeros(4, 3, dtype=torch.float64), torch.tensor([2, 4], dtype=torch.int32),
                                  m.double().generate(torch.randn(1, 2, 5, dtype=torch.float64)))


def test_group_counts_and_a_layout_from_host_counts():
    """group_counts equals bincount; a layout made from counts the caller fetched equals the one made alone."""
    from volsmpl.nn.pairs import group_counts
    g = torch.randint(0, 7, (500,), generator=torch.Generator().manual_seed(1))
    g[g == 3] = 5                                                   # an empty group
    c = group_counts(g, 9)
    assert torch.equal(c, torch.bincount(g, minlength=9)) and c[3] == 0 and c[8] == 0
    a, b = group_pairs(g, 9, 16), group_pairs(g, 9, 16, c, c.tolist())
    for x, y in zip(a[:3], b[:3]):
        assert torch.equal(x, y)
    # pairs that come sorted by group: the layout without a sort is the one the sort gives
    gs = g.sort().values
    a, b = group_pairs(gs, 9, 16), group_pairs(gs, 9, 16, group_sorted=True)
    for x, y in zip(a[:3], b[:3]):
        assert torch.equal(x, y)


def test_decode_pairs_with_host_counts_equals_without_and_checks_them():
    """Group counts handed over by the caller (the lean query's one sync) give the same values as counting here;
    counts that do not describe the pairs (wrong number of groups, wrong total) are refused in one line."""
    m = _tiny(K=4)
    g = torch.Generator().manual_seed(3)
    B, M = 3, 150
    z = torch.randn(B, 4, 5, dtype=torch.float64, generator=g)
    gen = m.generate(z)
    x = torch.randn(M, 3, dtype=torch.float64, generator=g) * 0.5
    bi, pi = torch.randint(0, B, (M,), generator=g), torch.randint(0, 4, (M,), generator=g)
    counts = torch.bincount(bi * 4 + pi, minlength=B * 4).tolist()
    with torch.no_grad():
        torch.testing.assert_close(m.decode_pairs(x, bi, pi, gen, counts_host=counts), m.decode_pairs(x, bi, pi, gen),
                                   atol=0, rtol=0)
        for bad in (counts[:-1], counts[:-1] + [counts[-1] + 1]):
            with pytest.raises(ValueError, match="counts_host must hold 12 group counts summing to the 150 pairs"):
                m.decode_pairs(x, bi, pi, gen, counts_host=bad)


@pytest.mark.parametrize("sorted_pairs", [True, False])
def test_decode_rows_cpu_path_equals_naive_per_point_decoder(monkeypatch, sorted_pairs):
    """The no-grad CPU path (volsmpl.nn.group_rows: each group's rows through its own weights, in tiles) against
    the naive decoder (latent concatenated per point, no folding): groups left empty, groups over several tiles,
    a skip on the last layer, two outputs, pairs given sorted or not."""
    m = _tiny(K=4, n_layers=4, skip_layers=(1, 3), out_dim=2)
    monkeypatch.setattr(NBWDecoder, "TILE_ROWS", 7)
    g = torch.Generator().manual_seed(5)
    B, K, M = 3, 4, 120
    z = torch.randn(B, K, 5, dtype=torch.float64, generator=g)
    x = torch.randn(M, 3, dtype=torch.float64, generator=g) * 0.5
    bi = torch.randint(0, B, (M,), generator=g)
    pi = torch.randint(0, 3, (M,), generator=g)               # part 3 of every body empty
    pi[bi == 1] = 0                                           # body 1 in one group of 40-odd rows (7 tiles)
    if sorted_pairs:
        order = torch.argsort(bi * K + pi, stable=True)
        x, bi, pi = x[order], bi[order], pi[order]
    full = m.blended_weights(z)
    u = torch.cat([positional_encoding(x, m.pe_levels), z[bi, pi]], -1)
    h = u
    for l, W in enumerate(full):                              # per point with its own (body, part) weights
        if l in m.skip_layers:
            h = torch.cat([h, u], -1)
        h = torch.einsum("moi,mi->mo", W[bi, pi], h) + m.base_bias[l]
        if l < m.n_layers - 1:
            h = torch.relu(h)
    with torch.no_grad():
        y = m.decode_pairs(x, bi, pi, m.generate(z), group_sorted=sorted_pairs)
    assert y.shape == (M, 2)
    torch.testing.assert_close(y, h)
