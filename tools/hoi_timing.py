"""Time per step of the human-object fit for each model kind, measured side by side in one process.

    python tools/hoi_timing.py --cases 13 --iters 100 --rounds 2 --threads 1 --out docs/hoi/timing.json

Takes the first N cases of the database's test half and, round after round, fits each case for `iters` steps with
every kind in turn (so that a change of machine load falls on all kinds alike); writes each (round, kind, case)'s
mean ms per step (the harness meter) and per kind the median over rounds of the mean over cases. The full table run
(`volsmpl hoi`) records times too, but over hours on a shared machine; this is the ratio to quote.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch


def main() -> int:
    import volsmpl
    from volsmpl.apps.hoi import database as db
    from volsmpl.apps.hoi.cli import select_cases
    from volsmpl.apps.hoi.fit import FitConfig, fit_cases
    from volsmpl.io.outputs import write_atomic
    from volsmpl.io.provenance import machine_info

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=13)
    p.add_argument("--iters", type=int, default=100)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--model", default="volsmpl,coap,mesh")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="docs/hoi/timing.json")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    folder = db.database_folder(args.seed)
    index = json.loads((folder / "index.json").read_text())
    cases = select_cases(db.load_database(folder), {c["name"]: c for c in index["cases"]}, "test", str(args.cases))
    body = volsmpl.create_body()
    models = args.model.split(",")
    volumes = {m: volsmpl.attach_volume(body, model=m) for m in models}
    cfg = FitConfig(iters=args.iters)
    rounds = []
    for r in range(args.rounds):
        row = {m: {} for m in models}
        for c in cases:
            for m in models:
                row[m][c.name] = round(fit_cases([c], body, volumes[m], cfg)[0].ms_per_iter, 2)
        rounds.append(row)
        print(f"round {r}: " + ", ".join(f"{m} {np.mean(list(row[m].values())):.1f} ms/step" for m in models))
    summary = {m: float(np.median([np.mean(list(row[m].values())) for row in rounds])) for m in models}
    result = {"command": "python tools/hoi_timing.py " + " ".join(
                  f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items()),
              "cases": [c.name for c in cases], "iters": args.iters, "ms_per_iter": summary,
              "ratio_to_volsmpl": {m: summary[m] / summary["volsmpl"] for m in models} if "volsmpl" in summary else None,
              "rounds": rounds, "meta": machine_info("cpu", args.threads)}
    write_atomic(Path(args.out), json.dumps(result, indent=1))
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
