"""The measurements of `volsmpl bench`, each run in a fresh Python process (`volsmpl.runtime.meter.run_isolated`).

    res = run_job("volsmpl.bench.jobs:volume_job", job, make_frames(body, 1, 60000, 7, seed=0))

`run_job` saves the input tensors to a temporary file named in the job, runs the job function in a fresh
process (so that its memory peak starts from a clean process) and returns the dict it returned; with
job['return_pred'] the job also saves its first output tensor and run_job returns it under 'pred'.

`volume_job` (per model and batch size B, and the volsmpl side of the body-body check):
  - inputs (`make_frames`): warmup + repeats frames, each B bodies (default shape, a new `sample_poses`
    pose per body and frame, no global rotation / translation) with `validation.query_points` (60k: half
    uniform in the body's box, half near the surface) per body. Posing (LBS) is not timed.
  - peak memory of an encode+query (frame 0) by `meter.peak_memory`: reported is the second call (steady
    state, after freed memory is trimmed back to the OS); the first call, which also holds one-time
    allocations (thread pools, kernels' workspaces), is kept as mem_first_call_bytes. mem_query_bytes: the
    query alone on a given encoding.
  - t_ms: median over `repeats` timed frames (after `warmup` frames) of encode + query with a fresh encoding
    (`vol.encode(out, fresh=True)`) of a new pose each frame; t_query_ms: median of the query alone on the
    encoding of frame 0. When warmup + repeats calls would exceed job['budget_s'] (judged from the memory
    calls), `fit_budget` drops the warm-up and lowers the repeats.
  - parameters, decoder evaluations per query point (pairs / (B N)) and the decoder FLOPs of one query:
    pairs x `flops_per_pair` (2 per multiply-add, latent folded into the generated biases); achieved
    GFLOP/s = decoder FLOPs / t_query (a lower bound on the decoder's rate: t_query also culls points by
    boxes, transforms them and takes the minimum over parts).

`winding_job` (paper Table C.4): exact generalised winding numbers (`groundtruth.winding_number`, float64
on the CPU) of the vertices of one posed body w.r.t. a second posed body that overlaps it
(`bodybody_inputs`): memory like volume_job, median time over repeats, the winding numbers as 'pred'.

  - per body: t_body_ms = t_ms / B and t_query_body_ms = t_query_ms / B (the batching gain, or loss).
  - `profile_query` (torch.profiler, CPU or CUDA): ops_per_query, the operator calls of one query on a cached
    encoding (top-level aten operators: an operator's own inner calls are not counted again), and
    t_decoder_ms, the time inside the volume's decoder scope (`volume.DECODER_SCOPE`), median of up to 3
    profiled queries; decoder_gflops = decoder FLOPs / t_decoder_ms is the decoder's own rate.
  - matmul_gflops_local: the fp32 matmul rate (`matmul_rate`, job['matmul_size']) measured in the job's own
    process just before and just after the profiled queries; decoder_share = decoder_gflops / their mean, the
    decoder's share of the machine's matmul rate at the moment it ran (the machine's speed drifts by tens of
    per cent within minutes, so a rate measured once at the start of a run is no yardstick for a job minutes
    later).

`matmul_rate` measures the machine's fp32 matmul rate in this process.
"""
from __future__ import annotations

import math
import os
import tempfile
from typing import List, Optional, Tuple

import numpy as np
import torch

from volsmpl.runtime.meter import Meter, peak_memory, run_isolated, timed_ms

__all__ = ["make_frames", "bodybody_inputs", "run_job", "volume_job", "winding_job", "build_volume",
           "memory_first_and_steady", "fit_budget", "start_job", "flops_per_pair", "derived", "matmul_rate", "profile_query",
           "is_top_level_op"]


# ---------------------------------------------------------------------------------------------- inputs
def make_frames(body, batch: int, n_points: int, n_frames: int, seed: int) -> dict:
    """Inputs of the per-model timing: n_frames frames of `batch` bodies, each a new `sample_poses` pose
    (default shape, no global rotation or translation), and `validation.query_points` per body.

    Returns: {'body_pose': (n_frames, batch, 69), 'points': (n_frames, batch, n_points, 3)} float32 CPU.
    """
    from volsmpl.body.poses import sample_poses
    from volsmpl.evaluation.validation_set import pose_bodies, query_points

    poses = sample_poses(n_frames * batch, seed=seed).float()
    zeros = lambda d: torch.zeros(n_frames * batch, d)
    bodies = {"betas": zeros(body.num_betas), "global_orient": zeros(3), "body_pose": poses, "transl": zeros(3)}
    verts = pose_bodies(body, bodies)
    points, _ = query_points(verts, body.faces, n_points, seed=seed)
    return {"body_pose": poses.reshape(n_frames, batch, -1), "points": points.reshape(n_frames, batch, n_points, 3)}


