"""Tuning of the human–object weights on the database's tuning half.

    volsmpl hoi tune --grid w_silhouette=1e3,4e3,1.6e4 --model volsmpl --cases all --batch 10 --out docs/hoi
    volsmpl hoi tune --grid w_silhouette=1e3,4e3 --grid w_normal=1e2,1e3 ...      # every combination of the two

Each --grid names a weight of FitConfig (a `w_` field) or one of SETTINGS (scale_free_std, ...) and its values; the settings tried are every combination,
each model kind fitting the selected cases of the 'tune' split at FitConfig's defaults otherwise (--batch cases
at a time). The score of a setting is the mean over kinds and cases of contact_cm + obj_trans_err_cm +
obj_rot_err_deg + collision_pct after the fit (all lower is better: the contact and the object's placement in cm,
its rotation in degrees, the object's vertices inside the body in %; a ball's rotation counts 0); the best
setting becomes FitConfig's default and is reported on the 'test' split only. Per-case records of every setting
are written to OUT/tune.json after each setting.
"""
from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np


#: the FitConfig fields besides the weights that --grid takes
SETTINGS = ("scale_free_std", "rotation_after", "contact_fraction", "contact_huber", "contact_margin", "depth_range")


def score(results: list) -> float:
    """Mean over the cases of contact_cm + obj_trans_err_cm + obj_rot_err_deg + collision_pct after the fit (a
    rotation of None, a ball's, counts 0)."""
    vals = [r.after.get("contact_cm", np.nan) + r.after.get("obj_trans_err_cm", np.nan)
            + (r.after.get("obj_rot_err_deg") or 0.0) + r.after.get("collision_pct", np.nan) for r in results]
    return float(np.nanmean(vals)) if vals else float("nan")


def parse_grid(specs: list) -> dict:
    """--grid NAME=v1,v2 ... -> {NAME: [v1, v2]}: NAME a weight of FitConfig (a `w_` field) or one of SETTINGS, the
    values numbers >= 0 (FitConfig checks each setting's range); one line naming the fix otherwise."""
    from dataclasses import fields

    from .fit import FitConfig

    weights = [f.name for f in fields(FitConfig) if f.name.startswith("w_") or f.name in SETTINGS]
    grid = {}
    for spec in specs:
        name, eq, values = spec.partition("=")
        name = name.strip().replace("-", "_")
        if not eq or name not in weights:
            raise ValueError(f"--grid {spec!r}: give a weight or setting and its values, NAME=v1,v2 with NAME one of "
                             f"{', '.join(weights)}")
        try:
            vals = [float(x) for x in values.split(",") if x.strip()]
        except ValueError:
            raise ValueError(f"--grid {spec!r}: the values must be comma-separated numbers, e.g. 1e3,4e3") from None
        if not vals or not all(np.isfinite(v) and v >= 0 for v in vals):
            raise ValueError(f"--grid {spec!r}: give one or more finite weights >= 0")
        if name in grid:
            raise ValueError(f"--grid names {name} twice: give its values once")
        for v in vals:  # each value in its field's range (FitConfig's checks), before any fit
            try:
                FitConfig(**{name: v})
            except ValueError as e:
                raise ValueError(f"--grid {spec!r}: {e}") from None
        grid[name] = vals
    return grid


def run_tune(args, cases: list, base) -> int:
    """`volsmpl hoi tune`: every combination of the --grid weights, every kind of --model fitting `cases` (the
    tuning half's selection, --batch at a time) at `base` (the options' FitConfig) otherwise; writes OUT/tune.json
    after every setting."""
    import itertools

    import volsmpl
    from volsmpl.apps.progress import progress, steps_bar
    from volsmpl.apps.table import check_common, checkpoint_names, volumes, write_results

    from .console import case_line
    from .fit import fit_cases

    grid = parse_grid(args.grid)
    models, ckpts = check_common(args)
    body = volsmpl.create_body().to(args.device)
    vols = volumes(body, models, ckpts, args.device)
    settings = [dict(zip(grid, values)) for values in itertools.product(*grid.values())]
    cfgs = [replace(base, **setting) for setting in settings]  # every setting checked before the first fit
    rows = []
    for setting, cfg in zip(settings, cfgs):
        label = " ".join(f"{k} {v:g}" for k, v in setting.items())
        res = {m: [] for m in models}
        for m in models:
            for i0 in progress(range(0, len(cases), args.batch), f"hoi tune {label} {m}", quiet=args.quiet):
                group = cases[i0:i0 + args.batch]
                for c, r in zip(group, fit_cases(group, body, vols[m], cfg, progress=steps_bar(args.quiet))):
                    res[m].append(r)
                    print(f"{label} {case_line(c.name, m, r)}", flush=True)
        row = {"setting": setting, "score": float(np.mean([score(rs) for rs in res.values()])),
               "per_model": {m: {"score": score(rs),
                                 **{k: float(np.nanmean([np.nan if r.after.get(k) is None else r.after[k] for r in rs]))
                                    for k in ("contact_cm", "obj_trans_err_cm", "obj_rot_err_deg", "collision_pct",
                                              "scale_err_pct", "human_scale_err_pct")},
                                 "cases": {r.name: r.after for r in rs}}
                             for m, rs in res.items()}}
        rows.append(row)
        print(f"{label}: score {row['score']:.3f}", flush=True)
        best = min(rows, key=lambda r: r["score"])  # written after every setting: a stopped run keeps what it did
        path = write_results(args.out, {"cases": [c.name for c in cases], "models": models,
                                        "checkpoints": checkpoint_names(models, ckpts), "grid": grid,
                                        "preset": args.preset,
                                        "config": {k: v for k, v in asdict(base).items() if k not in grid},
                                        "batch": args.batch, "rows": rows, "best": best}, "tune.json")
    print(f"best {' '.join(f'{k} {v:g}' for k, v in best['setting'].items())} (score {best['score']:.3f}); "
          f"wrote {path}")
    return 0
