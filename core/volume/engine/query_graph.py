"""The lean query in static shapes (`static_lean_query`) and its CUDA-graph replay (`QueryGraphs`, used by `Volume`
when `cuda_graph_queries` is on).

On a GPU the lean query of one body (volsmpl.volume.engine.lean_query) is ~180 small kernels and one host read of its pair counts:
at B = 1 and 60k points the host issuing them, not the device, sets its 2.3 ms (H200, t query of `volsmpl bench
--device cuda --batch 1 8 --points 60000` at commit fcde88a; docs/bench_cuda.md). Its shapes
depend on the data (the (point, part) pairs inside boxes, the points in no box), so it cannot be captured as it is.
`static_lean_query` computes the same values with shapes fixed by (B, N, K) and a pair `capacity`:

  - the pairs are the first `capacity` (body, part, point) entries inside boxes (`torch.nonzero_static`, sorted by
    (body, part)); the unused rows go to an extra, empty group whose results land in a discarded slot;
  - the decoder runs on the group-contiguous layout of `chunk`-row chunks of `NBWDecoder.decode_pairs`
    (`nn.pairs.group_pairs`, each group's last chunk padded) with a fixed number of chunks, capacity / chunk + groups,
    enough for any split of the pairs;
  - every point gets its box distance (the eager path computes it only for the points in no box) and the points in
    some box take the minimum of their parts' decoders instead.

It returns the values with the number of pairs and of NaN / Inf points, read by the caller in one host read: when the
pairs exceed the capacity the values are incomplete, and the caller answers eagerly instead and raises the capacity.

`QueryGraphs` keeps one captured `static_lean_query` per (batch shape, points, capacity, precision) and replays it
with the new encoding's tensors and points copied in (volsmpl.volume.engine.encode_graph.CapturedGraph). The capacity of a shape is
learnt from the eager query it first answers (its pairs x `slack`, rounded up); a replay whose pairs overflow it raises
it for the next capture.

    graphs = QueryGraphs()
    got = graphs.run(volume, enc, points)   # (values, pairs, NaN points), or None: answer eagerly, then
    graphs.observe(points, K, pairs)        # the eager query's pairs set the capacity of that shape
"""
from __future__ import annotations

import math

import torch

from volsmpl.geometry.boxes import box_test
from volsmpl.volume.engine.encode_graph import GraphStore, settings_key
from volsmpl.nn.analytic import outside_distance
from volsmpl.nn.pairs import group_pairs

#: rows per chunk of the static decoder layout (one group's rows; its last chunk padded)
STATIC_CHUNK = 256
#: the capacity learnt from an eager query: its pairs times this, rounded up to CAPACITY_STEP
SLACK = 1.15
CAPACITY_STEP = 4096


