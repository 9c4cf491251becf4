"""Training-step breakdown with each ground-truth backend, measured side by side in one process.

    python tools/gt_profile.py [--config cfg.json] [--steps 3] [--device cpu] [--threads 1] [--backends open3d torch]
                               [--trace]     # then the torch profiler's table of one torch ground-truth batch

For every step s the same batch (make_batch: LBS, query sampling) is made once per backend, so both backends label
the same points, then one forward+backward (micro-batched as in training) and one Adam step run on it. Prints a
JSON line per (step, backend) with make_s, gt_s, fwd_bwd_s, opt_s, and a summary: medians, steps/s (make + fwd/bwd
+ optimiser) and the ground truth's share of the step, per backend. Steps interleave the backends, so on a shared
CPU both see the same load. The config is a TrainConfig JSON (default: the shipped checkpoint's training config).
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import statistics
import time
from pathlib import Path

import torch

from volsmpl.volume.attach import attach_volume
from volsmpl.body.model import create_body
from volsmpl.train.loop import TrainStep
from volsmpl.train.batches import batch_stream
from volsmpl.train.config import TrainConfig


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", default=None, help="TrainConfig JSON (default: core/assets/volsmpl_anny.json's)")
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--device", default="cpu")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--backends", nargs="+", default=["open3d", "torch"])
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="override config fields")
    p.add_argument("--trace", action="store_true", help="profile one torch ground-truth batch (operators, host waits)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    if args.config:
        d = json.loads(Path(args.config).read_text())
    else:
        d = json.loads((Path(__file__).resolve().parent.parent / "core/assets/volsmpl_anny.json").read_text())
        d = d["meta"]["training"]["train_config"]
    for kv in args.set:
        k, _, v = kv.partition("=")
        d[k] = json.loads(v) if v[:1] in "0123456789-[{tf" else v
    cfg = TrainConfig.from_dict(d)
    dev = torch.device(args.device)
    body = create_body()
    volume = attach_volume(body, pretrained=False, model=cfg.model_kind, config=cfg.model).to(dev)
    volume.train()
    volume.net.encoder_bf16 = cfg.encoder_bf16
    model = TrainStep(volume, cfg)
    opt = torch.optim.Adam(volume.net.parameters(), lr=1e-12)  # a real optimiser step that barely moves the weights
    streams = {b: batch_stream(dataclasses.replace(cfg, gt_backend=b, num_workers=0), body, volume.partition, 0,
                               args.steps, device=dev) for b in args.backends}
    rows = {b: [] for b in args.backends}
    for step in range(args.steps):
        for b in args.backends:
            batch = next(streams[b])
            opt.zero_grad(set_to_none=True)
            t0 = time.perf_counter()
            B, m = batch["points"].shape[0], max(1, cfg.micro_batch)
            for s in range(0, B, m):  # micro-batches as the training loop (gradients of the full-batch mean)
                sub = {"posed": {k: v[s:s + m] for k, v in batch["posed"].items()}, "points": batch["points"][s:s + m],
                       "sdf": batch["sdf"][s:s + m], "seed": batch["seed"] * 7919 + s}
                loss, _ = model(sub)
                (loss * (len(sub["points"]) / B)).backward()
            t1 = time.perf_counter()
            opt.step()
            if dev.type == "cuda":
                torch.cuda.synchronize(dev)
            t2 = time.perf_counter()
            r = {"step": step, "backend": b, **batch["timing"], "fwd_bwd_s": t1 - t0, "opt_s": t2 - t1,
                 "points": int(batch["points"].shape[0] * batch["points"].shape[1])}
            rows[b].append(r)
            print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in r.items()}), flush=True)
    summary = {}
    for b, rs in rows.items():
        med = {k: statistics.median(r[k] for r in rs) for k in ("make_s", "gt_s", "fwd_bwd_s", "opt_s")}
        step_s = med["make_s"] + med["fwd_bwd_s"] + med["opt_s"]
        summary[b] = {**{k: round(v, 4) for k, v in med.items()}, "steps_per_s": round(1 / step_s, 4),
                      "gt_share": round(med["gt_s"] / step_s, 3)}
    print(json.dumps({"device": str(dev), "threads": args.threads, "batch_size": cfg.batch_size,
                      "encoder_bf16": cfg.encoder_bf16, "summary": summary}, indent=1))
    if args.trace:
        trace_ground_truth(cfg, body, volume.partition, dev)
    return 0


def trace_ground_truth(cfg: TrainConfig, body, partition, dev: torch.device) -> None:
    """The torch profiler's view of one training batch (make_batch with the torch ground truth) and of its ground
    truth alone: the operators by device time (host time on the CPU), the launches, the host waits and the wall
    times, so that a GPU's batch shows whether its time goes to device work or to the host issuing it."""
    from torch.profiler import ProfilerActivity, profile

    from volsmpl.geometry.groundtruth import batch_sdf
    from volsmpl.train.batches import make_batch

    cfg = dataclasses.replace(cfg, gt_backend="torch", num_workers=0)
    if body.v_template.device != dev:   # as batch_stream: a copy of the body on the device, its volume shared
        vol = getattr(body, "volume", None)
        body = copy.deepcopy(body, memo={} if vol is None else {id(vol): vol}).to(dev)
    batch = make_batch(cfg, body, partition, 10_000)
    jobs = {"make_batch": lambda: make_batch(cfg, body, partition, 10_001),
            "ground_truth": lambda: batch_sdf(batch["posed"]["vertices"], body.faces_tensor, batch["points"],
                                              sign=cfg.gt_sign, nsamples=cfg.gt_rays, backend="torch",
                                              check_closed=False)}
    cuda = dev.type == "cuda"
    acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])
    for name, run in jobs.items():
        run()
        with profile(activities=acts) as prof:
            t0 = time.perf_counter()
            run()
            if cuda:
                torch.cuda.synchronize(dev)
            wall = time.perf_counter() - t0
        ev = prof.key_averages()
        print(f"--- {name}")
        print(ev.table(sort_by="self_cuda_time_total" if cuda else "self_cpu_time_total", row_limit=20,
                       max_name_column_width=48))
        waits = {e.key: e.count for e in ev
                 if any(w in e.key for w in ("Synchronize", "item", "nonzero", "Memcpy", "_local_scalar"))}
        busy = sum(getattr(e, "self_device_time_total", 0) or 0 for e in ev) / 1e6 if cuda else None
        print(json.dumps({"trace": name, "points": int(batch["points"][..., 0].numel()), "wall_s": round(wall, 4),
                          "launches": sum(e.count for e in ev if "LaunchKernel" in e.key),
                          "aten_calls": sum(e.count for e in ev if e.key.startswith("aten::")),
                          "device_busy_s": None if busy is None else round(busy, 4), "host_waits": waits}))

if __name__ == "__main__":
    raise SystemExit(main())
