"""What the learned code refinement costs (docs/learned_refinement.md): the volume's share of an optimisation step.

    python docs/scripts/refiner_cost.py --checkpoint A [B ...] [--batch 1 8] [--points 2000] [--repeats 9] [--threads 1]
        [--refine-steps 0 1]

For each checkpoint and batch size B, the median wall time (ms) of `repeats` runs, after 2 untimed ones, of:
- encode: a fresh encoding of B validation bodies under torch.no_grad() (`Volume.encode(out, fresh=True)`);
- step: what an app's optimisation step asks of the volume: pose B bodies from body poses that require gradients
  (LBS), encode them, query `points` points per body near its surface (`validation.query_points`, half uniform in the
  body's box), sum the ReLU of the negated distances (a collision term) and back-propagate to the poses.
A body output is new at every run, as in an optimisation. `--refine-steps R ...` times each also with R steps of
test-time code refinement per encoding (`Volume.set_code_refinement`): R = 1 costs what one warm-started refinement
step per optimisation step costs (docs/code_refinement.md). Run it on a quiet machine: times compare within one run.
"""
import argparse
import json
import statistics
import sys
import time

import torch
from volsmpl.body.model import create_body
from volsmpl.evaluation.validation_set import query_points, validation_bodies
from volsmpl.io.provenance import machine_info
from volsmpl.volume.attach import attach_volume


def median_ms(fn, repeats: int) -> float:
    for _ in range(2):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1000)
    return statistics.median(times)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--checkpoint", nargs="+", required=True)
    p.add_argument("--batch", type=int, nargs="+", default=[1, 8])
    p.add_argument("--points", type=int, default=2000)
    p.add_argument("--repeats", type=int, default=9)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--refine-steps", type=int, nargs="+", default=[0])
    p.add_argument("--out", default=None)
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    rows = []
    for ck in args.checkpoint:
        body = create_body()
        vol = attach_volume(body, checkpoint=ck)
        for B, R in [(B, R) for B in args.batch for R in args.refine_steps]:
            vol.set_code_refinement(R)
            params = {k: v[:B] for k, v in validation_bodies(B).items()}
            with torch.no_grad():
                out = body(**params)
            pts, _ = query_points(out.vertices, body.faces, args.points, seed=3)

            def encode():
                with torch.no_grad():
                    vol.encode(out, fresh=True)

            def step():
                pose = params["body_pose"].clone().requires_grad_(True)
                o = body(**{**params, "body_pose": pose})
                torch.relu(-vol.query(o, pts)).sum().backward()

            rows.append({"checkpoint": ck, "B": B, "refiner_iters": vol.net.config.refiner_iters, "refine_steps": R,
                         "encode_ms": round(median_ms(encode, args.repeats), 1),
                         "step_ms": round(median_ms(step, args.repeats), 1)})
            print(json.dumps(rows[-1]), flush=True)
    if args.out:
        with open(args.out, "w") as fh:
            json.dump({"command": "python docs/scripts/refiner_cost.py " + " ".join(sys.argv[1:]),
                       "threads": args.threads, "points": args.points, "repeats": args.repeats, "rows": rows,
                       "meta": machine_info("cpu", args.threads)}, fh, indent=1)


if __name__ == "__main__":
    main()
