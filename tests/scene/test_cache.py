"""The user cache: folder resolution, build once, rebuild on version change, atomic writes, meshes."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import trimesh

from volsmpl.scene import cache as cache_mod
from volsmpl.scene.cache import cache_dir, cache_path, cached


def test_cache_dir_precedence(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path / "a"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert cache_dir() == tmp_path / "a"
    monkeypatch.delenv("VOLSMPL_CACHE")
    assert cache_dir() == tmp_path / "x" / "volsmpl"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "volsmpl"


def test_build_once_and_rebuild_on_version(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path))
    calls = []

    def build(v):
        def fn():
            calls.append(v)
            return {"x": np.arange(5) * v, "name": np.array("room")}
        return fn

    a = cached("thing", 1, 3, build(1))
    b = cached("thing", 1, 3, build(1))
    assert calls == [1] and np.array_equal(a["x"], b["x"]) and str(b["name"]) == "room"
    assert cache_path("thing", 1, 3).exists()
    c = cached("thing", 2, 3, build(2))
    assert calls == [1, 2] and np.array_equal(c["x"], np.arange(5) * 2)
    assert not cache_path("thing", 1, 3).exists() and cache_path("thing", 2, 3).exists()  # old version dropped
    cached("thing", 2, 4, build(2))
    assert cache_path("thing", 2, 3).exists()  # other seeds untouched
    cached("thing", 2, 3, build(2), refresh=True)
    assert calls == [1, 2, 2, 2]


def test_atomic_write(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path))
    dest = cache_path("atom", 1, 0)
    seen = []
    real_replace = os.replace

    def spy(src, dst):
        # at the moment of the rename: the destination does not exist, the temporary file is complete and
        # lies in the same folder (so the rename is atomic)
        seen.append((Path(dst).exists(), Path(src).parent == Path(dst).parent,
                     np.array_equal(np.load(src)["x"], np.arange(1000))))
        real_replace(src, dst)

    monkeypatch.setattr(cache_mod.os, "replace", spy)
    cached("atom", 1, 0, lambda: {"x": np.arange(1000)})
    assert seen == [(False, True, True)] and dest.exists()
    assert [p.name for p in dest.parent.iterdir()] == [dest.name]


def test_failed_write_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path))

    def broken_savez(fh, **arrays):
        fh.write(b"PK\x03\x04 half a file")
        raise OSError("disk full")

    monkeypatch.setattr(cache_mod.np, "savez", broken_savez)
    with pytest.raises(OSError, match="disk full"):
        cached("broken", 1, 0, lambda: {"x": np.zeros(3)})
    assert not any(p.is_file() for p in tmp_path.rglob("*"))  # no partial or temporary file


def test_corrupt_entry_rebuilt(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path))
    p = cache_path("c", 1, 0)
    p.parent.mkdir(parents=True)
    p.write_bytes(b"garbage")
    out = cached("c", 1, 0, lambda: {"x": np.ones(2)})
    assert np.array_equal(out["x"], np.ones(2)) and np.load(p)["x"].shape == (2,)


def test_mesh_entry(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path))
    box = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
    m = cached("mesh", 1, 0, lambda: box, mesh=True)
    assert cache_path("mesh", 1, 0, ".ply").exists()
    assert np.array_equal(m.faces, box.faces) and np.allclose(m.vertices, box.vertices, atol=1e-6)
    with pytest.raises(ValueError, match="trimesh"):
        cached("mesh2", 1, 0, lambda: {"x": np.zeros(1)}, mesh=True)


def test_bad_keys(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path))
    with pytest.raises(ValueError, match="name"):
        cached("../escape", 1, 0, lambda: {})
    with pytest.raises(ValueError, match="dict of numpy arrays"):
        cached("x", 1, 0, lambda: [1, 2])


def test_code_version_follows_the_generators_source(tmp_path, monkeypatch):
    """An entry keyed by `code_version` is rebuilt when the generator's source changes (a package: any of its
    files; a module: its file), and served while it does not; the room cloud is keyed so."""
    import importlib
    import sys

    from volsmpl.scene import cache as cache_mod2
    from volsmpl.scene import rooms

    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path / "cache"))
    pkg = tmp_path / "src" / "gen_pkg_for_test"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "shapes.py").write_text("SIZE = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path / "src"))
    importlib.invalidate_caches()
    sys.modules.pop("gen_pkg_for_test", None)
    calls = []
    build = lambda: calls.append(1) or {"x": np.arange(3)}  # noqa: E731
    v1 = cache_mod2.code_version(4, "gen_pkg_for_test")
    assert v1.startswith("4.") and v1 == cache_mod2.code_version(4, "gen_pkg_for_test")
    cached("gen", v1, 0, build)
    cached("gen", v1, 0, build)
    assert len(calls) == 1
    (pkg / "shapes.py").write_text("SIZE = 2\n")        # the generator's code changes, its number does not
    cache_mod2.code_version.cache_clear()
    v2 = cache_mod2.code_version(4, "gen_pkg_for_test")
    assert v2 != v1
    cached("gen", v2, 0, build)
    assert len(calls) == 2 and not cache_path("gen", v1, 0).exists()
    cache_mod2.code_version.cache_clear()
    rooms.room_points(1, n=64, oversample=2)
    made = [p.name for p in (tmp_path / "cache" / "room_points_64_x2").iterdir()]
    assert made == [f"v{cache_mod2.code_version(rooms.ROOM_VERSION, 'volsmpl.scene')}-s1.npz"]
