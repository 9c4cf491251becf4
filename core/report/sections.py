"""Section builders of `volsmpl report` (registry in volsmpl.report.build): each turns the result JSONs of one producer
into Markdown lines, our numbers beside the paper's (volsmpl.report.paper).

A builder is `build(ctx) -> list[str]`; ctx is a dict with
    'results'  result name -> parsed JSON, or None where that result is missing
    'paper'    the section's paper table ids (volsmpl.report.paper.TABLES keys), in order
    'name'     the section's name
Provenance, staleness, figures and missing results are written around the builder's lines by volsmpl.report.build.
"""
from __future__ import annotations

from volsmpl.report import paper as paper_tables
MIB = 2.0 ** 20
#: the widest table the report writes (columns, the row label included); further measures go to a second table
MAX_COLUMNS = 10


def fmt(v) -> str:
    """A measured number, compactly: '-' for None."""
    if v is None:
        return "-"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    a = abs(v)
    if a == 0:
        return "0"
    if a >= 100:
        return f"{v:,.1f}"
    if a >= 1:
        return f"{v:.2f}"
    if a >= 0.01:
        return f"{v:.3f}"
    return f"{v:.2e}"


def fmt_paper(v) -> str:
    """A paper number as printed (the value stored in volsmpl.report.paper)."""
    return "-" if v is None else f"{v:g}"


def md_table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table; columns whose cells all read as numbers are right-aligned."""
    num = lambda c: str(c) == "" or str(c)[:1].isdigit() or str(c)[:1] == "-"  # noqa: E731
    align = ["---:" if i and all(num(r[i]) for r in rows if i < len(r)) else "---" for i in range(len(header))]
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    return out + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]


def get_path(d, dotted: str):
    """d[a][b][c] for dotted 'a.b.c'; None where a key is missing."""
    for k in dotted.split("."):
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def paper_caption(tid: str) -> str:
    t = paper_tables.TABLES[tid]
    return f"Paper Table {tid}: {t['title'].rstrip('.')}; hardware: {t['hardware']}."


def summary_table(tid: str, groups: list[tuple[str, str, dict]], key_map: dict | None = None,
                  extra: list[str] | None = None, paper_rows: list[str] | None = None) -> list[str]:
    """Our summaries beside paper Table `tid`.

    groups: (row label, back-end key, {metric: value}); the paper's row of the same back-end key follows each
    group's first row. key_map: paper column -> our metric key where they differ. extra: more of our metric keys
    as columns (default: every numeric key of the summaries that no paper column reads); those beyond MAX_COLUMNS
    columns go to a second table of our rows. paper_rows: the paper rows to print (default: every row; the ones
    matching no group go last)."""
    t = paper_tables.TABLES[tid]
    key_map = key_map or {}
    cols = list(t["columns"])
    read = {key_map.get(c, c) for c in cols}
    if extra is None:
        extra = []
        for _, _, s in groups:
            extra += [k for k, v in s.items() if _is_num(v) and k not in read and k not in extra]
    # the paper's columns first; our further measures fill the table up to MAX_COLUMNS, the rest go to a second one
    more = extra[max(0, MAX_COLUMNS - 1 - len(cols)):]
    extra = extra[:len(extra) - len(more)]
    header = ["row"] + [f"{t['columns'][c]['label']} [{t['columns'][c]['unit']}]".replace(" []", "") for c in cols]
    header += extra
    notes = t.get("notes", {})
    wanted = list(t["rows"]) if paper_rows is None else list(paper_rows)
    rows, done = [], set()

    def paper_row(key):
        cells = [fmt_paper(t["rows"][key][c]) + ("*" if c in notes.get(key, {}) else "") for c in cols]
        rows.append([f"paper: {t['row_labels'][key]}"] + cells + [""] * len(extra))
        done.add(key)

    for label, backend, s in groups:
        rows.append([f"ours: {label}"] + [fmt(s.get(key_map.get(c, c))) for c in cols] + [fmt(s.get(k)) for k in extra])
        if backend in t["rows"] and backend in wanted and backend not in done:
            paper_row(backend)
    for key in wanted:
        if key not in done:
            paper_row(key)
    out = [paper_caption(tid), ""] + md_table(header, rows)
    for i in range(0, len(more), MAX_COLUMNS - 1):
        part = more[i:i + MAX_COLUMNS - 1]
        out += ["", "Our further measures:" if i == 0 else "And:", ""]
        out += md_table(["row"] + part, [[f"ours: {label}"] + [fmt(s.get(k)) for k in part] for label, _, s in groups])
    for key, n in notes.items():
        out += [""] + [f"\\* paper, {t['row_labels'][key]}, {t['columns'][c]['label']}: {txt}" for c, txt in n.items()]
    return out


def paper_mismatch(data: dict, tid: str) -> list[str]:
    """Lines naming the numbers where a result's own `paper` dict disagrees with volsmpl.report.paper."""
    own, t = data.get("paper"), paper_tables.TABLES[tid]
    if not isinstance(own, dict):
        return []
    bad = [f"{r}.{c}: {own[r][c]} (paper: {t['rows'][r][c]})" for r in t["rows"] if isinstance(own.get(r), dict)
           for c in t["columns"] if c in own[r] and own[r][c] != t["rows"][r][c]]
    return [f"Note: the result's own `paper` numbers differ from Table {tid}: " + "; ".join(bad) + "."] if bad else []


