"""One tuning run of the repair's hyper-parameters, the same grid for every model (issue: "tune them
once for both models alike and document the values").

The paper's values (lr 1e-5, pose-prior weight 1e3, self-penetration weight 0.1) were set for
COAP's SMPL-X code; with plain SGD only the products lr * w_selfpen and lr * w_prior matter, and
the prior step is stable only for lr * w_prior < 1. The default grid keeps the paper's
lr * w_prior = 1e-2 (lr 1e-2, w_prior 1) and raises the paper's lr * w_selfpen = 1e-6, which does
not move our bodies, to 1e-3 .. 0.3 (w_selfpen 0.1 .. 30), with VolumetricSMPL's SDF read in
centimetres (tau 1 cm, Volume.selfpen_loss) so that both models' losses have the same scale, and
every step limited to 0.1 rad per joint (SelfPenConfig.max_step); the other settings are the tuned preset's. Each grid point repairs the same
cases with each model; the table gives, per model and grid point, the mean fraction of triangle
collisions removed, the mean iterations and the mean pose change. Selection rule (`best`): the grid
point with the largest fraction removed averaged over the models, ties broken by the smaller pose
change.

    python -m volsmpl.apps.selfpen.tune --models volsmpl,coap --checkpoint-coap runs/coap/.../model \
        --cases forearm_through_torso_left,deep_squat --out out/selfpen_tune.json
"""
from __future__ import annotations

import argparse
import itertools
import json
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch

from .cases import load_cases
from .optimize import SelfPenConfig, repair_case, summarize

# default grid: learning rate and the two weights (w_selfpen, w_prior); module docstring
GRID_LR = (1e-2,)
GRID_W_SELFPEN = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0)
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


def tune(body, volumes: dict, cases, configs, log=print) -> dict:
    rows = []
    for cfg in configs:
        row = {"lr": cfg.lr, "w_selfpen": cfg.w_selfpen, "w_prior": cfg.w_prior, "models": {}}
        for m, vol in volumes.items():
            t0 = time.perf_counter()
            res = [repair_case(body, vol, c, cfg) for c in cases]
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


def main(argv=None) -> int:
    import volsmpl

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--models", default="volsmpl,coap")
    p.add_argument("--checkpoint-volsmpl", default=None)
    p.add_argument("--checkpoint-coap", default=None)
    p.add_argument("--cases", default="all")
    p.add_argument("--lr", type=float, nargs="+", default=list(GRID_LR))
    p.add_argument("--w-selfpen", type=float, nargs="+", default=list(GRID_W_SELFPEN))
    p.add_argument("--w-prior", type=float, nargs="+", default=list(GRID_W_PRIOR))
    p.add_argument("--max-iters", type=int, default=SelfPenConfig.max_iters)
    p.add_argument("--stop-checks", type=int, default=SelfPenConfig.stop_checks)
    p.add_argument("--tau", type=float, default=SelfPenConfig.tau)
    p.add_argument("--patience", type=int, default=SelfPenConfig.patience)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--out", default="out/selfpen_tune.json")
    p.add_argument("--combine", nargs="+", default=None, metavar="JSON",
                   help="only merge earlier tuning runs (one model each) into --out and pick the best grid point")
    a = p.parse_args(argv)
    if a.combine:
        result = combine([json.loads(Path(f).read_text()) for f in a.combine])
        Path(a.out).write_text(json.dumps(result, indent=1))
        print("best:", result["best"], "->", a.out)
        return 0
    if a.threads:
        torch.set_num_threads(a.threads)
    from .cli import parse_models

    models = parse_models(a.models)
    ck = {"volsmpl": a.checkpoint_volsmpl, "coap": a.checkpoint_coap}
    body = volsmpl.create_body()
    volumes = {m: volsmpl.attach_volume(body, checkpoint=ck[m], model=m) for m in models}
    names = None if a.cases == "all" else [n.strip() for n in a.cases.split(",") if n.strip()]
    cases = load_cases(names=names)
    base = SelfPenConfig(max_iters=a.max_iters, stop_checks=a.stop_checks, tau=a.tau, patience=a.patience)  # rest: tuned
    result = tune(body, volumes, cases, grid_configs(base, a.lr, a.w_selfpen, a.w_prior))
    result["checkpoints"] = {m: str(ck[m] or "shipped") for m in models}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(result, indent=1))
    print("best:", result["best"], "->", a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
