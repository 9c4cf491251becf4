"""Resource benchmark of the volumetric body models (paper Table 1 resources, Table 2 costs, Table B.4).

    volsmpl bench [--device cpu|cuda] [--batch 1 8] [--points 60000] [--repeats 5] [--threads N]
                  [--models volsmpl,volsmpl-encoder,volsmpl-dense,coap,coap-sparse] [--checkpoint-volsmpl P] [--checkpoint-coap P]
                  [--out bench.json] [--markdown docs/bench_cpu.md] [--quick]
    from volsmpl.bench.run import BenchConfig, run_bench; res = run_bench(BenchConfig(batches=(1,), n_points=2000))

This module holds the settings (`BenchConfig`), the run (`run_bench`) and the CLI; the measurements, each
in a fresh Python process, are in `volsmpl.bench.jobs`, the ratios and tables in `volsmpl.bench.summary`.
The result JSON records where and when it ran under 'meta' (`volsmpl.io.provenance.machine_info`).

Variants (`--models`): the names of `volsmpl.bench.variants.VARIANTS`, each a registry model kind ('volsmpl',
'coap') with the `Volume` settings it runs with (the sparse or dense path, the engine, the pair decoder, the
precision, one chunk, CUDA graphs of the encode and of the query); the table's notes say what each measures. A
variant whose `attach_volume(body, model=...)` is not available is skipped with a note, as is a CUDA-only variant
off CUDA.

A run measures:
  - the machine's fp32 matmul rate (`bench_jobs.matmul_rate`);
  - per model and batch size B (`bench_model`): time with and without encoding, peak memory, parameters,
    decoder work and FLOP rate (`bench_jobs.volume_job`). A (model, B) whose single call or memory,
    extrapolated linearly in B from the smaller batch, would exceed max_call_s or max_mem_fraction of the
    machine's memory is skipped with a note;
  - per-body time of the largest batch B against B = 1 for 'volsmpl', measured interleaved in one process on the
    same bodies (`volsmpl.bench.scaling`: the separate model rows drift with the machine between their runs);
  - `eval_resources.measure_resources` (evaluate's protocol: validation body 0, batch 1, sparse volsmpl) as a
    cross-check of the volsmpl batch-1 row (`evaluate_protocol`); it reports the first call's memory;
  - the body-body occupancy check (paper Table B.4, `bench_bodybody`): the vertices of one posed default
    body (13,348) tested inside a second posed body that overlaps it, by exact generalised winding numbers
    (> 1/2) and by `vol.query(...) < 0`, each in its own process; their agreement is the fraction of
    vertices with the same inside/outside label (meaningful only for a trained checkpoint);
  - accuracy: `evaluate` (IoU, MSE) on the validation set when a trained checkpoint of the model exists
    (default: the registry's, `volsmpl.volume.models`); otherwise 'untrained'. Skipped with --quick.
On a CPU shared with other busy processes use `--threads 1` (or the number of idle cores): spinning OpenMP
threads can slow a query many times.
"""
from __future__ import annotations

import dataclasses
import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Optional, Tuple

import torch

from volsmpl.bench.jobs import bodybody_inputs, make_frames, matmul_rate, run_job
from volsmpl.bench.summary import PAPER, caveats, compute_ratios, format_report, to_markdown
from volsmpl.bench.variants import DEFAULT_VARIANTS, KINDS, VARIANTS
from volsmpl.io.provenance import machine_info

__all__ = ["VARIANTS", "BenchConfig", "model_available",
           "checkpoint_for", "bench_model",
           "bench_batch_scaling", "bench_bodybody", "evaluate_protocol_check", "accuracy", "run_bench", "estimate_call_s", "estimate_mem_bytes",
           "add_parser", "config_from_args", "run", "PAPER", "compute_ratios", "format_report", "to_markdown"]

