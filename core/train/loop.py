"""Training of the volumetric body model (paper Sec. 3.4): `volsmpl train`.

Every step draws B bodies (random poses within joint limits: `pose_mode` 'realistic' by default, 'mixed'
makes a share `extreme_fraction` of them extreme, `contact_fraction` a share in self-contact poses; shapes from
Anny's calibrated population), per part 256 points uniform in its padded box and 256 near the surface
(optionally `n_body_surface` more per body near the whole surface, area-weighted like the evaluation's
near-surface set, and `n_contact_surface` around the vertices where the body touches itself), exact signed distances to the posed mesh
(open3d BVH distance; sign from the winding number, which calls self-overlapping parts inside, their union, like
the min over parts), and minimises eq. 3:

    L = mean (sgn(d~) - sgn(d))^2  +  abs_weight * mean (|d~| - |d|)^2

sgn has no useful derivative, so the sign term back-propagates a straight-through estimate
(d sgn(x)/dx := 1/tau, tau = 1 cm): every wrong sign is pushed across the surface, however far it is.
The absolute-value term is in metres^2; abs_weight = 1e4 measures it in cm^2 so that both terms are
O(1) (the paper's plain sum leaves it ~1e-4 of the sign term).

Sign term (`sign_loss`): 'ste' is the above. It has a degenerate optimum near the surface: a point whose sign
the network cannot yet resolve costs 1 at d~ = 0 but 4 when on the wrong side, and every wrong sign gets the
same large push (2 / tau) however close it is, so outputs collapse onto a plateau at d~ ~ 0 around the surface.
Measured on the step-8,700 checkpoint (6 validation bodies): 46 % of the points within 3 mm of the surface had
|d~| < 10 um (median -1.3e-7 m), so their sign, hence the surface IoU, was noise, with a bias outward (5 of 6 wrong
signs outside), and the SDF had no slope there for collision gradients. 'logistic' is a proper classification
term instead, sign_weight * softplus(-sgn(d) d~ / tau): an unresolved point's optimum is a graded d~ (tau times
the log-odds), wrong signs get a gradient that grows with how wrong they are up to 1 / tau, and right ones
a vanishing one.

Residual of the distance term (`residual`): where the predicted sign is right, (|d~| - |d|)^2 equals
(d~ - d)^2. Where it is wrong the literal |d| term pulls d~ *away* from the surface on the wrong side,
against the sign term: with tau = 1 cm and abs_weight = 1e4 the two gradients cancel at |d~| = |d| - 2 cm,
so every wrong-sign point more than 2 cm from the surface is a stable fixed point (measured: the first
1,500 steps plateaued at 10.5 % wrong signs). The default `residual='signed'` therefore uses (d~ - d)^2,
identical to eq. 3 wherever the sign is right and pointing across the surface where it is not;
`residual='abs'` is eq. 3 to the letter.

Weight averaging (`ema_decay` > 0): the checkpoints publish an exponential moving average of the weights as
the model (what eval and shipping read) and keep the optimised weights beside it for --resume. A fine-tuning
phase starts from a model checkpoint (--init) and anneals from `lr` at step `anneal_start` to `lr_final`.

Data of step s on rank r depend only on (seed, s, r), so a resumed run continues exactly, and `num_workers`
processes can make batches ahead of the step (DataLoader workers, one torch thread each) with the same result:
on a GPU machine the exact ground truth (CPU) would otherwise starve the GPU. Training states
(model, optimised weights and Adam's moments in safetensors files of at most 16 MiB each, nothing pickled, sha256
of every file in state.json: `volsmpl.train.state`) are written to <out>/ckpt-<step>/ and published by
atomically replacing <out>/latest; they continue on any device type; <out>/log.csv holds the losses, <out>/profile.jsonl the time breakdown of
the logged steps (batch, ground truth, forward+backward, optimiser: `volsmpl.train.batches.StepProfile`). Multi-process: torchrun (DDP, gloo on
CPU, nccl on CUDA).

This module holds the losses, the step, checkpointing/resume, the loop and the CLI; the configuration is in
`volsmpl.train.config` (TrainConfig, lr_at), the data in `volsmpl.train.batches` (make_batch, batch_stream).
"""
from __future__ import annotations