def bodybody_inputs(body, seed: int, n_vertices: Optional[int] = None) -> dict:
    """Two posed default bodies that overlap: A (tested) and B (the occupied volume), B shifted 25 cm along x.

    Returns: {'pose_b': (1, 69), 'transl_b': (1, 3), 'points': (1, N, 3) vertices of A, 'vertices_b': (V, 3)}.
    """
    from volsmpl.body.poses import sample_poses

    poses = sample_poses(2, seed=seed).float()
    transl_b = torch.tensor([[0.25, 0.0, 0.0]])
    with torch.no_grad():
        va = body(body_pose=poses[:1]).vertices[0]
        vb = body(body_pose=poses[1:], transl=transl_b).vertices[0]
    if n_vertices is not None and n_vertices < len(va):  # evenly spread over the body
        va = va[torch.linspace(0, len(va) - 1, n_vertices).round().long()]
    return {"pose_b": poses[1:], "transl_b": transl_b, "points": va[None].contiguous(), "vertices_b": vb}


# ---------------------------------------------------------------------------------------------- isolation
def run_job(target: str, job: dict, inputs: dict, timeout_s: float = 3600) -> dict:
    """Run a job function ('module:function') on `job` in a fresh Python process; `inputs` (tensors) travel
    through a temporary file (job['inputs']). Returns the job's dict, with 'pred' (its first output tensor)
    when job['return_pred']."""
    with tempfile.TemporaryDirectory() as tmp:
        job = dict(job, inputs=os.path.join(tmp, "inputs.pt"), pred_path=os.path.join(tmp, "pred.pt"))
        torch.save(inputs, job["inputs"])
        res = run_isolated(target, job, timeout_s=timeout_s)
        if job.get("return_pred"):
            res["pred"] = torch.load(job["pred_path"])
    return res


def start_job(job: dict) -> Tuple[dict, dict]:
    """Common start of a job: torch threads, the input tensors, the result's device and threads."""
    torch.set_num_threads(int(job["threads"]))
    data = torch.load(job["inputs"])
    return data, {"device": str(torch.device(job["device"])), "threads": torch.get_num_threads()}


# ---------------------------------------------------------------------------------------------- measurements
def memory_first_and_steady(fn, device) -> dict:
    """`meter.peak_memory` of a second call of fn (steady state), with the first call's (one-time
    allocations included) as mem_first_call_bytes."""
    first = peak_memory(fn, device)
    res = peak_memory(fn, device)
    res["mem_first_call_bytes"] = first["mem_bytes"]
    return res


def fit_budget(warmup: int, repeats: int, t_call: float, budget_s: float) -> Tuple[int, int]:
    """Warm-up and timed runs (each for the full and the query-only timing) that fit budget_s at t_call
    seconds per call; without warm-up (the memory calls before warm up) and at least 1 timed run when slow."""
    if t_call <= 0 or 2 * (warmup + repeats) * t_call <= budget_s:
        return warmup, repeats
    return 0, max(1, min(repeats, int(budget_s / (2 * t_call))))


def flops_per_pair(net) -> Optional[int]:
    """FLOPs of one (point, part) decoder evaluation of a registered network (volsmpl.volume.models)."""
    return int(net.flops_per_pair())


def derived(r: dict) -> dict:
    """Per-point decoder evaluations, decoder GFLOP per query, achieved GFLOP/s (over the whole query and, when
    profiled, over the decoder alone, and that rate's share of the matmul rate measured beside it) and per-body
    times of a volume_job result."""
    pairs, fpp = r.get("decoder_pairs"), r.get("flops_per_pair")
    out = {"evals_per_point": None, "decoder_gflop": None, "gflops": None, "decoder_gflops": None,
           "decoder_share": None, "t_body_ms": r["t_ms"] / r["batch"], "t_query_body_ms": r["t_query_ms"] / r["batch"]}
    if pairs is not None:
        out["evals_per_point"] = pairs / (r["batch"] * r["points"])
        if fpp:
            out["decoder_gflop"] = pairs * fpp / 1e9
            out["gflops"] = out["decoder_gflop"] / (r["t_query_ms"] / 1e3) if r["t_query_ms"] > 0 else None
            t_dec = r.get("t_decoder_ms")
            out["decoder_gflops"] = out["decoder_gflop"] / (t_dec / 1e3) if t_dec else None
            local = r.get("matmul_gflops_local")
            if out["decoder_gflops"] is not None and local:
                out["decoder_share"] = out["decoder_gflops"] / float(np.mean(local))
    return out