def n_cases(data: dict) -> int | None:
    cases = data.get("cases")
    if isinstance(cases, list):
        return len(cases)
    if isinstance(cases, dict):
        return sum(len(v) if isinstance(v, list) else 1 for v in cases.values())
    return None


def flagged_note(data: dict) -> list[str]:
    """The cases the app judged probably wrong (results.json `flagged`: diverged, object lost, worse than start,
    ...), counted by back-end and status; nothing for a result without the list (made before apps judged their
    cases)."""
    flagged = data.get("flagged")
    if not isinstance(flagged, list):
        return []
    if not flagged:
        return ["", "Flagged by the app's own judge (no ground truth): none."]
    counts = {}
    for f in flagged:
        key = (str(f.get("model")), str(f.get("status")))
        counts[key] = counts.get(key, 0) + 1
    parts = [f"{m} {st} {n}" for (m, st), n in sorted(counts.items())]
    return ["", f"Flagged by the app's own judge (no ground truth): {len(flagged)} case record(s): "
                + ", ".join(parts) + " (`flagged` in the result)."]


def refinement_note(data: dict) -> list[str]:
    """How the learned back-ends' part codes were made (results.json `config.code_refinement`: {steps, warm,
    passes, pass_every}); nothing for a result made before the apps recorded it."""
    r = (data.get("config") or {}).get("code_refinement")
    if not isinstance(r, dict):
        return []
    steps, every, n = r.get("steps") or 0, r.get("pass_every") or 1, r.get("passes")
    passes = ""
    if n:
        when = (f"at every {fmt(every)}th iteration of a fit, their correction carried between (`--pass-every "
                f"{fmt(every)}`)" if every > 1 else "at every encoding")
        passes = (f" VolumetricSMPL's codes corrected by {fmt(n)} learned pass{'' if n == 1 else 'es'} {when} "
                  f"(docs/learned_refinement.md).")
    elif every > 1:   # a result made before the apps recorded the passes
        passes = (f" VolumetricSMPL's learned passes ran at every {fmt(every)}th iteration of a fit, their correction "
                  f"carried between (`--pass-every {fmt(every)}`; docs/learned_refinement.md).")
    if not steps and n:
        return ["", "Part codes: one encoding per body and step, without fitted refinement steps." + passes]
    if not steps:
        return ["", "Part codes: the encoder's, one encoding per body and step (no code refinement)." + passes]
    how = ("carried from each iteration to the next (`--refine-warm`)" if r.get("warm")
           else "from the encoder's codes at every encoding")
    return ["", f"Part codes: {fmt(steps)} refinement step{'' if steps == 1 else 's'} per encoding, {how} "
                f"(`--refine-steps {fmt(steps)}`; docs/code_refinement.md)." + passes]


