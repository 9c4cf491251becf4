"""Encoding time of a checkpoint by number of encoder draws (`Volume.set_encoder_draws`, docs/encoder_draws.md) and
of code refinement steps (`Volume.set_code_refinement`, docs/code_refinement.md).

    python docs/scripts/encoder_draws_timing.py [--checkpoint core/assets/volsmpl_anny] [--model volsmpl]
                                                 [--draws 1 4 8] [--refine 0] [--batch 1 8] [--repeats 7] [--threads 1]
                                                 [--device cpu|cuda]

Each row: the median wall time of `repeats` fresh encodings (frames, boxes, surface samples, PointNet, the part
codes, their refinement; `Volume.encode(out, fresh=True)`) of the first B validation bodies, after 2 untimed ones, under
torch.no_grad(). Run it on a quiet machine: times only compare within one run.
"""
import argparse
import json
import statistics

import torch

from volsmpl.volume.attach import attach_volume
from volsmpl.body.model import create_body
from volsmpl.runtime.meter import timed_ms
from volsmpl.evaluation.validation_set import VAL_SEED, validation_bodies


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--checkpoint", default=None, help="checkpoint (default: the shipped one of --model)")
    p.add_argument("--model", default="volsmpl", choices=["volsmpl", "coap"])
    p.add_argument("--draws", type=int, nargs="+", default=[1, 4, 8])
    p.add_argument("--refine", type=int, nargs="+", default=[0], help="code refinement steps")
    p.add_argument("--batch", type=int, nargs="+", default=[1, 8])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    body = create_body()
    vol = attach_volume(body, checkpoint=args.checkpoint, model=args.model)
    body, vol = body.to(args.device), vol.to(args.device)
    rows = {}
    for B in args.batch:
        bodies = {k: v[:B].to(args.device) for k, v in validation_bodies(B, VAL_SEED, num_betas=body.num_betas).items()}
        with torch.no_grad():
            out = body(**bodies)
            for D in args.draws:
                vol.set_encoder_draws(D)
                for R in args.refine:
                    vol.set_code_refinement(R)
                    encode = lambda: vol.encode(out, fresh=True)
                    timed_ms([encode] * 2, out.vertices.device)                  # untimed warm-up
                    times = timed_ms([encode] * args.repeats, out.vertices.device)
                    name = f"B{B}_D{D}" + (f"_R{R}" if R else "")
                    rows[name] = round(statistics.median(times), 1)
                    print(f"B = {B}, D = {D}, R = {R}: {rows[name]} ms", flush=True)
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