def profile_query(query, runs: int = 3, device="cpu") -> dict:
    """Operator calls of one call of `query` and the time spent in the decoder scope (volume.DECODER_SCOPE).

    Shape: query() -> anything. Returns {'ops_per_query': int (top-level aten operator calls of one call),
    'op_names': {name: calls}, 't_decoder_ms': median decoder-scope time over `runs` profiled calls (None when
    the query never enters the scope)}. On CUDA the scope's time is its kernels' device time (its CPU time
    there is only the launches)."""
    from torch.profiler import ProfilerActivity, profile

    from volsmpl.volume.learned import DECODER_SCOPE

    if runs < 1:
        raise ValueError(f"profile_query needs runs >= 1, got {runs}")
    cuda = torch.device(device).type == "cuda"
    counts, dec = [], []
    names: dict = {}
    for _ in range(runs):
        with profile(activities=[ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])) as prof:
            query()
            if cuda:
                torch.cuda.synchronize(device)
        events = prof.events()
        top = [e for e in events if e.name.startswith("aten::") and is_top_level_op(e)]
        counts.append(len(top))
        if not names:
            for e in top:
                names[e.name] = names.get(e.name, 0) + 1
        scoped = [(e.device_time_total if cuda else e.cpu_time_total) / 1e3 for e in events if e.name == DECODER_SCOPE]
        if scoped:
            dec.append(sum(scoped))
    return {"ops_per_query": int(np.median(counts)), "op_names": dict(sorted(names.items(), key=lambda kv: -kv[1])),
            "t_decoder_ms": float(np.median(dec)) if dec else None}


def is_top_level_op(event) -> bool:
    """True when no enclosing profiler event of `event` is an aten operator (a top-level operator call)."""
    parent = event.cpu_parent
    while parent is not None:
        if parent.name.startswith("aten::"):
            return False
        parent = parent.cpu_parent
    return True


def build_volume(body, spec: dict):
    """The volume a job measures: spec {'model', 'dense', 'checkpoint' (or None: random init), 'init_seed',
    optional 'engine' (Volume.engine, default 'lean'), optional 'precision' (Volume.set_precision, default 'full'),
    optional 'one_chunk' (True: every query in one chunk, decoders in their batched one-pass form), optional 'pair_decoder'
    (Volume.pair_decoder; None: the Volume's default), optional 'cuda_graphs' (Volume.cuda_graphs), 'cuda_graph_queries'
    (Volume.cuda_graph_queries), optional 'passes' (Volume.set_passes; None: all the checkpoint's)}: a benchmark
    variant's `Variant.spec` (volsmpl.bench.variants)."""
    from volsmpl.volume.attach import attach_volume

    if spec.get("checkpoint"):
        vol = attach_volume(body, model=spec["model"], checkpoint=spec["checkpoint"], dense=spec["dense"])
    else:
        torch.manual_seed(int(spec.get("init_seed", 0)))
        vol = attach_volume(body, model=spec["model"], pretrained=False, dense=spec["dense"])
    vol.engine = spec.get("engine", "lean")
    vol.set_precision(spec.get("precision", "full"))
    if spec.get("pair_decoder"):
        vol.pair_decoder = spec["pair_decoder"]
    vol.cuda_graphs = bool(spec.get("cuda_graphs", True))
    vol.cuda_graph_queries = bool(spec.get("cuda_graph_queries", False))
    if spec.get("passes") is not None:
        vol.set_passes(int(spec["passes"]))     # 0: the encoder's codes (any checkpoint, or random weights)
    if spec["dense"] or spec.get("one_chunk"):
        # the published implementations evaluate all (body, part, point) entries in one pass: no chunking,
        # no cache tiling; 'one_chunk' does the same on the sparse path
        vol.chunk_elems = vol.cpu_chunk_elems = vol.gpu_chunk_elems = 1 << 62
        vol.net.set_tile_rows(None)
    return vol


