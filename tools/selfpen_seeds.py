"""Gather `volsmpl selfpen` runs that differ only in the point sampler's seed into one JSON (docs/selfpen/seeds.json,
read by `volsmpl report`): each seed's summary per model, the mean over seeds of the time, memory, iteration and
collision columns, and the ratio of triangle collisions removed per second of repair, VolumetricSMPL over COAP.

    for s in 0 1 2 3; do volsmpl selfpen --model volsmpl,coap --sampler-seed $s --threads 1 --out out/selfpen_seed$s; done
    python tools/selfpen_seeds.py out/selfpen_seed0 out/selfpen_seed1 out/selfpen_seed2 out/selfpen_seed3 \
        --command "volsmpl selfpen --model volsmpl,coap --sampler-seed S --threads 1 (S = 0..3)" --out docs/selfpen/seeds.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

MEAN_KEYS = ("step_ms", "memory_gb", "iterations", "total_s", "collisions_after", "collidable_after",
             "pose_change_deg", "max_change_deg", "removed_per_s")


def gather(folders: list, command: str) -> dict:
    """The seeds JSON of the runs in `folders` (each holding a selfpen results.json); ValueError when their
    configurations other than the seed differ or a run lacks a model."""
    runs = [json.loads((Path(f) / "results.json").read_text()) for f in folders]
    config = {k: v for k, v in runs[0]["config"].items() if k != "seed"}
    per_seed = {}
    for f, r in zip(folders, runs):
        other = {k: v for k, v in r["config"].items() if k != "seed"}
        if other != config:
            raise ValueError(f"{f}: its configuration differs from {folders[0]}'s beyond the seed")
        per_seed[str(r["config"]["seed"])] = r["summary"]
    models = list(runs[0]["summary"])
    for s, summ in per_seed.items():
        if list(summ) != models:
            raise ValueError(f"seed {s}: models {list(summ)}, expected {models}")
    mean = {m: {k: sum(per_seed[s][m][k] for s in per_seed) / len(per_seed) for k in MEAN_KEYS} for m in models}
    out = {"command": command, "config": config, "per_seed": per_seed, "mean_over_seeds": mean}
    if {"volsmpl", "coap"} <= set(models):
        out["removed_per_s_ratio_volsmpl_over_coap"] = {
            s: per_seed[s]["volsmpl"]["removed_per_s"] / per_seed[s]["coap"]["removed_per_s"] for s in per_seed}
    out["meta"] = runs[0].get("meta", {})
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="+", help="output folders of `volsmpl selfpen` runs (one per seed)")
    p.add_argument("--command", required=True, help="the command line of the runs, for the record")
    p.add_argument("--out", default="docs/selfpen/seeds.json")
    a = p.parse_args(argv)
    try:
        res = gather(a.folders, a.command)
    except (OSError, ValueError, KeyError) as e:
        print(f"selfpen_seeds: {e}", file=sys.stderr)
        return 2
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(f"wrote {a.out}: seeds {list(res['per_seed'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
