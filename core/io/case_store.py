"""Per-case records of a long CLI job, so that a run stopped at any moment resumes case by case.

A job (an app's table run) writes each finished case to ``OUT/cases/<name>.json`` atomically, with the case's key:
the sha256 of its configuration and inputs, of the weights it used and of the source files of the code that made
it (the `volsmpl` core package and the app's own package). `--resume` reuses a record only when its key is the
key the case would have now; a record made by other code, another configuration or another checkpoint is recomputed, never
served stale.

Example::

    store = CaseStore(out / "cases", resume=args.resume)
    key = job_key({"frames": 80, "start": [0, 1], ...}, modules=[volume], packages=["volsmpl.apps.motion"])
    rec = store.get("room0_0_volsmpl", key)
    if rec is None:
        rec = run_case(...)
        store.put("room0_0_volsmpl", key, rec)
"""
from __future__ import annotations

import functools
import hashlib
import importlib
import json
import os
import re
from pathlib import Path
from typing import Iterable

from volsmpl.io.outputs import write_atomic

__all__ = ["CaseStore", "job_key", "source_digest"]

_NAME = re.compile(r"^[A-Za-z0-9_.=+-]+$")


def _hash_files(h, root: Path, files: Iterable[Path]) -> None:
    for f in sorted(files):
        h.update(str(f.relative_to(root)).encode() + b"\0")
        h.update(f.read_bytes())


def source_digest(packages: Iterable[str] = ()) -> str:
    """sha256 of the .py files of the `volsmpl` core package (without its apps) and of each named package, as they
    were when this process first asked (the code it runs: files edited during a long job do not change its key)."""
    return _source_digest(tuple(packages))


@functools.lru_cache(maxsize=None)
def _source_digest(packages: tuple) -> str:
    h = hashlib.sha256()
    core = Path(__file__).resolve().parents[1]  # the volsmpl package folder (core/)
    _hash_files(h, core, (f for f in core.rglob("*.py") if "apps" not in f.relative_to(core).parts))
    for name in packages:
        d = Path(importlib.import_module(name).__file__).resolve().parent
        _hash_files(h, d, d.rglob("*.py"))
    return "sha256:" + h.hexdigest()


def _exact(value):
    """JSON stand-in of a configuration value that JSON has no type for, exact in every element: an array or
    tensor by its dtype, shape and the sha256 of its bytes (str() abbreviates large ones: two arrays that differ
    inside the '...' would share a key); numpy scalars as numbers; paths, devices, dtypes by their name."""
    import numpy as np
    import torch

    if isinstance(value, torch.Tensor):
        value = value.detach().cpu().numpy()
    if isinstance(value, np.ndarray):
        a = np.ascontiguousarray(value)
        return {"array": str(a.dtype), "shape": list(a.shape), "sha256": hashlib.sha256(a.tobytes()).hexdigest()}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (os.PathLike, torch.device, torch.dtype)):
        return str(value)
    raise TypeError(f"job_key: a configuration value of type {type(value).__name__} has no exact JSON form; pass "
                    f"numbers, strings, lists, dicts, arrays or tensors")


def job_key(config: dict, modules: Iterable = (), packages: Iterable[str] = ()) -> str:
    """The key of a job: sha256 over its configuration (canonical JSON; arrays and tensors by their bytes, see
    `_exact`), the weights of each module it uses (e.g. the attached volumes: every tensor of their state dicts,
    `volsmpl.io.checkpoint.weights_digest`) and `source_digest(packages)`."""
    from volsmpl.io.checkpoint import weights_digest

    h = hashlib.sha256(json.dumps(config, sort_keys=True, separators=(",", ":"), default=_exact).encode())
    for m in modules:
        h.update(weights_digest(m.state_dict()).encode())
    h.update(source_digest(packages).encode())
    return "sha256:" + h.hexdigest()


class CaseStore:
    """Records of one job's cases in a folder (module docstring), each stored with the key of what made it.
    resume=False ignores what the folder holds (every case is recomputed and overwritten)."""

    def __init__(self, folder: str | os.PathLike, resume: bool = True):
        self.folder, self.resume = Path(folder), resume
        self.reused, self.stale = 0, 0

    def _path(self, name: str) -> Path:
        if not _NAME.match(name):
            raise ValueError(f"case name {name!r}: use letters, digits and _.=+- only")
        return self.folder / f"{name}.json"

    def get(self, name: str, key: str):
        """The stored record of case `name` when resuming and it was stored with `key`, else None."""
        p = self._path(name)
        if not (self.resume and p.exists()):
            return None
        try:
            doc = json.loads(p.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            self.stale += 1
            return None
        if not isinstance(doc, dict) or doc.get("key") != key:
            self.stale += 1
            return None
        self.reused += 1
        return doc["record"]

    def put(self, name: str, key: str, record) -> Path:
        """Write case `name`'s record and its key atomically (JSON-serialisable)."""
        p = self._path(name)
        write_atomic(p, json.dumps({"key": key, "record": record}, allow_nan=True))
        return p