@dataclass
class BenchConfig:
    """Settings of one benchmark run (defaults: the full run of the module docstring).

    Attributes:
        models: benchmark variant names (keys of VARIANTS). batches: batch sizes B.
        n_points: query points per body (60k as in Table 1). repeats / warmup: timed / untimed frames.
        threads: torch CPU threads (None: this process's torch.get_num_threads()). device: 'cpu' or 'cuda'.
        checkpoints: model ('volsmpl' / 'coap') -> checkpoint path; missing: the registry's shipped checkpoint if present.
        seed: poses and points. init_seed: weights of untrained networks.
        accuracy: IoU/MSE on the validation set for trained checkpoints. n_bodies: validation bodies.
        batch_scaling: measure 'volsmpl' per body at the largest batch against B = 1 interleaved (bench_scaling).
        bodybody: run the body-body check. bodybody_vertices: test only N evenly spread vertices of body A (None: all).
        winding_repeats: timed winding-number runs (each takes seconds on a CPU).
        matmul_size / matmul_repeats: the fp32 matmul used to measure the machine's FLOP rate.
        evaluate_check: also run eval_resources.measure_resources (volsmpl, batch 1) as a cross-check.
        budget_s: wall-time budget of one (model, batch) measurement: when warmup + repeats calls would exceed
            it (judged from the first call), the worker drops the warm-up (the two memory calls warm up) and
            lowers repeats (at least 1); the counts used are reported.
        max_mem_fraction: skip a (model, batch) whose query memory, extrapolated linearly in B from the
            smaller batch, would exceed this fraction of the machine's (or GPU's) memory.
        max_call_s: skip a (model, batch) whose single encode+query, extrapolated linearly in B from the
            model's smaller batch, would exceed this (dense COAP at B=8 takes minutes per call on a CPU).
        timeout_s: limit of each subprocess.
    """

    models: Tuple[str, ...] = DEFAULT_VARIANTS
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
    batch_scaling: bool = True
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
        unknown = [m for m in self.models if m not in VARIANTS]
        if unknown:
            raise ValueError(f"unknown model(s) {unknown}; choose from {list(VARIANTS)}.")
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
        bad = sorted(set(self.checkpoints) - set(KINDS))
        if bad:
            raise ValueError(f"checkpoints for {bad}: give them for 'volsmpl' or 'coap'.")


def _positive(name: str, v) -> None:
    if not isinstance(v, int) or isinstance(v, bool) or v < 1:
        raise ValueError(f"{name} must be a positive integer, got {v!r}.")


# ---------------------------------------------------------------------------------------------- models
def model_available(model: str) -> Tuple[bool, str]:
    """Whether attach_volume builds `model` ('volsmpl' / 'coap') in this checkout; (False, reason) if not."""
    from volsmpl.body.model import create_body
    from volsmpl.volume.attach import attach_volume

    try:
        attach_volume(create_body(), model=model, pretrained=False)
    except (ValueError, NotImplementedError, ImportError, KeyError) as e:
        return False, f"attach_volume(body, model={model!r}) is not available in this checkout ({type(e).__name__}: {e})"
    return True, ""


def checkpoint_for(model: str, cfg: BenchConfig) -> Optional[str]:
    """Checkpoint path (without .safetensors) of a base model: the configured one (must exist), else the
    default one if it exists, else None (untrained)."""
    from volsmpl.volume.models import model_kind

    given = cfg.checkpoints.get(model)
    if given:
        p = Path(given)
        stem = p.with_suffix("") if p.suffix == ".safetensors" else p
        if not Path(str(stem) + ".safetensors").exists():
            raise FileNotFoundError(f"checkpoint {given} for {model!r} not found (looked for {stem}.safetensors).")
        return str(stem)
    default = model_kind(model).default_checkpoint
    if default is not None and Path(str(default) + ".safetensors").exists():
        return str(default)
    return None


def check_given_checkpoints(cfg: BenchConfig) -> None:
    """Every checkpoint given for a base model exists and holds that model (`checkpoint_model`: the JSON's
    config); ValueError / FileNotFoundError / CheckpointError in one line naming the option and the fix."""
    from volsmpl.volume.models import expect_checkpoint_model

    for base in sorted(cfg.checkpoints):
        expect_checkpoint_model(checkpoint_for(base, cfg), base, f"--checkpoint-{base}", "pass it as --checkpoint-{held}.")


