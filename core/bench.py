"""Resource benchmark of the volumetric body models (paper Table 1 resources, Table 2 costs, Table B.4).

    volsmpl bench [--device cpu|cuda] [--batch 1 8] [--points 60000] [--repeats 5] [--threads N]
                  [--models volsmpl,volsmpl-dense,coap,coap-sparse] [--checkpoint-volsmpl P] [--checkpoint-coap P]
                  [--out bench.json] [--markdown docs/bench_cpu.md] [--quick]
    from volsmpl.bench import BenchConfig, run_bench; res = run_bench(BenchConfig(batches=(1,), n_points=2000))

Models (`MODELS`): 'volsmpl' (sparse engine: decoders only on (point, part) pairs inside part boxes),
'volsmpl-dense' (the reference path: every part decoder on every point), 'coap' (COAP as published: every part
on every point, i.e. dense) and 'coap-sparse' (COAP's network on the sparse engine). COAP entries are skipped
with a note while `attach_volume(body, model='coap')` is not available.

Per model and batch size B, in a fresh Python subprocess per measurement (`_worker`):
  - inputs: warmup + repeats frames, each B bodies (default shape, a new `sample_poses` pose per body and
    frame, no global rotation / translation) with `evaluate.query_points` (60k: half uniform in the body's box,
    half near the surface) per body. Posing (LBS) is not timed.
  - peak memory of an encode+query (frame 0), measured like `evaluate.measure_resources` (whose helpers it
    reuses): CUDA max_memory_allocated minus what was allocated before, or on CPU the peak RSS increase
    (ru_maxrss when the query sets the process's high-water mark, else RSS polled every 0.2 ms). Reported:
    the second call (steady state, after freed memory is trimmed back to the OS); the first call, which also
    holds one-time allocations (thread pools, kernels' workspaces), is kept as mem_first_call_bytes.
    evaluate.measure_resources reports the first call.
  - t_ms: median over `repeats` timed frames (after `warmup` frames) of encode + query with a fresh encoding
    of a new pose each frame; t_query_ms: median of the query alone on a cached encoding (frame 0).
  - parameters of the network, decoder evaluations per query point (pairs / (B N)), and the decoder FLOPs
    of one query: pairs x `flops_per_pair()` (2 per multiply-add, latent folded into the generated
    biases); achieved GFLOP/s = decoder FLOPs / t_query (a lower bound on the decoder's rate: t_query also
    culls points by boxes, transforms them and takes the minimum over parts).
`measure_resources` itself (evaluate's protocol: validation body 0, batch 1, sparse volsmpl) is run as a
cross-check of the volsmpl batch-1 row (`evaluate_protocol`).

Body-body occupancy check (paper Table B.4): the vertices of one posed default body (13,348) tested inside a
second posed body that overlaps it: exact generalised winding numbers (`groundtruth.winding_number` > 1/2,
float64 on the CPU, in blocks of 2M point-triangle pairs) vs `vol.query(...) < 0` (encoding included and
excluded), each in its own subprocess; their agreement is the fraction of vertices with the same
inside/outside label (meaningful only for a trained checkpoint).

Accuracy: `evaluate` (IoU, MSE) on the validation set when a trained checkpoint of the model exists
(default `volume.DEFAULT_CHECKPOINTS`); otherwise 'untrained'. Skipped with --quick.

Ratios (`ratios`) are computed within one run, per batch size, next to the paper's (GPU) ratios in `PAPER`.
The paper measured on a GPU; CPU numbers compare only with each other. On a CPU shared with other busy
processes use `--threads 1` (or the number of idle cores): spinning OpenMP threads can slow a query many times.
"""
from __future__ import annotations

import dataclasses
import datetime
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch

#: benchmark model name -> (model given to attach_volume, dense query path)
MODELS: Dict[str, Tuple[str, bool]] = {
    "volsmpl": ("volsmpl", False),
    "volsmpl-dense": ("volsmpl", True),  # the paper's implementation: every part on every point, one pass
    "coap": ("coap", True),          # COAP as published evaluates every part on every point, in one pass
    "coap-sparse": ("coap", False),  # COAP's network on our sparse engine
}

#: the paper's figures (GPU, batch size not stated): Table 1 and supplementary Table B.4
PAPER = {
    "volsmpl": {"t_ms": 15.0, "mem_gb": 3.1},
    "coap": {"t_ms": 140.0, "mem_gb": 18.7},
    "winding_bodybody": {"t_ms": 464.41, "mem_gb": 15.58},
    "volsmpl_bodybody": {"t_ms": 11.06, "mem_gb": 0.27},
    "ratios": {
        "coap/volsmpl": {"time": 140.0 / 15.0, "mem": 18.7 / 3.1},
        "winding/volsmpl": {"time": 464.41 / 11.06, "mem": 15.58 / 0.27},
    },
}

#: (numerator, denominator) model pairs whose time and memory ratios are reported per batch size
RATIO_PAIRS = [("coap", "volsmpl"), ("coap-sparse", "volsmpl"), ("volsmpl-dense", "volsmpl"), ("coap", "coap-sparse")]


