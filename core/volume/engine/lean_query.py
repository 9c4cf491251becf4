"""The lean sparse query of SDF models (`Volume.engine = "lean"`), a mixin of Volume: box test, decoders on the
(point, part) pairs inside part boxes, one scatter-min, box distances for the points in no box, in chunks sized
for the device (`volsmpl.volume.engine.chunks`).

    values = volume._query_lean(encoding, points)          # (B, N, 3) -> (B, N); Volume.query calls it
    enc, pending = volume._lean_encoding(out, points)      # the encoding and the box test made to choose its parts
"""
from __future__ import annotations

import torch
from torch.profiler import record_function

from volsmpl.geometry.boxes import box_test, parts_holding
from volsmpl.volume.encoding import Encoding
from volsmpl.nn.analytic import box_excess, outside_distance
from volsmpl.volume.engine.chunks import lean_chunks
from volsmpl.volume.input_checks import nonfinite_points_error

#: profiler scope of the decoder evaluations of a query (volsmpl bench times the decoder alone by it)
DECODER_SCOPE = "volsmpl::decoder"


class LeanQuery:
    """The lean query of a Volume: needs the Volume's `num_parts`, `chunk_elems`, `cpu_chunk_elems`,
    `gpu_chunk_elems`, `decoder_evaluations`, `_decode_xin` and `_encoding_for` (EncodingCache)."""

    def _lean_encoding(self, out, points: torch.Tensor, frames=None):
        """`_encoding_for(out, points, frames)` and a holder {'test': (G, u, q_max)} of the box test it made of
        `points` to choose the parts to encode, when the lean query of these points is one chunk (so that the
        query reuses it instead of testing the same points again); the holder is empty otherwise, or when a cached
        full encoding needed no test."""
        pending: dict = {}
        holding = None
        if len(self._lean_chunks(*points.shape[:2], points.device)) == 1:
            def holding(G, box_min, box_max):
                test = box_test(points, G, box_min, box_max)
                pending["test"] = (G, *test)
                return parts_holding(test[1])
        return self._encoding_for(out, points, frames, holding), pending

    def _query_lean(self, enc: Encoding, points: torch.Tensor, b0: int = 0, outside: bool = True,
                    nonfinite=None, pending: dict | None = None) -> torch.Tensor:
        """`query` values of an SDF model on the lean sparse path, for bodies b0 .. b0 + B of the encoding.
        points (B, N, 3) -> (B, N).

        One batched matmul takes every point into every part's box-centred frame, u = x_k - c_k (B, N, K, 3:
        each point's K parts contiguous); a point is in box k when |u| <= half-extent on every axis. Points in
        some encoded part's box get the minimum over those parts' decoders (one scatter-min); the others the
        minimum over parts of the box distance, computed for them only (outside=False leaves them +inf, for
        callers to whom a point in no box is worth nothing: the collision loss). The box test runs without autograd;
        the coordinates of the pairs (and of the points in no box) are formed again from R_k, t_k and the box, so
        the backward pass touches those only. One host sync (the pairs per (body, part) and the points in no box;
        the decoders get the former, so they make none), then fixed-size nonzero. Same values as `_part_values` +
        minimum (the dense reference) up to rounding. nonfinite: (device count of NaN/Inf points, points given),
        read with the pairs: a non-zero count raises validate's error. pending: the holder `_lean_encoding` filled
        with the box test it made of these points on these frames (taken out of it here, so that its arrays are
        freed before the decoders run); without it, or for other frames, the test is made here."""
        B, N = points.shape[:2]
        K = self.num_parts
        G, box_min, box_max = (x[b0:b0 + B] for x in (enc.G, enc.box_min, enc.box_max))
        R, t = G[..., :3, :3], G[..., :3, 3]                                  # (B, K, 3, 3), (B, K, 3)
        c = 0.5 * (box_min + box_max)                                         # (B, K, 3)
        half = 0.5 * (box_max - box_min)
        test = pending.pop("test", None) if pending else None
        if test is not None and test[0] is enc.G and b0 == 0 and test[1].shape[:2] == (B, N):
            u, q_max = test[1:]                                               # made by `_lean_encoding`
        else:
            u, q_max = box_test(points, G, box_min, box_max)
        del test
        raw = q_max <= 0                                                      # (B, N, K) point in box k
        grad = torch.is_grad_enabled() and any(x.requires_grad for x in (points, G, box_min, box_max))
        if grad:
            del u, q_max  # formed again below for the pairs and the box-free points only, with autograd
        inside = raw if enc.slot is None else raw & enc.encoded(K)
        free = ~inside.any(dim=-1)                                            # (B, N)
        n_free_t = free.sum() if outside else torch.zeros((), dtype=torch.long, device=free.device)
        by_part = inside.transpose(1, 2).contiguous()                         # (B, K, N): pairs come sorted by (body, part)
        per_group = by_part.sum(dim=2)                                        # (B, K) pairs per (body, part)
        if enc.slot is not None:
            per_group = per_group[:, enc.parts]                               # in the code's part order
        extra = [] if nonfinite is None else [nonfinite[0].reshape(1)]
        host = torch.cat([per_group.reshape(-1), n_free_t.reshape(1)] + extra).tolist()   # the query's one host sync
        if nonfinite is not None and host.pop():
            raise nonfinite_points_error(int(nonfinite[0]), int(nonfinite[1]))
        n_free, n_pairs = host.pop(), sum(host)
        Kc = per_group.shape[1]                                               # groups of the whole encoding:
        counts_host = [0] * (b0 * Kc) + host + [0] * ((enc.G.shape[0] - b0 - B) * Kc)
        b, k, n = torch.nonzero_static(by_part, size=n_pairs).unbind(1)
        del by_part
        self.decoder_evaluations += n_pairs
        res = points.new_full((B * N,), float("inf")) if not outside else points.new_zeros(B * N)
        if not outside and torch.is_grad_enabled():  # stay in the graph: a gradient of exactly 0 where no point is in a box
            res = res + 0.0 * (points.sum() + c.sum())
        if n_pairs:
            ub = torch.einsum("mi,mij->mj", points[b, n] - t[b, k], R[b, k]) - c[b, k] if grad else u[b, n, k]  # (M, 3)
        if n_free:
            bf, nf = torch.nonzero_static(free, size=n_free).unbind(1)
            if grad:  # per body: no (F, K, 3, 3) gather of the frames
                uf = torch.cat([torch.einsum("fki,kij->fkj", points[i, nf[bf == i]][:, None] - t[i], R[i]) - c[i]
                                for i in range(B)])                           # (F, K, 3), bf is sorted
                qf, qf_max = box_excess(uf, half[bf])
            else:
                qf, qf_max = u[bf, nf].abs().sub_(half[bf]), q_max[bf, nf]
            # a part without a code is absent inside its box (as in _part_values)
            d = outside_distance(qf, qf_max, None if enc.slot is None else raw[bf, nf])   # (F,)
            res = res.index_put((bf * N + nf,), d)
            del qf, qf_max, d
        if not grad:
            del u, q_max  # before the decoders: their activations are the query's other large buffers
        if n_pairs:
            if enc.scale is not None:
                sc = enc.scale[b0:b0 + B][b, k]
                xin = ub / sc
            else:
                xin = ub + c[b, k]
            kc = k if enc.slot is None else enc.slot[k]
            with record_function(DECODER_SCOPE):
                vals = self._decode_xin(enc, xin, b + b0, kc, counts_host, group_sorted=True)
            if enc.scale is not None:
                vals = vals * sc[:, 0]
            res = res.scatter_reduce(0, b * N + n, vals, "amin", include_self=False)
        return res.view(B, N)

    #: on the CPU a lean chunk holds at most this many (body, part, point) entries, one body at 60k points, so that
    #: its arrays stay in cache: a cached query of B = 8 bodies x 60k points on one thread took 63-75 ms per body
    #: with one body per chunk against 99-140 ms with two (the two layouts interleaved in one process, commit
    #: b1b26c3). The default of `cpu_chunk_elems`; bench variant 'volsmpl-onechunk' runs the whole batch in one chunk
    CPU_CHUNK_ELEMS = 1 << 20
    #: on other devices (GPUs) a lean chunk holds at most this many entries (~1.1 GiB at ~70 B each), B = 8 at 60k
    #: points in one chunk: on an H100 encode + query of B = 8 took 11.6 ms in one chunk against 30.7 ms in four
    #: chunks of two bodies (rows 'volsmpl-onechunk' and 'volsmpl' of `volsmpl bench --device cuda --batch 1 8
    #: --points 60000 --repeats 10`, commit 508d1c0, docs/bench_cuda.md). The default of `gpu_chunk_elems`
    GPU_CHUNK_ELEMS = 1 << 24

    def _lean_chunks(self, B: int, N: int, device=None) -> list:
        """Chunks (b0, b1, s, e) of the lean query on `device`: whole bodies while a chunk's (body, part, point)
        entries stay within the budget (on the CPU chunk_elems and cpu_chunk_elems, so that each body's work runs
        as at B = 1, in cache; elsewhere gpu_chunk_elems: launches, not caches, set a GPU's cost), else point
        ranges of one body."""
        cpu = device is None or torch.device(device).type == "cpu"
        budget = min(self.chunk_elems, self.cpu_chunk_elems) if cpu else self.gpu_chunk_elems
        step = max(1024, (self.chunk_elems if cpu else budget) // self.num_parts)   # the CPU's as `_chunks(1, N)`
        return lean_chunks(B, N, self.num_parts, budget, step)

