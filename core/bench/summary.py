"""Reports of a `volsmpl bench` result: ratios between models, the paper's figures, notes, plain-text and
Markdown tables.

    from volsmpl.bench.summary import format_report, to_markdown
    print(format_report(result)); open("bench.md", "w").write(to_markdown(result))

Ratios (`compute_ratios`) are taken within one run, per batch size, for the variant pairs RATIO_PAIRS
(volsmpl.bench.variants) and for winding numbers / volsmpl in the body-body check, and shown next to the
paper's (GPU) ratios in `PAPER`. The paper measured on a GPU; CPU numbers compare only with each other.
"""
from __future__ import annotations

import math
import os
from typing import List, Optional, Tuple

from volsmpl.report import paper
from volsmpl.bench.scaling import scaling_line, scaling_rows
from volsmpl.bench.variants import RATIO_PAIRS

__all__ = ["PAPER", "RATIO_PAIRS", "compute_ratios", "caveats", "model_rows", "ratio_rows", "bodybody_rows",
           "text_table", "markdown_table", "summary_lines", "format_report", "to_markdown"]

#: the paper's figures (GPU, batch size not stated): Table 1 and supplementary Table C.4 (volsmpl.report.paper)
PAPER = paper.bench_paper()


# ---------------------------------------------------------------------------------------------- ratios
def _ratio(a, b) -> Optional[float]:
    return float(a) / float(b) if a is not None and b is not None and b > 0 and a >= 0 else None


def compute_ratios(models: dict, bodybody: Optional[dict]) -> dict:
    """Time and memory ratios of RATIO_PAIRS per batch size, and winding / volsmpl for the body-body check."""
    out = {}
    for num, den in RATIO_PAIRS:
        a, b = models.get(num, {}).get("batches", {}), models.get(den, {}).get("batches", {})
        per = {}
        for batch in sorted(set(a) & set(b), key=int):
            ra, rb = a[batch], b[batch]
            per[batch] = {"time": _ratio(ra["t_ms"], rb["t_ms"]), "time_query": _ratio(ra["t_query_ms"], rb["t_query_ms"]),
                          "mem": _ratio(ra["mem_bytes"], rb["mem_bytes"]),
                          "mem_query": _ratio(ra.get("mem_query_bytes"), rb.get("mem_query_bytes"))}
        if per:
            out[f"{num}/{den}"] = per
    if bodybody:
        w, v = bodybody["winding"], bodybody["volsmpl"]
        out["winding/volsmpl"] = {"bodybody": {"time": _ratio(w["t_ms"], v["t_ms"]),
                                               "time_query": _ratio(w["t_ms"], v["t_query_ms"]),
                                               "mem": _ratio(w["mem_bytes"], v["mem_bytes"]),
                                               "mem_query": _ratio(w["mem_bytes"], v.get("mem_query_bytes"))}}
    return out


def caveats(result: dict) -> List[str]:
    """Notes on how to read a result: CPU vs the paper's GPU, a busy machine, untrained weights, what t measures."""
    notes = []
    if not str(result["config"]["device"]).startswith("cuda"):
        notes.append("CPU run: the paper's figures are GPU time and GPU memory; compare the ratios, not the absolute values. "
                     "CPU memory is the peak RSS increase of the query process (allocator caching and page reuse make "
                     "small values noisy).")
    load = result["meta"].get("load_avg_1_5_15")
    if load and load[0] > 0.5 * (os.cpu_count() or 1):
        notes.append(f"the machine was busy (load average {load[0]} on {os.cpu_count()} cores): timings are noisy.")
    if any(a.get("status") == "untrained" for a in result.get("accuracy", {}).values()):
        notes.append("untrained models: time and memory do not depend on the weights, but the body-body agreement and "
                     "accuracy do; they are meaningful only with a trained checkpoint.")
    notes.append("t includes a fresh encoding of a new pose each frame (posing by LBS not timed); t query reuses a "
                 "cached encoding. Decoder GFLOP/s is a lower bound: t query also includes culling and transforms.")
    return notes


# ---------------------------------------------------------------------------------------------- tables
def _f(x, fmt: str) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


def _mem(b) -> str:
    if b is None:
        return "-"
    mib = b / 2 ** 20
    return f"{mib / 1024:.2f} GiB" if abs(mib) >= 1024 else f"{mib:.0f} MiB"


def _acc_cells(acc: Optional[dict]) -> List[str]:
    if not acc or acc.get("status") != "trained":
        return [acc.get("status", "-") if acc else "-", "-"]
    m = acc["metrics"]
    return [_f(100 * m["iou_mean"], "{:.2f}") if m.get("iou_mean") is not None else "-", _f(m.get("mse_sdf"), "{:.2e}")]