def volume_job(job: dict) -> dict:
    """Time and memory of a volume's encode+query over frames, and of the query alone (module docstring).

    job: {'spec' (see build_volume), 'inputs' ({'body_pose' (F, B, 69), 'points' (F, B, N, 3), optional
    'transl' (1, 3)}), 'device', 'threads', 'warmup', 'repeats', optional 'budget_s', 'return_pred',
    'pred_path'}."""
    import gc

    from volsmpl.body.model import create_body
    from volsmpl.nn.nbw import count_parameters

    data, res = start_job(job)
    device = torch.device(job["device"])
    body = create_body().to(device)
    vol = build_volume(body, job["spec"]).to(device)
    poses, points = data["body_pose"].to(device), data["points"].to(device)
    transl = data.get("transl")
    n_frames, B, N = points.shape[:3]
    gc.collect()
    with torch.no_grad():
        outs = [body(body_pose=poses[f], transl=None if transl is None else transl.to(device).expand(B, 3))
                for f in range(n_frames)]

        def full(f):  # a fresh encoding (bypassing the per-output cache), then the query
            return vol.query_encoded(vol.encode(outs[f], fresh=True), points[f])

        pred = {}
        with Meter(device, memory=False) as m:
            res.update(memory_first_and_steady(lambda: pred.update(v=full(0)), device))
        warm, rep = fit_budget(int(job["warmup"]), int(job["repeats"]), m.seconds / 2,
                               float(job.get("budget_s", math.inf)))
        res.update(warmup_used=warm, repeats_used=rep)
        counts = getattr(vol, "decoder_evaluations", None) is not None
        for i in range(warm):
            full(i % n_frames)
        t_full = timed_ms([lambda f=(warm + i) % n_frames: full(f) for i in range(rep)], device)
        enc = vol.encode(outs[0], fresh=True)
        query = lambda: vol.query_encoded(enc, points[0])
        for _ in range(warm):
            query()
        res["mem_query_bytes"] = peak_memory(query, device)["mem_bytes"]
        evals0 = vol.decoder_evaluations if counts else 0
        t_query = timed_ms([query] * rep, device)
        pairs = (vol.decoder_evaluations - evals0) // rep if counts else None
        size = int(job.get("matmul_size", 4096))
        before = matmul_rate(size, 1, job["device"])["gflops"]
        res.update(profile_query(query, min(3, rep), device))
        res["matmul_gflops_local"] = [before, matmul_rate(size, 1, job["device"])["gflops"]]
    if job.get("return_pred"):
        torch.save(pred["v"].cpu(), job["pred_path"])
    res.update(t_ms=float(np.median(t_full)), t_query_ms=float(np.median(t_query)), t_ms_all=t_full,
               t_query_ms_all=t_query, batch=int(B), points=int(N), params=int(count_parameters(vol.net)),
               num_parts=int(vol.num_parts), output=getattr(vol.net, "output", "sdf"), level=float(getattr(vol, "level", 0.0)),
               decoder_pairs=None if pairs is None else int(pairs), flops_per_pair=flops_per_pair(vol.net))
    res.update(derived(res))
    return res


def winding_job(job: dict) -> dict:
    """Exact winding numbers of inputs['points'] (1, N, 3) w.r.t. body B (inputs 'vertices_b', 'faces'; CPU,
    float64): memory, time over job['repeats'] runs; the values saved to job['pred_path']."""
    from volsmpl.geometry.groundtruth import winding_number

    data, res = start_job(job)
    vb, faces, pts = data["vertices_b"], data["faces"], data["points"][0]
    holder = {}
    with torch.no_grad():
        res.update(memory_first_and_steady(lambda: holder.update(w=winding_number(vb, faces, pts)), "cpu"))
        times = timed_ms([lambda: winding_number(vb, faces, pts)] * int(job["repeats"]), "cpu")
    torch.save(torch.as_tensor(holder["w"]), job["pred_path"])
    return dict(res, t_ms=float(np.median(times)), t_ms_all=times, points=int(pts.shape[0]), faces=int(len(faces)))


def matmul_rate(size: int = 4096, repeats: int = 3, device: str = "cpu") -> dict:
    """This machine's fp32 matmul rate: median time of a (size x size) @ (size x size) product (after one
    warm-up), as GFLOP/s with 2 size^3 FLOPs per product, in this process's torch threads."""
    dev = torch.device(device)
    g = torch.Generator().manual_seed(0)
    a = torch.randn(size, size, generator=g).to(dev)
    b = torch.randn(size, size, generator=g).to(dev)
    product = lambda: a @ b
    product()
    times: List[float] = timed_ms([product] * repeats, dev)
    t = float(np.median(times)) / 1e3
    return {"size": size, "t_ms": t * 1e3, "t_ms_all": times, "gflops": 2 * size ** 3 / t / 1e9,
            "threads": torch.get_num_threads(), "device": str(dev)}
