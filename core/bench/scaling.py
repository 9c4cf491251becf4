"""Per-body time by batch size, measured interleaved in one process: whether the per-body time at B = 8 is no higher
than at B = 1, as a controlled comparison.

The model rows of `volsmpl bench` time each (model, B) in its own process, minutes apart; on a shared machine the
drift between those runs (often 20-40 %) is larger than the effect of the batch. Here the same B bodies are
queried both ways in alternating rounds of one process: once as one batch of B, once as B queries of one body
each (every body with its own encoding), so that drift falls on both alike and the work is the same bodies and
points. Rounds alternate which way goes first.

    res = run_job("volsmpl.bench.scaling:batch_scaling_job", job, make_frames(body, 8, 60000, 1, seed=0))
    rows = scaling_rows(res)          # (head, rows) for bench_report's tables
"""
from __future__ import annotations

from typing import List, Tuple

import numpy as np
import torch

from volsmpl.bench.jobs import build_volume, start_job
from volsmpl.runtime.meter import timed_ms

__all__ = ["batch_scaling_job", "scaling_rows", "scaling_line"]


def batch_scaling_job(job: dict) -> dict:
    """Per-body times of B bodies queried as one batch and one by one, alternating (module docstring).

    job: {'spec' (bench_jobs.build_volume), 'inputs' ({'body_pose' (1, B, 69), 'points' (1, B, N, 3)}), 'device',
    'threads', 'warmup', 'repeats'}. Returns {'batch', 'points', 'rounds', 't_body_ms' and 't_query_body_ms': {'1':
    median per-body ms one by one, 'B': in one batch}, the same per round under '..._all', 'ratio_t' and
    'ratio_query' (batch over one by one)}; t: a fresh encoding + the query, t query: the query on a cached encoding.
    """
    from volsmpl.body.model import create_body

    data, res = start_job(job)
    device = torch.device(job["device"])
    body = create_body().to(device)
    vol = build_volume(body, job["spec"]).to(device)
    poses, points = data["body_pose"][0].to(device), data["points"][0].to(device)
    B, N = points.shape[:2]
    if B < 2:
        raise ValueError(f"batch_scaling_job needs a batch of at least 2 bodies, got {B}")
    with torch.no_grad():
        out = body(body_pose=poses)
        ones = [body(body_pose=poses[i:i + 1]) for i in range(B)]
        enc, encs = vol.encode(out, fresh=True), [vol.encode(o, fresh=True) for o in ones]
        ways = {
            "query_batch": lambda: vol.query_encoded(enc, points),
            "query_one": lambda: [vol.query_encoded(e, points[i:i + 1]) for i, e in enumerate(encs)],
            "full_batch": lambda: vol.query_encoded(vol.encode(out, fresh=True), points),
            "full_one": lambda: [vol.query_encoded(vol.encode(o, fresh=True), points[i:i + 1]) for i, o in enumerate(ones)],
        }
        for _ in range(int(job["warmup"])):
            for fn in ways.values():
                fn()
        times = {k: [] for k in ways}
        for r in range(int(job["repeats"])):
            order = list(ways) if r % 2 == 0 else list(reversed(ways))
            for k, t in zip(order, timed_ms([ways[k] for k in order], device)):
                times[k].append(t / B)
    med = {k: float(np.median(v)) for k, v in times.items()}
    res.update(batch=int(B), points=int(N), rounds=int(job["repeats"]),
               t_body_ms={"1": med["full_one"], str(B): med["full_batch"]},
               t_query_body_ms={"1": med["query_one"], str(B): med["query_batch"]},
               t_body_ms_all={"1": times["full_one"], str(B): times["full_batch"]},
               t_query_body_ms_all={"1": times["query_one"], str(B): times["query_batch"]},
               ratio_t=med["full_batch"] / med["full_one"], ratio_query=med["query_batch"] / med["query_one"])
    return res


def scaling_rows(s: dict) -> Tuple[List[str], List[List[str]]]:
    """Table of a batch_scaling_job result: per-body times one by one and in one batch, and their ratio."""
    B = str(s["batch"])
    head = ["time per body", "B = 1 (one by one)", f"B = {B} (one batch)", f"B = {B} / B = 1"]
    rows = [["t (fresh encoding + query) [ms]", f"{s['t_body_ms']['1']:.1f}", f"{s['t_body_ms'][B]:.1f}",
             f"{s['ratio_t']:.2f}x"],
            ["t query (cached encoding) [ms]", f"{s['t_query_body_ms']['1']:.1f}", f"{s['t_query_body_ms'][B]:.1f}",
             f"{s['ratio_query']:.2f}x"]]
    return head, rows


def scaling_line(s: dict) -> str:
    """One summary line of a batch_scaling_job result."""
    return (f"per body at B = {s['batch']} against B = 1, interleaved in one process ({s['rounds']} rounds, the same "
            f"bodies): t {s['ratio_t']:.2f}x, t query {s['ratio_query']:.2f}x")
