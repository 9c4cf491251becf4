"""Content fingerprints of tensors, for caches that must never serve a result for other values.

Autograd's version counter misses edits through `t.data`, `t.numpy()` or `t.detach()` storage aliases, and a
storage pointer says nothing about the values, so a cache keyed on them can serve stale results. A fingerprint
here is computed from the bytes themselves, read as 64-bit words (no copy for aligned contiguous tensors) laid
out in rows of 64: the wrap-around sums of each row and of each column, each XOR a fixed random word, summed
into two numbers (two reductions, ~0.8 ms for 3.6 M float32 weights on one CPU thread). An edit of a single
element changes the first for certain (a changed row sum changes its XOR term, a bijection); two elements
swapped change a row sum or a column sum; other edits collide with probability about 2^-64 unless chosen
against the random words. Dtype, shape and device are part of the fingerprint.

    fp = fingerprint((out.vertices, out.joints))     # compare with ==
    fp = module_fingerprint(net)                     # parameters and buffers
"""
from __future__ import annotations

import torch

_SEED = 0x5EED_F1A9
_KEYS: dict[torch.device, torch.Tensor] = {}


def _keys(n: int, device: torch.device) -> torch.Tensor:
    """n random int64 words on `device` (a per-process constant; grown when a longer tensor comes, which only
    makes earlier fingerprints differ: a cache then recomputes, never reuses)."""
    k = _KEYS.get(device)
    if k is None or k.numel() < n:
        g = torch.Generator().manual_seed(_SEED)
        size = max(n, 1 << 16, 0 if k is None else 2 * k.numel())
        k = torch.randint(-(1 << 62), 1 << 62, (size,), generator=g, dtype=torch.int64).to(device)
        _KEYS[device] = k
    return k[:n]


def _words(t: torch.Tensor) -> torch.Tensor:
    """The tensor's bytes as int64 words (B / 8 of them, the last zero-padded), without a copy when aligned."""
    t = t.detach()
    if t.dtype == torch.bool:
        t = t.to(torch.uint8)
    if t.is_complex():
        t = torch.view_as_real(t)
    b = t.contiguous().reshape(-1).view(torch.uint8)
    pad = (-b.numel()) % 8
    if pad:
        b = torch.cat([b, b.new_zeros(pad)])
    try:
        return b.view(torch.int64)
    except RuntimeError:  # storage offset not 8-byte aligned: copy
        return b.clone().view(torch.int64)


_ROW = 64


def _hash(w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(row part, column part) of the fingerprint of int64 words w (module docstring)."""
    r = w.numel() // _ROW
    k = _keys(max(r, _ROW) + _ROW, w.device)
    head, tail = w[: r * _ROW].view(r, _ROW), w[r * _ROW:]
    rows = (head.sum(dim=1) ^ k[:r]).sum() + (tail ^ k[r: r + tail.numel()]).sum()
    cols = (head.sum(dim=0) ^ k[:_ROW]).sum()
    return rows, cols


_SMALL = 1 << 15  # tensors of fewer words are hashed together (one concatenation): fewer, larger reductions


@torch.no_grad()
def fingerprint(tensors) -> tuple:
    """A hashable fingerprint of the contents (and dtype, shape, device) of a sequence of tensors."""
    tensors = list(tensors)
    meta = tuple((tuple(t.shape), t.dtype, t.device) for t in tensors)
    sums, small = [], {}
    for t in tensors:
        if t.numel():
            w = _words(t)
            if w.numel() < _SMALL:
                small.setdefault(w.device, []).append(w)
            else:
                sums.extend(_hash(w))
    for ws in small.values():
        sums.extend(_hash(torch.cat(ws)))  # the shapes in `meta` tell where each tensor ends
    if not sums:
        return meta, ()
    if len({s.device for s in sums}) == 1:
        return meta, tuple(torch.stack(sums).tolist())  # one device sync
    return meta, tuple(int(s) for s in sums)


def module_fingerprint(module: torch.nn.Module) -> tuple:
    """`fingerprint` of every parameter and buffer of a module: changes with any edit of a weight's values,
    by an optimiser, load_state_dict, `.to()`, `p.data`, or `p.detach().numpy()`."""
    return fingerprint([*module.parameters(), *module.buffers()])
