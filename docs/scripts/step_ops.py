"""Operator calls of one self-intersection repair step, phase by phase (what a GPU pays in launches).

    python docs/scripts/step_ops.py [--case arms_crossed_deep] [--model volsmpl] [--boxes loop|scatter]

One step as apps/selfpen takes it (B = 1): body forward, part frames, overlap samples, the encoder of the parts
involved, their decoders, the loss and the backward pass, each counted under torch.profiler as top-level aten calls
(calls made inside another aten call are not counted). --boxes scatter counts the part boxes as a GPU computes them.
"""
import argparse
import collections

import torch
from torch.profiler import ProfilerActivity, profile

import volsmpl
from volsmpl.apps.selfpen.cases import load_cases
from volsmpl.bench.jobs import is_top_level_op
from volsmpl.volume.self_penetration import overlap_samples, reduce_selfpen


def count(fn):
    """(top-level aten calls of fn(), its result, the 8 most frequent names)."""
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        r = fn()
    top = [e.name for e in prof.events() if e.name.startswith("aten::") and is_top_level_op(e)]
    return len(top), r, collections.Counter(top).most_common(8)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="arms_crossed_deep")
    ap.add_argument("--model", default="volsmpl")
    ap.add_argument("--boxes", choices=["loop", "scatter"], default="loop")
    args = ap.parse_args()
    body = volsmpl.create_body()
    vol = volsmpl.attach_volume(body, model=args.model)
    c = load_cases(names=[args.case])[0]
    pose = c.body_pose[None].clone().requires_grad_()
    p = vol.partition
    total = 0

    def phase(name, fn):
        nonlocal total
        n, r, top = count(fn)
        total += n
        print(f"{name:16s} {n:5d}  {top}")
        return r

    out = phase("body forward", lambda: body(betas=c.betas[None], global_orient=c.global_orient[None], body_pose=pose))
    G = phase("part transforms", lambda: p.part_transforms(out.full_pose, out.joints))
    bmin, bmax = phase("part boxes", lambda: p.boxes(out.vertices, G, method=args.boxes))
    overl, samples, padded = phase("overlap samples", lambda: overlap_samples(
        G, bmin, bmax, p.collision_mask, 300, torch.Generator().manual_seed(0)))
    if padded is None:
        raise SystemExit(f"case {args.case}: no overlapping part boxes, nothing to repair")
    need = overl.any(dim=0).any(dim=0)
    parts = None if need.all() else need.nonzero()[:, 0]
    enc = phase("encoder", lambda: vol._encode(out, None, parts=parts, frames=(G, bmin, bmax)))
    part, _ = phase("decoders", lambda: vol._part_values(enc, padded, False))
    loss = phase("loss", lambda: reduce_selfpen(part, vol.occupied(part), p.collision_mask, samples,
                                                vol.selfpen_penalty(0.01), False))
    phase("backward", lambda: loss.sum().backward())
    print(f"{'total':16s} {total:5d}  ({len(parts) if parts is not None else p.num_parts} parts encoded)")


if __name__ == "__main__":
    main()
