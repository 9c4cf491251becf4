"""Cached-query time of the lean path on the CPU with the decoder's two no-grad forms, alternating in one process.

    python docs/scripts/decoder_forms.py [--threads 1] [--points 60000] [--rounds 6] [--tiles 4096 2048]

Forms: 'rows T' (the default: each (body, part) group's rows through its own weights in tiles of T
rows, volsmpl.nn.group_rows) and 'batched' (`set_tile_rows(None)`: the pairs cut into padded chunks, one batched
matmul per layer over all of them, the GPU's form). The bench's inputs (`bench_jobs.make_frames`, the shipped
checkpoint), B = 1 and B = 8 (body 0 of the batch alone for B = 1); each round times every form once per batch
size, in an order that alternates between rounds, so that the machine's drift falls on all forms alike. Prints the
median milliseconds per body and the largest difference of each form's values from the first form's (float
rounding only).
"""
import argparse
import statistics
import time

import torch

from volsmpl.volume.attach import attach_volume
from volsmpl.bench.jobs import make_frames
from volsmpl.body.model import create_body


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--points", type=int, default=60000)
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--tiles", type=int, nargs="+", default=[4096, 2048])
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    body = create_body()
    vol = attach_volume(body, model="volsmpl")
    data = make_frames(body, 8, a.points, 1, 0)
    forms = {f"rows {t}": t for t in a.tiles} | {"batched": None}
    with torch.no_grad():
        pts = {8: data["points"][0], 1: data["points"][0][:1]}
        enc = {B: vol.encode(body(body_pose=data["body_pose"][0][:B]), fresh=True) for B in (1, 8)}
        ref, diff = {}, {}
        times = {(f, B): [] for f in forms for B in (1, 8)}
        for r in range(a.rounds):
            for f, t in (forms.items() if r % 2 == 0 else reversed(forms.items())):
                vol.net.set_tile_rows(t)
                for B in (1, 8):
                    v = vol.query_encoded(enc[B], pts[B])                    # warm, and the values
                    ref.setdefault(B, v)
                    diff[f, B] = max(diff.get((f, B), 0.0), float((v - ref[B]).abs().max()))
                    s = time.perf_counter()
                    vol.query_encoded(enc[B], pts[B])
                    times[f, B].append((time.perf_counter() - s) * 1e3 / B)
    for (f, B), ts in times.items():
        print(f"{f:>10}  B={B}  t query/body {statistics.median(ts):6.1f} ms  (rounds {min(ts):.1f}-{max(ts):.1f})  "
              f"max |value - first form's| {diff[f, B]:.1e} m")


if __name__ == "__main__":
    main()
