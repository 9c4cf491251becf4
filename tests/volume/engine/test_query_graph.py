"""The static-shape lean query and its replay (volsmpl.volume.engine.query_graph, Volume.cuda_graph_queries): on the CPU with the
emulating backend, and, marked `cuda`, with real CUDA graphs. References: the eager lean query of the same encoding
and points (`Volume.query_encoded`, itself tested against the dense path) and its pair count."""
from __future__ import annotations

import dataclasses

import pytest
import torch

import volsmpl
from conftest import random_pose
from volsmpl.volume.engine.encode_graph import EncodeGraphs
from volsmpl.volume.engine.query_graph import QueryGraphs, static_lean_query

DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.cuda)]


def _setup(config, device, batch=2, seed=0):
    torch.manual_seed(seed)
    body = volsmpl.create_body().to(device)
    vol = volsmpl.attach_volume(body, pretrained=False, config=config)
    emulate = device == "cpu"
    vol.encode_graphs = EncodeGraphs(backend="emulate" if emulate else "cuda")
    vol.query_graphs = QueryGraphs(backend="emulate" if emulate else "cuda")
    vol.cuda_graph_queries = True
    with torch.no_grad():
        out = body(**{k: v.to(device) for k, v in random_pose(batch, seed=seed + 1).items()})
    return body, vol, out


def _points(out, n, seed):
    """Points near the surface (most in some box), spread around the body (many in none) and far away."""
    g = torch.Generator().manual_seed(seed)
    B, V = out.vertices.shape[:2]
    dev = out.vertices.device
    near = out.vertices[:, torch.randint(0, V, (n,), generator=g)] + 0.03 * torch.randn(B, n, 3, generator=g).to(dev)
    lo, hi = out.vertices.amin(1, keepdim=True) - 0.3, out.vertices.amax(1, keepdim=True) + 0.3
    spread = lo + (hi - lo) * torch.rand(B, n, 3, generator=g).to(dev)
    far = 5.0 + torch.rand(B, 8, 3, generator=g).to(dev)
    return torch.cat([near, spread, far], dim=1)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("normalize", [True, False])
def test_static_query_equals_the_eager_query(tiny_config, normalize, device):
    cfg = dataclasses.replace(tiny_config, normalize_parts=normalize)
    _, vol, out = _setup(cfg, device)
    pts = _points(out, 700, 3)
    with torch.no_grad():
        enc = vol.encode(out)
        before = vol.decoder_evaluations
        ref = vol.query_encoded(enc, pts)
        pairs_ref = vol.decoder_evaluations - before
        w = enc.code.weights
        for cap, chunk in ((pairs_ref, 256), (pairs_ref + 5000, 64), (pairs_ref + 1, 7)):
            values, pairs, bad = static_lean_query(vol.net.decoder, enc.G, enc.box_min, enc.box_max, enc.center,
                                                   enc.scale, w.weights, w.biases, pts, cap, chunk)
            assert int(pairs) == pairs_ref and int(bad) == 0
            torch.testing.assert_close(values, ref, atol=1e-6, rtol=1e-6)
        _, pairs, _ = static_lean_query(vol.net.decoder, enc.G, enc.box_min, enc.box_max, enc.center, enc.scale,
                                        w.weights, w.biases, pts, pairs_ref - 10, 64)
        assert int(pairs) == pairs_ref    # the count reports an overflow of the capacity
    assert 0.3 < (ref > 0).float().mean() < 0.99   # points inside and outside the body, in boxes and in none


@pytest.mark.parametrize("device", DEVICES)
def test_volume_replays_after_one_eager_query(tiny_config, device):
    body, vol, out = _setup(tiny_config, device)
    g = vol.query_graphs
    with torch.no_grad():
        first = vol.query(out, _points(out, 600, 4))             # eager: learns the capacity
        assert g.captures == 0 and len(g.pair_capacities) == 1
        out2 = body(**{k: v.to(device) for k, v in random_pose(2, seed=7).items()})
        pts = _points(out2, 600, 5)
        before = vol.decoder_evaluations
        got = vol.query(out2, pts)                               # captured, replayed
        pairs = vol.decoder_evaluations - before
        assert g.captures == 1 and g.replays == 1
        vol.cuda_graph_queries = False
        before = vol.decoder_evaluations
        ref = vol.query_encoded(vol.encode(out2), pts)
        assert vol.decoder_evaluations - before == pairs
    torch.testing.assert_close(got, ref, atol=1e-6, rtol=1e-6)
    assert first.shape == got.shape == (2, 1208)


def _after_one_query(config, n, seed):
    """A CPU volume (emulated graphs) whose first, eager query of `n` points has set their shape's pair capacity:
    (volume, body output, points, its QueryGraphs)."""
    _, vol, out = _setup(config, "cpu")
    pts = _points(out, n, seed)
    with torch.no_grad():
        vol.query(out, pts)
    return vol, out, pts, vol.query_graphs


def test_overflow_answers_eagerly_and_raises_the_capacity(tiny_config):
    vol, out, pts, g = _after_one_query(tiny_config, 600, 6)
    with torch.no_grad():
        shape = next(iter(g.pair_capacities))
        g.pair_capacities[shape] = 16                                 # below this query's pairs
        got = vol.query(out, pts)                                # replay overflows: eager answer
        assert g.overflows == 1 and g.pair_capacities[shape] >= vol.decoder_evaluations // 2
        again = vol.query(out, pts)                              # the larger capacity: captured anew, replayed
        assert g.captures == 2 and g.replays == 2 and g.overflows == 1
        vol.cuda_graph_queries = False
        ref = vol.query(out, pts)
    torch.testing.assert_close(got, ref, atol=1e-6, rtol=1e-6)
    torch.testing.assert_close(again, ref, atol=1e-6, rtol=1e-6)


def test_nonfinite_points_and_where_no_graph_serves(tiny_config):
    vol, out, pts, g = _after_one_query(tiny_config, 300, 8)
    with torch.no_grad():
        bad = pts.clone()
        bad[1, 5, 0] = float("nan")
        with pytest.raises(ValueError, match="NaN"):
            vol.query(out, bad)                                  # the replay's count: the eager query's error
        assert g.replays == 1
        vol.query_encoded(vol.encode(out), pts)                  # query_encoded checks nothing: replayed, no error
        assert g.replays == 2
    vol.query(out, pts)                                          # autograd on: eager
    assert g.replays == 2
    with pytest.raises(ValueError, match="backend"):
        QueryGraphs(backend="vulkan")
