"""Re-run checks of a long result: some of its cases made again by later code and compared value by value.

A table that took hours (an app's `results.json`) is stale for `volsmpl report` as soon as its producer code
changes, even when the change cannot touch its numbers (a new check of user input, say). Rather than take that on
trust, re-run a few of its cases with the current code and compare: `compare_results` matches the per-case records
of the stored result and of the fresh run (by their identifying fields: model, w, scene, sequence, name, frame) and
compares every value both hold, except times and memory (`IGNORED`, they differ between any two runs; a value only
the fresh run holds, a field later code adds, is listed, one only the table holds is a mismatch);
`write_check` stores the comparison beside the result as `<result>.check.json`, with the sha256 of the result file,
so that it never vouches for another one. The report then calls the result current when the check agrees, was made
at or after the producer's last change and names this very file (`check_for`).

    volsmpl hoi --model volsmpl,coap,mesh --cases sit_chair_0052,hold_cup_0060 --render 0 --out out/hoi_check
    volsmpl report --verify hoi=out/hoi_check/results.json        # writes docs/hoi/results.check.json

Agreement means every compared number within `rel_tol` (relative) or `abs_tol` (absolute) and every other value equal.

Another machine (another CPU's float rounding, amplified by an iterative sampler) can make the same code give other
values than the stored table's, so a fresh run there proves nothing about the code. A chained check (`baseline`)
compares instead two fresh runs on one machine: the current code against the code of the result's last agreeing
check (an export of its `fresh_commit`) or of the table itself (its commit). When they agree, the code change changed nothing, and the earlier check ties
that older code to the table:

    volsmpl report --verify egohmr=out/new/results.json --baseline egohmr=out/old/results.json
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

from volsmpl.io.outputs import file_sha256, write_atomic

__all__ = ["IGNORED", "ID_KEYS", "case_leaves", "compare_results", "write_check", "chain_check", "check_path",
           "check_for"]

#: per-record fields that name a case (in this order in its label)
ID_KEYS = ("model", "w", "scene", "sequence", "name", "frame")
#: leaf names that measure the run, not the result: times, memory and what is derived from them
IGNORED = re.compile(r"(^|_)(ms|s|sec|seconds|mem|mb|gb|bytes|time|wall|memory)(_|$)|per_iter|max_batch|max_frames|"
                     r"^batch$|^meta$|^date$|^git_commit$")


def _label(i: int, rec) -> str:
    if isinstance(rec, dict):
        ids = [f"{k}={rec[k]}" for k in ID_KEYS if k in rec and not isinstance(rec[k], (dict, list))]
        if ids:
            return "|".join(ids)
    return f"#{i}"


def case_leaves(cases) -> dict:
    """The records of a result's `cases` as {(case label, value path): value}: lists of records are keyed by their
    identifying fields, nested dicts by their keys (but a kind's key over records that name that kind in their
    'model' field); ignored (run-measuring) fields are left out.

    Shape: cases (dict or list, any nesting) -> {(str, str): number | str | bool | None}."""
    out: dict = {}

    def walk(obj, case: str, path: tuple):
        if isinstance(obj, dict):
            for k, v in obj.items():
                if IGNORED.search(str(k)):
                    continue
                # records grouped under the kind they name themselves ({"coap": [{"model": "coap", ...}]}) are
                # labelled by their own fields alone: the same records grouped or listed flat compare as one
                grouped = isinstance(v, list) and v and all(isinstance(x, dict) and x.get("model") == k for x in v)
                walk(v, case, path if grouped else path + (str(k),))
        elif isinstance(obj, list) and obj and all(isinstance(x, dict) for x in obj):
            for i, rec in enumerate(obj):   # a record: its identifying fields name it, they are not values
                label = _label(i, rec)
                values = rec if label.startswith("#") else {k: v for k, v in rec.items() if k not in ID_KEYS}
                walk(values or rec, "/".join(filter(None, (case, *path, label))), ())
        elif isinstance(obj, list):
            for i, v in enumerate(obj):
                walk(v, case, path + (str(i),))
        else:
            out[(case, "/".join(path))] = obj
    walk(cases, "", ())
    return out


def _differ(a, b, rel_tol: float, abs_tol: float) -> float | None:
    """None when a and b agree, else how far apart (inf for values of other kinds)."""
    num = (int, float)
    if isinstance(a, num) and isinstance(b, num) and not isinstance(a, bool) and not isinstance(b, bool):
        if math.isnan(a) and math.isnan(b):
            return None
        if math.isclose(a, b, rel_tol=rel_tol, abs_tol=abs_tol):
            return None
        return abs(a - b) if math.isfinite(a) and math.isfinite(b) else math.inf
    return None if a == b else math.inf


def compare_results(stored: dict, fresh: dict, rel_tol: float = 1e-6, abs_tol: float = 1e-9) -> dict:
    """Compare the per-case records of a fresh run (a subset of the cases) with the stored result's.

    Returns {'agree', 'cases_compared', 'cases_total', 'values_compared', 'max_abs_diff', 'mismatches' (the first 10:
    case, value, stored, fresh), 'missing' (fresh cases the stored result lacks), 'added' (the first 10 names) and
    'n_added': values of shared cases that only the fresh run records (fields later code adds: not compared, listed),
    'rel_tol', 'abs_tol'}. A value of a shared case that the stored result has and the fresh run lacks is a mismatch.
    ValueError (one line) when either has no 'cases' or they share no case."""
    for name, d in (("stored", stored), ("fresh", fresh)):
        if not isinstance(d, dict) or not d.get("cases"):
            raise ValueError(f"the {name} result has no per-case records ('cases'): compare two results of the same app")
    old, new = case_leaves(stored["cases"]), case_leaves(fresh["cases"])
    old_cases, new_cases = {c for c, _ in old}, {c for c, _ in new}
    common = sorted(new_cases & old_cases)
    if not common:
        raise ValueError(f"the fresh run shares no case with the stored result (fresh: {sorted(new_cases)[:3]} ..., "
                         f"stored: {sorted(old_cases)[:3]} ...): re-run cases of the stored table")
    mismatches, added, worst, n = [], [], 0.0, 0
    for (case, path), v in sorted(new.items(), key=lambda kv: kv[0]):
        if case not in old_cases:
            continue
        if (case, path) not in old:  # a value later code records and the table predates: nothing to disagree with
            added.append(path)
            continue
        n += 1
        s = old.get((case, path), "<absent>")
        d = _differ(s, v, rel_tol, abs_tol)
        if d is not None:
            worst = max(worst, d)
            mismatches.append({"case": case, "value": path, "stored": s, "fresh": v})
    for (case, path), s in sorted(old.items(), key=lambda kv: kv[0]):  # a value of the table the code no longer makes
        if case in new_cases and (case, path) not in new:
            n += 1
            mismatches.append({"case": case, "value": path, "stored": s, "fresh": "<absent>"})
    return {"agree": not mismatches and n > 0, "cases_compared": len(common), "cases_total": len(old_cases),
            "values_compared": n, "max_abs_diff": worst if mismatches else 0.0, "mismatches": mismatches[:10],
            "n_mismatches": len(mismatches), "missing": sorted(new_cases - old_cases)[:10],
            "added": sorted(set(added))[:10], "n_added": len(added), "rel_tol": rel_tol, "abs_tol": abs_tol}


def check_path(result: Path) -> Path:
    """Where the check of a result file lives: beside it, `<stem>.check.json`."""
    result = Path(result)
    return result.with_name(result.stem + ".check.json")


def write_check(result: Path, fresh_path: Path, rel_tol: float = 1e-6, abs_tol: float = 1e-9) -> dict:
    """Compare the fresh run's results.json with the stored `result` and write the check beside it; returns it."""
    stored, fresh = (json.loads(Path(p).read_text(encoding="utf-8")) for p in (result, fresh_path))
    check = compare_results(stored, fresh, rel_tol, abs_tol)
    meta = fresh.get("meta", {}) if isinstance(fresh.get("meta"), dict) else {}
    check.update({"result": Path(result).name, "result_sha256": file_sha256(result), "fresh": str(fresh_path),
                  "fresh_commit": meta.get("git_commit"), "fresh_date": meta.get("date"),
                  "stored_commit": (stored.get("meta") or {}).get("git_commit")})
    write_atomic(check_path(result), json.dumps(check, indent=1, default=str) + "\n")
    return check


