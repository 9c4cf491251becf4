"""Cached-query time of the lean path on the CPU for several decoder cache tiles (`NBWDecoder.TILE_ROWS`).

    python docs/scripts/tile_rows_sweep.py [--threads 1] [--batch 1 8] [--points 60000] [--rounds 5]

The tile size of the padded batched form (8,192 rows) was chosen on the project's first machine (AMD EPYC); the CPU's no-grad decoder runs each group's rows in tiles of 4,096 (volsmpl.nn.group_rows: 2,048-8,192
timed within noise of each other on the Intel Xeon); the decoder's share of the matmul rate differs by machine. Every setting is timed in turn, round after round, in one process on the
benchmark's inputs (`bench_jobs.make_frames`, the shipped checkpoint), so a busy machine slows all of them alike;
reports the median milliseconds per body for each (batch, tile rows) and the operator calls of one query. Values are
checked equal across settings (the tiles only reorder work).
"""
import argparse
import statistics
import time

import torch

import volsmpl
from volsmpl.bench.jobs import make_frames, profile_query


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 8])
    ap.add_argument("--points", type=int, default=60000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--tiles", type=int, nargs="+", default=[2048, 4096, 8192, 16384, 32768, 1 << 40])
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    body = volsmpl.create_body()
    vol = volsmpl.attach_volume(body)
    decoder = vol.net.decoder
    for B in args.batch:
        data = make_frames(body, B, args.points, 1, seed=0)
        with torch.no_grad():
            out = body(body_pose=data["body_pose"][0])
            pts = data["points"][0]
            enc = vol.encode(out, fresh=True)
            times = {t: [] for t in args.tiles}
            ref = None
            for r in range(args.rounds + 1):
                for t in args.tiles:
                    decoder.TILE_ROWS = t
                    t0 = time.perf_counter()
                    v = vol.query_encoded(enc, pts)
                    dt = (time.perf_counter() - t0) * 1e3 / B
                    if r:  # round 0 warms up
                        times[t].append(dt)
                    ref = v if ref is None else ref
                    assert torch.allclose(v, ref, atol=1e-5), f"tile rows {t}: values differ"
            for t in args.tiles:
                decoder.TILE_ROWS = t
                ops = profile_query(lambda: vol.query_encoded(enc, pts), 1)["ops_per_query"]
                name = "untiled" if t >= 1 << 40 else str(t)
                print(f"B={B:2d} tile rows {name:>8}: {statistics.median(times[t]):7.1f} ms per body "
                      f"(min {min(times[t]):.1f}), {ops} operator calls")


if __name__ == "__main__":
    main()
