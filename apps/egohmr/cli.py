"""`volsmpl egohmr`: scene-aware body recovery from egocentric views with collision-guided diffusion (paper
Table 4, supp. D.2).

    volsmpl egohmr make-data                                  # the generated frames (train / val / test), cached
    volsmpl egohmr train --out runs/egohmr [--steps 4000] [--resume]
    volsmpl egohmr tune --split val --out docs/egohmr                # guidance scale per guide, on val: tune.json
    volsmpl egohmr sample --model none,volsmpl,coap,mesh --split test [--frames N] --out out/egohmr
    volsmpl egohmr sample --frame my_frame.json --scene scan.ply [--units mm] [--up z] [--spacing M] --out out/mine
                                                              # a user's frame: user_run.py (example: examples/egohmr/)

Writes OUT/results.json (volsmpl.apps.table's envelope: config, summary.<guide>, the paper's Table 4, per-frame
records per guide, figures, meta; then the regressor's row and the measured largest batch per guide) and
OUT/frame_<name>.png for the first --render frames. Each per-frame record holds its `status` (ok, diverged,
past_joint_limits, penetrating, far_from_keypoints: status.py) and `status_why`; results.json's `flagged` lists the
others and `warnings` what a user's frame or scene made the run warn about. Each record holds the recovered `body`
(bodies.py; on a split: compact, camera frame) and its `mesh` file under OUT/meshes/ (a user's frame: always, in
the scene file's units and axes; a split: with --save-meshes). A bar per batch and per denoising step shows on a
terminal (--quiet: none).

A user's scene may be a scan of any size: only its part in the 2 m cube around the estimated pelvis is sampled, at
one point per --spacing metres (user_scene.py).

Every option is checked against the mode before any work (options.check_options): an option the mode does not read
is refused, e.g. --split with `sample --frame`, --steps outside train, --factors outside tune; a user's frame and
scene are checked for plausibility before the network loads (user_checks.py). sample, tune and a user's frame hold
OUT for their run (volsmpl.apps.checks.claim_out).
"""
from __future__ import annotations

from volsmpl.apps.table import add_common, check_common

from .options import (ALONG, GUIDES, MAX_PELVIS_STEP, PAPER_SCALE, PELVIS_STEP, SUPPORT, SUPPORT_DEFAULT,
                      TUNE_FACTORS, options_of, parse_guides, scales_of)

#: --out of each action when none is given
DEFAULT_OUT = {"sample": "out/egohmr", "user": "out/egohmr_user", "tune": "out/egohmr", "train": "runs/egohmr",
               "make-data": None}

ACTIONS = ("sample", "make-data", "train", "tune")


