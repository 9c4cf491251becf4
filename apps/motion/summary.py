"""The summary rows of `volsmpl motion`'s results.json: per model (and weight) the means of its sequences' metrics
beside the collision term's per-frame cost, for the paper's protocol (every weight on every room: Tables 5 and D.1,
plus test-room rows <model>_test) and the tuned one (the sweep on the tuning rooms, the chosen weight on the others;
tuning.py), and the text table the CLI prints.

    summary = paper_summary(records, costs, coll_frames, weights)     # records: (model, w) -> sequence records
"""
from __future__ import annotations

import numpy as np

from .tuning import CRITERION, choose_weights, split_scenes

TABLE5_COAP_W = 0.1     # Table 5's COAP row is D.1's w = 0.1 row


def wkey(model: str, w: float) -> str:
    """Summary key of a (model, weight) run: the paper's D.1 row keys ('coap_w0.01', 'coap_w0.1', 'coap_w1.0')."""
    s = f"{w:g}"
    return f"{model}_w{s if '.' in s else s + '.0'}"


def compared_weight(model: str, weights: list, choice: dict | None = None) -> float:
    """The weight of the row that compares `model` with the others: its choice on the tuning rooms when `choice`
    (model -> weight) has one, else Table 5's: COAP's w = 0.1 when swept, otherwise the first of `weights`."""
    if choice and model in choice:
        return float(choice[model])
    ws = [float(w) for w in weights]
    return TABLE5_COAP_W if TABLE5_COAP_W in ws else ws[0]


def _mean(xs):
    """Mean of the finite values of xs; None when there are none."""
    xs = [x for x in xs if x is not None and np.isfinite(x)]
    return float(np.mean(xs)) if xs else None


def summarize(records: list, cost: dict, total_mem_mb: float, coll_frames) -> dict:
    """One row: the means of the records' metrics (their finite values), the cost columns, the total memory and
    the sequence count (every record, also one whose walk has no values: status 'diverged')."""
    keys = ("goal_dist_m", "collision_cm", "collision_obstacles_cm", "collision_frames_pct", "foot_skate_cm",
            "max_depth_cm", "jerk_max", "path_m", "optim_s", "ms_per_iter")
    s = {k: _mean([r["metrics"][k] for r in records]) for k in keys}
    s.update(cost_columns(cost))
    s.update({"total_mem_mb": total_mem_mb, "n_sequences": len(records),
              "collision_frames_evaluated": coll_frames,
              "total_mem_gb": None if total_mem_mb is None else total_mem_mb / 1024})
    return s


def cost_columns(cost: dict) -> dict:
    """The summary's per-frame cost columns of a `measure_cost` result (Table 5's in the paper's units too)."""
    return {"mem_per_frame_mb": cost["mem_per_frame_fwd_mb"], "mem_per_frame_fwdbwd_mb": cost["mem_per_frame_fwdbwd_mb"],
            "ms_per_frame_fwd": cost["ms_per_frame_fwd"], "ms_per_frame_fwdbwd": cost["ms_per_frame_fwdbwd"],
            "max_frames_in_budget": cost.get("max_frames_in_budget"), "memory_kind": cost["memory_kind"],
            "frame_mem_gb": cost["mem_per_frame_fwd_mb"] / 1024, "frame_ms": cost["ms_per_frame_fwd"]}


