"""Reduced-precision query modes of the learned volumes (`Volume.set_precision`, `volsmpl eval --precision`,
the bench's 'volsmpl-bf16' / 'volsmpl-tf32').

- 'full': the volume's own dtype (float32 by default), the reference.
- 'bf16': the decoder layers in bfloat16 on the grouped engine (`volsmpl.nn.grouped`): the positional encoding is
  computed in full precision, then it and the per-(body, part) layer matrices are rounded; accumulation in float32.
- 'tf32': float32 matmuls on TF32 tensor cores while the decoders run (CUDA only).

    with tf32_matmuls():
        y = a @ b          # TF32 on an Ampere-or-later GPU; the previous setting returns after the block
"""
from __future__ import annotations

import contextlib

import torch

__all__ = ["PRECISIONS", "check_precision", "matmul_precision", "tf32_matmuls"]

PRECISIONS = ("full", "bf16", "tf32")


def check_precision(precision: str, kind: str, grouped: bool, grouped_bf16: bool) -> None:
    """ValueError (one line, with the fix) unless a `kind` volume can run `precision`: bf16 needs a grouped decoder
    (`grouped`) that this torch runs in bfloat16 (`grouped_bf16`)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if precision == "bf16" and not grouped_bf16:
        raise ValueError(f"precision 'bf16' needs a grouped decoder in bfloat16, which the {kind} network "
                         f"{'cannot run in this torch' if grouped else 'has not'}; use precision 'full'")


@contextlib.contextmanager
def tf32_matmuls(device=None):
    """float32 CUDA matmuls on TF32 tensor cores inside the block; the previous setting is restored after it.
    device: where the matmuls run; ValueError (one line) when it is not a CUDA device."""
    if device is not None and torch.device(device).type != "cuda":
        raise ValueError(f"precision 'tf32' runs on CUDA tensor cores, but the query is on {torch.device(device).type}; "
                         f"use precision 'full' or 'bf16' there")
    m = torch.backends.cuda.matmul
    new_api = hasattr(m, "fp32_precision")   # torch >= 2.9 names the setting; older builds have allow_tf32
    before = m.fp32_precision if new_api else m.allow_tf32
    try:
        if new_api:
            m.fp32_precision = "tf32"
        else:
            m.allow_tf32 = True
        yield
    finally:
        if new_api:
            m.fp32_precision = before
        else:
            m.allow_tf32 = before


def matmul_precision(precision: str, device):
    """The context a query's decoders run in: `tf32_matmuls(device)` for 'tf32', nothing to change otherwise."""
    return tf32_matmuls(device) if precision == "tf32" else contextlib.nullcontext()