def _refine_steps(steps) -> str:
    """The cost line's words for R steps of test-time code refinement per encoding ('' for none or not recorded)."""
    return f", {fmt(steps)} refinement step{'' if steps == 1 else 's'} per encoding" if steps else ""


# ---------------------------------------------------------------------------------------------------------- builders

def eval_section(ctx) -> list[str]:
    """Table 1 accuracy from `volsmpl eval` JSONs (results 'eval_volsmpl', 'eval_coap')."""
    t = paper_tables.TABLES["1"]
    cols = [("iou_mean", 100), ("iou_surf", 100), ("iou_unif", 100), ("mse_sdf", 1), ("mse_abs_sdf", 1)]
    header = ["row", "IoU mean [%]", "IoU surf. [%]", "IoU unif. [%]", "MSE SDF [m^2]", "MSE abs SDF [m^2]",
              "MSE SDF near surface [m^2]"]
    rows, lines = [], []
    for name, label, backend in (("eval_volsmpl", "VolumetricSMPL", "volsmpl"), ("eval_coap", "COAP", "coap")):
        d = ctx["results"].get(name)
        if d is not None:
            m = d.get("metrics") or {}
            rows.append([f"ours: {label}"] + [fmt(None if m.get(k) is None else m[k] * s) for k, s in cols]
                        + [fmt(m.get("mse_sdf_surf"))])
            c = d.get("config") or {}
            lines.append(f"- {label}: {fmt(c.get('n_bodies'))} validation bodies, {fmt(c.get('n_points'))} points "
                         f"each ({c.get('sampling', 'body')} sampling, near-surface offsets "
                         f"{fmt(c.get('surface_sigma'))} m), ground-truth sign {c.get('gt_sign', 'not recorded')}, "
                         f"output {get_path(d, 'extra.output') or 'sdf'}.")
        rows.append([f"paper: {t['row_labels'][backend]}"] + [fmt_paper(t["rows"][backend][k]) for k, _ in cols]
                    + ["-"])
    rows.append([f"paper: {t['row_labels']['leap']}"] + [fmt_paper(t["rows"]["leap"][k]) for k, _ in cols] + ["-"])
    cost = ctx["results"].get("refiner_cost")
    if cost is not None:
        by = {}
        for r in cost.get("rows") or []:
            by.setdefault(r.get("B"), []).append(r)
        for B, rs_ in sorted(by.items(), key=lambda kv: str(kv[0])):
            parts = [f"{r.get('checkpoint')} ({fmt(r.get('refiner_iters'))} pass{'' if r.get('refiner_iters') == 1 else 'es'}"
                     f"{_refine_steps(r.get('refine_steps'))}): encode {fmt(r.get('encode_ms'))} ms, "
                     f"step {fmt(r.get('step_ms'))} ms" for r in rs_]
            lines.append(f"- Cost at B = {B} ({fmt(cost.get('threads'))} thread, {fmt(cost.get('points'))} points per body; "
                         f"`docs/scripts/refiner_cost.py`): " + "; ".join(parts) + ".")
    lines.append("- The paper does not publish the sampling behind its Table 1, and the surface IoU depends strongly on "
                 "the offsets' scale: `volsmpl eval --sampling parts --surface-sigma S` and the README's \"Sampling "
                 "protocols\" (docs/eval_protocols.json) give both samplings at 1-3 cm.")
    return [paper_caption("1"), ""] + md_table(header, rows) + [""] + lines