@dataclass
class BenchConfig:
    """Settings of one benchmark run (defaults: the full run of the module docstring).

    Attributes:
        models: benchmark model names (keys of MODELS). batches: batch sizes B.
        n_points: query points per body (60k as in Table 1). repeats / warmup: timed / untimed frames.
        threads: torch CPU threads (None: this process's torch.get_num_threads()). device: 'cpu' or 'cuda'.
        checkpoints: model ('volsmpl' / 'coap') -> checkpoint path; missing: volume.DEFAULT_CHECKPOINTS if present.
        seed: poses and points. init_seed: weights of untrained networks.
        accuracy: IoU/MSE on the validation set for trained checkpoints. n_bodies: validation bodies.
        bodybody: run the body-body check. bodybody_vertices: test only N evenly spread vertices of body A (None: all).
        winding_repeats: timed winding-number runs (each takes seconds on a CPU).
        matmul_size / matmul_repeats: the fp32 matmul used to measure the machine's FLOP rate.
        evaluate_check: also run evaluate.measure_resources (volsmpl, batch 1) as a cross-check.
        budget_s: wall-time budget of one (model, batch) measurement: when warmup + repeats calls would exceed
            it (judged from the first call), the worker drops the warm-up (the two memory calls warm up) and
            lowers repeats (at least 1); the counts used are reported.
        max_mem_fraction: skip a (model, batch) whose query memory, extrapolated linearly in B from the
            smaller batch, would exceed this fraction of the machine's (or GPU's) memory.
        max_call_s: skip a (model, batch) whose single encode+query, extrapolated linearly in B from the
            model's smaller batch, would exceed this (dense COAP at B=8 takes minutes per call on a CPU).
        timeout_s: limit of each subprocess.
    """

    models: Tuple[str, ...] = ("volsmpl", "volsmpl-dense", "coap", "coap-sparse")
    batches: Tuple[int, ...] = (1, 8)
    n_points: int = 60000
    repeats: int = 5
    warmup: int = 2
    threads: Optional[int] = None
    device: str = "cpu"
    checkpoints: Dict[str, Optional[str]] = field(default_factory=dict)
    seed: int = 0
    init_seed: int = 0
    accuracy: bool = True
    n_bodies: int = 64
    bodybody: bool = True
    bodybody_vertices: Optional[int] = None
    winding_repeats: int = 2
    matmul_size: int = 4096
    matmul_repeats: int = 3
    evaluate_check: bool = True
    budget_s: float = 120.0
    max_call_s: float = 60.0
    max_mem_fraction: float = 0.5
    timeout_s: int = 3600

    def __post_init__(self):
        self.models, self.batches = tuple(self.models), tuple(int(b) for b in self.batches)
        unknown = [m for m in self.models if m not in MODELS]
        if unknown:
            raise ValueError(f"unknown model(s) {unknown}; choose from {list(MODELS)}.")
        if not self.models or not self.batches:
            raise ValueError("give at least one model and one batch size.")
        for name in ("n_points", "repeats", "n_bodies", "winding_repeats", "matmul_size", "matmul_repeats"):
            _positive(f"BenchConfig.{name}", getattr(self, name))
        for b in self.batches:
            _positive("batch size", b)
        if not (self.budget_s > 0 and self.max_call_s > 0):
            raise ValueError(f"BenchConfig.budget_s={self.budget_s} and max_call_s={self.max_call_s} must be > 0 seconds.")
        if not isinstance(self.warmup, int) or self.warmup < 0:
            raise ValueError(f"BenchConfig.warmup must be an integer >= 0, got {self.warmup!r}.")
        if self.threads is not None:
            _positive("BenchConfig.threads", self.threads)
        if self.bodybody_vertices is not None:
            _positive("BenchConfig.bodybody_vertices", self.bodybody_vertices)
        if self.device not in ("cpu", "cuda") and not str(self.device).startswith("cuda:"):
            raise ValueError(f"BenchConfig.device={self.device!r}: use 'cpu' or 'cuda'.")
        bad = sorted(set(self.checkpoints) - {"volsmpl", "coap"})
        if bad:
            raise ValueError(f"checkpoints for {bad}: give them for 'volsmpl' or 'coap'.")


def _positive(name: str, v) -> None:
    if not isinstance(v, int) or isinstance(v, bool) or v < 1:
        raise ValueError(f"{name} must be a positive integer, got {v!r}.")


