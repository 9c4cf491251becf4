"""CUDA-graph replay of a volume's no-grad encode (`EncodeGraphs`, used by `Volume` when `cuda_graphs` is on).

On a GPU the encode of a body output (part frames, padded boxes, fixed surface samples, PointNet, decoder-weight
generation) is a few hundred small kernels whose shapes depend only on the output's shapes: at B = 1 the host
spends ~3.6 ms issuing them for ~0.5 ms of device work (H200, `python docs/scripts/cuda_profile.py --device cuda
--batch 1 8` at commit 37ed706; docs/bench_cuda.md). Captured once in a CUDA graph, one
replay issues them all: the new output's vertices, joints and full_pose are copied into the graph's static inputs,
the graph is replayed, and its outputs are cloned into a new `Encoding` (a later replay never changes an encoding
handed out before).

A graph is reused only while everything it baked in is unchanged, all part of its key (`graph_key`): the
output's shapes, dtype and device; the storage (address, dtype, shape) of every weight and buffer of the network
and the partition (a weight edited in place is read anew by the replay; one replaced, by `.to()` or assignment,
makes a new capture); every plain setting (bool, int, float, str, dataclass config) of them and their submodules
(e.g. the network's `encoder_bf16`, `training`, its config's `normalize_parts`); and torch's float32 matmul
precision. Up to `capacity` graphs are kept (least recently used dropped first: each holds its own memory pool).

    graphs = EncodeGraphs()
    enc = graphs.run((net, partition), encode_fn, out)   # None: not replayable here, encode eagerly

A capture that fails (an operation that reads the device from the host, e.g. with another body model) is
remembered for its key and that key is encoded eagerly from then on, with one warning. `backend='emulate'` runs
the same bookkeeping on any device with the function called again in place of a replay (tests of the keys and of
the outputs' ownership on a CPU).
"""
from __future__ import annotations

import warnings
from collections import OrderedDict
from dataclasses import fields, is_dataclass, replace
from types import SimpleNamespace

import torch

INPUTS = ("vertices", "joints", "full_pose")  # what the encode reads of a body output
BACKENDS = ("cuda", "emulate")  # real CUDA graphs, or the same bookkeeping with the function called again (tests)


def map_tensors(fn, x):
    """`x` with `fn` applied to every tensor it holds: tensors, (named) tuples, lists, dataclasses, None."""
    if isinstance(x, torch.Tensor):
        return fn(x)
    if is_dataclass(x) and not isinstance(x, type):
        return replace(x, **{f.name: map_tensors(fn, getattr(x, f.name)) for f in fields(x) if f.init})
    if isinstance(x, tuple):
        items = [map_tensors(fn, i) for i in x]
        return type(x)(*items) if hasattr(x, "_fields") else tuple(items)
    if isinstance(x, list):
        return [map_tensors(fn, i) for i in x]
    return x


_PLAIN = (bool, int, float, str, type(None))


class _Same:
    """Key item of a frozen dataclass setting (e.g. the partition's PartTable): equal to another only when it
    holds the same object, which it keeps alive (so its id is never reused while the key exists)."""

    __slots__ = ("obj",)

    def __init__(self, obj):
        self.obj = obj

    def __hash__(self):
        return id(self.obj)

    def __eq__(self, other):
        return isinstance(other, _Same) and other.obj is self.obj


def settings_key(modules) -> tuple:
    """The plain settings (bool, int, float, str, None; dataclass configs by their repr, frozen ones by identity:
    a frozen config is replaced, not edited) of `modules` and their submodules, in a fixed order (each module's
    attribute order). ~0.15 ms for the shipped network and partition on one CPU thread, where a sorted walk with
    every config's repr took 0.48 ms (the PartTable's repr prints its collision mask; commit fcde88a)."""
    out = []
    for i, module in enumerate(modules):
        for name, m in module.named_modules():
            for attr, value in m.__dict__.items():
                if attr[0] == "_":
                    continue
                kind = type(value)
                if kind in _PLAIN:
                    out.append((i, name, attr, value))
                elif hasattr(kind, "__dataclass_fields__"):
                    out.append((i, name, attr, _Same(value) if kind.__dataclass_params__.frozen else repr(value)))
    return tuple(out)


def graph_key(modules, out) -> tuple:
    """What a captured encode of `out` by `modules` (the modules the encode reads: a network and a partition)
    depends on besides the values of inputs and weights (module docstring). Host-side only: reads no device
    values."""
    inputs = tuple((tuple(getattr(out, k).shape), getattr(out, k).dtype) for k in INPUTS)
    storage = tuple((t.data_ptr(), t.dtype, tuple(t.shape))
                    for m in modules for t in (*m.parameters(), *m.buffers()))
    return (inputs, str(out.vertices.device), storage, settings_key(modules), torch.get_float32_matmul_precision(),
            torch.backends.cuda.matmul.allow_tf32)


