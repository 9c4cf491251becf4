"""Training-state folders of `volsmpl train`: write, verify and read back ``<out>/ckpt-<step>/``.

A training state is everything a run needs to continue exactly, in files small enough to move one at a time
(none over ``SHARD_BYTES``, 16 MiB, for the shipped model configurations) and independent of the device that
wrote them (every tensor is stored on the CPU; reading moves it to the training device)::

    ckpt-00012000/
        model.safetensors + model.json     the published model (a normal checkpoint: `volsmpl eval` reads it);
                                           with a weight average (ema_decay > 0) the average
        live-00-of-01.safetensors          the optimised weights (only with a weight average)
        optimizer-00-of-02.safetensors     Adam's moments, split into shards of at most SHARD_BYTES
        optimizer-01-of-02.safetensors
        state.json                         format, step, Adam's scalars, and the sha256 and size of every file

A folder is written under a temporary name and published by atomically replacing ``<out>/latest``, so a killed
run never leaves a half-written state under a name that is read. On resume every file is checked against the
sha256 recorded in state.json: a damaged or swapped file is refused with a message naming it and the fix.
Folders written before state.json existed (``optimizer.safetensors`` + ``optimizer.json``, ``live.safetensors``)
are still read.

Example (continue a run on another machine: copy the folder, then)::

    volsmpl train --resume --out runs/coap_pp --device cuda
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import torch

from volsmpl.io.checkpoint import load_checkpoint, save_checkpoint
from volsmpl.io.outputs import file_sha256
from volsmpl.train.config import same_weights_config

STATE_FORMAT = "volsmpl-train-state"
STATE_VERSION = 2
SHARD_BYTES = 16 * 2**20


class TrainStateError(RuntimeError):
    """A training-state folder is incomplete, damaged, or belongs to another run configuration."""


def _tensor_bytes(t: torch.Tensor) -> int:
    return t.numel() * t.element_size()


def shard_tensors(tensors: dict, limit: int = SHARD_BYTES) -> list[list[str]]:
    """Split tensor names, in name order, into consecutive groups of at most `limit` bytes of data each.

    A single tensor larger than `limit` gets a group of its own (the file then exceeds the limit; no shipped
    configuration has one: the largest tensor of the VolumetricSMPL network is 4.2 MB).
    """
    groups, cur, size = [], [], 0
    for k in sorted(tensors):
        n = _tensor_bytes(tensors[k])
        if cur and size + n > limit:
            groups.append(cur)
            cur, size = [], 0
        cur.append(k)
        size += n
    if cur or not groups:
        groups.append(cur)
    return groups


def _write_shards(folder: Path, stem: str, tensors: dict, limit: int) -> list[str]:
    from safetensors.torch import save_file

    groups = shard_tensors(tensors, limit)
    names = []
    for i, keys in enumerate(groups):
        name = f"{stem}-{i:02d}-of-{len(groups):02d}.safetensors"
        save_file({k: tensors[k] for k in keys}, str(folder / name))
        names.append(name)
    return names


def optimizer_tensors(opt: torch.optim.Optimizer) -> tuple[dict, dict]:
    """Adam's state as flat CPU tensors named 'opt.<param index>.<key>' and its JSON scalars (param groups)."""
    sd = opt.state_dict()
    tensors = {}
    for i, st in sd["state"].items():
        for k, v in st.items():
            tensors[f"opt.{i}.{k}"] = (v if torch.is_tensor(v) else torch.tensor(v)).detach().cpu().contiguous()
    return tensors, {"param_groups": sd["param_groups"]}


def load_optimizer(opt: torch.optim.Optimizer, tensors: dict, scalars: dict) -> None:
    """Restore what `optimizer_tensors` wrote through torch's own ``load_state_dict`` (which moves each moment to
    its parameter's device and keeps Adam's step counter where the optimiser expects it, on any device)."""
    state: dict = {}
    for name, v in tensors.items():
        _, i, key = name.split(".", 2)
        state.setdefault(int(i), {})[key] = v
    groups = scalars["param_groups"]
    if "params" not in groups[0]:  # written by an older volsmpl: parameters numbered in group order
        n = 0
        for g, cur in zip(groups, opt.param_groups):
            g["params"] = list(range(n, n + len(cur["params"])))
            n += len(cur["params"])
    opt.load_state_dict({"state": state, "param_groups": groups})