# ---------------------------------------------------------------------------------------------- environment
def machine_info(cfg: BenchConfig) -> dict:
    """Where and when the benchmark ran: CPU model, cores, load, GPU, threads, versions, date, git commit."""
    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as fh:
            names = [ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")]
        cpu = names[0] if names else cpu
    except OSError:
        pass
    info = {
        "cpu": cpu, "cpu_count": os.cpu_count(), "load_avg_1_5_15": _load_avg(),
        "platform": platform.platform(), "python": platform.python_version(), "torch": torch.__version__,
        "device": cfg.device, "threads": cfg.threads or torch.get_num_threads(),
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"), "git_commit": _git_commit(),
    }
    if str(cfg.device).startswith("cuda") and torch.cuda.is_available():
        info["gpu"] = torch.cuda.get_device_name(torch.device(cfg.device))
    return info


def _load_avg():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def _git_commit() -> Optional[str]:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).resolve().parent,
                             capture_output=True, text=True, timeout=10)
        return out.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def matmul_rate(size: int = 4096, repeats: int = 3, device: str = "cpu") -> dict:
    """This machine's fp32 matmul rate: median time of a (size x size) @ (size x size) product (after one
    warm-up), as GFLOP/s with 2 size^3 FLOPs per product, in this process's torch threads."""
    dev = torch.device(device)
    g = torch.Generator().manual_seed(0)
    a = torch.randn(size, size, generator=g).to(dev)
    b = torch.randn(size, size, generator=g).to(dev)
    a @ b
    _sync(dev)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        a @ b
        _sync(dev)
        times.append(time.perf_counter() - t0)
    t = float(np.median(times))
    return {"size": size, "t_ms": t * 1e3, "t_ms_all": [x * 1e3 for x in times], "gflops": 2 * size ** 3 / t / 1e9,
            "threads": torch.get_num_threads(), "device": str(dev)}


# ---------------------------------------------------------------------------------------------- models
def model_available(model: str) -> Tuple[bool, str]:
    """Whether attach_volume builds `model` ('volsmpl' / 'coap') in this checkout; (False, reason) if not."""
    from .body.model import create_body
    from .volume import attach_volume

    try:
        attach_volume(create_body(), model=model, pretrained=False)
    except (ValueError, NotImplementedError, ImportError, KeyError) as e:
        return False, f"attach_volume(body, model={model!r}) is not available in this checkout ({type(e).__name__}: {e})"
    return True, ""


def checkpoint_for(model: str, cfg: BenchConfig) -> Optional[str]:
    """Checkpoint path (without .safetensors) of a base model: the configured one (must exist), else the
    default one if it exists, else None (untrained)."""
    from .volume import DEFAULT_CHECKPOINTS

    given = cfg.checkpoints.get(model)
    if given:
        p = Path(given)
        stem = p.with_suffix("") if p.suffix == ".safetensors" else p
        if not Path(str(stem) + ".safetensors").exists():
            raise FileNotFoundError(f"checkpoint {given} for {model!r} not found (looked for {stem}.safetensors).")
        return str(stem)
    default = DEFAULT_CHECKPOINTS.get(model)
    if default is not None and Path(str(default) + ".safetensors").exists():
        return str(default)
    return None


def _build_volume(body, spec: dict):
    """The volume a worker measures: spec {'model', 'dense', 'checkpoint' (or None: random init), 'init_seed'}."""
    from .volume import attach_volume

    if spec.get("checkpoint"):
        vol = attach_volume(body, model=spec["model"], checkpoint=spec["checkpoint"], dense=spec["dense"])
    else:
        torch.manual_seed(int(spec.get("init_seed", 0)))
        vol = attach_volume(body, model=spec["model"], pretrained=False, dense=spec["dense"])
    if spec["dense"]:
        # the published implementations evaluate all (body, part, point) entries in one pass: no chunking,
        # no cache tiling
        vol.chunk_elems = 1 << 62
        if hasattr(vol.net, "TILE_ROWS"):
            vol.net.TILE_ROWS = 1 << 62
    return vol


# ---------------------------------------------------------------------------------------------- inputs
def make_frames(body, batch: int, n_points: int, n_frames: int, seed: int) -> dict:
    """Inputs of the per-model timing: n_frames frames of `batch` bodies, each a new `sample_poses` pose
    (default shape, no global rotation or translation), and `evaluate.query_points` per body.

    Returns: {'body_pose': (n_frames, batch, 69), 'points': (n_frames, batch, n_points, 3)} float32 CPU.
    """
    from .body.poses import sample_poses
    from .evaluate import pose_bodies, query_points

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
    from .body.poses import sample_poses

    poses = sample_poses(2, seed=seed).float()
    transl_b = torch.tensor([[0.25, 0.0, 0.0]])
    with torch.no_grad():
        va = body(body_pose=poses[:1]).vertices[0]
        vb = body(body_pose=poses[1:], transl=transl_b).vertices[0]
    if n_vertices is not None and n_vertices < len(va):  # evenly spread over the body
        va = va[torch.linspace(0, len(va) - 1, n_vertices).round().long()]
    return {"pose_b": poses[1:], "transl_b": transl_b, "points": va[None].contiguous(), "vertices_b": vb}


