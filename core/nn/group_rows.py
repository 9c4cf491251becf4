"""The NBW decoder on group-contiguous rows, one matrix product per (body, part) group, layer and cache tile: the
no-gradient CPU path of `NBWDecoder.decode_pairs`.

Each group's rows are a contiguous range of the group-sorted pairs, so a layer is ``addmm`` of that range with the
group's own (out, in) weight read in place as a transposed view: no padded chunks, no per-chunk copies of the
weights, no gathers of the points or scatters of the results. On the project's 2-core CPU, on the 44.5k pairs (16
groups) of one 60k-point query and 1 thread, this ran 1.4-1.6x faster than the padded batched matmul of
`NBWDecoder.mlp_chunks` (693cf34; whole queries gain less: docs/bench_cpu.md).
The loop costs about 16 operator calls per group and tile, which a GPU would pay as launches: there
`decode_pairs` keeps the batched form.

    h = decode_rows(p, counts, weights, biases, skip_layers=(3,), hidden=64, tile=4096)   # (M, out_dim)
"""
from __future__ import annotations

from typing import Sequence

import torch


def decode_rows(p: torch.Tensor, counts: Sequence[int], weights: Sequence[torch.Tensor],
                biases: Sequence[torch.Tensor], skip_layers: Sequence[int], hidden: int, tile: int) -> torch.Tensor:
    """Decoder of each group on its rows, relu between layers, none after the last.

    Shape: p (M, x_dim) positional encodings of the group-sorted pairs; counts: G ints, the rows of each group in
    order (sum M); weights[l] (G, out_l, in_pt_l) and biases[l] (G, out_l) (`NBWWeights` of B x K parts, flattened
    to G = B * K groups; any strides); skip layers read [h, p] through their first `hidden` and remaining input
    columns -> (M, out_dim).
    Example: ``decode_rows(positional_encoding(x_sorted, 2), [n0, n1], gen_w, gen_b, (3,), 64, 4096)``.
    """
    if sum(counts) != p.shape[0] or len(counts) != weights[0].shape[0]:
        raise ValueError(f"decode_rows: {len(counts)} group counts summing to {sum(counts)} for {p.shape[0]} rows "
                         f"and {weights[0].shape[0]} weight groups")
    if tile < 1:
        raise ValueError(f"decode_rows: tile must be >= 1 row, got {tile}")
    n_layers = len(weights)
    out = p.new_empty(p.shape[0], weights[-1].shape[1])
    # the (in, out) weights and biases of the groups with rows, as views made by one unbind per layer
    live = [g for g, n in enumerate(counts) if n]
    pick = None if len(live) == len(counts) else torch.tensor(live, device=p.device)
    Wt, Wp, bias = [], [], []
    for l, W in enumerate(weights):
        W = (W if pick is None else W[pick]).transpose(1, 2)            # (G', in, out)
        skip = l in skip_layers
        Wt.append((W[:, :hidden] if skip else W).unbind(0))
        Wp.append(W[:, hidden:].unbind(0) if skip else None)
        bias.append((biases[l] if pick is None else biases[l][pick]).unbind(0))
    start = 0
    for i, n in enumerate(counts[g] for g in live):
        for s in range(start, start + n, tile):
            e = min(start + n, s + tile)
            pe = p[s:e]
            h = pe
            for l in range(n_layers):
                last = l == n_layers - 1
                into = {"out": out[s:e]} if last else {}
                h = torch.addmm(bias[l][i], h, Wt[l][i], **into)
                if Wp[l] is not None:
                    h = h.addmm_(pe, Wp[l][i])
                if not last:
                    h = h.relu_()
        start += n
    return out
