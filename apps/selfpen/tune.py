"""One tuning run of the repair's hyper-parameters, the same grid for every model, so that both learned kinds
are tuned alike (`volsmpl selfpen tune`).

The paper's values (lr 1e-5, pose-prior weight 1e3, self-penetration weight 0.1) were set for
COAP's SMPL-X code; with plain SGD only the products lr * w_selfpen and lr * w_prior matter, and
the prior step is stable only for lr * w_prior < 1. The default grid keeps the paper's
lr * w_prior = 1e-2 (lr 1e-2, w_prior 1) and raises the paper's lr * w_selfpen = 1e-6, which does
not move our bodies, to 1e-3 .. 1 (w_selfpen 0.1 .. 100), with VolumetricSMPL's SDF read in
centimetres (tau 1 cm, Volume.selfpen_loss) so that both models' losses have the same scale, and
every step limited to 0.1 rad per joint (SelfPenConfig.max_step); the other settings are the tuned preset's. Each grid point repairs the same
cases with each model; the table gives, per model and grid point, the mean fraction of triangle
collisions removed, the mean iterations and the mean pose change. Selection rule (`best`): the grid
point with the largest fraction removed averaged over the models, ties broken by the smaller pose
change.

    volsmpl selfpen tune --model volsmpl,coap --checkpoint-coap runs/coap/.../model \
        --cases forearm_through_torso_left,deep_squat --out out/selfpen_tune          # -> out/selfpen_tune/tune.json
"""
from __future__ import annotations

import itertools
import json
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from volsmpl.apps.progress import progress, steps_bar

from .optimize import SelfPenConfig, repair_case, summarize

# default grid: learning rate and the two weights (w_selfpen, w_prior); module docstring
GRID_LR = (1e-2,)
GRID_W_SELFPEN = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)
GRID_W_PRIOR = (1.0,)


def grid_configs(base: SelfPenConfig, lrs=GRID_LR, w_selfpens=GRID_W_SELFPEN, w_priors=GRID_W_PRIOR) -> list:
    """Every (lr, w_selfpen, w_prior) with a stable prior step (lr * w_prior < 1), as SelfPenConfigs."""
    out = []
    for lr, ws, wp in itertools.product(lrs, w_selfpens, w_priors):
        if lr * wp < 1.0:
            out.append(replace(base, lr=float(lr), w_selfpen=float(ws), w_prior=float(wp)))
    if not out:
        raise ValueError("the grid is empty: every combination has lr * w_prior >= 1 (unstable SGD on the pose prior)")
    return out


def score(results) -> dict:
    """`optimize.summarize`'s iterations, pose change and collisions after (means over the cases with
    collisions), plus the mean fraction of collisions removed."""
    s = summarize(results)
    act = [r for r in results if r.status != "no_intersection"]
    removed = float(np.mean([1.0 - r.collisions_after / r.collisions_before for r in act])) if act else float("nan")
    return {"removed": removed, "iterations": s["iterations"], "pose_change_deg": s["pose_change_deg"],
            "collisions_after": s["collisions_after"], "cases": s["cases_with_collisions"]}


def _point(row: dict) -> tuple:
    """The grid point (lr, w_selfpen, w_prior) of a row."""
    return row["lr"], row["w_selfpen"], row["w_prior"]


def best(rows: list) -> dict:
    """The row (grid point) with the largest 'removed' averaged over models; ties: smaller pose change."""
    return max(rows, key=lambda r: (round(np.mean([s["removed"] for s in r["models"].values()]), 4),
                                    -np.mean([s["pose_change_deg"] for s in r["models"].values()])))


def _best_point(rows: list) -> dict:
    return dict(zip(("lr", "w_selfpen", "w_prior"), _point(best(rows))))


def tune(body, volumes: dict, cases, configs, log=print, quiet: bool = False) -> dict:
    """Every grid point (`configs`) on every case by every volume; quiet: no progress bars (they show on a
    terminal only)."""
    rows = []
    for cfg in configs:
        row = {"lr": cfg.lr, "w_selfpen": cfg.w_selfpen, "w_prior": cfg.w_prior, "models": {}}
        for m, vol in volumes.items():
            t0 = time.perf_counter()
            res = [repair_case(body, vol, c, cfg, progress=steps_bar(quiet))
                   for c in progress(cases, f"tune {m} w_selfpen {cfg.w_selfpen:g}", quiet=quiet)]
            row["models"][m] = {**score(res), "seconds": time.perf_counter() - t0,
                                "per_case": {r.name: [r.collisions_before, r.collisions_after, r.iterations] for r in res}}
            s = row["models"][m]
            log(f"lr {cfg.lr:g} w_selfpen {cfg.w_selfpen:g} w_prior {cfg.w_prior:g} {m:8s} removed {100 * s['removed']:5.1f} % "
                f"it {s['iterations']:6.1f} pose change {s['pose_change_deg']:5.2f} deg ({s['seconds']:.0f} s)")
        rows.append(row)
    return {"rows": rows, "best": _best_point(rows), "cases": [c.name for c in cases],
            "base_config": asdict(configs[0])}


def combine(results: list) -> dict:
    """Merge tuning runs over the same cases (e.g. one model, or one part of the grid, at a time). The best
    grid point is chosen among those that every model has run."""
    first = results[0]
    for r in results[1:]:
        if r["cases"] != first["cases"]:
            raise ValueError(f"tuning runs on different cases cannot be combined: {first['cases']} vs {r['cases']}")
    rows, ck = {}, {}
    for r in results:
        ck.update(r.get("checkpoints", {}))
        for row in r["rows"]:
            rows.setdefault(_point(row), {**row, "models": {}})["models"].update(row["models"])
    models = {m for row in rows.values() for m in row["models"]}
    complete = [row for row in rows.values() if set(row["models"]) == models]
    if not complete:
        raise ValueError(f"no grid point was run with every model ({sorted(models)}); nothing to choose from")
    return {**first, "rows": sorted(rows.values(), key=_point), "best": _best_point(complete), "checkpoints": ck}


def run_tune(args, body, volumes: dict, cases, checkpoints: dict) -> int:
    """`volsmpl selfpen tune`: the sweep over --grid-lr x --grid-w-selfpen x --grid-w-prior (the other settings: the
    tuned preset's, with --max-iters, --stop-checks, --tau, --patience) on the cases; writes OUT/tune.json."""
    from volsmpl.apps.table import write_results

    given = {k: getattr(args, k) for k in ("stop_checks", "tau", "patience") if getattr(args, k) is not None}
    base = SelfPenConfig(max_iters=args.max_iters, **given)   # the rest: the tuned preset's
    result = tune(body, volumes, cases, grid_configs(base, args.grid_lr, args.grid_w_selfpen, args.grid_w_prior),
                  quiet=args.quiet)
    result["checkpoints"] = {m: c for m, c in checkpoints.items() if c is not None}
    path = write_results(args.out, result, "tune.json")
    print("best:", result["best"], "->", path)
    return 0


def run_combine(args) -> int:
    """`volsmpl selfpen tune --combine A.json B.json`: earlier tuning runs merged into OUT/tune.json."""
    from volsmpl.apps.table import write_results
    from volsmpl.io.outputs import check_writable

    check_writable(args.out, "dir", "--out")
    runs = []
    for f in args.combine:
        try:
            runs.append(json.loads(Path(f).read_text(encoding="utf-8")))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise ValueError(f"--combine {f}: not a readable tuning result ({e.__class__.__name__}: {e})") from None
    result = combine(runs)
    path = write_results(args.out, result, "tune.json")
    print("best:", result["best"], "->", path)
    return 0
