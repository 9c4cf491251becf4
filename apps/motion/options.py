"""The options of `volsmpl motion` checked before any work: which options each mode reads (`USES`; the others,
given with a non-default value, are refused by volsmpl.apps.checks.applies), every number in its range, the
collision weights, the start and goal of a user's scene.

    mode = mode_of(args)          # 'motion tune', 'motion --scene' or 'motion without --scene' (generated rooms)
    opt = check_options(args)     # {'models', 'ckpts', 'protocol', 'weights', 'frames', 'cf', 'mode', 'warnings'}
"""
from __future__ import annotations

import math

from volsmpl.apps.checks import applies, number, warn
from volsmpl.apps.table import REFINE_OPTIONS

PAPER_W = {"volsmpl": [1.0], "mesh": [1.0], "coap": [0.01, 0.1, 1.0]}
ALL_SCENES = 15
SPARSE_SPACING_M = 0.1   # --spacing above this is warned about (a 20 cm object gets fewer than 24 points)

#: what every mode reads: the models and their cost, the walk's optimisation, the output
_WALK = {"model", "checkpoint_volsmpl", "checkpoint_coap", "threads", "out", "device", "resume", "render", "frames", "iters",
         "lr", "w", "coll_frames", "mem_budget_gb", "residuals", "floor_in_loss", "cost_frames", "cost_repeats",
         "published_cost", "encoder_bf16", "save_meshes"} | REFINE_OPTIONS
_ROOMS = _WALK | {"scenes", "sequences", "seed", "batch"}
#: mode -> the options (argparse dests) it reads
USES = {"motion without --scene": _ROOMS,
        "motion tune": _ROOMS,
        "motion --scene": _WALK | {"scene", "start", "goal", "up", "units", "floor_y", "spacing"}}


def mode_of(args) -> str:
    """The mode an invocation runs: 'motion tune', 'motion --scene' (a user's scene, one start/goal pair) or
    'motion without --scene' (generated rooms)."""
    if args.action == "tune":
        return "motion tune"
    return "motion --scene" if args.scene is not None else "motion without --scene"


def parse_xy(text, name: str):
    """A floor position 'A,B' (two finite numbers) -> (A, B); ValueError naming the option."""
    if text is None:
        raise ValueError(f"--scene needs --start and --goal (A,B floor positions); {name} is missing")
    try:
        a, b = (float(v) for v in str(text).split(","))
    except ValueError:
        raise ValueError(f"{name} must be two numbers A,B, got {text!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ValueError(f"{name} must be finite, got {text!r}")
    return a, b


def parse_weights(items, models) -> dict:
    """--w MODEL=W[,W...] (repeatable) -> model -> its collision weights (default PAPER_W); each weight finite and
    >= 0 (0: no collision term), given once; each model given once and in --model."""
    out = {m: list(PAPER_W.get(m, [1.0])) for m in models}
    seen = set()
    for it in items:
        if "=" not in it:
            raise ValueError(f"--w takes MODEL=W[,W...], got {it!r}")
        m, ws = it.split("=", 1)
        m = m.strip()
        if m not in out:
            raise ValueError(f"--w {it!r}: model {m!r} is not in --model ({', '.join(models)})")
        if m in seen:
            raise ValueError(f"--w {m}=... is given twice: give all of its weights once, comma-separated "
                             f"(--w {m}=0.01,0.1)")
        seen.add(m)
        try:
            vals = [float(v) for v in ws.split(",") if v.strip()]
        except ValueError:
            raise ValueError(f"--w {it!r}: weights must be numbers (--w {m}=0.1,1)") from None
        if not vals or any(not math.isfinite(v) or v < 0 for v in vals):
            raise ValueError(f"--w {it!r}: weights must be finite and >= 0 (0: no collision term)")
        if len(set(vals)) < len(vals):
            raise ValueError(f"--w {it!r}: a weight is given twice; give each once")
        out[m] = vals
    return out


def scene_count(text) -> int:
    """--scenes: 'all' (the paper's 15 rooms) or a whole number >= 1."""
    t = str(text).strip().lower()
    if t == "all":
        return ALL_SCENES
    x = number(t, "--scenes", lo=1, what="'all' or the number of generated rooms")
    if x != int(x):
        raise ValueError(f"--scenes {text}: give 'all' or a whole number of rooms >= 1")
    return int(x)


def coll_frames(text) -> str:
    """--coll-frames: 'auto', 'all' or a whole number >= 1 (as text)."""
    cf = str(text).strip().lower()
    if cf not in ("auto", "all") and not (cf.isdigit() and int(cf) >= 1):
        raise ValueError(f"--coll-frames must be 'auto', 'all' or a number >= 1, got {text!r}")
    return cf


def check_options(args) -> dict:
    """Every option checked before any work (module docstring), then the shared ones (volsmpl.apps.table's
    check_common: kinds, checkpoints, threads, render, out)."""
    from volsmpl.apps.table import check_common
    from volsmpl.volume.models import model_kind

    from .synth import check_frames
    from .user_scene import DEFAULT_SPACING_M

    mode = mode_of(args)
    applies(args, mode, USES[mode])
    frames = check_frames(args.frames)
    number(args.iters, "--iters", lo=0, what="Adam steps; 0: the straight start walk, not optimised")
    warnings = []
    if args.iters == 0:
        warn("motion", "--iters 0: the walks are not optimised; the straight start walks are measured", warnings)
    number(args.lr, "--lr", lo=0, lo_open=True, what="Adam's learning rate")
    number(args.mem_budget_gb, "--mem-budget-gb", lo=0, lo_open=True, what="GB of memory")
    number(args.cost_frames, "--cost-frames", lo=1, what="frames batched in the cost measurement")
    number(args.cost_repeats, "--cost-repeats", lo=1, what="repeats of the cost measurement")
    cf = coll_frames(args.coll_frames)
    if mode == "motion --scene":
        parse_xy(args.start, "--start"), parse_xy(args.goal, "--goal")
        if args.floor_y is not None:
            number(args.floor_y, "--floor-y", what="the floor's height in metres after --units")
        spacing = number(args.spacing, "--spacing", lo=0, lo_open=True,
                         what="metres between the scene points taken around the walk")
        if spacing > SPARSE_SPACING_M:
            warn("motion", f"--spacing {spacing:g}: a 20 cm object gets about {0.24 / spacing ** 2:.0f} points at "
                           f"{spacing:g} m apart, and the walk may pass through it unseen; the default is "
                           f"{DEFAULT_SPACING_M:g}", warnings)
    else:
        n = scene_count(args.scenes)
        number(args.sequences, "--sequences", lo=1, what="start/goal pairs per room")
        number(args.seed, "--seed", lo=0, what="a seed: a whole number")
        number(args.batch, "--batch", lo=1, what="pairs optimised together")
        if mode == "motion tune" and n < 2:
            raise ValueError("tune splits generated rooms into tuning and test rooms: use --scenes 2 or more")
    models, ckpts = check_common(args)
    weights = parse_weights(args.w, models)
    if args.encoder_bf16 and not any(model_kind(m).learned for m in models):
        raise ValueError(f"--encoder-bf16 sets the learned kinds' encoder arithmetic, but --model {','.join(models)} "
                         f"runs none: add volsmpl or coap, or drop the flag")
    if args.published_cost and "coap" not in models:
        raise ValueError("--published-cost measures COAP as published: add coap to --model")
    return {"models": models, "ckpts": ckpts, "protocol": "tuned" if args.action == "tune" else "paper",
            "weights": weights, "frames": frames, "cf": cf, "mode": mode, "warnings": warnings}