def add_parser(sub):
    from .evaluate import GUIDE_POINTS
    from .train import TrainSettings
    from .user_scene import DEFAULT_SPACING, MAX_SPACING, MIN_SPACING

    d = TrainSettings()
    p = sub.add_parser("egohmr", help="egocentric body recovery with collision-guided diffusion (Table 4)",
                       description="Sample body poses from a keypoint- and scene-conditioned diffusion model, guided "
                                   "away from the scene by VolumetricSMPL, COAP or the exact mesh (supp. D.2).")
    p.add_argument("action", nargs="?", default="sample", choices=ACTIONS,
                   help="sample (default): every guide samples the frames; tune: the guidance scale per guide on the "
                        "val split (OUT/tune.json); make-data: the generated frames; train: the network")
    # the learned passes at every 4th guided step: 1.1-1.2x the encoder's cost per frame, the same MPJPE
    # (docs/learned_refinement.md, "Passes at an interval")
    add_common(p, out=None, model="none,volsmpl,coap,mesh", none=True, render=4, pass_every=4,
               seed="the seed of the frames and of the sampler's noise",
               resume="sample: reuse each guide's finished samples in OUT/cases/ made by the same code, settings, "
                      "frames and weights; train: continue OUT's run")
    p.add_argument("--split", default="test", choices=["train", "val", "test"],
                   help="sample / tune: the generated split (tune's default: val)")
    p.add_argument("--frames", type=int, default=None, help="sample / tune: the first N frames of the split "
                                                            "(default: all)")
    p.add_argument("--checkpoint", default=None, help="the egohmr network's checkpoint (default: the shipped one)")
    p.add_argument("--scale", action="append", default=[], metavar="GUIDE=A",
                   help="sample: guidance scale a >= 0 of a guide in --model (repeatable); default: --tuned's, "
                        f"else the paper's ({', '.join(f'{k} {v:g}' for k, v in PAPER_SCALE.items())})")
    p.add_argument("--tuned", default=None, help="sample: a `tune` result (tune.json) whose best scales to use; it "
                                                  "must hold one for each guide in --model without a --scale")
    p.add_argument("--factors", default=",".join(f"{f:g}" for f in TUNE_FACTORS),
                   help="tune: the scales tried, as factors of the paper's (comma-separated)")
    p.add_argument("--guide-steps", type=int, default=10, help="guided last steps (paper 10; authors' code 11)")
    p.add_argument("--plain-steps", type=int, default=5, help="last steps without Sigma_t (paper 5)")
    p.add_argument("--plain-factor", type=float, default=1.0, help="their step a*F*grad (paper F=1; code 0.01)")
    p.add_argument("--wrt", default="denoised", choices=["denoised", "noisy"], help="pose J is evaluated at")
    p.add_argument("--joints", default="all", choices=["all", "legs"], help="joints the gradient moves")
    p.add_argument("--reduce", default="mean", choices=["mean", "code"], help="J's reduction (see guidance.py)")
    p.add_argument("--pelvis-step", type=float, default=PELVIS_STEP, metavar="M",
                   help="metres each guided step moves the pelvis down J's gradient (guidance.py); 0: the regressed "
                        f"pelvis stays (paper); 0 to {MAX_PELVIS_STEP:g}")
    p.add_argument("--support", default=SUPPORT_DEFAULT, choices=list(SUPPORT),
                   help="on: each guided step puts the body's lowest resting point on the scene's support below it "
                        "(support.py); off: the paper")
    p.add_argument("--pelvis-along", default="ray", choices=list(ALONG),
                   help="the guidance moves the pelvis along its camera ray (ray: the keypoints fix its image "
                        "position, not its depth) or freely in 3D (free); see guidance.py")
    p.add_argument("--encoder-bf16", action="store_true",
                   help="sample/tune: run the learned guides' part encoder (most of a guided step's cost) under "
                        "bfloat16 autocast, both kinds alike: ~1.5x faster per frame on a CPU with AVX512-BF16 or AMX "
                        "(emulated, not timed, on one without), codes rounded (docs/history/readme.md); default float32")
    p.add_argument("--batch", type=int, default=16, help="sample / tune on a split: frames sampled together")
    p.add_argument("--budget-mb", type=float, default=2048.0,
                   help="sample on a split: memory budget (MB, > 0) of the measured largest batch")
    p.add_argument("--no-max-batch", action="store_true", help="sample on a split: skip measuring the largest batch")
    p.add_argument("--frame", default=None, help="sample: a user's frame file (JSON, apps/egohmr/userframe.py)")
    p.add_argument("--scene", default=None, help="with --frame: the scene (mesh or point cloud file)")
    p.add_argument("--units", default="m", choices=["m", "cm", "mm"], help="with --frame: --scene's units")
    p.add_argument("--up", default="y", choices=["y", "z"],
                   help="with --frame: --scene's up axis: a z-up scan is turned Y-up before the frame's "
                        "world_to_camera applies")
    p.add_argument("--spacing", type=float, default=None, metavar="M",
                   help="with --frame: metres between the scene points taken in the 2 m cube around the body (a "
                        "mesh's faces sampled by area, a cloud thinned), so a scan of any size works as one cropped "
                        f"to the room; default {DEFAULT_SPACING:.4f} (a floor across the cube gives the guidance's "
                        f"{GUIDE_POINTS:,} points); {MIN_SPACING:g} to {MAX_SPACING:.3f}")
    p.add_argument("--steps", type=int, default=d.steps, help="train: optimisation steps")
    return p


def run(args) -> int:
    from .options import check_options, mode_of

    mode = mode_of(args)
    check_options(args, mode)  # every option against the mode, before any work
    user = mode == "egohmr sample --frame"
    if args.out is None and DEFAULT_OUT["user" if user else args.action]:
        args.out = DEFAULT_OUT["user" if user else args.action]
    ckpts = {}
    if args.action in ("sample", "tune"):
        models, ckpts = check_common(args, none=True)
        if args.encoder_bf16:
            from volsmpl.volume.models import model_kind

            if not any(g != "none" and model_kind(g).learned for g in models):
                raise ValueError(f"--encoder-bf16 sets the learned guides' encoder arithmetic, but --model "
                                 f"{args.model} has none: add volsmpl or coap, or drop the flag")
    if args.action == "make-data":
        from .data import make_frames

        for split in ("train", "val", "test"):
            fr = make_frames(split, seed=args.seed)
            print(f"{split}: {len(fr)} frames in {len({f.room_seed for f in fr})} rooms")
        return 0
    if args.action == "train":
        from .train import TrainSettings, train

        s = TrainSettings(steps=args.steps, seed=args.seed, threads=args.threads, device=args.device)
        path = train(args.out, s, resume=args.resume)
        print(f"wrote {path}.safetensors")
        return 0
    from volsmpl.apps.checks import claim_out

    from .run import run_sample, run_tune, run_user_frame

    with claim_out(args.out, "egohmr"):
        if args.action == "tune":
            return run_tune(args, ckpts)
        return run_user_frame(args, ckpts) if user else run_sample(args, ckpts)


__all__ = ["add_parser", "run", "parse_guides", "scales_of", "options_of", "GUIDES", "PAPER_SCALE", "TUNE_FACTORS"]