def app_cost_section(ctx) -> list[str]:
    """Each app's time per iteration with each VolumetricSMPL setting, and its ratio to the base setting's (the
    result's `base`; files without one hold `ratio_to_shipped`), from `tools/app_cost.py` (result 'app_cost'): the
    cost of a model or refinement setting as an app meets it."""
    d = ctx["results"].get("app_cost") or {}
    base = d.get("base", "shipped")
    med, work = d.get("median") or {}, d.get("workloads") or {}
    ratio = d.get("ratio_to_base", d.get("ratio_to_shipped")) or {}
    settings = list(d.get("settings") or {})
    header = ["setting"] + [f"{a} [{(work.get(a) or {}).get('unit', '?')}]" for a in med]
    rows = []
    for s in settings:
        cells = []
        for a in med:
            r = (ratio.get(a) or {}).get(s)
            cells.append(fmt(med[a].get(s)) + ("" if r is None else f" ({r:.2f}x)"))
        rows.append([f"`{s}`"] + cells)
    meta = d.get("meta") or {}
    lines = [f"Time per iteration of VolumetricSMPL in each app, the median of {len(d.get('rounds') or [])} rounds "
             f"(each round runs every setting in turn), and its ratio to `{base}`'s; "
             f"{fmt(meta.get('threads'))} thread on {meta.get('cpu', 'a CPU not recorded')}.", ""]
    lines += md_table(header, rows) + [""]
    lines += [f"- `{s}`: " + (" ".join(f) if f else "the shipped model, no flags")
              for s, f in (d.get("settings") or {}).items()]
    for a, w in work.items():
        reads = w.get("reads") or ["?"]
        lines.append(f"- {a}: `volsmpl {' '.join(w.get('command') or [])}`, reading `{reads[0]}`"
                     + (f" (kept beside it: {', '.join(map(str, reads[1:]))})" if len(reads) > 1 else ""))
    return lines


_BENCH_LABELS = {"volsmpl": "VolumetricSMPL (sparse)", "volsmpl-encoder": "VolumetricSMPL, the encoder's codes",
                 "volsmpl-dense": "VolumetricSMPL, dense", "coap": "COAP as published",
                 "coap-sparse": "COAP on our sparse engine"}