import contextlib
import copy
import csv
import json
import math
import os
import shutil
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import torch
import torch.distributed as dist

from volsmpl.volume.attach import attach_volume
from volsmpl.body.model import create_body
from volsmpl.io.checkpoint import load_checkpoint
from volsmpl.volume.models import model_kind
from volsmpl.io.outputs import exclusive_folder, write_atomic
from volsmpl.train.batches import StepProfile, batch_stream, write_profile
from volsmpl.train.config import TrainConfig, adds_refiner, lr_at, parse_set, read_config_file, same_weights_config
from volsmpl.train.state import latest_checkpoint, load_optimizer, read_training_state, save_training_state


class WeightEMA:
    """Exponential moving average of a module's floating-point state (weights and float buffers).

    avg <- avg + (1 - decay_t) * (live - avg) after every optimiser step, with decay_t = min(decay, (1 + n) / (10 + n))
    (n = updates so far in this process' average) so that an average started from fresh weights forgets them quickly.
    The average of a run is what its checkpoints publish as the model; the live weights are kept beside it
    (live-*.safetensors) so that --resume continues the optimisation, not the average.
    """

    def __init__(self, module: torch.nn.Module, decay: float, state: dict | None = None, updates: int = 0):
        self.decay, self.updates = decay, updates
        live = module.state_dict()
        src = live if state is None else state
        self.avg = {k: src[k].detach().clone().to(v.device) for k, v in live.items()}

    @torch.no_grad()
    def update(self, module: torch.nn.Module) -> None:
        d = min(self.decay, (1 + self.updates) / (10 + self.updates))
        for k, v in module.state_dict().items():
            if v.is_floating_point():
                self.avg[k].lerp_(v.detach(), 1.0 - d)
            else:
                self.avg[k].copy_(v)
        self.updates += 1


def sdf_loss(pred: torch.Tensor, gt: torch.Tensor, cfg: TrainConfig) -> tuple[torch.Tensor, dict]:
    """Eq. 3: l2(sgn(d~), sgn(d)) + abs_weight * l2(|d~|, |d|), means over points. pred, gt (B, N) metres.
    With cfg.residual == 'signed' (default) the distance term is (d~ - d)^2 (module docstring).

    The sign term's forward value is exactly the paper's; its gradient is a straight-through estimate,
    d sgn(d~)/d d~ := 1/sign_tau, so a wrong sign is pushed across the surface at any distance (a tanh
    surrogate saturates and leaves far wrong signs without gradient; the |d| term cannot flip a sign).
    With cfg.sign_loss == 'logistic' the sign term is mean softplus(-sgn(d) d~ / sign_tau) instead (module
    docstring). Either is multiplied by cfg.sign_weight.
    """
    if cfg.sign_loss == "logistic":
        sign = torch.nn.functional.softplus(-torch.sign(gt) * pred / cfg.sign_tau).mean()
    else:
        scaled = pred / cfg.sign_tau
        sgn = torch.sign(pred).detach() + scaled - scaled.detach()
        sign = (sgn - torch.sign(gt)).square().mean()
    sign = sign * cfg.sign_weight
    res = pred - gt if cfg.residual == "signed" else pred.abs() - gt.abs()
    absl = res.square().mean() * cfg.abs_weight
    return sign + absl, {"sign": float(sign.detach()), "abs": float(absl.detach())}


def occupancy_loss(pred: torch.Tensor, gt: torch.Tensor) -> tuple[torch.Tensor, dict]:
    """COAP's objective: binary cross-entropy of the max-aggregated occupancy (B, N) against gt < 0."""
    target = (gt < 0).to(pred.dtype)
    bce = torch.nn.functional.binary_cross_entropy(pred.clamp(1e-6, 1 - 1e-6), target)
    return bce, {"sign": float(bce.detach()), "abs": 0.0}



