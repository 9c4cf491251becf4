"""`volsmpl eval`: the evaluation of a checkpoint (volsmpl.evaluation.run) from the command line, its checks and
its result files (the standard split, the self-contact split, or both)."""
from __future__ import annotations

import json
from typing import Optional

import torch

from volsmpl.geometry.groundtruth import SIGN_MODES
from volsmpl.evaluation.gt_cache import default_cache_dir
from volsmpl.volume.precision import PRECISIONS

from volsmpl.evaluation.config import SAMPLINGS, EvalConfig, EvalResult
from volsmpl.evaluation.run import evaluate_checkpoint, format_table

__all__ = ["add_parser", "run"]


# ---------------------------------------------------------------------------------------------- CLI
def add_parser(sub):
    d = EvalConfig()
    p = sub.add_parser("eval", help="evaluate a checkpoint on the validation set (paper Table 1 columns)",
                       description="IoU (surface / uniform points) and SDF MSE against exact mesh SDFs on a fixed "
                                   "validation set of extreme poses and unusual shapes; optional time and memory.")
    p.add_argument("--checkpoint", default=None, help="checkpoint path (with or without .safetensors); default: shipped one")
    p.add_argument("--random-init", action="store_true", help="evaluate a randomly initialised default network instead")
    p.add_argument("--n-bodies", type=int, default=d.n_bodies)
    p.add_argument("--points", type=int, default=d.n_points, help="query points per body (half near the surface)")
    p.add_argument("--seed", type=int, default=d.seed, help="validation seed (default VAL_SEED)")
    p.add_argument("--batch-size", type=int, default=d.batch_size)
    p.add_argument("--device", default=d.device, choices=["cpu", "cuda"])
    p.add_argument("--timing", action="store_true", help="also measure query time and memory (subprocess)")
    p.add_argument("--repeats", type=int, default=d.timing_repeats, help="timed runs (median reported)")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice); "
                   "1 gives stable CPU timings on a busy machine")
    p.add_argument("--gt-sign", default=d.gt_sign, choices=SIGN_MODES,
                   help="ground-truth sign: the winding number of the posed mesh (self-overlaps inside), counted along "
                        "rays (default, exact) or through libigl (exact, or its fast approximation), or ray parity "
                        "(calls self-overlaps outside); cached")
    p.add_argument("--cache-dir", default=None, help=f"ground-truth cache (default {default_cache_dir()})")
    p.add_argument("--no-cache", action="store_true", help="recompute the ground truth, do not write the cache")
    p.add_argument("--precision", default="full", choices=list(PRECISIONS),
                   help="decoder arithmetic: full (default), bf16 (bfloat16 layers) or tf32 (CUDA tensor cores); "
                        "reduced precision trades accuracy for speed on GPUs")
    p.add_argument("--sampling", default=d.sampling, choices=list(SAMPLINGS),
                   help="where the points lie: body (default: uniform in the body's padded bounding box + near the whole "
                        "surface) or parts (COAP's per-part sampling: as many points per part, in its padded box and "
                        "near its own faces; --points a multiple of the part count)")
    p.add_argument("--surface-sigma", type=float, default=d.surface_sigma,
                   help=f"std of the near-surface points' offsets, metres (default {d.surface_sigma}); the surface "
                        "IoU depends strongly on it")
    p.add_argument("--encoder-draws", type=int, default=None,
                   help="encode each part as the mean code of this many fixed surface sample sets (default: the "
                        "checkpoint's own, 1 unless trained with more); more sets, steadier codes, slower encoding")
    p.add_argument("--refine-steps", type=int, default=0,
                   help="refine each body's part codes by this many optimiser steps on the posed mesh's own surface "
                        "before querying (volsmpl.volume.code_refinement; default 0: the encoder's codes); each step costs "
                        "about half an encoding")
    p.add_argument("--passes", type=int, default=None,
                   help="run only the first P of the checkpoint's learned code-refinement passes (0: the encoder's "
                        "codes; default: all it has; volsmpl.nn.code_refiner)")
    p.add_argument("--out", default=None, help="write the results as JSON here")
    p.add_argument("--split", default="all", choices=["standard", "self_contact", "all"],
                   help="validation split: the standard set, the self-contact poses (volsmpl.evaluation.contact_split: min(n-bodies, "
                        "16) bodies, same points and metrics; no timing) or both (default; JSON: the standard result "
                        "with the self-contact one under 'splits')")
    return p