# ---------------------------------------------------------------------------------------------- measurements
def bench_model(name: str, batch: int, cfg: BenchConfig, body, checkpoint: Optional[str]) -> dict:
    """Time, memory, parameters and decoder work of one benchmark variant at one batch size (isolated process)."""
    n_frames = max(1, cfg.warmup + cfg.repeats)
    inputs = make_frames(body, batch, cfg.n_points, n_frames, cfg.seed)
    job = {"spec": VARIANTS[name].spec(checkpoint, cfg.init_seed),
           "device": cfg.device, "threads": cfg.threads or torch.get_num_threads(), "warmup": cfg.warmup,
           "repeats": cfg.repeats, "budget_s": cfg.budget_s, "matmul_size": cfg.matmul_size}
    r = run_job("volsmpl.bench.jobs:volume_job", job, inputs, cfg.timeout_s)
    r["weights"] = "trained" if checkpoint else "random init"
    return r


def bench_batch_scaling(cfg: BenchConfig, body, checkpoint: Optional[str]) -> dict:
    """'volsmpl' per body at the largest batch against B = 1, interleaved in one isolated process (bench_scaling)."""
    B = max(cfg.batches)
    job = {"spec": VARIANTS["volsmpl"].spec(checkpoint, cfg.init_seed),
           "device": cfg.device, "threads": cfg.threads or torch.get_num_threads(), "warmup": min(1, cfg.warmup),
           "repeats": cfg.repeats}
    return run_job("volsmpl.bench.scaling:batch_scaling_job", job, make_frames(body, B, cfg.n_points, 1, cfg.seed),
                   cfg.timeout_s)


def bench_bodybody(cfg: BenchConfig, body, checkpoint: Optional[str]) -> dict:
    """Paper Table C.4: vertices of body A inside body B by winding numbers vs VolumetricSMPL (sparse)."""
    inp = bodybody_inputs(body, cfg.seed + 1, cfg.bodybody_vertices)
    threads = cfg.threads or torch.get_num_threads()
    vjob = {"spec": VARIANTS["volsmpl"].spec(checkpoint, cfg.init_seed),
            "device": cfg.device, "threads": threads, "warmup": cfg.warmup, "repeats": cfg.repeats, "return_pred": True}
    vol = run_job("volsmpl.bench.jobs:volume_job", vjob,
                  {"body_pose": inp["pose_b"][None], "transl": inp["transl_b"], "points": inp["points"][None]},
                  cfg.timeout_s)
    wjob = {"device": "cpu", "threads": threads, "repeats": cfg.winding_repeats, "return_pred": True}
    wn = run_job("volsmpl.bench.jobs:winding_job", wjob,
                 {"vertices_b": inp["vertices_b"].double(), "faces": torch.as_tensor(body.faces),
                  "points": inp["points"].double()}, cfg.timeout_s)
    inside_wn = wn.pop("pred") > 0.5
    pred = vol.pop("pred")[0]
    inside_vol = pred < 0 if vol.get("output", "sdf") == "sdf" else pred > vol["level"]
    return {"vertices_tested": int(inp["points"].shape[1]), "faces": int(len(body.faces)),
            "inside_winding": int(inside_wn.sum()), "inside_volsmpl": int(inside_vol.sum()),
            "agreement": float((inside_wn == inside_vol).double().mean()),
            "weights": "trained" if checkpoint else "random init", "volsmpl": vol, "winding": wn}


def evaluate_protocol_check(cfg: BenchConfig, checkpoint: Optional[str]) -> dict:
    """eval_resources.measure_resources on sparse volsmpl (its protocol: validation body 0, batch 1)."""
    from volsmpl.evaluation.resources import measure_resources
    from volsmpl.evaluation import EvalConfig
    from volsmpl.nn.config import VolumeConfig

    spec = {"checkpoint": checkpoint} if checkpoint else {"config": VolumeConfig().to_dict(), "init_seed": cfg.init_seed}
    ecfg = EvalConfig(n_points=cfg.n_points, device=cfg.device, timing_repeats=cfg.repeats, timing_warmup=cfg.warmup,
                      timing_threads=cfg.threads or torch.get_num_threads())
    return measure_resources(spec, ecfg)