class TrainStep(torch.nn.Module):
    """loss = forward(batch): one module so DistributedDataParallel sees the whole computation."""

    def __init__(self, volume, cfg: TrainConfig):
        super().__init__()
        self.net = volume.net
        self._volume, self.cfg = volume, cfg

    def forward(self, batch: dict):
        out = SimpleNamespace(**batch["posed"])  # posed once, by make_batch
        g = torch.Generator(device=batch["points"].device).manual_seed(batch["seed"])  # draws stay on the device
        enc = self._volume.encode(out, generator=g)  # fresh surface samples: augmentation
        pred = self._volume.query_encoded(enc, batch["points"])
        if model_kind(self._volume.kind).train_loss == "sdf":
            return sdf_loss(pred, batch["sdf"], self.cfg)
        return occupancy_loss(pred, batch["sdf"])


def _accumulate(model, batch: dict, micro: int, ddp: bool) -> tuple[float, dict]:
    """Forward/backward the batch in chunks of `micro` bodies, accumulating gradients of the full-batch
    mean loss (every body has the same number of points, so the chunk means weigh B_c / B). Returns
    the loss and its parts as floats. Exact: same gradient as one pass, less peak memory, faster on CPU."""
    import contextlib

    B = batch["points"].shape[0]
    idx = list(range(0, B, max(1, micro)))
    loss, parts = 0.0, {"sign": 0.0, "abs": 0.0}
    for i, s in enumerate(idx):
        e = min(B, s + max(1, micro))
        sub = {"params": {k: v[s:e] for k, v in batch["params"].items()},
               "posed": {k: v[s:e] for k, v in batch["posed"].items()}, "points": batch["points"][s:e],
               "sdf": batch["sdf"][s:e], "seed": batch["seed"] * 7919 + i}
        sync = contextlib.nullcontext() if (not ddp or i == len(idx) - 1) else model.no_sync()
        with sync:
            l, p = model(sub)
            w = (e - s) / B
            (l * w).backward()
        loss += float(l.detach()) * w
        for k in parts:
            parts[k] += p[k] * w
    return loss, parts


# ---------------------------------------------------------------------- the loop
def _dist_info():
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        if not dist.is_initialized():
            dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def _truncate_log(path: Path, step: int) -> None:
    """Drop log rows after `step` (the step a resumed run restarts from), and a row cut short by a killed run,
    atomically."""
    lines = path.read_text().splitlines(keepends=True)
    n = len(LOG_HEADER)
    keep = lines[:1] + [ln for ln in lines[1:] if ln.endswith("\n") and len(ln.split(",")) == n
                        and ln.split(",", 1)[0].isdigit() and int(ln.split(",", 1)[0]) <= step]
    _replace_lines(path, lines, keep)


def _truncate_profile(path: Path, step: int) -> None:
    """The same for profile.jsonl: drop records after `step` and a line cut short by a killed run."""
    lines = path.read_text().splitlines(keepends=True)
    keep = []
    for ln in lines:
        try:
            rec = json.loads(ln) if ln.endswith("\n") else None
        except json.JSONDecodeError:
            rec = None
        if isinstance(rec, dict) and isinstance(rec.get("step"), int) and rec["step"] <= step:
            keep.append(ln)
    _replace_lines(path, lines, keep)


def _replace_lines(path: Path, lines: list, keep: list) -> None:
    if len(keep) != len(lines):
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text("".join(keep))
        os.replace(tmp, path)


LOG_HEADER = ["step", "loss", "sign", "abs", "lr", "sec_per_step", "data_sec"]


def train(cfg: TrainConfig, out_dir: str | Path, resume: bool = False, max_steps: int | None = None,
          device: str = "cpu", quiet: bool = False, init: str | Path | None = None,
          max_seconds: float | None = None) -> dict:
    """Run (or resume) training. max_steps stops early (this process) without changing the schedule;
    so does max_seconds, a budget of cumulative training time (seconds over all processes' runs of
    this model, recorded as meta.training.train_seconds in every checkpoint): equal budgets compare
    models at equal compute.

    resume continues the run in out_dir exactly (weights, Adam state, step). init starts a new run from
    a model checkpoint (e.g. a shipped one): its weights and its training step,
    so the learning-rate schedule and the data stream continue; Adam's moments start afresh.

    One process (rank 0) writes out_dir at a time (a second one stops with a RuntimeError naming the first), and a
    run killed at any moment, even during a checkpoint write, resumes from its last complete checkpoint.

    Returns a summary dict: last step, last loss, steps/s.
    """
    out_dir = Path(out_dir)
    rank, world = _dist_info()
    with exclusive_folder(out_dir, "volsmpl train") if rank == 0 else contextlib.nullcontext():
        if rank == 0:  # what a killed run left half-written: never published, so never read
            for tmp in out_dir.glob(".tmp-ckpt-*"):
                shutil.rmtree(tmp, ignore_errors=True)
            (out_dir / ".latest.tmp").unlink(missing_ok=True)
        return _train(cfg, out_dir, rank, world, resume, max_steps, device, quiet, init, max_seconds)


