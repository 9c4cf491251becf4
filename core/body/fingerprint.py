"""Content fingerprint of a SMPL-family model file.

A checkpoint records the fingerprint of the body it was trained for; loading it on another body
fails with a clear message. The fingerprint depends only on the arrays that define the body's
geometry and skinning, never on file names or on how the arrays were stored (npz/pkl, float32/64).
"""
from __future__ import annotations

import hashlib

import numpy as np

FINGERPRINT_KEYS = ("v_template", "f", "weights", "kintree_table", "J_regressor", "shapedirs")
FINGERPRINT_BETAS = 10  # only the first 10 shape directions count (smplx keeps num_betas of them)


def _canonical_bytes(name: str, array) -> bytes:
    a = np.asarray(array)
    if hasattr(array, "toarray"):  # scipy sparse J_regressor in official SMPL pickles
        a = np.asarray(array.toarray())
    if name == "kintree_table":  # parents only, root parent normalised to -1 (SMPL stores 2**32-1)
        a = a.reshape(-1, a.shape[-1])[0].astype(np.int64) if a.ndim == 2 else a.astype(np.int64)
        a = np.where((a < 0) | (a >= a.shape[0]), -1, a).astype("<i8")
    elif name == "f":
        a = a.astype("<i8")
    elif name == "shapedirs":
        a = a[..., :FINGERPRINT_BETAS].astype("<f4")
    else:
        # float32 bytes, so float32 and float64 copies of the same body agree.
        a = a.astype("<f4")
    return name.encode() + str(a.shape).encode() + np.ascontiguousarray(a).tobytes()


def body_fingerprint(arrays) -> str:
    """sha256 (first 16 hex digits) of a body's defining arrays.

    Args:
        arrays: mapping with at least the keys of FINGERPRINT_KEYS (SMPL file format names);
            'kintree_table' may be the (2, J) table or the (J,) parents array.
    Returns:
        str, e.g. "3fa2c9...". Equal for the same body whatever its storage dtype.
    """
    h = hashlib.sha256()
    for k in FINGERPRINT_KEYS:
        if k not in arrays:
            raise KeyError(f"cannot fingerprint body: array '{k}' is missing (SMPL files hold {FINGERPRINT_KEYS})")
        h.update(_canonical_bytes(k, arrays[k]))
    return h.hexdigest()[:16]


def fingerprint_of_model(body) -> str:
    """Fingerprint of a loaded body module (volsmpl.Body or smplx SMPL/SMPL-H/SMPL-X) from its buffers;
    equals body_fingerprint of the file it was loaded from."""
    import torch

    def np_(t):
        return t.detach().cpu().numpy() if torch.is_tensor(t) else np.asarray(t)

    return body_fingerprint({
        "v_template": np_(body.v_template).reshape(-1, 3), "f": np_(body.faces),
        "weights": np_(body.lbs_weights), "kintree_table": np_(body.parents),
        "J_regressor": np_(body.J_regressor), "shapedirs": np_(body.shapedirs),
    })