class CapturedGraph:
    """A function of named tensors captured once (static copies of its inputs, the graph, its outputs) and replayed.

    Args: fn: function of a namespace holding the inputs by name; inputs: {name: tensor} (cloned into the static
    inputs); backend: 'cuda' or 'emulate' (fn called again at each replay, its outputs written into the captured
    ones: the same bookkeeping on any device). Calling it with new inputs of the same shapes copies them in, replays,
    and returns clones of the outputs (tensors, (named) tuples, lists, dataclasses: `map_tensors`)."""

    def __init__(self, fn, inputs: dict, backend: str):
        self.static = SimpleNamespace(**{k: v.detach().clone() for k, v in inputs.items()})
        self.fn, self.graph = fn, None
        if backend == "emulate":
            self.result = fn(self.static)
            return
        device = next(iter(inputs.values())).device
        side = torch.cuda.Stream(device)
        side.wait_stream(torch.cuda.current_stream(device))
        with torch.cuda.stream(side):  # warm-up on a side stream, as capture requires (allocator, cuBLAS handles)
            for _ in range(2):
                fn(self.static)
        torch.cuda.current_stream(device).wait_stream(side)
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            self.result = fn(self.static)

    def __call__(self, inputs: dict):
        for k, v in inputs.items():
            getattr(self.static, k).copy_(v)
        if self.graph is None:  # emulation: the function again, its outputs written into the captured ones
            new, held = [], []
            map_tensors(new.append, self.fn(self.static))
            map_tensors(held.append, self.result)
            for h, n in zip(held, new):
                h.copy_(n)
        else:
            self.graph.replay()
        return map_tensors(torch.Tensor.clone, self.result)


class GraphStore:
    """Captured graphs by key (`CapturedGraph`), least recently used dropped first; a key whose capture failed is
    remembered, and its caller runs eagerly from then on (one warning). The base of `EncodeGraphs` and
    `volsmpl.volume.engine.query_graph.QueryGraphs`.

    Args:
        capacity: graphs kept at most (each holds a memory pool).
        backend: 'cuda' (CUDA graphs) or 'emulate' (any device: the function is called again instead of a replay;
            for tests).

    Attributes: captures, replays (counts), failed (keys whose capture failed).
    """

    BACKENDS = BACKENDS

    def __init__(self, capacity: int = 4, backend: str = "cuda"):
        if backend not in self.BACKENDS:
            raise ValueError(f"backend must be one of {self.BACKENDS}, got {backend!r}")
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.capacity, self.backend = int(capacity), backend
        self._graphs: OrderedDict = OrderedDict()
        self.failed: set = set()
        self.captures = self.replays = 0

    def replay(self, key, fn, inputs: dict, what: str):
        """fn's outputs for `inputs` ({name: tensor}) by a replay of the graph captured under `key` (captured now
        when new), or None when the key's capture failed (now or before). what: the thing captured, for the
        warning."""
        if key in self.failed:
            return None
        captured = self._graphs.get(key)
        if captured is None:
            try:
                captured = CapturedGraph(fn, inputs, self.backend)
            except RuntimeError as e:  # an operation that cannot be captured
                self.failed.add(key)
                warnings.warn(f"{what} cannot be captured in a CUDA graph ({str(e).splitlines()[0]}); it runs "
                              f"eagerly.", RuntimeWarning, stacklevel=4)
                return None
            self.captures += 1
            self._graphs[key] = captured
            while len(self._graphs) > self.capacity:
                self._graphs.popitem(last=False)
        self._graphs.move_to_end(key)
        self.replays += 1
        return captured(inputs)

    def clear(self) -> None:
        """Drop every captured graph (and its memory pool) and the record of failed captures."""
        self._graphs.clear()
        self.failed.clear()


class EncodeGraphs(GraphStore):
    """Captured encodes of one volume, keyed by `graph_key` (module docstring); a `GraphStore`.

    Args: capacity, backend: GraphStore's ('cuda': outputs on CUDA devices only).
    """

    def supports(self, out) -> bool:
        """Whether `out` can be replayed here: a CUDA output (any device when emulating) with autograd off."""
        return not torch.is_grad_enabled() and (self.backend == "emulate" or out.vertices.is_cuda)

    def run(self, modules, fn, out):
        """`fn(out)` by replay of a captured `fn` (captured now when new), or None where `out` is not
        replayable (`supports`) or its key's capture failed: the caller then runs `fn` itself.

        Shape: out.vertices (B, V, 3), out.joints (B, J', 3), out.full_pose (B, J*3); the result has fn's."""
        if not self.supports(out):
            return None
        return self.replay(graph_key(modules, out), fn, {k: getattr(out, k) for k in INPUTS},
                           "the encode of this body output")

    def __deepcopy__(self, memo):
        """A copy without graphs (they hold device memory and the original's storage): it captures anew."""
        return EncodeGraphs(self.capacity, self.backend)


__all__ = ["EncodeGraphs", "GraphStore", "CapturedGraph", "graph_key", "settings_key", "map_tensors", "INPUTS", "BACKENDS"]