def model_rows(result: dict) -> Tuple[List[str], List[List[str]]]:
    """Header and rows of the per-model table."""
    head = ["model", "B", "t [ms]", "t query [ms]", "runs", "peak mem", "mem query", "params", "dec. evals/pt", "decoder GFLOP",
            "GFLOP/s", "IoU mean [%]", "MSE SDF", "t/body [ms]", "t query/body [ms]", "ops/query", "decoder GFLOP/s",
            "decoder / matmul"]
    mm = (result.get("matmul") or {}).get("gflops")
    rows = []
    for name, e in result["models"].items():
        if e["status"] != "ok":
            rows.append([name, "-", "skipped"] + [""] * (len(head) - 3))
            continue
        accs = result.get("accuracy", {})
        acc = accs.get(name, accs.get(e["model"]))   # a reduced-precision or passes variant has its own
        skipped = e.get("skipped_batches", {})
        for batch in sorted(set(e["batches"]) | set(skipped), key=int):
            if batch in skipped:
                rows.append([name, batch, "skipped (too slow)"] + [""] * (len(head) - 3))
                continue
            r = e["batches"][batch]
            rows.append([name, batch, _f(r["t_ms"], "{:.1f}"), _f(r["t_query_ms"], "{:.1f}"),
                         str(r.get("repeats_used", len(r["t_ms_all"]))), _mem(r["mem_bytes"]),
                         _mem(r.get("mem_query_bytes")), f"{r['params'] / 1e6:.2f} M", _f(r["evals_per_point"], "{:.2f}"), _f(r["decoder_gflop"], "{:.2f}"),
                         _f(r["gflops"], "{:.1f}")] + _acc_cells(acc)
                        + [_f(r.get("t_body_ms"), "{:.1f}"), _f(r.get("t_query_body_ms"), "{:.1f}"),
                           _f(r.get("ops_per_query"), "{:d}"), _f(r.get("decoder_gflops"), "{:.1f}"),
                           _f(r["decoder_share"] if r.get("decoder_share") is not None
                              else _ratio(r.get("decoder_gflops"), mm), "{:.0%}")])
    return head, rows


def ratio_rows(result: dict) -> Tuple[List[str], List[List[str]]]:
    """Header and rows of the ratio table (ours per batch size beside the paper's)."""
    head = ["ratio", "B", "time (t)", "time (t query)", "memory", "memory (query)", "paper time", "paper memory"]
    rows = []
    for key, per in result["ratios"].items():
        paper = PAPER["ratios"].get(key, {})
        for batch, r in per.items():
            rows.append([key, batch, _f(r["time"], "{:.2f}x"), _f(r["time_query"], "{:.2f}x"), _f(r["mem"], "{:.2f}x"),
                         _f(r.get("mem_query"), "{:.2f}x"), _f(paper.get("time"), "{:.1f}x"), _f(paper.get("mem"), "{:.1f}x")])
    return head, rows


def bodybody_rows(result: dict) -> Tuple[List[str], List[List[str]]]:
    """Header and rows of the body-body table (paper Table C.4)."""
    bb = result.get("bodybody")
    head = ["method", "t [ms]", "t query [ms]", "peak mem", "mem query", "inside", "paper t [ms]", "paper mem"]
    if not bb:
        return head, []
    w, v = bb["winding"], bb["volsmpl"]
    p_w, p_v = PAPER["winding_bodybody"], PAPER["volsmpl_bodybody"]
    return head, [
        ["winding numbers (exact)", _f(w["t_ms"], "{:.1f}"), "-", _mem(w["mem_bytes"]), "-", str(bb["inside_winding"]),
         f"{p_w['t_ms']:.2f}", f"{p_w['mem_gb']:.2f} GB"],
        [f"volsmpl ({bb['weights']})", _f(v["t_ms"], "{:.1f}"), _f(v["t_query_ms"], "{:.1f}"), _mem(v["mem_bytes"]),
         _mem(v.get("mem_query_bytes")), str(bb["inside_volsmpl"]), f"{p_v['t_ms']:.2f}", f"{p_v['mem_gb']:.2f} GB"],
    ]


def text_table(head: List[str], rows: List[List[str]]) -> str:
    """Aligned plain-text table."""
    widths = [max(len(str(r[i])) for r in [head] + rows) for i in range(len(head))]
    line = lambda cells: "  ".join(str(c).ljust(w) if i == 0 else str(c).rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))
    return "\n".join([line(head), line(["-" * w for w in widths])] + [line(r) for r in rows])


