"""Where and how code runs: devices checked before the work, heavy optional packages imported on first use with
one error naming the fix, and the resource meter (time with device synchronisation, peak memory, isolated runs)."""
from volsmpl.runtime.deps import MissingDependency
from volsmpl.runtime.devices import check_device
from volsmpl.runtime.meter import Meter, peak_memory, run_isolated, timed_ms

__all__ = ["Meter", "MissingDependency", "check_device", "peak_memory", "run_isolated", "timed_ms"]
