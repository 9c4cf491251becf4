"""Grouped evaluation of the per-(body, part) NBW decoders: one grouped matmul per layer, no padding.

The query engine sorts its (point, body, part) pairs by group g = body * K' + slot (the order of
``inside.nonzero()`` on a (B, K, N) mask already is) and passes the cumulative group sizes ``offs``. Every
decoder layer is then one ``torch.nn.functional.grouped_mm`` over the jagged row segments: each segment is
multiplied by its own group's weights, with no zero padding and no Python loop over groups (the loop over
segments runs inside the operator). The operator count of a decode is fixed (a few per layer), whatever
the number of bodies, parts and pairs.

Biases ride in the matmul (homogeneous coordinates): the activations carry a column of ones, and each
layer's matrix is [[W^T, 0], [b, 1]] (relu(1) = 1 keeps the ones), so a layer is a grouped matmul and an
in-place relu: no per-row bias gather, no extra pass over the activations. The skip layer reads
[h, 1, gamma(x), 1] (one concatenation). grouped_mm wants 16-byte strides, so widths are padded with zero
columns to multiples of ALIGN = 8 (65 -> 72): 27 % more multiply-adds than the 64-wide layers, not counted as
FLOPs (72-wide matmuls run at the 64-wide rate; 68-wide ones at 0.8 of it).

``grouped_mm`` takes float32, bfloat16 and float16 (this torch: on the CPU too); other dtypes (float64) and
older torch builds use the chunked engine (``NBWDecoder.decode_pairs``): ``grouped_supported`` says which.
"""
from __future__ import annotations

from typing import List, Sequence

import torch
import torch.nn.functional as F

__all__ = ["grouped_supported", "augmented_matrices", "grouped_mlp", "group_offsets", "pad4"]

_DTYPES = (torch.float32, torch.bfloat16, torch.float16)


def grouped_supported(dtype: torch.dtype, device=None) -> bool:
    """True when this torch has ``F.grouped_mm`` and it takes `dtype` on `device` (CPU: float32, bfloat16,
    float16; CUDA: bfloat16 only)."""
    if not hasattr(F, "grouped_mm"):
        return False
    if device is not None and torch.device(device).type == "cuda":
        return dtype == torch.bfloat16
    return dtype in _DTYPES


def group_offsets(counts: torch.Tensor) -> torch.Tensor:
    """Cumulative group sizes for ``grouped_mm``. Shape: counts (G,) integer >= 0 -> (G,) int32 ends."""
    if counts.dim() != 1:
        raise ValueError(f"group_offsets expects (G,) counts, got {tuple(counts.shape)}")
    return torch.cumsum(counts, 0).to(torch.int32)


class _ContiguousGrad(torch.autograd.Function):
    """Identity whose backward hands on a contiguous gradient (grouped_mm's backward refuses expanded ones)."""

    @staticmethod
    def forward(ctx, x):
        return x.view_as(x)

    @staticmethod
    def backward(ctx, g):
        return g.contiguous()


#: activation widths are padded to multiples of this (grouped_mm wants 16-byte strides; CPU matmul kernels run
#: fastest on whole 8-float AVX2 vectors: 1 thread, 45k rows, 64 / 68 / 72 wide: 6.6 / 10.3 / 9.0 ms)
ALIGN = 8


def pad4(n: int) -> int:
    """n rounded up to a multiple of ALIGN (named for the 16-byte minimum of grouped_mm)."""
    return (n + ALIGN - 1) // ALIGN * ALIGN


def augmented_matrices(weights: Sequence[torch.Tensor], biases: Sequence[torch.Tensor], skip_layers: Sequence[int],
                       hidden: int) -> List[torch.Tensor]:
    """Per-group layer matrices in homogeneous form, ready for ``grouped_mm`` (row vector times matrix).

    Activation layouts (widths padded to multiples of ALIGN with zero columns): p_aug = [gamma(x), 1, 0..] (px wide),
    h_aug = [h, 1, 0..] (hw = pad4(hidden + 1) wide). Layer 0 reads p_aug, a skip layer [h_aug, p_aug], the others
    h_aug; hidden layers write h_aug (their matrix carries the ones on), the last layer pad4(out) columns.

    Shape: weights[l] (G, out_l, in_l) per-point weights (skip layers: columns [h (hidden), gamma(x)]), biases[l]
    (G, out_l) -> list of (G, rows_l, cols_l) as above.
    """
    n = len(weights)
    if n != len(biases) or n < 1:
        raise ValueError(f"augmented_matrices needs one bias per weight, got {len(weights)} and {len(biases)}")
    x_dim = weights[0].shape[2]
    px, hw = pad4(x_dim + 1), pad4(hidden + 1)
    mats = []
    for l, (W, b) in enumerate(zip(weights, biases)):
        if W.dim() != 3 or b.shape != W.shape[:2]:
            raise ValueError(f"layer {l}: weights (G, out, in) and biases (G, out), got {tuple(W.shape)} and {tuple(b.shape)}")
        G, o, i = W.shape
        last = l == n - 1
        Wt = W.transpose(1, 2)                                           # (G, in, out)
        if l == 0:
            rows, one_row, blocks = px, x_dim, [(0, Wt)]                 # [gamma(x), 1]
        elif l in skip_layers:
            rows, one_row, blocks = hw + px, hidden, [(0, Wt[:, :hidden]), (hw, Wt[:, hidden:])]
        else:
            rows, one_row, blocks = hw, hidden, [(0, Wt)]
        cols = pad4(o) if last else hw
        M = W.new_zeros(G, rows, cols)
        for r0, blk in blocks:
            M[:, r0:r0 + blk.shape[1], :o] = blk
        M[:, one_row, :o] = b
        if not last:
            M[:, one_row, hidden] = 1.0                                  # the ones column carries on
        mats.append(M)
    return mats


def grouped_mlp(p: torch.Tensor, offs: torch.Tensor, mats: Sequence[torch.Tensor], skip_layers: Sequence[int]) -> torch.Tensor:
    """The decoder MLP on group-sorted rows: relu between layers, none after the last.

    Shape: p (M, x_dim) positional encodings, rows sorted by group; offs (G,) int32 cumulative group sizes
    (offs[-1] == M); mats from `augmented_matrices` -> (M, pad4(out_dim)) (columns past out_dim are zero).
    """
    if p.dim() != 2 or offs.dim() != 1 or offs.dtype != torch.int32:
        raise ValueError(f"grouped_mlp expects p (M, D) and int32 offs (G,), got {tuple(p.shape)} and {offs.dtype}")
    rows = p.shape[0]
    pad = pad4(p.shape[1] + 1) - p.shape[1] - 1
    p = torch.cat([p, p.new_ones(rows, 1), p.new_zeros(rows, pad)], dim=1)  # p_aug = [gamma(x), 1, 0..]
    h = p
    for l, M in enumerate(mats):
        if l in skip_layers:
            h = torch.cat([h, p], dim=1)                                 # [h_aug, p_aug]
        h = F.grouped_mm(h, M, offs=offs)
        if l < len(mats) - 1:
            h = h.relu_()  # in place is autograd-safe: grouped_mm saves its inputs, not its output
        if torch.is_grad_enabled() and h.requires_grad:
            h = _ContiguousGrad.apply(h)
    return h
