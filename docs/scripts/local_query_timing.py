"""Time of one hand-object optimisation step with lazy part encoding vs every part encoded.

    python docs/scripts/local_query_timing.py [--threads 1] [--points 2000] [--repeats 5]

Step: pose the default body (gradient on body_pose), `collision_loss` of object points around the right hand,
backward. "all parts" encodes the output first (`volume.encode(out)`, the full encoding), "lazy" lets the query
encode only the parts whose boxes hold a point. Median over repeats, both shipped checkpoints.
"""
import argparse
import statistics
import time

import torch

import volsmpl
from volsmpl.evaluation.validation_set import validation_bodies


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--points", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    params = {k: v[[1]] for k, v in validation_bodies(2).items()}  # validation body 1: a T-pose
    for model in ("volsmpl", "coap"):
        body = volsmpl.create_body()
        vol = volsmpl.attach_volume(body, model=model).eval()
        hand = torch.nonzero(vol.partition.vertex_labels == vol.partition.table.part_names.index("right_hand"))[:, 0]
        g = torch.Generator().manual_seed(0)
        with torch.no_grad():
            v0 = body(**params).vertices
        pts = v0[:, hand][:, torch.randint(0, len(hand), (a.points,), generator=g)]
        pts = pts + 0.03 * torch.randn(pts.shape, generator=g)
        ms, parts = {}, {}
        for full in (True, False, True, False):  # interleaved, second round kept
            times = []
            for _ in range(a.repeats):
                pose = params["body_pose"].clone().requires_grad_()
                t = time.perf_counter()
                out = body(**{**params, "body_pose": pose})
                if full:
                    vol.encode(out)
                vol.collision_loss(out, pts).backward()
                times.append(time.perf_counter() - t)
            ms[full] = 1e3 * statistics.median(times)
            enc = out._volsmpl_encoding[1]
            parts[full] = vol.num_parts if enc.parts is None else len(enc.parts)
        print(f"{model}: all parts ({parts[True]}) {ms[True]:.1f} ms/step, lazy ({parts[False]} parts) "
              f"{ms[False]:.1f} ms/step, x{ms[True] / ms[False]:.2f}")


if __name__ == "__main__":
    main()