def bench_section(ctx) -> list[str]:
    """Table 1 resources and Table C.4 from `volsmpl bench` (results 'bench': the CPU run, 'bench_cuda': a GPU run)."""
    runs = [(dev, ctx["results"].get(k) or {}) for dev, k in (("cpu", "bench"), ("cuda", "bench_cuda"))]
    runs = [(dev, r) for dev, r in runs if r or dev == "cpu"]
    d = runs[0][1]
    t1, c4 = paper_tables.TABLES["1"]["rows"], paper_tables.TABLES["C.4"]["rows"]
    rows, skipped = [], []
    for dev, run in runs:
        where = (run.get("meta") or {}).get("gpu") or (run.get("meta") or {}).get("cpu") or dev
        for m, r in (run.get("models") or {}).items():
            for b, x in sorted((r.get("batches") or {}).items(), key=lambda kv: int(kv[0])):
                mem = x.get("mem_bytes")
                rows.append([f"ours ({where}): {_BENCH_LABELS.get(m, m)}", b, fmt(x.get("t_ms")),
                             fmt(x.get("t_query_ms")), fmt(None if mem is None else mem / MIB) + " MiB",
                             fmt((x.get("params") or 0) / 1e6 or None), x.get("mem_kind", "not recorded")])
            skipped += [f"- {dev}: {m}, B = {b}: {why}" for b, why in (r.get("skipped_batches") or {}).items()]
            if r.get("status") not in (None, "ok"):
                skipped.append(f"- {dev}: {m}: {r.get('status')} {r.get('error', '')}".rstrip())
    for k in ("volsmpl", "coap"):
        rows.append([f"paper: {paper_tables.TABLES['1']['row_labels'][k]}", "not stated", fmt_paper(t1[k]["t_ms"]), "-",
                     f"{fmt_paper(t1[k]['gpu_gb'])} GB", "-", "GPU memory"])
    out = [paper_caption("1") + " Time and memory of 60k query points.", ""]
    out += md_table(["row", "B", "t [ms]", "t query [ms]", "memory", "params [M]", "memory kind"], rows)
    out += ([""] + skipped if skipped else [])
    rr = []
    p_coap = (t1["coap"]["t_ms"] / t1["volsmpl"]["t_ms"], t1["coap"]["gpu_gb"] / t1["volsmpl"]["gpu_gb"])
    for pair, p_time, p_mem in (("coap/volsmpl", *p_coap), ("coap/volsmpl-encoder", *p_coap),
                                ("winding/volsmpl", c4["winding"]["t_ms"] / c4["volsmpl"]["t_ms"],
                                 c4["winding"]["mem_gb"] / c4["volsmpl"]["mem_gb"])):
        for dev, run in runs:
            for b, x in ((run.get("ratios") or {}).get(pair) or {}).items():
                rr.append([f"{pair} ({dev}), {'B = ' + b if b.isdigit() else b}", fmt(x.get("time")),
                           fmt(x.get("time_query")), fmt(x.get("mem")), f"{p_time:.1f}", f"{p_mem:.1f}"])
    if rr:
        out += ["", "Ratios within one run beside the paper's (Tables 1 and C.4):", ""]
        out += md_table(["ratio", "time", "time (cached encoding)", "memory", "paper time", "paper memory"], rr)
    bb = d.get("bodybody")
    if isinstance(bb, dict):
        w, v = bb.get("winding") or {}, bb.get("volsmpl") or {}
        mem = lambda x: fmt(None if x.get("mem_bytes") is None else x["mem_bytes"] / MIB) + " MiB"  # noqa: E731
        gb = lambda k: f"{fmt_paper(c4[k]['mem_gb'])} GB"  # noqa: E731
        out += ["", paper_caption("C.4") + f" {fmt(bb.get('vertices_tested'))} vertices of one body inside another; "
                f"agreement {fmt(bb.get('agreement'))}.", ""]
        out += md_table(["row", "t [ms]", "t cached encoding [ms]", "memory"], [
            ["ours: winding numbers (libigl)", fmt(w.get("t_ms")), "-", mem(w)],
            ["ours: VolumetricSMPL", fmt(v.get("t_ms")), fmt(v.get("t_query_ms")), mem(v)],
            ["paper: Winding Numbers", fmt_paper(c4["winding"]["t_ms"]), "-", gb("winding")],
            ["paper: VolumetricSMPL", fmt_paper(c4["volsmpl"]["t_ms"]), "-", gb("volsmpl")]])
    acc = d.get("accuracy") or {}
    if acc:
        out += ["", "Accuracy in the same run: " + ", ".join(
            f"{m} IoU mean {fmt((a.get('metrics') or {}).get('iou_mean', 0) * 100)} % ({a.get('status')})"
            for m, a in acc.items()) + "."]
    for dev, run in runs:
        if run.get("notes"):
            out += ["", f"Notes of the {dev} run:", ""] + [f"- {n}" for n in run["notes"]]
    return out


def selfpen_section(ctx) -> list[str]:
    """Table 6 from `volsmpl selfpen` (results 'selfpen', 'selfpen_seeds', 'selfpen_tune')."""
    res = ctx["results"]
    d, seeds, tune = res.get("selfpen") or {}, res.get("selfpen_seeds"), res.get("selfpen_tune")
    groups = []
    for m, s in (get_path(seeds, "mean_over_seeds") or {}).items():
        groups.append((f"{m}, mean over {len(seeds.get('per_seed') or {}) or 'all'} seeds", m, s))
    seed = get_path(d, "config.seed")
    for m, s in (d.get("summary") or {}).items():
        groups.append((f"{m}, seed {seed if seed is not None else 'not recorded'}", m, s))
    extra = ["collisions_before", "collidable_before", "collidable_after", "collidable_left_cases", "pose_change_deg",
             "max_change_deg", "largest_change_deg", "largest_still_change_deg", "limit_violations", "removed_per_s"]
    out = summary_table("6", groups, key_map={"collisions": "collisions_after"}, extra=extra)
    kinds = sorted({s.get("memory_kind") for _, _, s in groups if s.get("memory_kind")})
    preset = get_path(d, "config.preset") or d.get("preset", "not recorded")   # the envelope's config, or top level
    out += ["", f"Ours: preset {preset}, memory {', '.join(kinds) or 'not recorded'}; "
                "triangle collisions after repair (pose-induced pairs; the paper counts PROX meshes). "
                "pose_change_deg: the mean joint change; max_change_deg: the mean of each case's largest, "
                "largest_change_deg the largest of all; largest_still_change_deg: the largest change of a joint the "
                "contact does not turn (held by --hold); limit_violations: joint angles the repairs moved beyond "
                "their anatomical limits; collidable_left_cases: cases with collidable pairs left."]
    out += paper_mismatch(d, "6")
    if isinstance(tune, dict):
        best = tune.get("best") or {}
        ran = {k: (d.get("config") or {}).get(k) for k in best}
        out += ["", f"Tuning run: {len(tune.get('rows') or [])} settings over {len(tune.get('cases') or [])} cases; "
                    f"best {best}" + ("." if ran == best else f"; the table above ran {ran} (its preset).")]
    return out + flagged_note(d)


