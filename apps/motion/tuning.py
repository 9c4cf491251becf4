"""Tune a collision weight on some rooms, report it on the others (the honest form of Table D.1's sweep).

The paper picks COAP's w = 0.1 for Table 5 from a sweep over the same sequences it reports (Table D.1). Here every
third generated room (the 1st, 4th, 7th, ...) tunes and the others test: per model, the weight with the lowest
`criterion` on the tuning rooms is chosen, and its row over the test rooms alone is what compares the models. A
model run at one weight is "tuned" trivially and still gets its test-split row, so that all rows cover the same
sequences.

    split = split_scenes(["room0", "room1", "room2", "room3"])   # (['room0', 'room3'], ['room1', 'room2'])
    choice = choose_weights(records, split[0])                  # {'coap': {'w': 0.1, 'scores': {...}}, ...}
"""
from __future__ import annotations

import math

import numpy as np

#: how a weight is scored on the tuning rooms (lower is better): Table 5's two outcome columns, both in metres
CRITERION = "mean goal_dist_m + mean collision_cm / 100 (the two outcomes of Table 5, in metres)"


def split_scenes(names: list[str]) -> tuple[list[str], list[str]]:
    """(tuning rooms, test rooms): every third room from the first tunes, the rest test.

    Raises ValueError for fewer than two rooms (no room would be left to test on)."""
    if len(names) < 2:
        raise ValueError(f"a tuning split needs at least 2 rooms, got {len(names)}")
    return [n for i, n in enumerate(names) if i % 3 == 0], [n for i, n in enumerate(names) if i % 3 != 0]


def criterion(records: list[dict]) -> float:
    """The tuning score of one (model, weight) over `records` (lower is better; see CRITERION); inf when a metric
    is missing or non-finite in every record."""
    goal = [r["metrics"]["goal_dist_m"] for r in records]
    coll = [r["metrics"]["collision_cm"] for r in records]
    goal = [g for g in goal if g is not None and math.isfinite(g)]
    coll = [c for c in coll if c is not None and math.isfinite(c)]
    if not goal or not coll:
        return math.inf
    return float(np.mean(goal) + np.mean(coll) / 100.0)


def choose_weights(records: dict, tune: list[str]) -> dict:
    """Per model, the weight with the lowest criterion over the tuning rooms' records.

    records: (model, w) -> per-sequence records (each with 'scene' and 'metrics'). Returns model -> {'w': chosen,
    'scores': {w: criterion}}; ties go to the smaller weight."""
    tune = set(tune)
    scores: dict = {}
    for (m, w), recs in records.items():
        scores.setdefault(m, {})[w] = criterion([r for r in recs if r["scene"] in tune])
    return {m: {"w": min(sc, key=lambda w: (sc[w], w)), "scores": sc} for m, sc in scores.items()}