# ---------------------------------------------------------------------------------------------- subprocess
def run_worker(job: dict, inputs: dict, timeout_s: int = 3600) -> dict:
    """Run `_worker` on `job` in a fresh Python subprocess; inputs (tensors) travel through a temporary file.
    Returns the worker's JSON result (with 'pred': the first frame's output tensor when job['return_pred'])."""
    with tempfile.TemporaryDirectory() as tmp:
        job = dict(job, inputs=os.path.join(tmp, "inputs.pt"), pred_path=os.path.join(tmp, "pred.pt"))
        torch.save(inputs, job["inputs"])
        proc = subprocess.run([sys.executable, "-c", "import sys; from volsmpl.bench import _worker; _worker(sys.argv[1])",
                               json.dumps(job)], capture_output=True, text=True, timeout=timeout_s)
        if proc.returncode != 0:
            raise RuntimeError(f"benchmark subprocess ({job['kind']}) failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
        res = json.loads(proc.stdout.strip().splitlines()[-1])
        if job.get("return_pred"):
            res["pred"] = torch.load(job["pred_path"])
    return res


def _peak_memory(fn, device: torch.device) -> dict:
    """Peak memory of one call of fn (the approach of evaluate._resource_worker, whose helpers it uses)."""
    from .evaluate import _malloc_trim, _maxrss_bytes, _rss_bytes, _RssSampler

    if device.type == "cuda":
        _sync(device)
        torch.cuda.reset_peak_memory_stats(device)
        base = torch.cuda.memory_allocated(device)
        fn()
        _sync(device)
        peak = torch.cuda.max_memory_allocated(device)
        return {"mem_bytes": int(peak - base), "mem_total_bytes": int(peak), "mem_kind": "cuda max_memory_allocated",
                "mem_method": "torch.cuda.max_memory_allocated"}
    _malloc_trim()
    base, peak0 = _rss_bytes(), _maxrss_bytes()
    with _RssSampler() as sampler:
        fn()
    peak1 = _maxrss_bytes()
    if peak1 > peak0:  # the call set a new high-water mark of the process: exact
        return {"mem_bytes": int(peak1 - base), "mem_total_bytes": int(peak1), "mem_kind": "cpu peak RSS increase",
                "mem_method": "ru_maxrss"}
    return {"mem_bytes": int(sampler.peak - base), "mem_total_bytes": int(sampler.peak), "mem_kind": "cpu peak RSS increase",
            "mem_method": f"RSS sampled every {sampler.interval * 1e3:g} ms"}


def _memory_first_and_steady(fn, device: torch.device) -> dict:
    """_peak_memory of a second call of fn (steady state), with the first call's (one-time allocations
    included) as mem_first_call_bytes."""
    first = _peak_memory(fn, device)
    res = _peak_memory(fn, device)
    res["mem_first_call_bytes"] = first["mem_bytes"]
    return res


def _fit_budget(warmup: int, repeats: int, t_call: float, budget_s: float) -> Tuple[int, int]:
    """Warm-up and timed runs (each for the full and the query-only timing) that fit budget_s at t_call
    seconds per call; without warm-up (the memory calls before warm up) and at least 1 timed run when slow."""
    if t_call <= 0 or 2 * (warmup + repeats) * t_call <= budget_s:
        return warmup, repeats
    return 0, max(1, min(repeats, int(budget_s / (2 * t_call))))


def _timed_ms(fns, device: torch.device) -> List[float]:
    """Wall time (ms) of each call in fns, synchronised."""
    out = []
    for fn in fns:
        _sync(device)
        t0 = time.perf_counter()
        fn()
        _sync(device)
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def _worker(job_json: str) -> None:
    """Body of a benchmark subprocess: job['kind'] 'volume' (model timing / body-body query) or 'winding'.
    Prints one JSON line."""
    import gc

    job = json.loads(job_json)
    torch.set_num_threads(int(job["threads"]))
    device = torch.device(job["device"])
    data = torch.load(job["inputs"])
    res = {"device": str(device), "threads": torch.get_num_threads()}
    with torch.no_grad():
        if job["kind"] == "winding":
            res.update(_winding_job(job, data))
        elif job["kind"] == "volume":
            gc.collect()
            res.update(_volume_job(job, data, device))
        else:
            raise ValueError(f"unknown benchmark job kind {job['kind']!r}")
    print(json.dumps(res))


def _winding_job(job: dict, data: dict) -> dict:
    """Exact winding numbers of data['points'] (1, N, 3) w.r.t. body B (CPU, float64): memory, time, values."""
    from .groundtruth import winding_number

    vb, faces, pts = data["vertices_b"], data["faces"], data["points"][0]
    holder = {}
    res = _memory_first_and_steady(lambda: holder.update(w=winding_number(vb, faces, pts)), torch.device("cpu"))
    times = _timed_ms([lambda: winding_number(vb, faces, pts)] * int(job["repeats"]), torch.device("cpu"))
    torch.save(torch.as_tensor(holder["w"]), job["pred_path"])
    return dict(res, t_ms=float(np.median(times)), t_ms_all=times, points=int(pts.shape[0]), faces=int(len(faces)))


def _volume_job(job: dict, data: dict, device: torch.device) -> dict:
    """Time and memory of a volume's encode+query over frames, and of the query alone (see module docstring)."""
    from .body.model import create_body
    from .nn.nbw import count_parameters

    body = create_body().to(device)
    vol = _build_volume(body, job["spec"]).to(device)
    poses, points = data["body_pose"].to(device), data["points"].to(device)
    transl = data.get("transl")
    n_frames, B, N = points.shape[:3]
    with torch.no_grad():
        outs = [body(body_pose=poses[f], transl=None if transl is None else transl.to(device).expand(B, 3))
                for f in range(n_frames)]

    def full(f):  # a fresh encoding (bypassing the per-output cache), then the query
        return vol.query_encoded(vol._encode(outs[f], None), points[f])

    pred = {}
    t0 = time.perf_counter()
    res = _memory_first_and_steady(lambda: pred.update(v=full(0)), device)
    warm, rep = _fit_budget(int(job["warmup"]), int(job["repeats"]), (time.perf_counter() - t0) / 2,
                            float(job.get("budget_s", math.inf)))
    res.update(warmup_used=warm, repeats_used=rep)
    counts = getattr(vol, "decoder_evaluations", None) is not None
    for i in range(warm):
        full(i % n_frames)
    t_full = _timed_ms([lambda f=(warm + i) % n_frames: full(f) for i in range(rep)], device)
    enc = vol._encode(outs[0], None)
    for _ in range(warm):
        vol.query_encoded(enc, points[0])
    res["mem_query_bytes"] = _peak_memory(lambda: vol.query_encoded(enc, points[0]), device)["mem_bytes"]
    evals0 = vol.decoder_evaluations if counts else 0
    t_query = _timed_ms([lambda: vol.query_encoded(enc, points[0])] * rep, device)
    pairs = (vol.decoder_evaluations - evals0) // rep if counts else None
    if job.get("return_pred"):
        torch.save(pred["v"].cpu(), job["pred_path"])
    fpp = _flops_per_pair(vol.net)
    res.update(t_ms=float(np.median(t_full)), t_query_ms=float(np.median(t_query)), t_ms_all=t_full,
               t_query_ms_all=t_query, batch=int(B), points=int(N), params=int(count_parameters(vol.net)),
               num_parts=int(vol.num_parts), output=getattr(vol.net, "output", "sdf"), level=float(getattr(vol, "level", 0.0)),
               decoder_pairs=None if pairs is None else int(pairs), flops_per_pair=fpp)
    return res


def _flops_per_pair(net) -> Optional[int]:
    """FLOPs of one (point, part) decoder evaluation: net.flops_per_pair() (COAP) or net.decoder's (VolumetricSMPL)."""
    for owner in (net, getattr(net, "decoder", None)):
        if hasattr(owner, "flops_per_pair"):
            return int(owner.flops_per_pair())
    return None


# ---------------------------------------------------------------------------------------------- measurements
def _derived(r: dict) -> dict:
    """Per-point decoder evaluations, decoder GFLOP per query and achieved GFLOP/s of a volume result."""
    pairs, fpp = r.get("decoder_pairs"), r.get("flops_per_pair")
    out = {"evals_per_point": None, "decoder_gflop": None, "gflops": None}
    if pairs is not None:
        out["evals_per_point"] = pairs / (r["batch"] * r["points"])
        if fpp:
            out["decoder_gflop"] = pairs * fpp / 1e9
            out["gflops"] = out["decoder_gflop"] / (r["t_query_ms"] / 1e3) if r["t_query_ms"] > 0 else None
    return out


def bench_model(name: str, batch: int, cfg: BenchConfig, body, checkpoint: Optional[str]) -> dict:
    """Time, memory, parameters and decoder work of one benchmark model at one batch size (subprocess)."""
    model, dense = MODELS[name]
    n_frames = max(1, cfg.warmup + cfg.repeats)
    inputs = make_frames(body, batch, cfg.n_points, n_frames, cfg.seed)
    job = {"kind": "volume", "spec": {"model": model, "dense": dense, "checkpoint": checkpoint, "init_seed": cfg.init_seed},
           "device": cfg.device, "threads": cfg.threads or torch.get_num_threads(), "warmup": cfg.warmup,
           "repeats": cfg.repeats, "budget_s": cfg.budget_s}
    r = run_worker(job, inputs, cfg.timeout_s)
    r.update(_derived(r))
    r["weights"] = "trained" if checkpoint else "random init"
    return r


def bench_bodybody(cfg: BenchConfig, body, checkpoint: Optional[str]) -> dict:
    """Paper Table B.4: vertices of body A inside body B by winding numbers vs VolumetricSMPL (sparse)."""
    inp = bodybody_inputs(body, cfg.seed + 1, cfg.bodybody_vertices)
    threads = cfg.threads or torch.get_num_threads()
    vjob = {"kind": "volume", "spec": {"model": "volsmpl", "dense": False, "checkpoint": checkpoint, "init_seed": cfg.init_seed},
            "device": cfg.device, "threads": threads, "warmup": cfg.warmup, "repeats": cfg.repeats, "return_pred": True}
    vol = run_worker(vjob, {"body_pose": inp["pose_b"][None], "transl": inp["transl_b"], "points": inp["points"][None]},
                     cfg.timeout_s)
    vol.update(_derived(vol))
    wjob = {"kind": "winding", "device": "cpu", "threads": threads, "repeats": cfg.winding_repeats, "return_pred": True}
    wn = run_worker(wjob, {"vertices_b": inp["vertices_b"].double(), "faces": torch.as_tensor(body.faces),
                           "points": inp["points"].double()}, cfg.timeout_s)
    inside_wn = wn.pop("pred") > 0.5
    pred = vol.pop("pred")[0]
    inside_vol = pred < 0 if vol.get("output", "sdf") == "sdf" else pred > vol["level"]
    return {"vertices_tested": int(inp["points"].shape[1]), "faces": int(len(body.faces)),
            "inside_winding": int(inside_wn.sum()), "inside_volsmpl": int(inside_vol.sum()),
            "agreement": float((inside_wn == inside_vol).double().mean()),
            "weights": "trained" if checkpoint else "random init", "volsmpl": vol, "winding": wn}


def evaluate_protocol_check(cfg: BenchConfig, checkpoint: Optional[str]) -> dict:
    """evaluate.measure_resources on sparse volsmpl (its protocol: validation body 0, batch 1)."""
    from .evaluate import EvalConfig, measure_resources
    from .nn.config import VolumeConfig

    spec = {"checkpoint": checkpoint} if checkpoint else {"config": VolumeConfig().to_dict(), "init_seed": cfg.init_seed}
    ecfg = EvalConfig(n_points=cfg.n_points, device=cfg.device, timing_repeats=cfg.repeats, timing_warmup=cfg.warmup,
                      timing_threads=cfg.threads or torch.get_num_threads())
    return measure_resources(spec, ecfg)


def accuracy(model: str, checkpoint: Optional[str], cfg: BenchConfig) -> dict:
    """IoU/MSE of a trained base model on the validation set; {'status': 'untrained'} without a checkpoint."""
    from .checkpoint import checkpoint_model
    from .evaluate import EvalConfig, evaluate_checkpoint

    if checkpoint is None:
        return {"status": "untrained"}
    ecfg = EvalConfig(n_bodies=cfg.n_bodies, n_points=cfg.n_points, device=cfg.device)
    held = checkpoint_model(checkpoint)
    if held != model:
        raise ValueError(f"{checkpoint} holds a {held} model, not {model}; pass it as --checkpoint-{held}")
    res = evaluate_checkpoint(checkpoint, config=ecfg)  # occupancy models: IoU only (MSE None)
    return {"status": "trained", "checkpoint": checkpoint, "metrics": res.metrics, "n_bodies": cfg.n_bodies,
            "validation_digest": res.validation_digest}


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


# ---------------------------------------------------------------------------------------------- run
def run_bench(cfg: BenchConfig, log=print) -> dict:
    """Run every measurement of the module docstring; returns the JSON-able result."""
    from .body.model import create_body

    if str(cfg.device).startswith("cuda") and not torch.cuda.is_available():
        raise RuntimeError("device='cuda' but torch sees no CUDA GPU; use --device cpu.")
    if cfg.threads is not None:
        torch.set_num_threads(cfg.threads)
    body = create_body()
    result = {"meta": machine_info(cfg), "config": dataclasses.asdict(cfg), "paper": PAPER, "notes": [], "models": {}}
    log(f"matmul {cfg.matmul_size}^2 fp32 ...")
    result["matmul"] = matmul_rate(cfg.matmul_size, cfg.matmul_repeats, cfg.device)
    available, ckpts = {}, {}
    for name in cfg.models:
        base = MODELS[name][0]
        if base not in available:
            available[base] = model_available(base)
            ckpts[base] = checkpoint_for(base, cfg) if available[base][0] else None
        ok, why = available[base]
        if not ok:
            result["models"][name] = {"status": "skipped", "note": why}
            result["notes"].append(f"{name}: skipped: {why}")
            log(f"{name}: skipped ({why})")
            continue
        entry = {"status": "ok", "model": base, "dense": MODELS[name][1], "checkpoint": ckpts[base], "batches": {}}
        for batch in sorted(cfg.batches):
            est = _estimate_call_s(entry["batches"], batch)
            est_mem = _estimate_mem_bytes(entry["batches"], batch)
            note = None
            if est is not None and est > cfg.max_call_s:
                note = (f"{name} B={batch}: skipped, one encode+query would take ~{est:.0f} s (linear in B from "
                        f"the smaller batch) > max_call_s={cfg.max_call_s:g} s")
            elif est_mem is not None and est_mem > cfg.max_mem_fraction * _total_memory_bytes(cfg.device):
                note = (f"{name} B={batch}: skipped, the query would need ~{est_mem / 2**30:.1f} GiB (linear in B from "
                        f"the smaller batch) > {cfg.max_mem_fraction:.0%} of this machine's memory")
            if note is not None:
                entry.setdefault("skipped_batches", {})[str(batch)] = note
                result["notes"].append(note)
                log(note)
                continue
            log(f"{name} batch {batch} x {cfg.n_points} points ...")
            entry["batches"][str(batch)] = bench_model(name, batch, cfg, body, ckpts[base])
        result["models"][name] = entry
    if "volsmpl" in available and available["volsmpl"][0]:
        if cfg.evaluate_check and "volsmpl" in cfg.models:
            log("evaluate.measure_resources cross-check ...")
            result["evaluate_protocol"] = evaluate_protocol_check(cfg, ckpts["volsmpl"])
        if cfg.bodybody:
            log("body-body occupancy (winding numbers vs volsmpl) ...")
            result["bodybody"] = bench_bodybody(cfg, body, ckpts["volsmpl"])
    result["accuracy"] = {}
    for base, (ok, _) in available.items():
        if ok:
            if not cfg.accuracy:
                result["accuracy"][base] = {"status": "skipped (--quick)"}
            else:
                log(f"{base} accuracy ...")
                result["accuracy"][base] = accuracy(base, ckpts[base], cfg)
    result["ratios"] = compute_ratios(result["models"], result.get("bodybody"))
    result["notes"] += _caveats(cfg, result)
    return result


def _estimate_mem_bytes(done: dict, batch: int) -> Optional[float]:
    """Peak query memory at `batch`, extrapolated linearly from the largest measured smaller batch."""
    smaller = [int(b) for b in done if int(b) < batch]
    if not smaller:
        return None
    b = max(smaller)
    return done[str(b)]["mem_bytes"] * batch / b


def _total_memory_bytes(device) -> int:
    if str(device).startswith("cuda"):
        return torch.cuda.get_device_properties(torch.device(device)).total_memory
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _estimate_call_s(done: dict, batch: int) -> Optional[float]:
    """Seconds of one encode+query at `batch`, extrapolated linearly from the largest measured smaller batch."""
    smaller = [int(b) for b in done if int(b) < batch]
    if not smaller:
        return None
    b = max(smaller)
    return done[str(b)]["t_ms"] / 1e3 * batch / b


def _caveats(cfg: BenchConfig, result: dict) -> List[str]:
    notes = []
    if not str(cfg.device).startswith("cuda"):
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


# ---------------------------------------------------------------------------------------------- report
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
            "GFLOP/s", "IoU mean [%]", "MSE SDF"]
    rows = []
    for name, e in result["models"].items():
        if e["status"] != "ok":
            rows.append([name, "-", "skipped"] + [""] * (len(head) - 3))
            continue
        acc = result.get("accuracy", {}).get(e["model"])
        skipped = e.get("skipped_batches", {})
        for batch in sorted(set(e["batches"]) | set(skipped), key=int):
            if batch in skipped:
                rows.append([name, batch, "skipped (too slow)"] + [""] * (len(head) - 3))
                continue
            r = e["batches"][batch]
            rows.append([name, batch, _f(r["t_ms"], "{:.1f}"), _f(r["t_query_ms"], "{:.1f}"),
                         str(r.get("repeats_used", len(r["t_ms_all"]))), _mem(r["mem_bytes"]),
                         _mem(r.get("mem_query_bytes")), f"{r['params'] / 1e6:.2f} M", _f(r["evals_per_point"], "{:.2f}"), _f(r["decoder_gflop"], "{:.2f}"),
                         _f(r["gflops"], "{:.1f}")] + _acc_cells(acc))
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
    """Header and rows of the body-body table (paper Table B.4)."""
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


