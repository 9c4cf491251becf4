"""Checkpoint files: tensors in safetensors (nothing is unpickled) + a JSON sidecar.

A checkpoint ``<path>`` is the pair ``<path>.safetensors`` (the state dict) and ``<path>.json``::

    {"format": "volsmpl-checkpoint", "version": 1,
     "config": {...network config, e.g. VolumeConfig.to_dict()...},
     "meta":   {"body_fingerprint": "...", "parts": ..., "training": ...},
     "digests": {"weights": "sha256:...", "config": "sha256:..."}}

Both files are written to temporary names and moved into place with ``os.replace`` so a crash
never leaves a half-written checkpoint under the final name. On load the digests are verified (the
config's also when only the JSON is read) and non-finite weights are refused, each with a message naming
the file. A checkpoint without digests (written before they were recorded) loads with a warning that it
cannot be verified; ``add_digests(path)`` records them for the files as they are.
"""
from __future__ import annotations

import hashlib
import json
import os
import warnings
from typing import Any, Dict, Optional, Tuple

import torch

FORMAT = "volsmpl-checkpoint"
VERSION = 1
FINGERPRINT_KEY = "body_fingerprint"
DIGESTS_KEY = "digests"

_HOWTO = ("download the released checkpoint or train one with `volsmpl train ...` "
          "(see `volsmpl train --help`)")


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt, of an unknown format, or trained for another body."""


def weights_digest(state_dict: Dict[str, torch.Tensor]) -> str:
    """sha256 of a state dict: every tensor's name, dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    for k in sorted(state_dict):
        t = state_dict[k].detach().to("cpu").contiguous()
        h.update(f"{k}|{t.dtype}|{tuple(t.shape)}\n".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy())
    return "sha256:" + h.hexdigest()