def summary_section(ctx) -> list[str]:
    """Any app writing OUT/results.json with `summary.<back-end>` = {metric: value} (back-ends 'volsmpl', 'coap',
    'mesh', ...): one table per paper table of the section; a back-end goes to the first table with a row of its
    key (e.g. 'coap_w0.1' to Table D.1), else to the first. Metric keys named as the paper's column keys line up
    with the paper's columns; other numeric metrics follow as extra columns."""
    name, tids = ctx["name"], list(ctx["paper"])
    d = ctx["results"].get(name) or {}
    summary = d.get("summary") or {}
    if not isinstance(summary, dict) or not summary:
        return ["The result has no `summary` dict (back-end -> metrics): nothing to tabulate."]
    assign = {tid: [] for tid in tids}
    for backend, s in summary.items():
        if isinstance(s, dict):
            tid = next((t for t in tids if backend in paper_tables.TABLES[t]["rows"]), tids[0])
            assign[tid].append((backend, backend, s))
    out = []
    for tid in tids:
        key_map = paper_tables.TABLES[tid].get("our_keys")
        out += ([""] if out else []) + summary_table(tid, assign[tid], key_map) + paper_mismatch(d, tid)
    out += tuning_note(d.get("tuning"))
    n = n_cases(d)
    if n is not None:
        out += ["", f"{n} per-case records in the result (`cases`)."]
    return out + refinement_note(d) + flagged_note(d)


def paired_table(p) -> list[str]:
    """The paired differences of an app's compared rows (`paired`: volsmpl.apps.motion.stats) as a Markdown table;
    none without them."""
    if not isinstance(p, dict) or not p.get("pairs"):
        return []
    rows = [[f"{q['a']} - {q['b']}", m, fmt(v["mean_a"]), fmt(v["mean_b"]),
             f"{v['mean_diff']:+.4g} [{v['ci'][0]:+.4g}, {v['ci'][1]:+.4g}]",
             f"{v['a_lower']:.0%} / {v['a_higher']:.0%}", str(q["n"])]
            for q in p["pairs"] for m, v in q["metrics"].items()]
    head = [f"Paired over the same cases ({p.get('method', 'bootstrap')}, {p.get('confidence', 0.95):.0%} interval; "
            f"{p.get('diff', 'a - b')}):", ""]
    return head + md_table(["a - b", "metric", "mean a", "mean b", "a - b [interval]", "a lower / higher", "n"], rows)


def motion_section(ctx) -> list[str]:
    """Tables 5 and D.1 from `volsmpl motion` (summary_section) and the paired differences of its compared rows
    (results 'motion_paired', else the result's own `paired`)."""
    res = ctx["results"]
    table = paired_table(res.get("motion_paired") or (res.get("motion") or {}).get("paired"))
    return summary_section(ctx) + ([""] + table if table else [])


