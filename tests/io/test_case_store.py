"""Per-case records of long CLI jobs: reused only under the same key, written atomically."""
from __future__ import annotations

import json

import pytest
import torch

from volsmpl.io.case_store import CaseStore, job_key, source_digest


def test_records_are_reused_only_under_their_key(tmp_path):
    store = CaseStore(tmp_path / "cases")
    assert store.get("a", "k1") is None
    store.put("a", "k1", {"x": 1.5})
    assert store.get("a", "k1") == {"x": 1.5} and store.reused == 1
    assert store.get("a", "k2") is None and store.stale == 1
    assert CaseStore(tmp_path / "cases", resume=False).get("a", "k1") is None  # no --resume: recompute
    (tmp_path / "cases" / "a.json").write_text('{"key": "k1", "rec')  # cut short: recomputed, not trusted
    assert store.get("a", "k1") is None
    assert not [p for p in (tmp_path / "cases").iterdir() if ".tmp" in p.name]
    with pytest.raises(ValueError, match="case name"):
        store.put("../escape", "k1", {})


def test_key_changes_with_config_weights_and_code(tmp_path, monkeypatch):
    lin = torch.nn.Linear(2, 2)
    k0 = job_key({"iters": 100}, modules=[lin])
    assert job_key({"iters": 100}, modules=[lin]) == k0
    assert job_key({"iters": 101}, modules=[lin]) != k0
    with torch.no_grad():
        lin.weight[0, 0] += 1e-6
    assert job_key({"iters": 100}, modules=[lin]) != k0
    # the source digest covers the app's package: a changed file changes it
    pkg = tmp_path / "fakeapp"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("A = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    from volsmpl.io import case_store
    d0 = source_digest(["fakeapp"])
    (pkg / "__init__.py").write_text("A = 2\n")
    assert source_digest(["fakeapp"]) == d0  # the code this process runs: fixed at its first call
    case_store._source_digest.cache_clear()  # a new process
    assert source_digest(["fakeapp"]) != d0
    assert json.dumps(source_digest()).startswith('"sha256:')


def test_key_sees_every_element_of_large_arrays():
    """Arrays and tensors in a configuration are keyed by their bytes: str() abbreviates arrays of over 1,000
    elements ('...'), so two that differ only inside the abbreviation shared a key (a stale record reused); a value
    with no exact JSON form is refused in one line instead of keyed by its str()."""
    import numpy as np

    a = np.arange(5000, dtype=np.float64)
    b = a.copy()
    b[2500] += 1e-9
    assert str(a) == str(b)
    assert job_key({"x": a}) != job_key({"x": b})
    assert job_key({"x": torch.from_numpy(a)}) != job_key({"x": torch.from_numpy(b)})
    assert job_key({"x": a}) == job_key({"x": a.copy()})
    assert job_key({"x": np.float32(0.5), "n": np.int64(3)}) == job_key({"x": 0.5, "n": 3})
    with pytest.raises(TypeError, match="job_key: a configuration value of type object has no exact JSON form"):
        job_key({"x": object()})
