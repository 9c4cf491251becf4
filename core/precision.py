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

__all__ = ["PRECISIONS", "tf32_matmuls"]

PRECISIONS = ("full", "bf16", "tf32")


@contextlib.contextmanager
def tf32_matmuls():
    """float32 CUDA matmuls on TF32 tensor cores inside the block; the previous setting is restored after it."""
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
