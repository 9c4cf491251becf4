"""The guides of `volsmpl egohmr` and their settings: which kinds guide (`--model`, with 'none' for the unguided
sampler), each one's guidance scale (--scale over --tuned over the paper's), the guidance options, and the check of
every option against the mode it is given to (`check_options`, before any work).

    mode = mode_of(args)                  # 'egohmr sample', 'egohmr sample --frame', 'egohmr tune', ...
    check_options(args, mode)             # ValueError / FileNotFoundError in one line naming the option and the fix
"""
from __future__ import annotations

from volsmpl.apps.checks import applies, number, warn, read_json
from volsmpl.apps.table import REFINE_OPTIONS

GUIDES = ("none", "volsmpl", "coap", "mesh")
PAPER_SCALE = {"volsmpl": 30.0, "coap": 0.4, "mesh": 30.0}
TUNE_FACTORS = (0.0, 0.3, 1.0, 3.0)
#: defaults of --pelvis-step and --support (the paper: 0 and 'off'). The step: the lowest collision ratio, summed
#: over the three guides, among 0.005 / 0.01 / 0.02 m, each guide's pelvis error within 1 mm of the unguided
#: sampler's, with the pose unguided, the support term on and the pelvis moved along its ray (first 64 val frames:
#: collision 0.00424 unguided -> 0.00074 / 0.00128 / 0.00071 at 0.01 for volsmpl / coap / mesh, 0.00103 / 0.00103 /
#: 0.00100 at 0.02; pelvis error 96-102 mm against 107; `volsmpl egohmr tune --split val --frames 64 --factors 0
#: --pelvis-step S`)
PELVIS_STEP = 0.01
SUPPORT_DEFAULT = "on"

#: the options that shape the guided sampler (read only where --model has a guide other than 'none')
GUIDANCE = {"guide_steps", "plain_steps", "plain_factor", "wrt", "joints", "reduce", "encoder_bf16", "pelvis_step",
            "support", "pelvis_along"} | REFINE_OPTIONS
#: the largest --pelvis-step (metres per guided step): the regressed pelvis is off by 12 cm on average (val split)
MAX_PELVIS_STEP = 0.1
SUPPORT = ("on", "off")
ALONG = ("ray", "free")
#: the options of the volumes and of the egohmr network
MODELS = {"model", "checkpoint_volsmpl", "checkpoint_coap", "checkpoint", "threads", "seed", "out", "device"}
#: mode -> the options (argparse dests) it reads; any other given with a non-default value is refused
USES = {
    "egohmr sample": MODELS | GUIDANCE | {"scale", "tuned", "split", "frames", "batch", "budget_mb", "no_max_batch",
                                          "resume", "render", "save_meshes"},
    # a user's frame writes its meshes always: --save-meshes is accepted and changes nothing
    "egohmr sample --frame": MODELS | GUIDANCE | {"scale", "tuned", "frame", "scene", "units", "up", "spacing",
                                                  "render", "save_meshes"},
    "egohmr tune": MODELS | GUIDANCE | {"split", "frames", "batch", "factors"},
    "egohmr train": {"out", "steps", "seed", "threads", "resume", "device"},
    "egohmr make-data": {"seed", "threads"},
}


def parse_guides(text: str) -> list[str]:
    """`--model` -> the guides in order ('none': the unguided sampler)."""
    from volsmpl.apps.table import parse_kinds

    return parse_kinds(text, none=True)


def mode_of(args) -> str:
    """The mode an invocation runs (a key of USES): `sample --frame` is a user's frame, `sample` the split."""
    if args.action == "sample" and getattr(args, "frame", None) is not None:
        return "egohmr sample --frame"
    return f"egohmr {args.action}"


def read_tuned(path, guides: list[str], given: set) -> dict:
    """The best scales of a `tune` result for the guides in `guides` whose scale --scale does not give (`given`):
    the file read with read_json; one line naming it when it has no best scale for such a guide, or one that is not
    a finite number >= 0."""
    doc = read_json(path, "the tuning file", "--tuned")
    best = doc.get("best") if isinstance(doc, dict) else None
    if not isinstance(best, dict):
        raise ValueError(f"the tuning file {path} (--tuned) has no 'best' scales: give the tune.json that "
                         f"`volsmpl egohmr tune` wrote")
    need = [g for g in guides if g != "none" and g not in given]
    missing = [g for g in need if g not in best]
    if missing:
        raise ValueError(f"the tuning file {path} (--tuned) has no best scale for {', '.join(missing)} (it has "
                         f"{', '.join(sorted(best)) or 'none'}): tune {'them' if len(missing) > 1 else 'it'} "
                         f"(`volsmpl egohmr tune --model {','.join(missing)}`) or give --scale "
                         f"{missing[0]}=A")
    out = {}
    for g in need:
        out[g] = number(best[g], f"the tuning file {path} (--tuned): best scale of {g}", lo=0,
                        what="a guidance scale; a negative one pushes the body into the scene")
    return out


