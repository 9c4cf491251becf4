"""`volsmpl egohmr`: scene-aware body recovery from egocentric views with collision-guided diffusion (paper
Table 4, supp. D.2).

    volsmpl egohmr make-data                                  # the generated frames (train / val / test), cached
    volsmpl egohmr train --out runs/egohmr [--steps 4000] [--resume]
    volsmpl egohmr tune --split val --out docs/egohmr/tune.json     # guidance scale per guide, on val
    volsmpl egohmr sample --guide none,volsmpl,coap,mesh --split test [--frames N] --out out/egohmr
    volsmpl egohmr sample --frame my_frame.json --scene scan.ply [--units mm] [--up z] --out out/mine   # userframe.py

Writes OUT/results.json (config, options, summary.<guide>, the paper's Table 4, per-frame records, the measured
largest batch per guide, machine meta) and OUT/frame_<name>.png for the first --render frames.
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import torch

ACTIONS = ("sample", "make-data", "train", "tune")
GUIDES = ("none", "volsmpl", "coap", "mesh")
PAPER_SCALE = {"volsmpl": 30.0, "coap": 0.4, "mesh": 30.0}
TUNE_FACTORS = (0.1, 0.3, 1.0, 3.0, 10.0)


def add_parser(sub):
    from .train import TrainSettings

    d = TrainSettings()
    p = sub.add_parser("egohmr", help="egocentric body recovery with collision-guided diffusion (Table 4)",
                       description="Sample body poses from a keypoint- and scene-conditioned diffusion model, guided "
                                   "away from the scene by VolumetricSMPL, COAP or the exact mesh (supp. D.2).")
    p.add_argument("action", nargs="?", default="sample", choices=ACTIONS)
    p.add_argument("--guide", default="none,volsmpl,coap,mesh", help=f"comma-separated guides ({', '.join(GUIDES)})")
    p.add_argument("--split", default="test", choices=["train", "val", "test"])
    p.add_argument("--frames", type=int, default=None, help="the first N frames of the split (default: all)")
    p.add_argument("--out", default=None, help="output folder (sample: out/egohmr; train: runs/egohmr) or file (tune)")
    p.add_argument("--checkpoint", default=None, help="egohmr checkpoint (default: the shipped one)")
    p.add_argument("--scale", action="append", default=[], metavar="GUIDE=A",
                   help="guidance scale a of a guide (repeatable); default: --tuned's, else the paper's "
                        f"({', '.join(f'{k} {v:g}' for k, v in PAPER_SCALE.items())})")
    p.add_argument("--tuned", default=None, help="a `tune` result whose best scales to use")
    p.add_argument("--factors", default=",".join(f"{f:g}" for f in TUNE_FACTORS),
                   help="tune: the scales tried, as factors of the paper's (comma-separated)")
    p.add_argument("--guide-steps", type=int, default=10, help="guided last steps (paper 10; authors' code 11)")
    p.add_argument("--plain-steps", type=int, default=5, help="last steps without Sigma_t (paper 5)")
    p.add_argument("--plain-factor", type=float, default=1.0, help="their step a*F*grad (paper F=1; code 0.01)")
    p.add_argument("--wrt", default="denoised", choices=["denoised", "noisy"], help="pose J is evaluated at")
    p.add_argument("--joints", default="all", choices=["all", "legs"], help="joints the gradient moves")
    p.add_argument("--reduce", default="mean", choices=["mean", "code"], help="J's reduction (see guidance.py)")
    p.add_argument("--encoder-bf16", action="store_true",
                   help="sample/tune: run the learned guides' part encoder (most of a guided step's cost) under "
                        "bfloat16 autocast, both kinds alike: ~1.5x faster per frame on a CPU with AVX512-BF16 or AMX "
                        "(emulated, not timed, on one without), codes rounded (README, apps/egohmr); default float32")
    p.add_argument("--batch", type=int, default=16, help="frames sampled together")
    p.add_argument("--budget-mb", type=float, default=2048.0, help="memory budget of the measured largest batch")
    p.add_argument("--no-max-batch", action="store_true", help="skip measuring the largest batch")
    p.add_argument("--render", type=int, default=4, help="figures for the first N frames")
    p.add_argument("--seed", type=int, default=0, help="data and sampling seed")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    p.add_argument("--frame", default=None, help="sample: a user's frame file (JSON, apps/egohmr/userframe.py)")
    p.add_argument("--scene", default=None, help="with --frame: the scene (mesh or point cloud file)")
    p.add_argument("--units", default="m", choices=["m", "cm", "mm"], help="--scene's units")
    p.add_argument("--up", default="y", choices=["y", "z"],
                   help="--scene's up axis: a z-up scan is turned Y-up before the frame's world_to_camera applies")
    p.add_argument("--steps", type=int, default=d.steps, help="train: optimisation steps")
    p.add_argument("--resume", action="store_true", help="train: continue OUT's run")
    return p


def parse_guides(text: str) -> list[str]:
    names = list(dict.fromkeys(g.strip() for g in str(text).split(",") if g.strip()))
    bad = [g for g in names if g not in GUIDES]
    if bad or not names:
        raise ValueError(f"unknown guide(s) {bad or text!r}; --guide takes a comma-separated list of {', '.join(GUIDES)}")
    return names


def scales_of(args, guides: list[str]) -> dict:
    """Guide -> scale: --scale over --tuned over the paper's."""
    out = {g: PAPER_SCALE.get(g, 0.0) for g in guides}
    if args.tuned:
        best = json.loads(Path(args.tuned).read_text()).get("best", {})
        out.update({g: float(best[g]) for g in guides if g in best})
    for item in args.scale:
        g, _, v = item.partition("=")
        if g not in GUIDES or g == "none" or not v:
            raise ValueError(f"--scale {item!r}: write GUIDE=A with GUIDE one of volsmpl, coap, mesh")
        try:
            out[g] = float(v)
        except ValueError:
            raise ValueError(f"--scale {item!r}: {v!r} is not a number") from None
    out["none"] = 0.0
    return {g: out[g] for g in guides}


