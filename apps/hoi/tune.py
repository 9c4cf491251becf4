"""Tuning of the human–object weights that the paper does not give (the image terms), on the database's tuning half.

    volsmpl hoi tune --cases 13 --grid 1e4,1e5,1e6,1e7 --model volsmpl --threads 1 --out docs/hoi     # docs/hoi/tune.json

Every grid value sets both image weights (keypoints and silhouette); each model kind fits the first --cases of the
'tune' split (13: one case of each kind) at the paper's settings otherwise. The score of a value is the mean over
kinds and cases of contact_cm + obj_trans_err_cm + collision_pct after the fit (all lower is better: the contact
and the object's placement in cm, the object's vertices inside the body in %); the best value becomes FitConfig's
default and is reported on the 'test' split only. Per-case records of every value are written too.
"""
from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np


def score(results: list) -> float:
    """Mean over the cases of contact_cm + obj_trans_err_cm + collision_pct after the fit."""
    vals = [r.after.get("contact_cm", np.nan) + r.after.get("obj_trans_err_cm", np.nan) + r.after["collision_pct"]
            for r in results]
    return float(np.nanmean(vals)) if vals else float("nan")


def run_tune(args, cases: list) -> int:
    """`volsmpl hoi tune`: each --grid value as both image weights, every kind of --model fitting `cases` (the
    tuning half's selection) at the other settings given; writes OUT/tune.json after every value."""
    import volsmpl
    from volsmpl.apps.progress import progress, steps_bar
    from volsmpl.apps.table import check_common, checkpoint_names, volumes, write_results

    from .console import case_line
    from .fit import FitConfig, Problem, fit_case

    try:
        grid = [float(x) for x in args.grid.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--grid {args.grid!r}: give comma-separated numbers, e.g. 1e4,1e5,1e6") from None
    if not grid:
        raise ValueError(f"--grid {args.grid!r} names no weight: give comma-separated numbers")
    models, ckpts = check_common(args)
    body = volsmpl.create_body().to(args.device)
    vols = volumes(body, models, ckpts, args.device)
    base = FitConfig(iters=args.iters, lr=args.lr, contact_fraction=args.contact_fraction,
                     contact_huber=args.contact_huber, device=args.device)
    rows = []
    for w in grid:
        cfg = replace(base, w_keypoints=w, w_silhouette=w)
        res = {m: [] for m in models}
        for m in models:
            for c in progress(cases, f"hoi tune w_image {w:g} {m}", quiet=args.quiet):
                r = fit_case(c, body, vols[m], cfg, Problem(c, body, vols[m], cfg), progress=steps_bar(args.quiet))
                res[m].append(r)
                print(f"w_image {w:g} {case_line(c.name, m, r)}", flush=True)
        row = {"w_image": w, "score": float(np.mean([score(rs) for rs in res.values()])),
               "per_model": {m: {"score": score(rs),
                                 **{k: float(np.nanmean([np.nan if r.after.get(k) is None else r.after[k] for r in rs]))
                                    for k in ("contact_cm", "obj_trans_err_cm", "obj_rot_err_deg", "collision_pct",
                                              "scale_err_pct", "human_scale_err_pct")},
                                 "cases": {r.name: r.after for r in rs}}
                             for m, rs in res.items()}}
        rows.append(row)
        print(f"w_image {w:g}: score {row['score']:.3f}", flush=True)
        best = min(rows, key=lambda r: r["score"])  # written after every value: a stopped run keeps what it did
        path = write_results(args.out, {"cases": [c.name for c in cases], "models": models,
                                        "checkpoints": checkpoint_names(models, ckpts),
                                        "config": {k: v for k, v in asdict(cfg).items() if k not in
                                                   ("w_keypoints", "w_silhouette")},
                                        "rows": rows, "best": best}, "tune.json")
    print(f"best w_image {best['w_image']:g} (score {best['score']:.3f}); wrote {path}")
    return 0