def save_training_state(out_dir: Path, step: int, volume, opt, cfg, summary: dict, ema=None,
                        shard_bytes: int | None = None) -> Path:
    """Write <out>/ckpt-<step>/ (model, optimised weights, Adam's moments, state.json) and point <out>/latest at it;
    keep the newest `cfg.keep_ckpts` folders and, with `cfg.keep_every` > 0, those whose step is a multiple of it
    (milestones, e.g. a phase's end before the next phase resumes from it). With a weight average the model file
    holds the average."""
    out_dir = Path(out_dir)
    shard_bytes = SHARD_BYTES if shard_bytes is None else shard_bytes
    d = out_dir / f"ckpt-{step:08d}"
    tmp = out_dir / f".tmp-ckpt-{step:08d}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    meta = {"body_fingerprint": volume.fingerprint, "part_table": volume.partition.table.to_dict(),
            "training": {**summary, "step": step, "train_config": cfg.to_dict()}}
    live = {k: v.detach().cpu().contiguous() for k, v in volume.net.state_dict().items()}
    files = ["model.safetensors", "model.json"]
    live_files = []
    if ema is not None:
        meta["training"]["ema_updates"] = ema.updates
        save_checkpoint(tmp / "model", {k: v.detach().cpu() for k, v in ema.avg.items()}, cfg.model.to_dict(), meta)
        live_files = _write_shards(tmp, "live", live, shard_bytes)
    else:
        save_checkpoint(tmp / "model", live, cfg.model.to_dict(), meta)
    tensors, scalars = optimizer_tensors(opt)
    opt_files = _write_shards(tmp, "optimizer", tensors, shard_bytes)
    files += live_files + opt_files
    doc = {"format": STATE_FORMAT, "version": STATE_VERSION, "step": step, "live": live_files,
           "optimizer": {"files": opt_files, **scalars},
           "files": {f: {"sha256": file_sha256(tmp / f), "bytes": (tmp / f).stat().st_size} for f in files}}
    with open(tmp / "state.json", "w") as f:
        f.write(json.dumps(doc, indent=1))
        f.flush()
        os.fsync(f.fileno())
    shutil.rmtree(d, ignore_errors=True)
    os.replace(tmp, d)
    latest_tmp = out_dir / ".latest.tmp"
    latest_tmp.write_text(d.name)
    os.replace(latest_tmp, out_dir / "latest")
    ckpts = sorted(p for p in out_dir.glob("ckpt-*") if p.is_dir())
    for old in ckpts[:-cfg.keep_ckpts]:
        if not (cfg.keep_every and int(old.name.split("-")[1]) % cfg.keep_every == 0):
            shutil.rmtree(old, ignore_errors=True)
    return d


def latest_checkpoint(out_dir: Path) -> Path | None:
    """The folder <out>/latest points at, or None when the run has no checkpoint yet."""
    f = Path(out_dir) / "latest"
    if not f.exists():
        return None
    d = Path(out_dir) / f.read_text().strip()
    if not (d / "model.safetensors").exists():
        raise FileNotFoundError(f"{f} points at {d}, which has no model.safetensors; remove {f} to start over.")
    return d


def _fix_hint(ck: Path) -> str:
    older = sorted(p.name for p in ck.parent.glob("ckpt-*") if p.is_dir() and p.name < ck.name)
    if older:
        return f"copy the folder again, or resume from {older[-1]}: echo {older[-1]} > {ck.parent / 'latest'}"
    return "copy the folder again from where the run was written, or start over with --init from its model file"


def verify_state(ck: Path) -> dict | None:
    """Check every file of a training-state folder against state.json; return that document (None for a folder
    written before state.json existed, which carries no digests)."""
    ck = Path(ck)
    p = ck / "state.json"
    if not p.exists():
        return None
    try:
        doc = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise TrainStateError(f"{p} is damaged (not valid JSON: {e}); {_fix_hint(ck)}.") from e
    if doc.get("format") != STATE_FORMAT or doc.get("version") != STATE_VERSION:
        raise TrainStateError(f"{p} is a training state of format {doc.get('format')!r} version {doc.get('version')!r}; "
                              f"this volsmpl reads {STATE_FORMAT!r} version {STATE_VERSION}: resume with the volsmpl "
                              "release that wrote it, or start over with --init from its model file.")
    for name, rec in doc["files"].items():
        f = ck / name
        if not f.exists():
            raise TrainStateError(f"{f} is missing (a training state is the whole folder {ck.name}/); {_fix_hint(ck)}.")
        if f.stat().st_size != rec["bytes"] or file_sha256(f) != rec["sha256"]:
            raise TrainStateError(f"{f} does not match the sha256 recorded in {p} (damaged, truncated or from another "
                                  f"checkpoint); {_fix_hint(ck)}.")
    return doc


def read_training_state(ck: Path, volume, cfg) -> dict:
    """Load a training-state folder's optimised weights into `volume.net`; return {'step', 'train_seconds',
    'ema_state' (averaged weights or None), 'ema_updates', 'optimizer': (tensors, scalars)}, all on the CPU.

    Give 'optimizer' to `load_optimizer` once the network is on its training device (Adam's moments follow their
    parameters there), so a state written on one device type continues on another."""
    from safetensors.torch import load_file

    ck = Path(ck)
    doc = verify_state(ck)
    state, _, meta = load_checkpoint(ck / "model", expected_fingerprint=volume.fingerprint)
    saved_cfg = meta["training"]["train_config"]
    if not same_weights_config(saved_cfg["model"], cfg.model):
        raise ValueError(f"{ck} was trained with model config {saved_cfg['model']}, not {cfg.model.to_dict()}; "
                         f"resume with the run's own config ({ck.parent}/config.json).")
    if doc is not None:
        live_files, opt_files, scalars = doc["live"], doc["optimizer"]["files"], doc["optimizer"]
    else:  # a folder written before state.json
        live_files = ["live.safetensors"] if (ck / "live.safetensors").exists() else []
        opt_files, scalars = ["optimizer.safetensors"], json.loads((ck / "optimizer.json").read_text())
    ema_state, ema_updates = None, 0
    if live_files:  # the model file is the average; optimise on from the live weights
        if not cfg.ema_decay:
            raise ValueError(f"{ck} holds averaged weights (ema_decay > 0) but the config has ema_decay=0; resume "
                             f"with the run's own config ({ck.parent}/config.json).")
        ema_state, state = state, {k: v for f in live_files for k, v in load_file(str(ck / f)).items()}
        ema_updates = int(meta["training"].get("ema_updates", 0))
    volume.net.load_state_dict(state)
    opt_tensors = {k: v for f in opt_files for k, v in load_file(str(ck / f)).items()}
    return {"step": int(meta["training"]["step"]), "train_seconds": float(meta["training"].get("train_seconds", 0.0)),
            "ema_state": ema_state, "ema_updates": ema_updates,
            "optimizer": (opt_tensors, {"param_groups": scalars["param_groups"]})}