def options_of(args, scale: float):
    from .evaluate import GuideOptions

    if not 0 <= args.plain_steps <= args.guide_steps:
        raise ValueError(f"--plain-steps {args.plain_steps} must lie in 0..--guide-steps ({args.guide_steps})")
    return GuideOptions(scale=scale, steps=args.guide_steps, plain_steps=args.plain_steps,
                        plain_factor=args.plain_factor, wrt=args.wrt, joints=args.joints, reduce=args.reduce)


def run(args) -> int:
    from volsmpl.runtime.devices import check_device

    check_device(args.device)
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.batch < 1:
        raise ValueError(f"--batch must be >= 1, got {args.batch}")
    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames must be >= 1, got {args.frames}")
    if args.encoder_bf16:
        from volsmpl.volume.models import model_kind

        if args.action not in ("sample", "tune"):
            raise ValueError(f"--encoder-bf16 sets the guides' encoder arithmetic: it applies to sample and tune, "
                             f"not {args.action}; drop it")
        if not any(g != "none" and model_kind(g).learned for g in parse_guides(args.guide)):
            raise ValueError(f"--encoder-bf16 sets the learned guides' encoder arithmetic, but --guide {args.guide} "
                             f"has none: add volsmpl or coap, or drop the flag")
    if args.action == "make-data":
        from .data import make_frames

        for split in ("train", "val", "test"):
            fr = make_frames(split, seed=args.seed)
            print(f"{split}: {len(fr)} frames in {len({f.room_seed for f in fr})} rooms")
        return 0
    if args.action == "train":
        from .train import TrainSettings, train

        s = TrainSettings(steps=args.steps, seed=args.seed, threads=args.threads, device=args.device)
        path = train(args.out or "runs/egohmr", s, resume=args.resume)
        print(f"wrote {path}.safetensors")
        return 0
    from .run import run_sample, run_tune, run_user_frame

    if args.action == "tune":
        return run_tune(args)
    return run_user_frame(args) if (args.frame or args.scene) else run_sample(args)


__all__ = ["add_parser", "run", "parse_guides", "scales_of", "options_of", "GUIDES", "PAPER_SCALE"]