def _summary_lines(result: dict) -> List[str]:
    m, mm = result["meta"], result["matmul"]
    lines = [f"machine: {m['cpu']} ({m['cpu_count']} cores, load {m['load_avg_1_5_15']}), device {m['device']}"
             + (f" ({m['gpu']})" if m.get("gpu") else "") + f", {m['threads']} torch threads, torch {m['torch']}, "
             f"python {m['python']}, {m['date']}, commit {m['git_commit']}",
             f"fp32 matmul {mm['size']}x{mm['size']}: {mm['t_ms']:.1f} ms = {mm['gflops']:.1f} GFLOP/s "
             f"(median of {len(mm['t_ms_all'])})"]
    ev = result.get("evaluate_protocol")
    if ev:
        lines.append(f"evaluate.measure_resources (volsmpl, validation body 0, batch 1): t {ev['t_ms']:.1f} ms, "
                     f"t query {ev['t_query_ms']:.1f} ms, mem {_mem(ev['mem_bytes'])} ({ev['mem_method']})")
    bb = result.get("bodybody")
    if bb:
        lines.append(f"body-body: {bb['vertices_tested']} vertices of body A vs body B ({bb['faces']} faces); "
                     f"winding and volsmpl agree on {100 * bb['agreement']:.2f}% ({bb['weights']} volsmpl)")
    return lines