def hoi_section(ctx) -> list[str]:
    """Table 3 from `volsmpl hoi` (summary_section), then the medians over the cases of each back-end before -> after
    the fit, overall and per kind of case (results.json `by_kind`), with the cases whose rotation error grew."""
    d = ctx["results"].get(ctx["name"]) or {}
    out = summary_section(ctx)
    summary, kinds = d.get("summary") or {}, d.get("by_kind") or {}
    cols = (("obj_rot_err_deg", "rotation [deg]"), ("contact_cm", "contact [cm]"), ("obj_trans_err_cm", "object [cm]"),
            ("collision_pct", "inside [%]"))
    arrow = lambda r, k: f"{fmt(r.get(k + '_median_before'))} -> {fmt(r.get(k + '_median'))}"  # noqa: E731
    worse = lambda m: str(sum(r.get("worse_rotation", 0) for r in (kinds.get(m) or {}).values())) if m in kinds else ""  # noqa: E731
    rows = [[m, "all", str(s.get("n_cases", "")), *[arrow(s, k) for k, _ in cols], worse(m)]
            for m, s in summary.items() if isinstance(s, dict) and "obj_rot_err_deg_median" in s]
    rows += [[m, k, str(r.get("n", "")), *[arrow(r, c) for c, _ in cols], str(r.get("worse_rotation", ""))]
             for m, per in kinds.items() for k, r in per.items()]
    if rows:
        out += ["", "Medians over the cases, first stage -> fit (each back-end; `rotation worse`: the cases whose "
                    "rotation error grew):", ""]
        out += md_table(["back-end", "kind", "n", *[c for _, c in cols], "rotation worse"], rows)
    return out


def egohmr_section(ctx) -> list[str]:
    """Table 4 from `volsmpl egohmr sample` (summary_section), then each guide's MPJPE minus the unguided sampler's,
    paired over the same frames (`mpjpe_diff_mm`, its 95 % interval), and MPJPE / contact per activity of the frames
    (results.json `by_activity`)."""
    d = ctx["results"].get(ctx["name"]) or {}
    out = summary_section(ctx)
    summary, acts = d.get("summary") or {}, d.get("by_activity") or {}
    diffs = [[g, f"{s['mpjpe_diff_mm']:+.2f} [{s['mpjpe_diff_ci95_mm'][0]:+.2f}, {s['mpjpe_diff_ci95_mm'][1]:+.2f}]",
              fmt(s.get("collision_ratio")), fmt(s.get("contact_pct"))]
             for g, s in summary.items() if isinstance(s, dict) and "mpjpe_diff_mm" in s]
    if diffs:
        out += ["", "MPJPE minus the unguided sampler's, paired over the same frames (mm, 95 % bootstrap interval):",
                ""]
        out += md_table(["guide", "MPJPE - unguided", "collision ratio", "contact [%]"], diffs)
    names = sorted({a for rows in acts.values() if isinstance(rows, dict) for a in rows})
    if names:
        guides = [g for g in acts if isinstance(acts[g], dict)]
        rows = [[a, str(next(acts[g][a]["n_frames"] for g in guides if a in acts[g])),
                 *[f"{fmt(acts[g][a].get('mpjpe_mm'))} / {fmt(acts[g][a].get('contact_pct'))}" if a in acts[g] else ""
                   for g in guides]] for a in names]
        out += ["", "MPJPE [mm] / contact [%] per activity:", ""]
        out += md_table(["activity", "frames", *guides], rows)
    return out


def tuning_note(t) -> list[str]:
    """The lines saying which rows a result tuned on which cases (`tuning`: tune_scenes, test_scenes, choice
    {back-end: weight}, criterion); none without it."""
    if not isinstance(t, dict) or not t.get("test_scenes"):
        return []
    choice = ", ".join(f"{m} w = {w:g}" for m, w in (t.get("choice") or {}).items())
    tune, test = ", ".join(t.get("tune_scenes") or []), ", ".join(t["test_scenes"])
    crit = t.get("criterion", "not recorded")
    if t.get("protocol") == "tuned":
        return ["", f"Protocol 'tuned': the rows named by back-end cover the test cases only ({test}), each at the "
                    f"weight that scored best on the tuning cases ({tune}): {choice}; rows `*_w<w>` are the sweep "
                    f"over the tuning cases. Criterion: {crit}."]
    return ["", f"Rows `*_test`: the test cases only ({test}), each back-end at the weight that scored best on the "
                f"tuning cases ({tune}): {choice}; criterion: {crit}."]
