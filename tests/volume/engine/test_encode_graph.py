"""The replayed encode (volsmpl.volume.engine.encode_graph, Volume.cuda_graphs): on the CPU with the emulating backend (the
bookkeeping: static inputs, outputs owned by each encoding, keys, capacity), and, marked `cuda`, with real CUDA
graphs on a GPU. References: the eager encode of the same output (`Volume._encode_eager`), exact."""
from __future__ import annotations

import copy
import dataclasses

import pytest
import torch

import volsmpl
from conftest import random_pose
from volsmpl.volume.engine.encode_graph import EncodeGraphs, map_tensors

DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.cuda)]


def _volume(tiny_config, device, batch=2):
    torch.manual_seed(0)
    body = volsmpl.create_body().to(device)
    vol = volsmpl.attach_volume(body, pretrained=False, config=tiny_config)
    vol.cuda_graphs = True
    vol.encode_graphs = EncodeGraphs(backend="emulate" if device == "cpu" else "cuda")
    with torch.no_grad():
        outs = [body(**{k: v.to(device) for k, v in random_pose(batch, seed=s).items()}) for s in (1, 2)]
    return body, vol, outs


def _captured_once(tiny_config, device):
    """A volume whose encode of its first output has been captured once: (body, volume, that output, its graphs)."""
    body, vol, (o1, _) = _volume(tiny_config, device)
    with torch.no_grad():
        vol.encode(o1, fresh=True)
    return body, vol, o1, vol.encode_graphs


def _tensors(enc) -> list:
    held = []
    map_tensors(held.append, enc)
    return held


def _assert_equal(a, b):
    ta, tb = _tensors(a), _tensors(b)
    assert len(ta) == len(tb) > 5
    for x, y in zip(ta, tb):
        assert torch.equal(x, y)


@pytest.mark.parametrize("device", DEVICES)
def test_replay_equals_eager_and_owns_its_outputs(tiny_config, device):
    _, vol, (o1, o2) = _volume(tiny_config, device)
    with torch.no_grad():
        e1 = vol.encode(o1, fresh=True)
        first = [t.clone() for t in _tensors(e1)]
        e2 = vol.encode(o2, fresh=True)
        ref1, ref2 = vol._encode_eager(o1, None), vol._encode_eager(o2, None)
    assert vol.encode_graphs.captures == 1 and vol.encode_graphs.replays == 2
    _assert_equal(e2, ref2)   # the second output's inputs reached the replay
    _assert_equal(e1, ref1)   # and the first encoding was not overwritten by it
    assert all(torch.equal(a, b) for a, b in zip(first, _tensors(e1)))
    assert not torch.equal(e1.code.z, e2.code.z)


@pytest.mark.parametrize("device", DEVICES)
def test_weights_edited_in_place_are_read_replaced_ones_recaptured(tiny_config, device):
    _, vol, o1, g = _captured_once(tiny_config, device)
    with torch.no_grad():
        w = vol.net.encoder.fc_pos.weight
        w.mul_(1.5)                                  # in place: same storage, same graph, new values
        e = vol.encode(o1, fresh=True)
        _assert_equal(e, vol._encode_eager(o1, None))
        assert g.captures == 1
        vol.net.encoder.fc_pos.weight = torch.nn.Parameter(w * 0.5)   # replaced: another storage
        e = vol.encode(o1, fresh=True)
        _assert_equal(e, vol._encode_eager(o1, None))
        assert g.captures == 2


@pytest.mark.parametrize("device", DEVICES)
def test_settings_batch_and_autograd_decide_the_graph(tiny_config, device):
    body, vol, o1, g = _captured_once(tiny_config, device)
    with torch.no_grad():
        vol.net.encoder_bf16 = True                  # a setting the encode reads: a new capture
        _assert_equal(vol.encode(o1, fresh=True), vol._encode_eager(o1, None))
        assert g.captures == 2
        vol.net.encoder_bf16 = False
        vol.encode(o1, fresh=True)                   # the first graph again
        assert g.captures == 2 and g.replays == 3
        table = vol.partition.table                  # a frozen config replaced by an equal copy: a new capture
        vol.partition.table = dataclasses.replace(table)
        vol.encode(o1, fresh=True)
        assert g.captures == 3
        vol.partition.table = table                  # the first object again: its graph
        vol.encode(o1, fresh=True)
        assert g.captures == 3 and g.replays == 5
        o3 = body(**{k: v.to(device) for k, v in random_pose(3, seed=4).items()})
        _assert_equal(vol.encode(o3, fresh=True), vol._encode_eager(o3, None))
        assert g.captures == 4
    e = vol.encode(o1, fresh=True)                   # autograd on: eager, with its graph
    assert g.replays == 6 and e.code.z.requires_grad