def scales_of(args, guides: list[str]) -> dict:
    """Guide -> scale: --scale over --tuned over the paper's; every scale a finite number >= 0, every --scale for a
    guide in --model and given once."""
    given = {}
    for item in args.scale:
        g, _, v = item.partition("=")
        g = g.strip()
        if g not in GUIDES or g == "none" or not v:
            raise ValueError(f"--scale {item!r}: write GUIDE=A with GUIDE one of volsmpl, coap, mesh")
        if g not in guides:
            raise ValueError(f"--scale {item}: {g} is not in --model {','.join(guides)}; add it to --model or drop "
                             f"the --scale")
        if g in given:
            raise ValueError(f"--scale {g} is given twice ({given[g]:g} and {v}); give it once")
        given[g] = number(v, f"--scale {g}", lo=0,
                          what="the guidance scale a; a negative one pushes the body into the scene")
    out = {g: PAPER_SCALE.get(g, 0.0) for g in guides}
    if args.tuned:
        guided = [g for g in guides if g != "none"]
        if not guided:
            raise ValueError(f"--tuned gives guidance scales, but --model {','.join(guides)} has no guide; drop it")
        if all(g in given for g in guided):
            raise ValueError("--tuned: every guide's scale is given by --scale, so the tuning file is not read; "
                             "drop --tuned or a --scale")
        out.update(read_tuned(args.tuned, guides, set(given)))
    out.update(given)
    out["none"] = 0.0
    return {g: out[g] for g in guides}


def factors_of(text: str) -> list[float]:
    """`--factors` -> the factors, each finite and >= 0 (0: the pose unguided, the pelvis moved by --pelvis-step
    and --support alone)."""
    parts = [f.strip() for f in str(text).split(",") if f.strip()]
    if not parts:
        raise ValueError(f"--factors {text!r}: give comma-separated factors >= 0 of the paper's scales, e.g. "
                         f"0,0.1,1,10")
    return [number(f, "--factors", lo=0, what="factors of the paper's scales, comma-separated; 0: the pose "
                                              "unguided") for f in parts]


def _given(args, dests) -> list[str]:
    """The options among `dests` given with a value other than the parser's default (none where the namespace was
    built in code, without the parser)."""
    parser = getattr(args, "_parser", None)
    if parser is None:
        return []
    return ["--" + d.replace("_", "-") for d in dests if getattr(args, d) != parser.get_default(d)]


