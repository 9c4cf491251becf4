"""A section's headline figures beside those of a record made with the models shipped before a model change.

When the shipped models change, each table's result is kept once, before it is made again, as a record
(`docs/<app>/results_previous.json`, `docs/eval_*_previous.json`): a frozen result of the earlier models, never
stale and never remade. The report then shows, per back-end, each headline figure as `before -> now`:

    lines = previous_table("hoi", {"hoi": now}, {"hoi": before})

Shape of the inputs: an app's results.json (`summary`: back-end -> {metric: value}) or a `volsmpl eval` JSON
(`metrics`, and `splits.self_contact.metrics`; IoUs as fractions, shown in %).
"""
from __future__ import annotations

__all__ = ["HEADLINES", "previous_table"]

#: section -> the headline figures compared: (key, column label, scale)
HEADLINES = {
    "hoi": (("collision_pct", "collision %", 1), ("contact_cm", "contact cm", 1), ("obj_trans_err_cm", "object cm", 1),
            ("obj_rot_err_deg", "rotation deg", 1), ("ms_per_iter", "ms per step", 1)),
    "egohmr": (("mpjpe_mm", "MPJPE mm", 1), ("pelvis_err_mm", "pelvis mm", 1), ("collision_ratio", "collision", 1),
               ("contact_pct", "contact %", 1), ("s_per_frame", "s per frame", 1)),
    "motion": (("goal_dist_m", "goal m", 1), ("collision_cm", "collision cm", 1), ("foot_skate_cm", "foot skate cm", 1),
               ("ms_per_frame_fwdbwd", "ms per frame", 1), ("ms_per_iter", "ms per step", 1)),
    "selfpen": (("collidable_after", "collidable pairs after", 1), ("collidable_left_cases", "cases left", 1),
                ("collisions_after", "pairs after", 1), ("step_ms", "ms per step", 1)),
    "eval": (("iou_mean", "mean IoU %", 100), ("iou_surf", "surf. IoU %", 100), ("iou_unif", "unif. IoU %", 100)),
}


def _fmt(v, scale) -> str:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return "-"
    v = v * scale
    return f"{v:,}" if isinstance(v, int) else f"{v:,.3g}" if abs(v) < 1 else f"{v:,.2f}"


def _rows_of(data: dict, section: str, label: str) -> dict:
    """row label -> {metric: value} of one result: its back-ends (an app) or its splits (an eval, as `label`)."""
    if section != "eval":
        return {k: v for k, v in (data.get("summary") or {}).items() if isinstance(v, dict)}
    rows = {f"{label}, standard split": data.get("metrics") or {}}
    contact = ((data.get("splits") or {}).get("self_contact") or {}).get("metrics")
    if contact:
        rows[f"{label}, self-contact split"] = contact
    return rows


def previous_table(section: str, now: dict, before: dict, labels: dict | None = None) -> list[str]:
    """Markdown lines: a table with a row per back-end (or eval split) found in both a result and its record, each
    headline figure (HEADLINES[section]) as 'before -> now'; then the record's commit. now, before: result name
    -> its JSON (pairs matched by order); labels: result name -> row label (evals). Nothing when no record is given.
    """
    pairs = [(n, now.get(n), b) for n, b in zip(now, before.values()) if b is not None and now.get(n) is not None]
    if not pairs:
        return []
    heads = HEADLINES[section]
    rows, commits = [], []
    for name, cur, old in pairs:
        label = (labels or {}).get(name, name)
        a, b = _rows_of(old, section, label), _rows_of(cur, section, label)
        for row in (r for r in b if r in a):
            rows.append([row] + [f"{_fmt(a[row].get(k), s)} -> {_fmt(b[row].get(k), s)}" for k, _, s in heads])
        meta = old.get("meta") or {}
        commits.append(str(meta.get("git_commit") or meta.get("commit") or "not recorded"))
    if not rows:
        return []
    out = ["", "Before and after the last change of the shipped models (the earlier models' result kept as a record, "
               f"made at commit {', '.join(dict.fromkeys(commits))}):", "",
           "| " + " | ".join(["back-end"] + [h for _, h, _ in heads]) + " |",
           "|" + "---|" * (len(heads) + 1)]
    return out + ["| " + " | ".join(r) + " |" for r in rows]