def test_capacity_keeps_the_most_recent(tiny_config):
    body, vol, (o1, _) = _volume(tiny_config, "cpu")
    vol.encode_graphs = g = EncodeGraphs(capacity=2, backend="emulate")
    with torch.no_grad():
        outs = {b: body(**random_pose(b, seed=b)) for b in (1, 2, 3)}
        for b in (1, 2, 3, 3, 1):                    # 1 was dropped when 3 came: captured again
            vol.encode(outs[b], fresh=True)
    assert g.captures == 4 and g.replays == 5
    with pytest.raises(ValueError, match="capacity"):
        EncodeGraphs(capacity=0)


@pytest.mark.parametrize("device", DEVICES)
def test_query_with_replayed_encode_equals_eager_query(tiny_config, device):
    body, vol, (o1, _) = _volume(tiny_config, device)
    gen = torch.Generator().manual_seed(5)
    idx = torch.randint(0, o1.vertices.shape[1], (400,), generator=gen)
    pts = o1.vertices[:, idx] + 0.05 * torch.randn(2, 400, 3, generator=gen).to(device)
    with torch.no_grad():
        got = vol.query(o1, pts)
        again = vol.query(o1, pts)                   # cached on the output: no second replay
        assert vol.encode_graphs.replays == 1
        vol.cuda_graphs = False
        o1b = body(**{k: v.to(device) for k, v in random_pose(2, seed=1).items()})
        ref = vol.query(o1b, pts)
    torch.testing.assert_close(got, ref, atol=1e-6, rtol=1e-6)
    assert torch.equal(got, again)


def test_query_on_the_replay_path_makes_no_eager_frames(tiny_config):
    """A query of a new output leaves the frames to the replay: one `_frames` call (the emulated replay's), not a
    second eager one to choose parts that the replay encodes anyway."""
    _, vol, _, g = _captured_once(tiny_config, "cpu")
    _, _, (_, o2) = _volume(tiny_config, "cpu")
    calls = []
    frames = vol._frames
    vol._frames = lambda out: calls.append(1) or frames(out)
    with torch.no_grad():
        pts = o2.vertices[:, :300] * 1.01
        got = vol.query(o2, pts)
        ref = vol.query_encoded(vol._encode_eager(o2, None), pts)
    assert g.replays == 2 and len(calls) == 2           # one in the replay, one in the eager reference
    torch.testing.assert_close(got, ref, atol=1e-6, rtol=1e-6)


def test_a_copied_volume_captures_anew(tiny_config):
    _, vol, _, _ = _captured_once(tiny_config, "cpu")
    twin = copy.deepcopy(vol)
    assert vol.encode_graphs.captures == 1 and twin.encode_graphs.captures == 0
    assert twin.encode_graphs.backend == "emulate"


def test_cuda_backend_leaves_cpu_outputs_to_the_eager_encode(tiny_config):
    _, vol, (o1, _) = _volume(tiny_config, "cpu")
    vol.encode_graphs = EncodeGraphs()               # 'cuda': a CPU output is not replayable
    with torch.no_grad():
        _assert_equal(vol.encode(o1, fresh=True), vol._encode_eager(o1, None))
    assert vol.encode_graphs.captures == 0


def test_a_failed_capture_is_remembered_and_warned_once():
    from volsmpl.volume.engine.encode_graph import GraphStore

    calls = []

    def broken(s):
        calls.append(1)
        raise RuntimeError("operation not permitted when stream is capturing\nmore")

    store = GraphStore(backend="emulate")
    x = {"x": torch.ones(3)}
    with pytest.warns(RuntimeWarning, match="cannot be captured.*operation not permitted"):
        assert store.replay("k", broken, x, "the thing") is None
    assert store.replay("k", broken, x, "the thing") is None     # remembered: not tried again
    assert len(calls) == 1 and store.failed == {"k"} and store.captures == 0
    assert torch.equal(store.replay("j", lambda s: s.x * 2, x, "the thing"), torch.full((3,), 2.0))
