"""Resource meter: wall time with device synchronisation and peak memory on CPU and CUDA, optionally in
a fresh subprocess. Used by `volsmpl eval`, `volsmpl bench`, the optimisation harness and every app.

    with Meter("cpu") as m:
        loss = body.volume.query(out, points)
    m.seconds, m.peak_bytes, m.kind        # 0.05, 12_345_678, 'cpu peak RSS increase'

Memory is the peak above what was in use when the block started: on CUDA the caching allocator's
`max_memory_allocated`; on the CPU the process's resident set size: exactly, from the kernel's peak-RSS mark
(VmHWM), reset at the start of the block (Linux /proc/self/clear_refs), with no thread beside the block; where
that reset is unavailable, from `ru_maxrss` when the block set a new high-water mark of the process (exact),
else from a thread polling /proc/self/statm every 0.2 ms (torch releases the GIL inside operators; a spike
shorter than the interval can be missed; the polling thread also slows Python-heavy blocks, by up to 1.5x on
the 2-core project machine, so time such blocks with memory=False). Without /proc (macOS) only the rise of
`ru_maxrss` during the block is known: a lower bound of its peak above the start, 0 where the block stayed
below an earlier peak of the process; `method` says so. Freed heap is returned to the OS before
the block (glibc `malloc_trim`), so the block's own pages count. Meters may nest: an inner meter's reset of a
peak mark first hands the peak so far to the meters around it.

`run_isolated("volsmpl.bench.jobs:volume_job", job)` runs a worker function in a fresh Python process (its
memory then starts from a clean process) and returns the JSON object it printed last.
"""
from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import threading
import time

import torch

__all__ = ["Meter", "RssSampler", "sync", "rss_bytes", "maxrss_bytes", "hwm_bytes", "reset_peak_rss", "malloc_trim",
           "peak_memory", "timed_ms", "run_isolated"]


def sync(device) -> None:
    """Wait for the device's queued work (CUDA); a no-op on the CPU."""
    device = torch.device(device)
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def rss_bytes() -> int:
    """This process's resident set size in bytes (-1 where /proc is unavailable)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        return -1


def maxrss_bytes() -> int:
    """This process's high-water mark of the resident set size in bytes."""
    import resource
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(r) if sys.platform == "darwin" else int(r) * 1024  # Linux reports KiB


def hwm_bytes() -> int:
    """This process's peak resident set size since start or the last `reset_peak_rss()`, in bytes (VmHWM; -1
    where /proc is unavailable)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return -1


def reset_peak_rss() -> bool:
    """Reset the kernel's peak-RSS mark (VmHWM) to the current RSS (Linux >= 4.0); False where that is unavailable."""
    if hwm_bytes() < 0:
        return False
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


_ACTIVE: list = []  # meters whose block is running (outermost first): see Meter._hand_peak_to_outer


def malloc_trim() -> None:
    """Return freed heap memory to the OS (glibc); a no-op elsewhere (RSS may then include reusable memory)."""
    try:
        import ctypes
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


class RssSampler:
    """Context manager polling this process's RSS in a thread every `interval` seconds; `.peak` in bytes."""

    def __init__(self, interval: float = 2e-4):
        self.interval, self.peak = interval, rss_bytes()

    def __enter__(self):
        self._stop = threading.Event()

        def poll():
            while not self._stop.is_set():
                self.peak = max(self.peak, rss_bytes())
                self._stop.wait(self.interval)
        self._thread = threading.Thread(target=poll, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, rss_bytes())
        return False


