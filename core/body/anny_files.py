"""SMPL / SMPL-X file assembly and writing for the default-body export (`volsmpl.body.anny_export`): the
arrays of each format, reproducible .npz writing, the smplx.create folder layout and float rounding for a
stable JSON.
"""
from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from .anny_skeleton import (N_SMPLX_BETAS, N_SMPLX_EXPR, SMPL_JOINT_NAMES, SMPL_PARENTS, SMPLX_JOINT_NAMES,
                            SMPLX_PARENTS, ZIP_DATE_TIME)


# ----------------------------------------------------------------------------------------------------------------
# Writers
# ----------------------------------------------------------------------------------------------------------------
def save_npz_deterministic(path, arrays: dict) -> None:
    """np.savez_compressed equivalent with reproducible bytes (sorted entries, fixed zip timestamps).

    Args:
        path: output file; arrays: name -> np.ndarray (stored with its dtype, no pickles).
    """
    with zipfile.ZipFile(path, "w") as zf:
        for name in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(name + ".npy", date_time=ZIP_DATE_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue(), compress_type=zipfile.ZIP_DEFLATED, compresslevel=9)


def _kintree(parents) -> np.ndarray:
    """(2, J) int64 kintree_table: parents (root -1) over joint ids."""
    return np.stack([np.asarray(parents, dtype=np.int64), np.arange(len(parents), dtype=np.int64)])


def smpl_arrays(v_template, shapedirs, weights, J_regressor, faces) -> dict:
    """Arrays of the SMPL-format file (float32 / int64)."""
    V = len(v_template)
    return {
        "v_template": v_template.astype(np.float32), "shapedirs": shapedirs.astype(np.float32),
        "posedirs": np.zeros((V, 3, 9 * 23), np.float32), "J_regressor": J_regressor.astype(np.float32),
        "weights": weights.astype(np.float32), "kintree_table": _kintree(SMPL_PARENTS),
        "f": faces.astype(np.int64), "joint_names": np.array(SMPL_JOINT_NAMES),
    }


def smplx_arrays(v_template, shapedirs, weights, J_regressor, faces) -> dict:
    """Arrays of the SMPL-X-format file, with what the unmodified smplx.SMPLX needs."""
    V = len(v_template)
    sd = np.concatenate([shapedirs[..., :N_SMPLX_BETAS], np.zeros((V, 3, N_SMPLX_EXPR))], axis=-1)
    return {
        "v_template": v_template.astype(np.float32), "shapedirs": sd.astype(np.float32),
        "posedirs": np.zeros((V, 3, 9 * 54), np.float32), "J_regressor": J_regressor.astype(np.float32),
        "weights": weights.astype(np.float32), "kintree_table": _kintree(SMPLX_PARENTS),
        "f": faces.astype(np.int64), "joint_names": np.array(SMPLX_JOINT_NAMES),
        "hands_componentsl": np.eye(45, dtype=np.float32), "hands_componentsr": np.eye(45, dtype=np.float32),
        "hands_meanl": np.zeros(45, np.float32), "hands_meanr": np.zeros(45, np.float32),
        # no facial landmarks are defined on this body: empty static landmark set
        "lmk_faces_idx": np.zeros(0, np.int64), "lmk_bary_coords": np.zeros((0, 3), np.float32),
    }


def make_smplx_model_dir(model_dir, smplx_file) -> Path:
    """Folder layout for `smplx.create(model_dir, model_type='smplx')`: model_dir/smplx/SMPLX_NEUTRAL.npz (symlink).

    Args:
        model_dir: folder to create; smplx_file: the exported anny_smplx_neutral.npz.
    Returns:
        model_dir as Path.
    """
    d = Path(model_dir) / "smplx"
    d.mkdir(parents=True, exist_ok=True)
    link = d / "SMPLX_NEUTRAL.npz"
    if not link.exists():
        link.symlink_to(Path(smplx_file).resolve())
    return Path(model_dir)


def round_floats(x, nd=6):
    """Round floats (recursively) for a stable JSON."""
    if isinstance(x, dict):
        return {k: round_floats(v, nd) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [round_floats(v, nd) for v in x]
    if isinstance(x, (float, np.floating)):
        return round(float(x), nd)
    if isinstance(x, np.integer):
        return int(x)
    return x