def config_digest(config: Dict[str, Any]) -> str:
    """sha256 of a config dict in canonical JSON (sorted keys, no spaces)."""
    text = json.dumps(config, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()


def _non_finite(state_dict: Dict[str, torch.Tensor]) -> Optional[str]:
    """'name (n of m entries)' of the first floating tensor with NaN or inf entries, else None."""
    for k in sorted(state_dict):
        t = state_dict[k]
        if (t.is_floating_point() or t.is_complex()) and not bool(torch.isfinite(t).all()):
            return f"'{k}' ({int((~torch.isfinite(t)).sum())} of {t.numel()} entries)"
    return None


def checkpoint_paths(path: str | os.PathLike) -> Tuple[str, str]:
    """(tensor file, JSON file) of a checkpoint given with or without extension."""
    p = os.fspath(path)
    for ext in (".safetensors", ".json"):
        if p.endswith(ext):
            p = p[: -len(ext)]
            break
    return p + ".safetensors", p + ".json"


def save_checkpoint(path: str | os.PathLike, state_dict: Dict[str, torch.Tensor],
                    config: Dict[str, Any], meta: Dict[str, Any]) -> Tuple[str, str]:
    """Write ``<path>.safetensors`` and ``<path>.json`` atomically.

    Args:
        path: checkpoint path, with or without extension.
        state_dict: name -> tensor (moved to CPU, made contiguous; shared storage is copied).
        config: JSON-serialisable network configuration.
        meta: JSON-serialisable metadata; ``meta["body_fingerprint"]`` is checked on load.
    Returns:
        (tensor file, JSON file) paths.
    """
    from safetensors.torch import save_file

    st_path, js_path = checkpoint_paths(path)
    tensors = {}
    for k, v in state_dict.items():
        if not isinstance(v, torch.Tensor):
            raise TypeError(f"save_checkpoint: state_dict['{k}'] is a {type(v).__name__}, only tensors can be "
                            "stored; put other values into `meta`")
        tensors[k] = v.detach().to("cpu").contiguous().clone()
    bad = _non_finite(tensors)
    if bad is not None:
        raise ValueError(f"save_checkpoint: {bad} of the weights are NaN or inf (training diverged?); "
                         f"nothing written to {st_path}. Lower the learning rate or resume from an earlier checkpoint.")
    try:
        digests = {"weights": weights_digest(tensors), "config": config_digest(config)}
        doc = json.dumps({"format": FORMAT, "version": VERSION, "config": config, "meta": meta, DIGESTS_KEY: digests},
                         indent=2, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise TypeError(f"save_checkpoint: config/meta must be JSON-serialisable (plain dicts, lists, "
                        f"str, finite numbers): {e}") from e
    fp = meta.get(FINGERPRINT_KEY) if isinstance(meta, dict) else None
    header = {"format": FORMAT, "version": str(VERSION)}
    if fp is not None:
        header[FINGERPRINT_KEY] = str(fp)

    d = os.path.dirname(os.path.abspath(st_path))
    os.makedirs(d, exist_ok=True)
    tmp_st, tmp_js = st_path + f".tmp{os.getpid()}", js_path + f".tmp{os.getpid()}"
    try:
        save_file(tensors, tmp_st, metadata=header)
        with open(tmp_js, "w") as f:
            f.write(doc)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp_st, st_path)
        os.replace(tmp_js, js_path)
    finally:
        for t in (tmp_st, tmp_js):
            if os.path.exists(t):
                os.remove(t)
    return st_path, js_path


def _folder_hint(path) -> Optional[str]:
    """The fix when `path` names a folder rather than a checkpoint: a training-state folder (ckpt-<step>/, whose
    model is <folder>/model) or a run folder (its latest training state's model); None for anything else."""
    p = os.fspath(path)
    if not os.path.isdir(p):
        return None
    d = p.rstrip("/\\") or p
    if os.path.isfile(os.path.join(d, "model.safetensors")):
        return (f"{p} is a training-state folder, not a checkpoint; its model checkpoint is "
                f"{os.path.join(d, 'model')}.")
    latest = os.path.join(d, "latest")
    if os.path.isfile(latest):
        with open(latest) as f:
            name = f.read().strip()
        return (f"{p} is a training run folder, not a checkpoint; its latest model checkpoint is "
                f"{os.path.join(d, name, 'model')}.")
    return (f"{p} is a folder, not a checkpoint; a checkpoint is the pair <name>.safetensors + <name>.json: give "
            f"<folder>/<name>.")


def load_checkpoint(path: str | os.PathLike, expected_fingerprint: Optional[str] = None,
                    map_location: str | torch.device = "cpu", weights: bool = True
                    ) -> Tuple[Optional[Dict[str, torch.Tensor]], Dict[str, Any], Dict[str, Any]]:
    """Read a checkpoint written by :func:`save_checkpoint`.

    Args:
        path: checkpoint path, with or without extension.
        expected_fingerprint: if given, the fingerprint of the body the caller uses; the
            checkpoint must have been trained for it.
        map_location: device of the returned tensors.
        weights: False reads only the JSON (state_dict None; both files must still exist).
    Returns:
        (state_dict, config, meta).
    Raises:
        CheckpointError: missing/corrupt files, unknown format or version, fingerprint mismatch.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    st_path, js_path = checkpoint_paths(path)
    for f in (js_path, st_path):
        if not os.path.isfile(f):
            hint = _folder_hint(path)
            if hint:
                raise CheckpointError(hint)
            raise CheckpointError(f"checkpoint file not found: {f}. A checkpoint is the pair "
                                  f"{os.path.basename(st_path)} + {os.path.basename(js_path)}; {_HOWTO}.")
    try:
        with open(js_path, "r") as f:
            doc = json.load(f)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CheckpointError(f"checkpoint file {js_path} is corrupt (not valid JSON: {e}); "
                              f"re-save or re-download it, or {_HOWTO}.") from e
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        fmt = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise CheckpointError(f"{js_path} is not a volsmpl checkpoint (format {fmt!r}, expected {FORMAT!r}).")
    if doc.get("version") != VERSION:
        raise CheckpointError(f"{js_path} has checkpoint version {doc.get('version')!r}; this volsmpl reads "
                              f"version {VERSION}. Use the volsmpl release that wrote it, or re-train.")
    for key in ("config", "meta"):
        if not isinstance(doc.get(key), dict):
            raise CheckpointError(f"checkpoint file {js_path} is corrupt: '{key}' must be an object.")
    config, meta = doc["config"], doc["meta"]
    digests = doc.get(DIGESTS_KEY)
    if digests is None:
        warnings.warn(f"checkpoint {js_path} records no digests (written before volsmpl recorded them), so damaged "
                      "weights or an edited config cannot be detected; record them for the files as they are with "
                      "volsmpl.io.checkpoint.add_digests(path).", stacklevel=2)
    elif not (isinstance(digests, dict) and all(isinstance(digests.get(k), str) for k in ("weights", "config"))):
        raise CheckpointError(f"checkpoint file {js_path} is corrupt: '{DIGESTS_KEY}' must hold 'weights' and 'config' strings.")
    elif digests["config"] != config_digest(config):
        raise CheckpointError(f"checkpoint file {js_path}: its config differs from the one it was saved with (config "
                              f"digest mismatch: the JSON was edited or damaged); re-save or re-download it, or {_HOWTO}.")

    if expected_fingerprint is not None:
        fp = meta.get(FINGERPRINT_KEY)
        if fp is None:
            raise CheckpointError(f"checkpoint {js_path} records no body fingerprint, so it cannot be checked "
                                  f"against this body ({expected_fingerprint}); train one with `volsmpl train ...` "
                                  "or load it without expected_fingerprint.")
        if fp != expected_fingerprint:
            raise CheckpointError(f"checkpoint was trained for body {fp}, this body is {expected_fingerprint}; "
                                  "train one with `volsmpl train ...` or pass the matching body.")

    if not weights:
        return None, config, meta
    try:
        state_dict = load_file(st_path, device=str(map_location))
    except (SafetensorError, OSError, ValueError, RuntimeError) as e:
        raise CheckpointError(f"checkpoint file {st_path} is corrupt or truncated ({e}); "
                              f"re-save or re-download it, or {_HOWTO}.") from e
    if digests is not None and weights_digest(state_dict) != digests["weights"]:
        raise CheckpointError(f"checkpoint file {st_path} does not match the weights digest recorded in {js_path} "
                              f"(damaged bytes, or the tensor file of another checkpoint); re-save or re-download it, "
                              f"or {_HOWTO}.")
    bad = _non_finite(state_dict)
    if bad is not None:
        raise CheckpointError(f"checkpoint file {st_path} holds NaN or inf weights in {bad}: the training diverged "
                              f"or the file is damaged; use an earlier checkpoint, or {_HOWTO}.")
    return state_dict, config, meta


def add_digests(path: str | os.PathLike) -> str:
    """Record the digests of a checkpoint's weights and config as they are now (for a checkpoint written before
    digests existed; the weights file is not changed). The weights must be finite. Returns the JSON path."""
    from safetensors.torch import load_file

    st_path, js_path = checkpoint_paths(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, config, _ = load_checkpoint(path, weights=False)
    with open(js_path) as f:
        doc = json.load(f)
    state = load_file(st_path)
    bad = _non_finite(state)
    if bad is not None:
        raise CheckpointError(f"checkpoint file {st_path} holds NaN or inf weights in {bad}; no digests recorded.")
    doc[DIGESTS_KEY] = {"weights": weights_digest(state), "config": config_digest(config)}
    tmp = js_path + f".tmp{os.getpid()}"
    try:
        with open(tmp, "w") as f:
            f.write(json.dumps(doc, indent=2, sort_keys=True, allow_nan=False))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, js_path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return js_path