def format_report(result: dict) -> str:
    """Plain-text report: summary, model table, ratios, body-body table, notes."""
    parts = _summary_lines(result) + ["", text_table(*model_rows(result)), "", text_table(*ratio_rows(result))]
    if result.get("bodybody"):
        parts += ["", text_table(*bodybody_rows(result))]
    return "\n".join(parts + [""] + [f"note: {n}" for n in result["notes"]])


def to_markdown(result: dict) -> str:
    """Markdown report (included by the README)."""
    c = result["config"]
    out = ["# Benchmark: time, memory and cost of the volumetric body models", "",
           f"`volsmpl bench` with batch sizes {list(c['batches'])}, {c['n_points']} query points per body, median of "
           f"{c['repeats']} runs after {c['warmup']} warm-up runs.", ""]
    out += [f"- {ln}" for ln in _summary_lines(result)] + ["", "## Models", "", markdown_table(*model_rows(result)), "",
            "t: fresh encoding of a new pose + query; t query: query on a cached encoding; peak mem: "
            + ("CUDA max allocated" if str(c["device"]).startswith("cuda") else "peak RSS increase of the process")
            + " during encoding + query (mem query: query on a cached encoding); dec. evals/pt: part decoders evaluated per query point; decoder GFLOP: pairs x FLOPs per decoder "
            "evaluation; GFLOP/s: decoder GFLOP / t query; runs: timed runs (fewer than asked when over the time budget).", "", "## Ratios (same run) beside the paper's (GPU)", "",
            markdown_table(*ratio_rows(result))]
    if result.get("bodybody"):
        out += ["", "## Body-body occupancy check (paper Table B.4)", "", markdown_table(*bodybody_rows(result))]
    out += ["", "## Notes", ""] + [f"- {n}" for n in result["notes"]]
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------------------------- CLI
def add_parser(sub):
    d = BenchConfig()
    p = sub.add_parser("bench", help="time / memory / FLOP benchmark of the volumetric models (Tables 1, 2, B.4)",
                       description="Median query time with and without encoding, peak memory, parameters, decoder "
                                   "work and FLOP rate per model and batch size; winding-number body-body check; "
                                   "ratios beside the paper's.")
    p.add_argument("--device", default=d.device, choices=["cpu", "cuda"])
    p.add_argument("--batch", type=int, nargs="+", default=list(d.batches), help="batch sizes (default 1 8)")
    p.add_argument("--points", type=int, default=d.n_points, help="query points per body")
    p.add_argument("--repeats", type=int, default=d.repeats, help="timed runs (median reported)")
    p.add_argument("--warmup", type=int, default=d.warmup, help="untimed warm-up runs")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (1 gives stable timings on a busy machine)")
    p.add_argument("--models", default=",".join(d.models), help=f"comma-separated, from {','.join(MODELS)}")
    p.add_argument("--checkpoint-volsmpl", default=None, help="trained volsmpl checkpoint (default: shipped one if present)")
    p.add_argument("--checkpoint-coap", default=None, help="trained COAP checkpoint (default: shipped one if present)")
    p.add_argument("--n-bodies", type=int, default=d.n_bodies, help="validation bodies for the accuracy columns")
    p.add_argument("--bodybody-vertices", type=int, default=None, help="test only N evenly spread vertices of body A")
    p.add_argument("--winding-repeats", type=int, default=d.winding_repeats, help="timed winding-number runs")
    p.add_argument("--matmul-size", type=int, default=d.matmul_size, help="size of the fp32 matmul timing the machine")
    p.add_argument("--budget", type=float, default=d.budget_s, help="seconds per (model, batch): fewer repeats beyond")
    p.add_argument("--max-call", type=float, default=d.max_call_s,
                   help="skip a (model, batch) whose single query would take longer (seconds, extrapolated)")
    p.add_argument("--no-bodybody", action="store_true", help="skip the body-body winding-number check")
    p.add_argument("--quick", action="store_true", help="skip accuracy (IoU/MSE)")
    p.add_argument("--out", default=None, help="write the results as JSON here")
    p.add_argument("--markdown", default=None, help="write a Markdown report here")
    return p


def config_from_args(args) -> BenchConfig:
    """BenchConfig of parsed CLI arguments."""
    models = tuple(m.strip() for m in args.models.split(",") if m.strip())
    ckpts = {k: v for k, v in (("volsmpl", args.checkpoint_volsmpl), ("coap", args.checkpoint_coap)) if v}
    return BenchConfig(models=models, batches=tuple(args.batch), n_points=args.points, repeats=args.repeats,
                       warmup=args.warmup, threads=args.threads, device=args.device, checkpoints=ckpts,
                       accuracy=not args.quick, n_bodies=args.n_bodies, bodybody=not args.no_bodybody,
                       bodybody_vertices=args.bodybody_vertices, winding_repeats=args.winding_repeats,
                       matmul_size=args.matmul_size, budget_s=args.budget, max_call_s=args.max_call)


def _write(path: str, text: str) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(text)
    print(f"wrote {path}")


def run(args) -> int:
    cfg = config_from_args(args)
    result = run_bench(cfg, log=lambda s: print(s, file=sys.stderr, flush=True))
    print(format_report(result))
    if args.out:
        _write(args.out, json.dumps(result, indent=1))
    if args.markdown:
        _write(args.markdown, to_markdown(result))
    return 0