def run(args) -> int:
    from volsmpl.io.outputs import check_writable
    if args.out:  # before the evaluation: a bad path fails in seconds, not after it
        check_writable(args.out, "file", "--out")
    if args.cache_dir is not None and not args.no_cache:  # written after the ground truth: checked before it
        check_writable(args.cache_dir, "dir", "--cache-dir")
    if args.timing and args.split == "self_contact":
        raise ValueError("--timing measures validation body 0 of the standard split, which --split self_contact does "
                         "not run: use --split standard or all with --timing.")
    if args.checkpoint is not None and args.random_init:
        raise ValueError("--checkpoint and --random-init exclude each other; give one.")
    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads {args.threads}: give a positive number of CPU threads.")
        torch.set_num_threads(args.threads)
    cfg = EvalConfig(n_bodies=args.n_bodies, n_points=args.points, seed=args.seed, batch_size=args.batch_size,
                     device=args.device, timing=args.timing, timing_repeats=args.repeats, cache_dir=args.cache_dir,
                     use_cache=not args.no_cache, timing_threads=args.threads, gt_sign=args.gt_sign,
                     precision=args.precision, sampling=args.sampling, surface_sigma=args.surface_sigma,
                     encoder_draws=args.encoder_draws, refine_steps=args.refine_steps, passes=args.passes)
    init = {"config": {}, "init_seed": 0} if args.random_init else None
    if args.split == "self_contact":
        from volsmpl.evaluation.contact_split import evaluate_self_contact
        return _write_split(args, evaluate_self_contact(args.checkpoint, cfg, init))
    res = evaluate_checkpoint(args.checkpoint, config=cfg, random_init=init)
    print(f"validation set: {cfg.n_bodies} bodies (seed {cfg.seed}, digest {res.validation_digest[:12]}), "
          f"{cfg.n_points} points each ({cfg.sampling} sampling, sigma {cfg.surface_sigma:g} m); ground truth {res.seconds['ground_truth']:.1f} s, "
          f"model {res.seconds['predict']:.1f} s")
    print(format_table(res))
    if res.resources:
        print(f"time: batch 1 x {res.resources['points']} points on {res.resources['device']} "
              f"({res.resources['threads']} threads), median of {cfg.timing_repeats}; t = encoding + query, "
              f"t query = query only; mem = {res.resources['mem_kind']}")
    if args.split == "all":
        from volsmpl.evaluation.contact_split import evaluate_self_contact
        return _write_split(args, res, evaluate_self_contact(args.checkpoint, cfg, init))
    return _write_split(args, res)


def _write_split(args, res: EvalResult, contact: Optional[EvalResult] = None) -> int:
    """Print the self-contact table (when `contact`, or when `res` is it) and write --out: `res` with `contact`
    under 'splits'."""
    from volsmpl.io.outputs import write_atomic
    for r in [x for x in (res, contact) if x is not None and x.extra.get("split") == "self_contact"]:
        poses = dict.fromkeys(x.split(":")[-1].split("/")[0].rstrip("~") for x in r.per_body["label"])
        print(f"self-contact split: {r.config['n_bodies']} bodies (seed {r.config['seed']}; {', '.join(poses)})")
        print(format_table(r))
    if args.out:
        d = res.to_dict()
        if contact is not None:
            d["splits"] = {"self_contact": contact.to_dict()}
        write_atomic(args.out, json.dumps(d, indent=1))
        print(f"wrote {args.out}")
    return 0
