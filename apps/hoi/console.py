"""The lines `volsmpl hoi` prints: one per fitted case, and the summary beside the paper's Table 3."""
from __future__ import annotations

__all__ = ["case_line", "format_table"]


def case_line(name: str, model: str, r) -> str:
    """One fitted case's line: time per step, collisions, contact and the object's errors before -> after."""
    a, b = r.after, r.before
    num = lambda d, k: float("nan") if d.get(k) is None else d[k]  # noqa: E731 - None: not defined (a ball's rotation)
    return (f"{name:24s} {model:8s} {r.ms_per_iter:8.2f} ms/it  collision {b['collision_pct']:5.1f} -> "
            f"{a['collision_pct']:5.1f} %  contact {num(b, 'contact_cm'):6.2f} -> {num(a, 'contact_cm'):6.2f} cm  "
            f"object {num(a, 'obj_trans_err_cm'):6.2f} cm {num(a, 'obj_rot_err_deg'):5.1f} deg")


def format_table(summary: dict) -> str:
    """Our rows beside the paper's Table 3."""
    from volsmpl.report import paper
    head = f"{'':22s} {'ms/iter':>9s} {'total min':>9s} {'collision %':>12s} {'contact cm':>11s} {'obj cm':>7s} {'obj deg':>8s} {'scale %':>8s}"
    lines = [head, "-" * len(head)]
    f = lambda x, p=2: "-" if x is None else f"{x:.{p}f}"  # noqa: E731
    for m, s in summary.items():
        lines.append(f"{'ours ' + m:22s} {f(s['ms_per_iter']):>9s} {f(s['total_min'], 3):>9s} "
                     f"{f(s['collision_pct_before'], 1) + ' -> ' + f(s['collision_pct'], 1):>12s} "
                     f"{f(s['contact_cm']):>11s} {f(s['obj_trans_err_cm']):>7s} {f(s['obj_rot_err_deg'], 1):>8s} "
                     f"{f(s['scale_err_pct'], 1):>8s}")
    for key, row in paper.rows("hoi").items():
        lines.append(f"{'paper ' + key:22s} {f(row['iter_ms']):>9s} {f(row['total_min'], 2):>9s} "
                     f"{f(row['collision_pct']):>12s} {f(row['contact_cm']):>11s}")
    return "\n".join(lines)