def check_options(args, mode: str) -> None:
    """Every option checked against `mode` before any work: options the mode does not read (given with a
    non-default value) refused, numbers in range, --scale and --tuned read; one line naming the option and the fix."""
    from volsmpl.apps.table import check_threads

    if mode in ("egohmr train", "egohmr make-data") and args.encoder_bf16:
        raise ValueError(f"--encoder-bf16 sets the guides' encoder arithmetic: it applies to sample and tune, not "
                         f"{args.action}; drop it")
    if mode == "egohmr sample":
        stray = _given(args, ("scene", "units", "up", "spacing")) or (["--scene"] if args.scene else [])
        if stray:
            one = len(stray) < 2
            raise ValueError(f"{', '.join(stray)} describe{'s' if one else ''} the scene of a user's frame: add "
                             f"--frame FRAME.json (apps/egohmr/userframe.py) or drop {'it' if one else 'them'}")
    uses = set(USES[mode])
    if mode == "egohmr sample" and args.no_max_batch:
        if _given(args, ("budget_mb",)):
            raise ValueError("--budget-mb is the budget of the measured largest batch, which --no-max-batch skips: "
                             "drop one of them")
        uses.discard("budget_mb")
    guides = None
    if "model" in uses:
        guides = parse_guides(args.model)
        if all(g == "none" for g in guides):
            if mode == "egohmr tune":
                raise ValueError(f"--model {args.model}: tune sweeps the guides' scales; give volsmpl, coap or mesh")
            stray = _given(args, sorted(GUIDANCE | {"scale", "tuned"}))
            if stray:
                raise ValueError(f"{', '.join(stray)} set{'s' if len(stray) < 2 else ''} the guidance, but --model "
                                 f"{args.model} has no guide: add volsmpl, coap or mesh to --model, or drop "
                                 f"{'it' if len(stray) < 2 else 'them'}")
            uses -= GUIDANCE | {"scale", "tuned"}
    applies(args, mode, uses)
    check_threads(args.threads)
    if mode == "egohmr sample --frame" and not args.scene:
        raise ValueError("--frame needs the frame's scene: add --scene SCAN (a mesh or point-cloud file)")
    if "seed" in uses:
        number(args.seed, "--seed", lo=0, what="a seed: a whole number")
    if "batch" in uses:
        number(args.batch, "--batch", lo=1, what="frames sampled together")
    if "frames" in uses and args.frames is not None:
        number(args.frames, "--frames", lo=1, what="the first N frames of the split")
    if "budget_mb" in uses:
        number(args.budget_mb, "--budget-mb", lo=0, lo_open=True, what="megabytes of the measured largest batch")
    if "steps" in uses:
        number(args.steps, "--steps", lo=1, what="optimisation steps")
    if "render" in uses:
        number(args.render, "--render", lo=0, what="figures of the first N frames; 0: none")
    if "spacing" in uses and getattr(args, "spacing", None) is not None:
        from .user_scene import MAX_SPACING, MIN_SPACING

        number(args.spacing, "--spacing", lo=MIN_SPACING, hi=MAX_SPACING,
               what="metres between scene points: coarser, a floor across the 2 m cube around the body gives fewer "
                    "points than the guidance needs; finer adds nothing it reads")
    if "guide_steps" in uses:
        number(args.guide_steps, "--guide-steps", lo=1, what="the last diffusion steps that are guided")
        number(args.plain_steps, "--plain-steps", lo=0, hi=args.guide_steps,
               what=f"of the {args.guide_steps} guided steps (--guide-steps), the last ones without Sigma_t")
        number(args.plain_factor, "--plain-factor", lo=0, what="the factor F of those steps' a*F*grad")
    if "pelvis_step" in uses:
        number(args.pelvis_step, "--pelvis-step", lo=0, hi=MAX_PELVIS_STEP,
               what="metres the collision score's gradient moves the pelvis per guided step; 0: the regressed "
                    "pelvis stays (the paper)")
    if "support" in uses and args.support not in SUPPORT:
        raise ValueError(f"--support {args.support!r}: choose one of {', '.join(SUPPORT)}")
    if "pelvis_along" in uses and args.pelvis_along not in ALONG:
        raise ValueError(f"--pelvis-along {args.pelvis_along!r}: choose one of {', '.join(ALONG)}")
    if "factors" in uses:
        fs = factors_of(args.factors)
        if 0 in fs and not args.pelvis_step and args.support == "off":
            raise ValueError("--factors 0 leaves the pose unguided, and --pelvis-step 0 --support off the pelvis too: "
                             "that row is the unguided sampler's; drop the 0 or give --pelvis-step or --support on")
    if "scale" in uses:
        for g, a in scales_of(args, guides).items():
            if g != "none" and a > 100 * PAPER_SCALE[g]:
                warn("egohmr", f"--scale {g} {a:g} is {a / PAPER_SCALE[g]:.0f}x the paper's ({PAPER_SCALE[g]:g}): "
                               f"steps this large throw the pose far from the sample (a typo?)")


def options_of(args, scale: float):
    from .evaluate import GuideOptions

    if not 0 <= args.plain_steps <= args.guide_steps:
        raise ValueError(f"--plain-steps {args.plain_steps} must lie in 0..--guide-steps ({args.guide_steps})")
    return GuideOptions(scale=scale, steps=args.guide_steps, plain_steps=args.plain_steps,
                        plain_factor=args.plain_factor, wrt=args.wrt, joints=args.joints, reduce=args.reduce,
                        pelvis_step=args.pelvis_step, support=args.support, pelvis_along=args.pelvis_along)


__all__ = ["GUIDES", "PAPER_SCALE", "TUNE_FACTORS", "MAX_PELVIS_STEP", "SUPPORT", "ALONG", "PELVIS_STEP",
           "SUPPORT_DEFAULT", "USES", "parse_guides", "mode_of", "read_tuned", "scales_of",
           "factors_of", "check_options", "options_of"]