def _train(cfg: TrainConfig, out_dir: Path, rank: int, world: int, resume: bool, max_steps: int | None, device: str,
           quiet: bool, init, max_seconds: float | None) -> dict:
    """The body of `train`, with out_dir locked."""
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    torch.manual_seed(cfg.seed)
    body = create_body()
    volume = attach_volume(body, pretrained=False, model=cfg.model_kind, config=cfg.model)
    start, spent, ema_state, ema_updates = 0, 0.0, None, 0
    ck = latest_checkpoint(out_dir) if resume else None
    if resume and ck is None and not quiet and rank == 0:
        print(f"no checkpoint in {out_dir}: starting from scratch", file=sys.stderr)
    if not resume and (out_dir / "latest").exists():
        raise FileExistsError(f"{out_dir} already holds a run; pass --resume to continue it or choose another --out.")
    saved = None
    if init is not None and ck is not None and rank == 0:  # said, not silently skipped (a script may pass both)
        print(f"--init {init} is not used: --resume continues {out_dir} from its checkpoint {ck.name}", file=sys.stderr)
    if init is not None and ck is None:
        state, cfg_dict, meta = load_checkpoint(init, expected_fingerprint=volume.fingerprint)
        fresh_refiner = adds_refiner(cfg_dict, cfg.model)
        if not (same_weights_config(cfg_dict, cfg.model) or fresh_refiner):
            raise ValueError(f"{init} holds model config {cfg_dict}, not the training config's {cfg.model.to_dict()}; "
                             f"pass a --config whose 'model' is the checkpoint's (its JSON's meta.training.train_config, "
                             f"which a plain --init uses), or it with more refiner_iters.")
        if fresh_refiner:   # the checkpoint's weights; the passes it lacks start as the identity
            state = {**{f"refiner.{k}": v for k, v in volume.net.refiner.state_dict().items()}, **state}
        volume.net.load_state_dict(state)
        start = int(meta.get("training", {}).get("step", 0))
        spent = float(meta.get("training", {}).get("train_seconds", 0.0))
        if start >= cfg.steps:  # a new run that would train nothing: its schedule ended at or before that step
            raise ValueError(f"{init} is at step {start} and the training config ends at steps={cfg.steps}: nothing to "
                             f"train; give the phase its end, e.g. --set steps={start + 1000} anneal_start={start}.")
    if ck is not None:
        saved = read_training_state(ck, volume, cfg)
        start, spent = saved["step"], saved["train_seconds"]
        ema_state, ema_updates = saved["ema_state"], saved["ema_updates"]
    end = cfg.steps if max_steps is None else min(cfg.steps, start + max_steps)
    if max_seconds is not None and spent >= max_seconds:
        end = start  # the budget is spent already
        if rank == 0 and not quiet:
            print(f"{out_dir}: {spent / 3600:.2f} h of training already reach the budget of {max_seconds / 3600:.2f} h")
    # workers fork before the model moves to a GPU; they get a CPU copy of the partition
    batches = batch_stream(cfg, body, copy.deepcopy(volume.partition).cpu(), start, end, rank,
                           device=None if cfg.num_workers else device)  # made on the device unless by CPU workers
    volume.to(device)
    volume.train()
    if cfg.train_weights == "refiner":   # the encoder and decoders stay fixed (no gradients computed for them)
        volume.net.requires_grad_(False)
        volume.net.refiner.requires_grad_(True)
    trained = [p for p in volume.net.parameters() if p.requires_grad]
    opt = torch.optim.Adam(trained, lr=lr_at(cfg, 0))  # after the move: its state lives on the device
    if saved is not None:
        load_optimizer(opt, *saved["optimizer"])
    ema = WeightEMA(volume.net, cfg.ema_decay, ema_state, ema_updates) if cfg.ema_decay else None
    volume.net.encoder_bf16 = cfg.encoder_bf16
    step_mod = TrainStep(volume, cfg)  # the body stays on the CPU: batches (and exact GT) are made there
    model = torch.nn.parallel.DistributedDataParallel(step_mod) if world > 1 else step_mod
    if rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
        write_atomic(out_dir / "config.json", json.dumps(cfg.to_dict(), indent=1))
    log_path = out_dir / "log.csv"
    if rank == 0 and log_path.exists():
        _truncate_log(log_path, start)  # rows past the checkpoint were logged by a run that stopped before saving
    if rank == 0 and (out_dir / "profile.jsonl").exists():
        _truncate_profile(out_dir / "profile.jsonl", start)
    new_log = rank == 0 and not log_path.exists()
    logf = open(log_path, "a", newline="") if rank == 0 else None
    writer = csv.writer(logf, lineterminator="\n") if logf else None  # the ends a truncation keeps
    if new_log:
        writer.writerow(LOG_HEADER)
    t0, losses, last = time.time(), [], {}
    step_profile = StepProfile()
    for step in range(start, end):
        td = time.time()
        batch = next(batches)
        batch = {**batch, "points": batch["points"].to(device), "sdf": batch["sdf"].to(device),
                 "params": {k: v.to(device) for k, v in batch["params"].items()},
                 "posed": {k: v.to(device) for k, v in batch["posed"].items()}}
        data_sec = time.time() - td
        for g_ in opt.param_groups:
            g_["lr"] = lr_at(cfg, step)
        opt.zero_grad(set_to_none=True)
        tf = time.perf_counter()
        loss, parts = _accumulate(model, batch, cfg.micro_batch, world > 1)
        tf = time.perf_counter() - tf
        if not math.isfinite(loss):  # before the update, so the last checkpoint stays sound
            raise RuntimeError(f"loss became {loss} at step {step}; lower the learning rate or check the data.")
        to = time.perf_counter()
        opt.step()
        if ema is not None:
            ema.update(volume.net)
        step_profile(batch, data_sec, tf, to, device)
        losses.append(loss)
        last = {"step": step + 1, "loss": loss, **parts}
        if rank == 0 and ((step + 1) % cfg.log_every == 0 or step + 1 == end):
            sps = (time.time() - t0) / (step + 1 - start)
            writer.writerow([step + 1, f"{loss:.6g}", f"{parts['sign']:.6g}", f"{parts['abs']:.6g}",
                             f"{lr_at(cfg, step):.3g}", f"{sps:.3f}", f"{data_sec:.3f}"])
            logf.flush()
            write_profile(out_dir / "profile.jsonl", step + 1, step_profile.last)
            if not quiet:
                eta = (cfg.steps - step - 1) * sps / 3600
                print(f"\rstep {step + 1}/{cfg.steps} loss {loss:.4f} (sign {parts['sign']:.4f}, abs {parts['abs']:.4f}) "
                      f"lr {lr_at(cfg, step):.2e} {sps:.2f} s/step, ETA {eta:.1f} h", end="", flush=True)
        used = spent + time.time() - t0
        over = max_seconds is not None and used >= max_seconds
        if world > 1 and max_seconds is not None:  # every rank stops at the same step
            flag = torch.tensor([float(over)])
            dist.all_reduce(flag)
            over = bool(flag.item() > 0)
        if rank == 0 and ((step + 1) % cfg.ckpt_every == 0 or step + 1 == end or over):
            save_training_state(out_dir, step + 1, volume, opt, cfg, {"loss": loss, "train_seconds": round(used, 3)}, ema)
        if over:
            break
    if logf:
        logf.close()
        if not quiet:
            print()
    if world > 1:
        dist.barrier()
    return {**last, "losses": losses, "sec_per_step": (time.time() - t0) / max(1, end - start), "start_step": start,
            "steps": cfg.steps}


