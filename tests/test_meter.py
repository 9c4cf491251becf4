"""The resource meter (`volsmpl.meter`) against independent references: allocations of known size, call
counts, a worker's own return value and error text. Wall-clock values are never asserted."""
from __future__ import annotations

import os
import textwrap

import pytest
import torch

from volsmpl.meter import Meter, peak_memory, run_isolated, timed_ms

N_FLOATS = 50_000_000  # 200 MB of float32


def test_cpu_peak_sees_an_allocation_held_in_the_block():
    with Meter("cpu") as m:
        x = torch.ones(N_FLOATS)  # every page written
    nbytes = x.numel() * x.element_size()
    assert nbytes == 200_000_000
    assert m.peak_bytes >= 0.9 * nbytes, (m.peak_bytes, m.method)
    assert m.peak_total_bytes >= m.peak_bytes
    assert m.kind == "cpu peak RSS increase" and m.method
    assert m.seconds > 0
    d = m.as_dict()
    assert d["mem_bytes"] == m.peak_bytes and d["seconds"] == m.seconds
    assert set(d) == {"seconds", "mem_bytes", "mem_total_bytes", "mem_kind", "mem_method"}
    del x


def test_cpu_peak_ignores_memory_freed_before_the_block():
    x = torch.ones(N_FLOATS)
    del x
    small = []
    with Meter("cpu") as m:
        small.append(torch.ones(1000))
    assert m.peak_bytes < 50e6, (m.peak_bytes, m.method)


def test_peak_memory_of_one_call():
    held = []
    d = peak_memory(lambda: held.append(torch.ones(N_FLOATS)), "cpu")
    assert d["mem_bytes"] >= 0.9 * 200_000_000
    assert "seconds" not in d and d["mem_kind"] == "cpu peak RSS increase"
    held.clear()


def test_time_only_meter_measures_no_memory():
    with Meter("cpu", memory=False) as m:
        torch.ones(1000).sum()
    assert m.seconds > 0 and m.peak_bytes == 0 and m.kind == ""


def test_timed_ms_one_value_per_callable_in_order():
    calls = []
    fns = [lambda i=i: calls.append(i) for i in range(4)]
    out = timed_ms(fns, "cpu")
    assert calls == [0, 1, 2, 3]
    assert len(out) == 4 and all(isinstance(t, float) and t >= 0 for t in out)
    assert timed_ms([], "cpu") == []


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA GPU")
def test_cuda_meter_without_cuda_is_a_clear_error():
    with pytest.raises(ValueError, match="CUDA"):
        Meter("cuda")


@pytest.fixture
def probe_module(tmp_path, monkeypatch):
    """A worker module importable by the isolated process (through PYTHONPATH)."""
    (tmp_path / "meter_probe.py").write_text(textwrap.dedent("""
        import os

        def echo(job):
            return {"pid": os.getpid(), "job": job, "total": sum(job["values"])}

        def fail(job):
            raise ValueError("probe failed because " + job["why"])
    """))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")])))
    return "meter_probe"


def test_run_isolated_returns_the_workers_dict(probe_module):
    job = {"values": [1, 2, 3.5], "name": "x", "nested": {"a": [True, None]}}
    res = run_isolated(f"{probe_module}:echo", job)
    assert res["job"] == job and res["total"] == 6.5
    assert res["pid"] != os.getpid()  # ran in another process


def test_run_isolated_reports_the_workers_error(probe_module):
    with pytest.raises(RuntimeError, match="probe failed because the disk is full"):
        run_isolated(f"{probe_module}:fail", {"why": "the disk is full"})
    with pytest.raises(ValueError, match="module:function"):
        run_isolated(probe_module, {})
