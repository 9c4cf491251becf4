"""`volsmpl bench`: time, memory and accuracy of the volume kinds (paper Tables 1, 2 and C.4), each measurement in
a fresh process; the batch-scaling probe and the reports beside the paper's figures."""
from volsmpl.bench.run import BenchConfig, run_bench

__all__ = ["BenchConfig", "run_bench"]