# ---------------------------------------------------------------------- CLI
def add_parser(sub):
    p = sub.add_parser("train", help="train the volumetric model on the default body (resumable; torchrun for DDP)")
    p.add_argument("--config", default=None, help="JSON with TrainConfig fields (and 'model': VolumeConfig fields)")
    p.add_argument("--out", default="runs/volsmpl", help="run folder: checkpoints, log.csv, config.json")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its latest checkpoint")
    p.add_argument("--max-steps", type=int, default=None, help="stop this process after so many steps")
    p.add_argument("--max-hours", type=float, default=None,
                   help="stop when the run's cumulative training time reaches this many hours (equal-compute budgets)")
    p.add_argument("--init", default=None, help="start from this model checkpoint's weights and step (new optimiser)")
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="override config fields, e.g. batch_size=4")
    return p


def _checkpoint_train_config(path) -> dict:
    """The training config recorded in a model checkpoint's JSON (meta.training.train_config), {} when it has none;
    the checkpoint is named with or without suffix and checked as `load_checkpoint` checks it."""
    _, _, meta = load_checkpoint(path, weights=False)
    training = meta.get("training")
    tc = training.get("train_config") if isinstance(training, dict) else None
    return dict(tc) if isinstance(tc, dict) else {}


def _start_config(args) -> dict:
    """The config fields a `volsmpl train` starts from, before --set: the --config file; on --resume the run's own
    (its config.json, or the latest checkpoint's training config in a folder holding only copied checkpoint
    folders); with --init the init checkpoint's training config; else {} (the defaults)."""
    if args.config:
        return read_config_file(args.config)
    out = Path(args.out)
    if args.resume:
        if (out / "config.json").exists():
            return read_config_file(out / "config.json", "the run's config")
        ck = latest_checkpoint(out)
        if ck is not None:
            return _checkpoint_train_config(ck / "model")
    if args.init:
        return _checkpoint_train_config(args.init)
    return {}