def _meta(d: dict) -> dict:
    return d.get("meta") if isinstance(d.get("meta"), dict) else {}


def chain_check(result: Path, fresh_path: Path, baseline_path: Path, rel_tol: float = 1e-6,
                abs_tol: float = 1e-9) -> dict:
    """A chained check (module docstring): the fresh run against `baseline_path`, a run on the same machine of the
    code of the result's current agreeing check (or of the table itself); written beside the result like `write_check`'s, with the earlier
    check under 'chained_from' and how the baseline differs from the stored table (the machine, not the code) under
    'machine'. ValueError (one line) when there is no agreeing check to chain from, the baseline was made by other
    code than that check's (or the table's own), or the two runs were made on different machines. Without an agreeing
    check the baseline must be a run of the table's own code."""
    stored, fresh, base = (json.loads(Path(p).read_text(encoding="utf-8")) for p in (result, fresh_path, baseline_path))
    previous = check_for(result)
    # the code tied to the table: its own commit, and that of its last agreeing check
    anchors = {"the table itself": {"fresh_commit": _meta(stored).get("git_commit")}}
    if previous is not None and previous.get("agree"):
        anchors["its last agreeing check"] = previous
    made = str(_meta(base).get("git_commit") or "")
    tie = next(((what, c) for what, c in anchors.items()
                if c.get("fresh_commit") and made[:7] == str(c["fresh_commit"])[:7]), None)
    if tie is None:
        at = " or ".join(f"{c['fresh_commit']} ({what})" for what, c in anchors.items() if c.get("fresh_commit"))
        raise ValueError(f"--baseline {baseline_path} was made at {made or 'an unrecorded commit'}; the code tied to "
                         f"{Path(result).name} is {at or 'not recorded'}: make the baseline from an export of it")
    previous = tie[1]
    where = lambda d: (_meta(d).get("cpu"), _meta(d).get("platform"))  # noqa: E731
    if where(base) != where(fresh) or None in where(fresh):
        raise ValueError(f"--baseline {baseline_path} and the fresh run must come from the same machine; they name "
                         f"{where(base)} and {where(fresh)}")
    check = compare_results(base, fresh, rel_tol, abs_tol)
    table = compare_results(stored, base, rel_tol, abs_tol)
    check.update({"result": Path(result).name, "result_sha256": file_sha256(result), "fresh": str(fresh_path),
                  "fresh_commit": _meta(fresh).get("git_commit"), "fresh_date": _meta(fresh).get("date"),
                  "stored_commit": _meta(stored).get("git_commit"), "cases_total": table["cases_total"],
                  "baseline": {"path": str(baseline_path), "commit": _meta(base).get("git_commit")},
                  "chained_from": {k: previous.get(k) for k in ("fresh_commit", "fresh_date", "cases_compared",
                                                                  "values_compared", "stored_commit", "chained_from")},
                  "machine": {"cpu": _meta(fresh).get("cpu"), "stored_cpu": _meta(stored).get("cpu"),
                              "baseline_vs_table_mismatches": table["n_mismatches"],
                              "baseline_vs_table_max_abs_diff": table["max_abs_diff"]}})
    write_atomic(check_path(result), json.dumps(check, indent=1, default=str) + "\n")
    return check


def check_for(result: Path) -> dict | None:
    """The check stored beside `result` when it describes this very file (same sha256), else None."""
    p = check_path(result)
    if not p.exists():
        return None
    try:
        check = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return check if check.get("result_sha256") == file_sha256(result) else None
