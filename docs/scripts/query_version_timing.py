"""Per-body time of the sparse query of one code version, for before/after comparisons run alternately.

    tools/export_snapshot.sh /tmp/old OLD_COMMIT && tools/export_snapshot.sh /tmp/new NEW_COMMIT
    for r in 1 2; do for v in old new; do for B in 1 8; do
        PYTHONPATH=/tmp/$v python docs/scripts/query_version_timing.py --label $v --batch $B; done; done; done

Poses `--frames` bench frames (`volsmpl.bench.jobs.make_frames`: 60k points per body, half uniform in the body box,
half near the surface), then times `t` (a fresh encoding of each frame's pose and the query, `--rounds` passes over
the frames) and `t query` (15 queries on one cached encoding), medians per body, in this process: the machine's
drift over minutes falls on both versions alike when they alternate (docs/history/readme.md, "Lean query, second pass").
"""
import argparse
import statistics

import torch

import volsmpl
from volsmpl.bench.jobs import make_frames
from volsmpl.runtime.meter import timed_ms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--label", default="this")
    ap.add_argument("--batch", type=int, default=1)
    ap.add_argument("--points", type=int, default=60000)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    body = volsmpl.create_body()
    vol = volsmpl.attach_volume(body)
    fr = make_frames(body, a.batch, a.points, a.frames, 0)
    with torch.no_grad():
        outs = [body(body_pose=fr["body_pose"][f]) for f in range(a.frames)]

        def full(f):
            return vol.query_encoded(vol.encode(outs[f], fresh=True), fr["points"][f])

        for f in range(min(2, a.frames)):
            full(f)
        t_full = timed_ms([lambda f=f: full(f) for _ in range(a.rounds) for f in range(a.frames)], "cpu")
        enc = vol.encode(outs[0], fresh=True)
        query = lambda: vol.query_encoded(enc, fr["points"][0])
        t_query = timed_ms([query] * 17, "cpu")[2:]                   # 2 warm-up calls
    print(f"{a.label} B={a.batch} t/body {statistics.median(t_full) / a.batch:.1f} ms  "
          f"t query/body {statistics.median(t_query) / a.batch:.1f} ms")


if __name__ == "__main__":
    main()
