"""Content fingerprint of a SMPL-family model file.

A checkpoint records the fingerprint of the body it was trained for; loading it on another body
fails with a clear message. The fingerprint depends only on the arrays that define the body's
geometry and skinning, never on file names or on how the arrays were stored (npz/pkl, float32/64).
"""
from __future__ import annotations

import hashlib

import numpy as np

FINGERPRINT_KEYS = ("v_template", "f", "weights", "kintree_table", "J_regressor", "shapedirs")


def _canonical_bytes(name: str, array) -> bytes:
    a = np.asarray(array)
    if hasattr(array, "toarray"):  # scipy sparse J_regressor in official SMPL pickles
        a = np.asarray(array.toarray())
    if name in ("f", "kintree_table"):
        a = a.astype("<i8")
    else:
        # float32 bytes, so float32 and float64 copies of the same body agree.
        a = a.astype("<f4")
    return name.encode() + str(a.shape).encode() + np.ascontiguousarray(a).tobytes()


def body_fingerprint(arrays) -> str:
    """sha256 (first 16 hex digits) of a body's defining arrays.

    Args:
        arrays: mapping with at least the keys of FINGERPRINT_KEYS (SMPL file format names).
    Returns:
        str, e.g. "3fa2c9...". Equal for the same body whatever its storage dtype.
    """
    h = hashlib.sha256()
    for k in FINGERPRINT_KEYS:
        if k not in arrays:
            raise KeyError(f"cannot fingerprint body: array '{k}' is missing (SMPL files hold {FINGERPRINT_KEYS})")
        h.update(_canonical_bytes(k, arrays[k]))
    return h.hexdigest()[:16]
