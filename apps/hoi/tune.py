"""Tuning of the human–object weights that the paper does not give (the image terms), on the database's tuning half.

    python -m volsmpl.apps.hoi.tune --cases 13 --grid 1e4,1e5,1e6,1e7 --model volsmpl --threads 1 --out docs/hoi/tune.json

Every grid value sets both image weights (keypoints and silhouette); each model kind fits the first --cases of the
'tune' split (13: one case of each kind) at the paper's settings otherwise. The score of a value is the mean over
kinds and cases of contact_cm + obj_trans_err_cm + collision_pct after the fit (all lower is better: the contact
and the object's placement in cm, the object's vertices inside the body in %); the best value becomes FitConfig's
default and is reported on the 'test' split only. Per-case records of every value are written too.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np


def score(results: list) -> float:
    """Mean over the cases of contact_cm + obj_trans_err_cm + collision_pct after the fit."""
    vals = [r.after.get("contact_cm", np.nan) + r.after.get("obj_trans_err_cm", np.nan) + r.after["collision_pct"]
            for r in results]
    return float(np.nanmean(vals)) if vals else float("nan")


def main(argv=None) -> int:
    import torch

    import volsmpl
    from volsmpl.volume.models import parse_models
    from volsmpl.io.outputs import check_writable, write_atomic

    from volsmpl.apps.hoi import database
    from .cli import case_line, select_cases
    from .fit import FitConfig, Problem, fit_case

    p = argparse.ArgumentParser(prog="python -m volsmpl.apps.hoi.tune", description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=13)
    p.add_argument("--grid", default="1e4,1e5,1e6,1e7")
    p.add_argument("--model", default="volsmpl")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--db", default=None)
    p.add_argument("--iters", type=int, default=FitConfig().iters)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--out", default="docs/hoi/tune.json")
    args = p.parse_args(argv)
    check_writable(args.out, "file", "--out")
    if args.threads:
        torch.set_num_threads(args.threads)
    grid = [float(x) for x in args.grid.split(",")]
    folder = Path(args.db) if args.db else database.database_folder(args.seed)
    if not (folder / "index.json").is_file():
        raise SystemExit(f"no interaction database in {folder}; build it with `volsmpl hoi make-db --seed {args.seed}`")
    index = {c["name"]: c for c in json.loads((folder / "index.json").read_text())["cases"]}
    cases = select_cases(database.load_database(folder), index, "tune", str(args.cases))
    body = volsmpl.create_body()
    models = parse_models(args.model)
    volumes = {m: volsmpl.attach_volume(body, model=m) for m in models}
    rows = []
    for w in grid:
        cfg = replace(FitConfig(iters=args.iters), w_keypoints=w, w_silhouette=w)
        res = {m: [] for m in models}
        for m in models:
            for c in cases:
                r = fit_case(c, body, volumes[m], cfg, Problem(c, body, volumes[m], cfg))
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
        write_atomic(args.out, json.dumps({"cases": [c.name for c in cases], "models": models,
                                           "config": {k: v for k, v in asdict(cfg).items() if k not in
                                                      ("w_keypoints", "w_silhouette")},
                                           "rows": rows, "best": best}, indent=1))
    print(f"best w_image {best['w_image']:g} (score {best['score']:.3f}); wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