def _say_config_changes(out: Path, cfg: TrainConfig) -> None:
    """On --resume, name on stderr every field of `cfg` that differs from the training config recorded in the
    checkpoint it continues (a --config or --set that changes the run is meant, but never silent)."""
    ck = latest_checkpoint(out)
    if ck is None:
        return
    saved, now = _checkpoint_train_config(ck / "model"), cfg.to_dict()
    changed = [f"{k} {saved[k]!r} -> {now[k]!r}" for k in sorted(now) if k in saved and saved[k] != now[k]]
    if changed:
        print(f"note: resuming {ck.name} with a changed training config: {'; '.join(changed)}", file=sys.stderr)


def run(args) -> int:
    from volsmpl.io.outputs import check_writable
    check_writable(args.out, "dir", "--out")  # before any work: a bad run folder fails in seconds
    if args.max_steps is not None and args.max_steps < 0:
        raise ValueError(f"--max-steps {args.max_steps}: give a number of steps >= 0.")
    if args.max_hours is not None and not (math.isfinite(args.max_hours) and args.max_hours > 0):
        raise ValueError(f"--max-hours {args.max_hours}: give a finite number of hours > 0.")
    d = _start_config(args)
    d.update(parse_set(args.set))
    cfg = TrainConfig.from_dict(d)
    if args.resume:
        _say_config_changes(Path(args.out), cfg)
    summary = train(cfg, args.out, resume=args.resume, max_steps=args.max_steps, device=args.device, init=args.init,
                    max_seconds=None if args.max_hours is None else args.max_hours * 3600)
    if "step" in summary:
        print(f"done: step {summary['step']} loss {summary['loss']}")
    elif summary["start_step"] >= summary["steps"]:
        print(f"nothing to train: {args.out} is at step {summary['start_step']}, the end of its schedule "
              f"(steps={summary['steps']}); to go on, give it a later end: --resume --set steps=N")
    else:
        print(f"nothing trained: {args.out} stays at step {summary['start_step']} (--max-steps 0 or the --max-hours "
              f"budget)")
    return 0