def static_lean_query(decoder, G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor, center, scale,
                      weights, biases, points: torch.Tensor, capacity: int, chunk: int = STATIC_CHUNK):
    """The lean query's values in shapes fixed by (B, N, K, capacity, chunk): no host reads (module docstring).

    Shape: G (B, K, 4, 4), box_min/max (B, K, 3), center (B, K, 3) and scale (B, K, 1) of normalised parts (or both
    None), weights[l] (B, K, out_l, in_l) and biases[l] (B, K, out_l) (NBWWeights of all K parts), points (B, N, 3)
    -> values (B, N), pairs () int64 (the pairs inside boxes; the values are complete only when <= capacity),
    nonfinite () int64 (points with a NaN or Inf coordinate).
    """
    B, N = points.shape[:2]
    K = G.shape[1]
    groups = B * K + 1                                                    # the last: unused rows of the capacity
    u, q_max = box_test(points, G, box_min, box_max)                      # (B, N, K, 3), (B, N, K)
    inside = q_max <= 0
    by_part = inside.transpose(1, 2).contiguous()                         # (B, K, N): pairs sorted by (body, part)
    pairs = by_part.sum()
    idx = torch.nonzero_static(by_part, size=capacity, fill_value=-1)     # (capacity, 3)
    used = idx[:, 0] >= 0
    b, k, n = idx.clamp(min=0).unbind(1)
    group = torch.where(used, b * K + k, groups - 1)                      # non-decreasing
    ub = u[b, n, k]                                                       # (capacity, 3) box-centred coordinates
    sc = scale[b, k] if scale is not None else None                       # (capacity, 1)
    xin = ub / sc if sc is not None else ub + 0.5 * (box_min + box_max)[b, k]
    # NBWDecoder.decode_pairs' group-contiguous chunks, with a fixed number of chunks (enough for any split)
    lay = group_pairs(group, groups, chunk, group_sorted=True, n_chunks_total=-(-capacity // chunk) + groups)
    Ws, bs = [], []
    for W, bias in zip(weights, biases):
        W = W.reshape(B * K, *W.shape[2:])
        Ws.append(torch.cat([W, W.new_zeros(1, *W.shape[1:])])[lay.chunk_group].transpose(1, 2))
        bias = bias.reshape(B * K, 1, bias.shape[-1])
        bs.append(torch.cat([bias, bias.new_zeros(1, *bias.shape[1:])])[lay.chunk_group])
    xs = xin[lay.src].view(len(lay.chunk_group), chunk, 3)
    h = decoder.mlp_chunks(xs, Ws, bs)[..., 0].reshape(-1)[lay.slot]     # (capacity,)
    if sc is not None:
        h = h * sc[:, 0]
    target = torch.where(used, b * N + n, B * N)                          # unused rows: a discarded last slot
    best = points.new_full((B * N + 1,), math.inf).scatter_reduce(0, target, h, "amin")[:-1].view(B, N)
    free = ~inside.any(dim=-1)
    q = u.abs() - 0.5 * (box_max - box_min)[:, None]                      # (B, N, K, 3) excess over each box
    box = outside_distance(q.reshape(B * N, K, 3), q_max.reshape(B * N, K)).view(B, N)
    values = torch.where(free, box, best)
    nonfinite = (~torch.isfinite(points)).any(dim=-1).sum()
    return values, pairs, nonfinite


class QueryGraphs(GraphStore):
    """Captured `static_lean_query` calls of one volume (module docstring); a `volsmpl.volume.engine.encode_graph.GraphStore`.

    Args: capacity, backend: GraphStore's (graphs kept; 'cuda' or 'emulate'); chunk: rows per decoder chunk.
    Attributes: GraphStore's, overflows (replays whose pairs exceeded their pair capacity), pair_capacities
    {(B, N, K): pairs}.
    """

    def __init__(self, capacity: int = 4, backend: str = "cuda", chunk: int = STATIC_CHUNK):
        super().__init__(capacity, backend)
        if chunk < 1:
            raise ValueError(f"chunk must be >= 1, got {chunk}")
        self.chunk = int(chunk)
        self.pair_capacities: dict = {}
        self.overflows = 0

    def supports(self, enc, points: torch.Tensor) -> bool:
        """Whether the query of `points` (B, N, 3) on `enc` can be replayed: autograd off, a CUDA query (any
        device when emulating), an encoding of all parts."""
        return (not torch.is_grad_enabled() and enc.slot is None and enc.code is not None
                and (self.backend == "emulate" or points.is_cuda))

    def observe(self, points: torch.Tensor, num_parts: int, pairs: int) -> None:
        """Learn the pair capacity of the shape of `points` from the pairs an eager query of them had."""
        need = max(CAPACITY_STEP, math.ceil(pairs * SLACK / CAPACITY_STEP) * CAPACITY_STEP)
        shape = (*points.shape[:2], num_parts)
        self.pair_capacities[shape] = max(need, self.pair_capacities.get(shape, 0))

    def run(self, volume, enc, points: torch.Tensor):
        """Values (B, N) of `volume`'s lean query of `points` on `enc` by a replay, pairs (int) and NaN/Inf points
        (int) from one host read; None where there is no pair capacity for this shape yet, the capture failed, or
        the pairs overflowed the capacity (raised then): the caller answers eagerly. Checks nothing else: see
        supports."""
        B, N = points.shape[:2]
        K = enc.G.shape[1]
        cap = self.pair_capacities.get((B, N, K))
        if cap is None:
            return None
        code = enc.code.weights
        inputs = {"points": points, "G": enc.G, "box_min": enc.box_min, "box_max": enc.box_max}
        if enc.scale is not None:
            inputs.update(center=enc.center, scale=enc.scale)
        inputs.update({f"w{i}": w for i, w in enumerate(code.weights)})
        inputs.update({f"b{i}": x for i, x in enumerate(code.biases)})
        decoder = volume.net.decoder
        key = (tuple((k, tuple(v.shape), v.dtype) for k, v in inputs.items()), str(points.device), cap, self.chunk,
               settings_key((decoder,)), volume.precision, torch.get_float32_matmul_precision(),
               torch.backends.cuda.matmul.allow_tf32)
        n_layers = len(code.weights)

        def fn(s):
            return static_lean_query(decoder, s.G, s.box_min, s.box_max, getattr(s, "center", None),
                                     getattr(s, "scale", None), [getattr(s, f"w{i}") for i in range(n_layers)],
                                     [getattr(s, f"b{i}") for i in range(n_layers)], s.points, cap, self.chunk)

        got = self.replay(key, fn, inputs, "the lean query of this shape")
        if got is None:
            return None
        values, pairs, bad = got
        pairs, bad = torch.stack([pairs, bad]).tolist()                  # the query's one host read
        if pairs > cap:
            self.overflows += 1
            self.observe(points, K, pairs)
            return None
        return values, pairs, bad

    def __deepcopy__(self, memo):
        """A copy without graphs (they hold device memory and the original's storage): it captures anew."""
        return QueryGraphs(self.capacity, self.backend, self.chunk)

    def clear(self) -> None:
        """Drop every captured graph, the record of failed captures and the learnt pair capacities."""
        super().clear()
        self.pair_capacities.clear()


__all__ = ["static_lean_query", "QueryGraphs", "STATIC_CHUNK", "SLACK", "CAPACITY_STEP"]