def accuracy(model: str, checkpoint: Optional[str], cfg: BenchConfig, precision: str = "full",
             passes: Optional[int] = None) -> dict:
    """IoU/MSE of a trained base model on the validation set (its decoders in `precision`, the first `passes` of
    its learned passes; None: all); {'status': 'untrained'} without a checkpoint."""
    from volsmpl.volume.models import checkpoint_model
    from volsmpl.evaluation import EvalConfig, evaluate_checkpoint

    if checkpoint is None:
        return {"status": "untrained"}
    ecfg = EvalConfig(n_bodies=cfg.n_bodies, n_points=cfg.n_points, device=cfg.device, precision=precision,
                      passes=passes)
    held = checkpoint_model(checkpoint)
    if held != model:
        raise ValueError(f"{checkpoint} holds a {held} model, not {model}; pass it as --checkpoint-{held}")
    res = evaluate_checkpoint(checkpoint, config=ecfg)  # occupancy models: IoU only (MSE None)
    return {"status": "trained", "checkpoint": checkpoint, "metrics": res.metrics, "n_bodies": cfg.n_bodies,
            "validation_digest": res.validation_digest, "precision": precision, "passes": passes}


# ---------------------------------------------------------------------------------------------- run
def estimate_mem_bytes(done: dict, batch: int) -> Optional[float]:
    """Peak query memory at `batch`, extrapolated linearly from the largest measured smaller batch."""
    smaller = [int(b) for b in done if int(b) < batch]
    if not smaller:
        return None
    b = max(smaller)
    return done[str(b)]["mem_bytes"] * batch / b


def estimate_call_s(done: dict, batch: int) -> Optional[float]:
    """Seconds of one encode+query at `batch`, extrapolated linearly from the largest measured smaller batch."""
    smaller = [int(b) for b in done if int(b) < batch]
    if not smaller:
        return None
    b = max(smaller)
    return done[str(b)]["t_ms"] / 1e3 * batch / b


def _total_memory_bytes(device) -> int:
    if str(device).startswith("cuda"):
        return torch.cuda.get_device_properties(torch.device(device)).total_memory
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _skip_note(name: str, batch: int, entry: dict, cfg: BenchConfig) -> Optional[str]:
    """Why (model, batch) is skipped (too slow or too much memory, extrapolated from the smaller batch), else None."""
    est, est_mem = estimate_call_s(entry["batches"], batch), estimate_mem_bytes(entry["batches"], batch)
    if est is not None and est > cfg.max_call_s:
        return (f"{name} B={batch}: skipped, one encode+query would take ~{est:.0f} s (linear in B from "
                f"the smaller batch) > max_call_s={cfg.max_call_s:g} s")
    if est_mem is not None and est_mem > cfg.max_mem_fraction * _total_memory_bytes(cfg.device):
        return (f"{name} B={batch}: skipped, the query would need ~{est_mem / 2**30:.1f} GiB (linear in B from "
                f"the smaller batch) > {cfg.max_mem_fraction:.0%} of this machine's memory")
    return None