class Meter:
    """Time and peak memory of a block (module docstring).

    Args:
        device: where the block runs ('cpu', 'cuda', 'cuda:1', torch.device).
        memory: measure memory (False: time only, no sampling thread).
    After the block: seconds, peak_bytes (above the start), peak_total_bytes, kind, method; `as_dict()`.
    Example:
        >>> with Meter("cpu") as m:
        ...     _ = torch.ones(1000, 1000).sum()
        >>> m.seconds > 0
        True
    """

    def __init__(self, device="cpu", memory: bool = True):
        self.device = torch.device(device)
        if self.device.type == "cuda" and not torch.cuda.is_available():
            raise ValueError(f"cannot measure on {self.device}: torch sees no CUDA GPU; use device 'cpu'")
        self.memory = memory
        self.seconds, self.peak_bytes, self.peak_total_bytes, self.kind, self.method = 0.0, 0, 0, "", ""

    def _peak_now(self) -> int:
        """The peak of this meter's block so far, in bytes in use (CUDA: allocated; CPU exact mode: RSS)."""
        if self.device.type == "cuda":
            return max(self._seen, torch.cuda.max_memory_allocated(self.device))
        return max(self._seen, hwm_bytes())

    def _hand_peak_to_outer(self) -> None:
        """Before this meter resets a peak mark, the meters around it keep the peak reached so far."""
        for m in _ACTIVE:
            if m._mode == self._mode:  # (another CUDA device's meter just reads its own peak)
                m._seen = m._peak_now()

    def __enter__(self):
        self._mode = None
        if self.memory:
            if self.device.type == "cuda":
                self._mode = "cuda"
                sync(self.device)
                self._hand_peak_to_outer()
                torch.cuda.reset_peak_memory_stats(self.device)
                self._base = self._seen = torch.cuda.memory_allocated(self.device)
            elif rss_bytes() < 0:  # no /proc: the rise of the process's high-water mark is all there is
                self._mode = "maxrss"
                self._hw0 = self._base = maxrss_bytes()
            else:
                malloc_trim()
                self._mode = "hwm"
                self._hand_peak_to_outer()
                self._base = rss_bytes()
                if reset_peak_rss():
                    self._seen = self._base
                else:
                    self._mode = "sampled"
                    self._hw0 = maxrss_bytes()
                    self._sampler = RssSampler().__enter__()
            _ACTIVE.append(self)
        sync(self.device)
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        sync(self.device)
        self.seconds = time.perf_counter() - self._t0
        if not self.memory:
            return False
        _ACTIVE.remove(self)
        if self._mode == "cuda":
            peak = self._peak_now()
            self.peak_bytes, self.peak_total_bytes = int(peak - self._base), int(peak)
            self.kind = self.method = "cuda max_memory_allocated"
            return False
        self.kind = "cpu peak RSS increase"
        if self._mode == "hwm":
            peak = self._peak_now()
            self.peak_bytes, self.peak_total_bytes = int(max(0, peak - self._base)), int(peak)
            self.method = "VmHWM (peak RSS mark reset at the start)"
            return False
        if self._mode == "maxrss":
            hw1 = maxrss_bytes()
            self.peak_bytes, self.peak_total_bytes = int(max(0, hw1 - self._hw0)), int(hw1)
            self.method = ("ru_maxrss rise (no /proc here): a lower bound of the block's peak above its start, 0 "
                           "where the block stayed below an earlier peak of the process")
            return False
        self._sampler.__exit__(*exc)
        hw1 = maxrss_bytes()
        if hw1 > self._hw0:  # the block set a new high-water mark of the process: exact
            self.peak_bytes, self.peak_total_bytes, self.method = int(hw1 - self._base), int(hw1), "ru_maxrss"
        else:  # an earlier peak of the process was higher: the polled RSS
            peak = self._sampler.peak
            self.peak_bytes, self.peak_total_bytes = int(max(0, peak - self._base)), int(peak)
            self.method = f"RSS sampled every {self._sampler.interval * 1e3:g} ms"
        return False

    def as_dict(self) -> dict:
        """The measurement under the keys that result JSONs use."""
        return {"seconds": self.seconds, "mem_bytes": self.peak_bytes, "mem_total_bytes": self.peak_total_bytes,
                "mem_kind": self.kind, "mem_method": self.method}


def peak_memory(fn, device) -> dict:
    """Peak memory of one call of fn: Meter(device).as_dict() without the time."""
    with Meter(device) as m:
        fn()
    d = m.as_dict()
    d.pop("seconds")
    return d


def timed_ms(fns, device) -> list[float]:
    """Wall time in milliseconds of each call in fns, each synchronised on the device."""
    out = []
    for fn in fns:
        with Meter(device, memory=False) as m:
            fn()
        out.append(m.seconds * 1e3)
    return out


def run_isolated(target: str, job: dict, timeout_s: float = 3600) -> dict:
    """Run `target` ('package.module:function', called with the job dict) in a fresh Python process and
    return the JSON object it printed on its last line of standard output.

    The job travels as JSON (tensors: pass file paths). A failing worker raises RuntimeError with the end
    of its standard error."""
    if ":" not in target:
        raise ValueError(f"target must be 'module:function', got {target!r}")
    proc = subprocess.run([sys.executable, "-m", "volsmpl.runtime.meter", target, json.dumps(job)],
                          capture_output=True, text=True, timeout=timeout_s)
    if proc.returncode != 0:
        raise RuntimeError(f"the isolated worker {target} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    lines = proc.stdout.strip().splitlines()
    if not lines:
        raise RuntimeError(f"the isolated worker {target} printed nothing")
    return json.loads(lines[-1])


def _main(argv: list[str]) -> None:
    module, function = argv[0].split(":", 1)
    result = getattr(importlib.import_module(module), function)(json.loads(argv[1]))
    print(json.dumps(result))


if __name__ == "__main__":
    _main(sys.argv[1:])
