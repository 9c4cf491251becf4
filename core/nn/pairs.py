"""(point, group) pairs of the sparse decoders: their counts per group, the padded group-contiguous chunk layout the
batched decoder runs on, its default chunk size, and the check of (point, body, part) pairs against an encoded batch.

A group is one (body, part) decoder, g = body * K + part; a layer of the batched decoder is one batched matmul over
chunks that each hold pairs of a single group (`NBWDecoder.decode_pairs`, `volsmpl.volume.engine.query_graph`).

    lay = group_pairs(group, n_groups=B * K, chunk=default_chunk(M, n_nonempty))
    xs = x[lay.src].view(-1, lay.chunk, 3)            # chunk c is decoded with the weights of group lay.chunk_group[c]
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import torch


class PairLayout(NamedTuple):
    """Padded, group-contiguous layout of (point, group) pairs, see :func:`group_pairs`.

    Attributes:
        src: (n_chunks * chunk,) index of the pair stored in each padded slot (padding repeats a
            valid index; its results are never read).
        slot: (M,) padded slot of every pair.
        chunk_group: (n_chunks,) group id of each chunk.
        chunk: rows per chunk.
    """
    src: torch.Tensor
    slot: torch.Tensor
    chunk_group: torch.Tensor
    chunk: int


def group_counts(group: torch.Tensor, n_groups: int) -> torch.Tensor:
    """Pairs per group, without a host sync (``torch.bincount`` reads the maximum on the host on a GPU).

    Shape: group (M,) int64 in [0, n_groups) -> (n_groups,) int64."""
    return torch.zeros(n_groups, dtype=torch.long, device=group.device).index_add_(0, group, torch.ones_like(group))


def group_pairs(group: torch.Tensor, n_groups: int, chunk: int, counts: Optional[torch.Tensor] = None,
                counts_host: Optional[list] = None, group_sorted: bool = False,
                n_chunks_total: Optional[int] = None) -> PairLayout:
    """Sort pairs by group and cut every group into chunks of ``chunk`` rows (last one padded).

    Each chunk holds pairs of a single group, so a layer is one batched matmul over chunks with
    the chunk's group weights. Padding waste is below ``n_nonempty_groups * chunk`` rows.

    Args:
        group: (M,) int64 group id in [0, n_groups).
        n_groups: number of groups G.
        chunk: rows per chunk (>= 1).
        counts, counts_host: `group_counts(group, n_groups)` and its values as a list, when the caller has them
            (the layout then needs no host sync of its own; else one, for the number of chunks).
        group_sorted: the caller guarantees `group` is non-decreasing (no sort is made; unsorted input then gives
            a wrong layout).
        n_chunks_total: a fixed number of chunks, at least the layout's (e.g. ceil(M / chunk) + n_groups): no host
            sync and shapes set by (M, chunk, n_chunks_total) alone (volsmpl.volume.engine.query_graph captures it); the chunks past
            the layout's are given to the last group and hold pair 0.
    Returns:
        :class:`PairLayout`.
    """
    M = group.shape[0]
    dev = group.device
    counts = group_counts(group, n_groups) if counts is None else counts   # (G,)
    n_chunks = (counts + (chunk - 1)) // chunk                          # (G,)
    chunk_end = torch.cumsum(n_chunks, 0)
    chunk_start = chunk_end - n_chunks
    group_start = torch.cumsum(counts, 0) - counts
    order = torch.arange(M, device=dev) if group_sorted else torch.argsort(group, stable=True)   # (M,)
    gs = group if group_sorted else group[order]
    rank = torch.arange(M, device=dev) - group_start[gs]
    slot_sorted = (chunk_start[gs] + torch.div(rank, chunk, rounding_mode="floor")) * chunk + rank % chunk
    slot = torch.empty_like(slot_sorted)
    slot[order] = slot_sorted
    if n_chunks_total is not None:
        total = int(n_chunks_total)
    else:
        total = int(n_chunks.sum()) if counts_host is None else sum((c + chunk - 1) // chunk for c in counts_host)
    src = torch.zeros(total * chunk, dtype=torch.long, device=dev)
    src[slot_sorted] = order
    if n_chunks_total is None:
        chunk_group = torch.repeat_interleave(torch.arange(n_groups, device=dev), n_chunks, output_size=total)
    else:
        chunk_group = torch.searchsorted(chunk_end, torch.arange(total, device=dev), right=True).clamp(max=n_groups - 1)
    return PairLayout(src, slot, chunk_group, chunk)


def default_chunk(n_pairs: int, n_nonempty: int) -> int:
    """Chunk size for :func:`group_pairs`: the largest power of two <= half the mean group size,
    clamped to [16, 512]. Larger chunks make faster batched matmuls on CPU (64-row chunks run at
    about half the speed of 512-row ones); half the mean size bounds the padding to ~50% worst case."""
    half = max(1, n_pairs // (2 * max(1, n_nonempty)))
    return int(min(512, max(16, 1 << (half.bit_length() - 1))))


def check_pairs(x_local: torch.Tensor, body_idx: torch.Tensor, part_idx: torch.Tensor, B: int, K: int,
                bounds: bool = True) -> torch.Tensor:
    """Validate (point, body, part) pairs for a decoder batch of B bodies x K parts (bounds=False: shapes and
    dtypes only, no host sync, for indices the caller made in range).

    Args: x_local (M, 3); body_idx, part_idx (M,) integers. Returns the group ids body * K + part (M,) int64.
    """
    if x_local.dim() != 2 or x_local.shape[1] != 3:
        raise ValueError(f"decode_pairs expects x_local of shape (M, 3), got {tuple(x_local.shape)}")
    M = x_local.shape[0]
    if body_idx.shape != (M,) or part_idx.shape != (M,):
        raise ValueError(f"decode_pairs expects body_idx and part_idx of shape (M={M},), "
                         f"got {tuple(body_idx.shape)} and {tuple(part_idx.shape)}")
    if body_idx.dtype not in (torch.int64, torch.int32) or part_idx.dtype not in (torch.int64, torch.int32):
        raise TypeError("decode_pairs: body_idx and part_idx must be integer (int64) tensors")
    if M and bounds:
        # one host sync for the four bounds, not one each
        bmin, bmax, pmin, pmax = torch.stack([body_idx.min(), body_idx.max(), part_idx.min().to(body_idx.dtype),
                                              part_idx.max().to(body_idx.dtype)]).tolist()
        if bmin < 0 or bmax >= B or pmin < 0 or pmax >= K:
            raise IndexError(f"decode_pairs: body_idx in [{bmin}, {bmax}] and part_idx in [{pmin}, {pmax}] "
                             f"must lie in [0, {B}) and [0, {K}) (the encoded batch)")
    return body_idx.long() * K + part_idx.long()
