"""The guides of `volsmpl egohmr` and their settings: which kinds guide (`--model`, with 'none' for the unguided
sampler), each one's guidance scale (--scale over --tuned over the paper's) and the guidance options."""
from __future__ import annotations

import json
from pathlib import Path

GUIDES = ("none", "volsmpl", "coap", "mesh")
PAPER_SCALE = {"volsmpl": 30.0, "coap": 0.4, "mesh": 30.0}
TUNE_FACTORS = (0.1, 0.3, 1.0, 3.0, 10.0)


def parse_guides(text: str) -> list[str]:
    """`--model` -> the guides in order ('none': the unguided sampler)."""
    from volsmpl.apps.table import parse_kinds

    return parse_kinds(text, none=True)


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


__all__ = ["GUIDES", "PAPER_SCALE", "TUNE_FACTORS", "parse_guides", "scales_of", "options_of"]