def markdown_table(head: List[str], rows: List[List[str]]) -> str:
    """GitHub Markdown table."""
    out = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|"]
    return "\n".join(out + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])


# ---------------------------------------------------------------------------------------------- reports
def summary_lines(result: dict) -> List[str]:
    """Machine, matmul rate, evaluate-protocol cross-check and body-body agreement, one line each."""
    m, mm = result["meta"], result["matmul"]
    lines = [f"machine: {m['cpu']} ({m['cpu_count']} cores, load {m['load_avg_1_5_15']}), device {m['device']}"
             + (f" ({m['gpu']})" if m.get("gpu") else "") + f", {m['threads']} torch threads, torch {m['torch']}, "
             f"python {m['python']}, {m['date']}, commit {m['git_commit']}",
             f"fp32 matmul {mm['size']}x{mm['size']}: {mm['t_ms']:.1f} ms = {mm['gflops']:.1f} GFLOP/s "
             f"(median of {len(mm['t_ms_all'])})"]
    ev = result.get("evaluate_protocol")
    if ev:
        lines.append(f"eval_resources.measure_resources (volsmpl, validation body 0, batch 1): t {ev['t_ms']:.1f} ms, "
                     f"t query {ev['t_query_ms']:.1f} ms, mem {_mem(ev['mem_bytes'])} ({ev['mem_method']})")
    if result.get("batch_scaling"):
        lines.append(scaling_line(result["batch_scaling"]))
    bb = result.get("bodybody")
    if bb:
        lines.append(f"body-body: {bb['vertices_tested']} vertices of body A vs body B ({bb['faces']} faces); "
                     f"winding and volsmpl agree on {100 * bb['agreement']:.2f}% ({bb['weights']} volsmpl)")
    return lines


def format_report(result: dict) -> str:
    """Plain-text report: summary, model table, ratios, body-body table, notes."""
    parts = summary_lines(result) + ["", text_table(*model_rows(result)), "", text_table(*ratio_rows(result))]
    if result.get("batch_scaling"):
        parts += ["", text_table(*scaling_rows(result["batch_scaling"]))]
    if result.get("bodybody"):
        parts += ["", text_table(*bodybody_rows(result))]
    return "\n".join(parts + [""] + [f"note: {n}" for n in result["notes"]])


def to_markdown(result: dict) -> str:
    """The Markdown report of a bench result (docs/bench_cpu.md, docs/bench_cuda.md)."""
    c = result["config"]
    out = ["# Benchmark: time, memory and cost of the volumetric body models", "",
           f"`volsmpl bench` with batch sizes {list(c['batches'])}, {c['n_points']} query points per body, median of "
           f"{c['repeats']} runs after {c['warmup']} warm-up runs.", ""]
    out += [f"- {ln}" for ln in summary_lines(result)] + ["", "## Models", "", markdown_table(*model_rows(result)), "",
            "t: fresh encoding of a new pose + query; t query: query on a cached encoding; peak mem: "
            + ("CUDA max allocated" if str(c["device"]).startswith("cuda") else "peak RSS increase of the process")
            + " during encoding + query (mem query: query on a cached encoding); dec. evals/pt: part decoders evaluated per query point; decoder GFLOP: pairs x FLOPs per decoder "
            "evaluation; GFLOP/s: decoder GFLOP / t query; runs: timed runs (fewer than asked when over the time budget); "
            "t/body: t / B; ops/query: top-level operator calls of one query (torch.profiler); decoder GFLOP/s: decoder "
            "GFLOP / the time inside the decoder (profiled); decoder / matmul: that rate over the fp32 matmul rate "
            "measured in the same process just before and after the profiled queries (their mean; results without it: "
            "over the run's rate in the header).", "", "## Ratios (same run) beside the paper's (GPU)", "",
            markdown_table(*ratio_rows(result))]
    if result.get("batch_scaling"):
        out += ["", "## Per-body time by batch size, interleaved in one process", "",
                markdown_table(*scaling_rows(result["batch_scaling"])), "",
                "The same bodies and points queried in alternating rounds as one batch and as one query per body "
                "(each with its own encoding), medians per body (volsmpl.bench.scaling): the model rows above run "
                "each batch size in its own process, minutes apart, and drift with the machine."]
    if result.get("bodybody"):
        out += ["", "## Body-body occupancy check (paper Table C.4)", "", markdown_table(*bodybody_rows(result))]
    out += ["", "## Notes", ""] + [f"- {n}" for n in result["notes"]]
    return "\n".join(out) + "\n"