def run_bench(cfg: BenchConfig, log=print) -> dict:
    """Run every measurement of the module docstring; returns the JSON-able result."""
    from volsmpl.body.model import create_body

    if str(cfg.device).startswith("cuda") and not torch.cuda.is_available():
        raise RuntimeError("device='cuda' but torch sees no CUDA GPU; use --device cpu.")
    if cfg.threads is not None:
        torch.set_num_threads(cfg.threads)
    check_given_checkpoints(cfg)  # before any work: a wrong file fails in seconds, not after the other models
    body = create_body()
    result = {"meta": machine_info(cfg.device, cfg.threads), "config": dataclasses.asdict(cfg), "paper": PAPER,
              "notes": [], "models": {}}
    log(f"matmul {cfg.matmul_size}^2 fp32 ...")
    result["matmul"] = matmul_rate(cfg.matmul_size, cfg.matmul_repeats, cfg.device)
    available, ckpts = {}, {}
    for name in cfg.models:
        variant = VARIANTS[name]
        base = variant.kind
        if base not in available:
            available[base] = model_available(base)
            ckpts[base] = checkpoint_for(base, cfg) if available[base][0] else None
        ok, why = available[base]
        if ok and variant.cuda_only and cfg.device != "cuda":
            ok, why = False, variant.cuda_only
        if not ok:
            result["models"][name] = {"status": "skipped", "note": why}
            result["notes"].append(f"{name}: skipped: {why}")
            log(f"{name}: skipped ({why})")
            continue
        entry = {"status": "ok", "model": base, "dense": variant.dense, "checkpoint": ckpts[base], "batches": {}}
        for batch in sorted(cfg.batches):
            note = _skip_note(name, batch, entry, cfg)
            if note is not None:
                entry.setdefault("skipped_batches", {})[str(batch)] = note
                result["notes"].append(note)
                log(note)
                continue
            log(f"{name} batch {batch} x {cfg.n_points} points ...")
            entry["batches"][str(batch)] = bench_model(name, batch, cfg, body, ckpts[base])
        result["models"][name] = entry
    if "volsmpl" in available and available["volsmpl"][0]:
        if cfg.batch_scaling and "volsmpl" in cfg.models and max(cfg.batches) > 1:
            log(f"volsmpl per body at B = {max(cfg.batches)} against B = 1, interleaved ...")
            result["batch_scaling"] = bench_batch_scaling(cfg, body, ckpts["volsmpl"])
        if cfg.evaluate_check and "volsmpl" in cfg.models:
            log("eval_resources.measure_resources cross-check ...")
            result["evaluate_protocol"] = evaluate_protocol_check(cfg, ckpts["volsmpl"])
        if cfg.bodybody:
            log("body-body occupancy (winding numbers vs volsmpl) ...")
            result["bodybody"] = bench_bodybody(cfg, body, ckpts["volsmpl"])
    result["accuracy"] = {}
    own = [n for n in cfg.models if (VARIANTS[n].precision != "full" or VARIANTS[n].passes is not None)
           and result["models"].get(n, {}).get("status") == "ok"]
    for key, base, precision, passes in [(b, b, "full", None) for b, (ok, _) in available.items() if ok] + \
            [(n, VARIANTS[n].kind, VARIANTS[n].precision, VARIANTS[n].passes) for n in own]:
        # a variant in a reduced precision, or with its own number of learned passes, has its own accuracy
        if not cfg.accuracy:
            result["accuracy"][key] = {"status": "skipped (--quick)"}
        else:
            log(f"{key} accuracy ...")
            result["accuracy"][key] = accuracy(base, ckpts[base], cfg, precision, passes)
    result["ratios"] = compute_ratios(result["models"], result.get("bodybody"))
    result["notes"] += caveats(result)
    return result


# ---------------------------------------------------------------------------------------------- CLI
def add_parser(sub):
    d = BenchConfig()
    p = sub.add_parser("bench", help="time / memory / FLOP benchmark of the volumetric models (Tables 1, 2, C.4)",
                       description="Median query time with and without encoding, peak memory, parameters, decoder "
                                   "work and FLOP rate per model and batch size; winding-number body-body check; "
                                   "ratios beside the paper's.")
    p.add_argument("--device", default=d.device, choices=["cpu", "cuda"])
    p.add_argument("--batch", type=int, nargs="+", default=list(d.batches), help="batch sizes (default 1 8)")
    p.add_argument("--points", type=int, default=d.n_points, help="query points per body")
    p.add_argument("--repeats", type=int, default=d.repeats, help="timed runs (median reported)")
    p.add_argument("--warmup", type=int, default=d.warmup, help="untimed warm-up runs")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (1 gives stable timings on a busy machine)")
    p.add_argument("--models", default=",".join(d.models), help=f"comma-separated, from {','.join(VARIANTS)}")
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
    p.add_argument("--no-batch-scaling", action="store_true",
                   help="skip the interleaved per-body timing of volsmpl at the largest batch against B = 1")
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
                       batch_scaling=not args.no_batch_scaling,
                       bodybody_vertices=args.bodybody_vertices, winding_repeats=args.winding_repeats,
                       matmul_size=args.matmul_size, budget_s=args.budget, max_call_s=args.max_call)


def _write(path: str, text: str) -> None:
    from volsmpl.io.outputs import write_atomic
    write_atomic(path, text)
    print(f"wrote {path}")


def run(args) -> int:
    from volsmpl.io.outputs import check_writable
    if args.out:  # before the benchmark: a bad path fails in seconds, not after it
        check_writable(args.out, "file", "--out")
    if args.markdown:
        check_writable(args.markdown, "file", "--markdown")
    cfg = config_from_args(args)
    result = run_bench(cfg, log=lambda s: print(s, file=sys.stderr, flush=True))
    print(format_report(result))
    if args.out:
        _write(args.out, json.dumps(result, indent=1))
    if args.markdown:
        _write(args.markdown, to_markdown(result))
    return 0