def fit_budget(cost: dict, budget_bytes: float) -> str:
    """Record in `cost` the frames whose forward + backward fit the memory budget; the cost's one-line summary."""
    fb = cost["mem_per_frame_fwdbwd_mb"] * 2 ** 20
    cost["max_frames_in_budget"] = int(budget_bytes // fb) if fb > 0 else None
    return (f"collision term per frame: {cost['ms_per_frame_fwd']:.1f} ms fwd, {cost['ms_per_frame_fwdbwd']:.1f} ms "
            f"fwd+bwd, {cost['mem_per_frame_fwd_mb']:.1f} MB fwd, {cost['mem_per_frame_fwdbwd_mb']:.1f} MB fwd+bwd; "
            f"{cost['max_frames_in_budget']} frames fit {budget_bytes / 2 ** 30:g} GB")


def format_table(summary: dict) -> str:
    """The summary rows as the fixed-width text table the CLI prints."""
    cols = [("ms_per_frame_fwd", "ms/fr fwd", "{:.1f}"), ("ms_per_frame_fwdbwd", "ms/fr f+b", "{:.1f}"),
            ("mem_per_frame_mb", "MB/fr fwd", "{:.1f}"), ("mem_per_frame_fwdbwd_mb", "MB/fr f+b", "{:.1f}"),
            ("total_mem_mb", "total MB", "{:.0f}"), ("max_frames_in_budget", "max fr", "{}"),
            ("collision_cm", "coll cm", "{:.3f}"), ("collision_frames_pct", "coll fr %", "{:.1f}"),
            ("goal_dist_m", "goal m", "{:.3f}"), ("foot_skate_cm", "skate cm", "{:.3f}"), ("optim_s", "s/seq", "{:.0f}"),
            ("n_sequences", "n", "{}")]
    lines = ["{:14s}".format("run") + " ".join(f"{c[1]:>10s}" for c in cols)]
    for k, s in summary.items():
        lines.append(f"{k:14s}" + " ".join(f"{(c[2].format(s[c[0]]) if s.get(c[0]) is not None else '-'):>10s}"
                                           for c in cols))
    return "\n".join(lines)


def _row(recs: list, cost: dict, coll_frames, w: float, **extra) -> dict:
    """One summary row of a model's records at weight w (its total memory: the peak over the sequences that have
    one)."""
    peaks = [r["metrics"]["optim_peak_mem_mb"] for r in recs]
    s = summarize(recs, cost, max((p for p in peaks if p is not None and np.isfinite(p)), default=None), coll_frames)
    return dict(s, w=w, **extra)


def paper_summary(records: dict, costs: dict, coll_frames: dict, weights: dict) -> dict:
    """The paper's protocol (every weight on every room): summary.<model> at `compared_weight` (Table 5: COAP at
    w = 0.1, or its first weight without 0.1) and summary.<model>_w<w> (Table D.1's sweep; VolumetricSMPL's w = 1
    row beside it)."""
    summary = {}
    for (m, w), recs in records.items():
        s = _row(recs, costs[m], coll_frames[m], w)
        if w == compared_weight(m, weights[m]):
            summary[m] = s
        if m == "coap" or (m == "volsmpl" and w == 1.0):
            summary[wkey(m, w)] = dict(s)
    return summary


def tuned_summary(records: dict, choice: dict, tune: list, test: list, costs: dict, coll_frames: dict,
                  weights: dict) -> tuple[dict, dict]:
    """`volsmpl motion tune`: summary.<model> over the test rooms at the weight chosen on the tuning rooms (the rows
    that compare the models), summary.<model>_w<w> the sweep over the tuning rooms; and the tuning record."""
    summary = {}
    for m, c in choice.items():
        recs = [r for r in records[(m, c["w"])] if r["scene"] in set(test)]
        summary[m] = _row(recs, costs[m], coll_frames[m], c["w"], split="test")
        if len(weights[m]) > 1 or (m == "volsmpl" and c["w"] == 1.0):
            for w in weights[m]:
                tr = [r for r in records[(m, w)] if r["scene"] in set(tune)]
                summary[wkey(m, w)] = _row(tr, costs[m], coll_frames[m], w, split="tune")
    return summary, {"criterion": CRITERION, "tune_scenes": tune, "test_scenes": test, "protocol": "tuned",
                     "choice": {m: c["w"] for m, c in choice.items()},
                     "scores": {m: {f"{w:g}": sc for w, sc in c["scores"].items()} for m, c in choice.items()}}


def tuned_rows(summary: dict, records: dict, names: list[str], costs: dict, coll_frames: dict) -> dict | None:
    """Add to `summary` the rows '<model>_test' (the test rooms only, at the weight chosen on the tuning rooms:
    tuning.py) and return the tuning record for results.json; None (no rows) with fewer than two rooms."""
    if len(names) < 2:
        return None
    tune, test = split_scenes(names)
    choice = choose_weights(records, tune)
    for m, c in choice.items():
        recs = [r for r in records[(m, c["w"])] if r["scene"] in set(test)]
        summary[f"{m}_test"] = _row(recs, costs[m], coll_frames[m], c["w"], split="test")
    return {"criterion": CRITERION, "tune_scenes": tune, "test_scenes": test, "protocol": "paper",
            "choice": {m: c["w"] for m, c in choice.items()},
            "scores": {m: {f"{w:g}": sc for w, sc in c["scores"].items()} for m, c in choice.items()}}


