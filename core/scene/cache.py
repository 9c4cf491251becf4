"""A per-user cache for generated data (scene point clouds, room meshes), so costly generation runs once.

Folder: `$VOLSMPL_CACHE`, else `$XDG_CACHE_HOME/volsmpl`, else `~/.cache/volsmpl` (never inside the repository:
nothing generated is committed). An entry is keyed by a name, the generator's version and the seed:
`<folder>/<name>/v<version>-s<seed>.npz` (a dict of arrays, exact) or `.ply` (a trimesh mesh, binary PLY with
float32 vertices). A version made by `code_version(n, "volsmpl.scene", ...)` carries a digest of the generator's
source, so an entry made by other generator code is rebuilt, never served (a hand-bumped number alone is easily
forgotten); on a new version the entry is rebuilt and older versions of the same name and seed are removed. Files are written atomically (a temporary file in the same folder, then
`os.replace`), so a reader never sees half a file, and an unreadable entry is rebuilt.
"""
from __future__ import annotations

import functools
import hashlib
import importlib
import os
import re
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh

_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


def cache_dir() -> Path:
    """The cache folder ($VOLSMPL_CACHE, else $XDG_CACHE_HOME/volsmpl, else ~/.cache/volsmpl); not created here."""
    if os.environ.get("VOLSMPL_CACHE"):
        return Path(os.environ["VOLSMPL_CACHE"]).expanduser()
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]).expanduser() / "volsmpl"
    return Path.home() / ".cache" / "volsmpl"


@functools.lru_cache(maxsize=None)
def code_version(version, *modules: str) -> str:
    """`version` and a digest of the generator's source: `modules` are module names, a package standing for all
    its .py files (read when this process first asks: files edited during a run do not change its entries' keys).

    Example:
        >>> cached("room_points_16384_x4", code_version(1, "volsmpl.scene"), 7, build)   # '1.<12 hex digits>'
    """
    h = hashlib.sha256()
    for name in modules:
        f = Path(importlib.import_module(name).__file__).resolve()
        files = sorted(f.parent.rglob("*.py")) if f.name == "__init__.py" else [f]
        for x in files:
            h.update(name.encode() + b"\0" + str(x.relative_to(f.parent)).encode() + b"\0" + x.read_bytes())
    return f"{version}.{h.hexdigest()[:12]}"


def cache_path(name: str, version, seed, suffix: str = ".npz") -> Path:
    """Where `cached(name, version, seed, ...)` keeps its entry."""
    for what, v in (("name", name), ("version", str(version)), ("seed", str(seed))):
        if not _NAME.match(v):
            raise ValueError(f"cache {what} {v!r} must be non-empty and use only letters, digits, '_', '-', '.'.")
    return cache_dir() / name / f"v{version}-s{seed}{suffix}"


def _write_atomic(path: Path, value) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=path.suffix + ".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            if isinstance(value, trimesh.Trimesh):
                fh.write(value.export(file_type="ply"))
            else:
                np.savez(fh, **value)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes it private; cache entries are ordinary files
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _read(path: Path):
    if path.suffix == ".ply":
        return trimesh.load(path, file_type="ply", process=False)
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def cached(name: str, version, seed, build_fn: Callable[[], object], mesh: bool = False, refresh: bool = False):
    """Load an entry from the cache, or build it with build_fn(), store it atomically and return it.

    Args:
        name: what is cached, e.g. 'room_points_16384' (letters, digits, '_', '-', '.').
        version: the generator's version; a different version rebuilds (and drops the other versions).
        seed: the generator's seed (or any key of that form).
        build_fn: no-argument function returning a dict of numpy arrays (mesh=False) or a trimesh.Trimesh (mesh=True).
        mesh: store a mesh as binary .ply instead of arrays as .npz.
        refresh: rebuild even if an entry exists.

    Returns: the dict of arrays (a fresh load, so identical whether built now or read) or the mesh.

    Example:
        >>> pts = cached("demo_points", 1, 0, lambda: {"points": np.zeros((4, 3))})["points"]
    """
    path = cache_path(name, version, seed, ".ply" if mesh else ".npz")
    if path.exists() and not refresh:
        try:
            return _read(path)
        except Exception:  # truncated or foreign file: rebuild
            pass
    value = build_fn()
    if mesh and not isinstance(value, trimesh.Trimesh):
        raise ValueError(f"build_fn for {name!r} must return a trimesh.Trimesh when mesh=True, "
                         f"got {type(value).__name__}.")
    if not mesh:
        if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
            raise ValueError(f"build_fn for {name!r} must return a dict of numpy arrays with str keys "
                             f"(or pass mesh=True).")
        value = {k: np.asarray(v) for k, v in value.items()}
        bad = [k for k, v in value.items() if v.dtype == object]
        if bad:
            raise ValueError(f"build_fn for {name!r} returned non-numeric arrays {bad}; store numbers or strings only.")
    _write_atomic(path, value)
    for old in path.parent.glob(f"v*-s{seed}{path.suffix}"):
        if old != path:
            old.unlink(missing_ok=True)
    return _read(path)
