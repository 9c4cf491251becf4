"""Paired differences between the compared rows of a motion table, with bootstrap confidence intervals.

A walk's optimisation is chaotic: the same code on two CPUs (other float rounding) ends some sequences in other
local optima (README, "apps/motion"), so one sequence's outcome is one draw and two rows of the table differ by
more than their code does. Every model walks the same start/goal pairs, so the honest comparison pairs them: per
sequence the difference of a metric between two models, its mean and a bootstrap confidence interval of that mean
(volsmpl.apps.stats.mean_ci: scipy's BCa bootstrap), and how often each model did better (all metrics here: lower is better).

    runs = compared_runs(result)                         # label -> sequence records (results.json's cases)
    table = paired_differences(runs)                     # {'pairs': [{'a', 'b', 'n', 'metrics': {...}}], ...}
    python -m volsmpl.apps.motion.stats docs/motion/results.json --out docs/motion/paired.json
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np

from volsmpl.apps.stats import mean_ci
from volsmpl.apps.table import case_records
from volsmpl.io.outputs import write_atomic
from volsmpl.io.provenance import machine_info

from .summary import compared_weight

#: the outcome metrics compared (lower is better for each)
METRICS = ("collision_cm", "collision_frames_pct", "goal_dist_m", "foot_skate_cm")


def _by_sequence(records: list) -> dict:
    return {(r["scene"], int(r["sequence"])): r["metrics"] for r in records}


def paired_differences(runs: dict, metrics=METRICS, confidence: float = 0.95, n_resamples: int = 10000,
                       seed: int = 0) -> dict:
    """For every two runs (in `runs`' order) and metric, over the sequences both walked: the means, the mean of
    a - b with its confidence interval, and the share of sequences where a is lower, equal, higher.

    runs: label -> list of sequence records ({'scene', 'sequence', 'metrics': {metric: value}}). ValueError (one
    line) when two runs share fewer than 2 sequences or a shared sequence lacks a finite metric."""
    seqs = {label: _by_sequence(recs) for label, recs in runs.items()}
    pairs = []
    for a, b in itertools.combinations(list(runs), 2):
        common = sorted(set(seqs[a]) & set(seqs[b]))
        if len(common) < 2:
            raise ValueError(f"runs {a!r} and {b!r} share {len(common)} sequences; a paired comparison needs 2 or more")
        row = {"a": a, "b": b, "n": len(common), "metrics": {}}
        for m in metrics:
            va = np.array([seqs[a][k].get(m, np.nan) for k in common], dtype=np.float64)
            vb = np.array([seqs[b][k].get(m, np.nan) for k in common], dtype=np.float64)
            if not (np.all(np.isfinite(va)) and np.all(np.isfinite(vb))):
                raise ValueError(f"metric {m!r} is missing or not finite in some sequences of {a!r} or {b!r}")
            d = va - vb
            lo, hi = mean_ci(d, confidence, n_resamples, seed)
            row["metrics"][m] = {"mean_a": float(va.mean()), "mean_b": float(vb.mean()), "mean_diff": float(d.mean()),
                                 "ci": [lo, hi], "a_lower": float(np.mean(d < 0)), "equal": float(np.mean(d == 0)),
                                 "a_higher": float(np.mean(d > 0))}
        pairs.append(row)
    return {"confidence": confidence, "n_resamples": n_resamples, "method": "BCa bootstrap of the mean difference",
            "diff": "a - b (lower is better for every metric)", "pairs": pairs}


def compared_runs(result: dict) -> dict:
    """The rows a motion results.json compares, as label -> sequence records: under `volsmpl motion tune` (or with a
    tuning split) each model at its chosen weight on the test rooms; else Table 5's rows (COAP at w = 0.1, or its
    first weight) on every room. A walk whose optimisation stopped on NaN/Inf (status 'diverged', its metrics
    null and the optimiser's `error`) has nothing to pair and is left out (results.json flags it)."""
    cases = case_records(result.get("cases")) if isinstance(result, dict) else None
    if not cases or not all(isinstance(c, dict) and {"model", "w", "scene", "sequence", "metrics"} <= set(c)
                            for c in cases):
        raise ValueError("no per-sequence records ('cases' with model, w, scene, sequence, metrics): "
                         "give a results.json of volsmpl motion")
    tuning = result.get("tuning") or {}
    models = (result.get("config") or {}).get("models") or sorted({c["model"] for c in cases})
    weights = (result.get("config") or {}).get("weights") or {}
    runs = {}
    choice = tuning.get("choice") or {}
    for m in models:
        w = compared_weight(m, weights.get(m, [1.0]), choice)
        scenes = set(tuning["test_scenes"]) if m in choice else None
        recs = [c for c in cases if c["model"] == m and float(c["w"]) == w and (scenes is None or c["scene"] in scenes)
                and not (c["metrics"] or {}).get("error")]
        if recs:
            runs[f"{m}" if len(weights.get(m, [w])) == 1 else f"{m} (w {w:g})"] = recs
    return runs


def format_pairs(table: dict) -> str:
    """The paired differences as text lines (one per pair and metric)."""
    lines = [f"paired differences a - b, mean and {table['confidence']:.0%} CI ({table['method']}); "
             "share of sequences where a is lower / higher"]
    for p in table["pairs"]:
        for m, s in p["metrics"].items():
            lines.append(f"{p['a']:>14s} - {p['b']:<14s} {m:22s} {s['mean_a']:8.4f} - {s['mean_b']:8.4f} = "
                         f"{s['mean_diff']:+8.4f} [{s['ci'][0]:+.4f}, {s['ci'][1]:+.4f}]  n {p['n']}  "
                         f"{s['a_lower']:.0%} / {s['a_higher']:.0%}")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m volsmpl.apps.motion.stats",
                                description="Paired differences between the compared rows of a motion results.json")
    p.add_argument("results", help="a results.json of volsmpl motion")
    p.add_argument("--out", default=None, help="write the table as JSON here")
    p.add_argument("--resamples", type=int, default=10000, help="bootstrap resamples")
    args = p.parse_args(argv)
    try:
        result = json.loads(Path(args.results).read_text(encoding="utf-8"))
        table = paired_differences(compared_runs(result), n_resamples=args.resamples)
    except json.JSONDecodeError as e:
        print(f"error: {args.results} is not JSON ({e}): give a results.json of volsmpl motion", file=sys.stderr)
        return 2
    except (OSError, ValueError) as e:
        print(f"error: {args.results}: {e}", file=sys.stderr)
        return 2
    table["source"] = {"results": str(args.results), "table_commit": (result.get("meta") or {}).get("git_commit")}
    table["meta"] = machine_info("cpu")   # the code that computed these differences (the table's: source)
    print(format_pairs(table))
    if args.out:
        write_atomic(Path(args.out), json.dumps(table, indent=1) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
