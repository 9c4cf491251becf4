"""`check_device`: a device a command was asked to run on either exists here or is refused in one line (before
any work), so `--device cuda` on a machine without CUDA never ends in an assertion deep inside torch."""
from __future__ import annotations

import torch


def check_device(spec, what: str = "--device") -> torch.device:
    """torch.device of `spec` ('cpu', 'cuda', 'cuda:1', a torch.device); ValueError naming the fix when this machine
    cannot run on it."""
    try:
        dev = torch.device(spec)
    except (RuntimeError, TypeError, ValueError) as e:
        raise ValueError(f"{what} {spec!r} is not a device name ({e}); use cpu or cuda (cuda:N for GPU N).") from e
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            why = ("this torch is a CPU-only build" if torch.version.cuda is None
                   else f"torch (CUDA {torch.version.cuda}) finds no usable GPU")
            raise ValueError(f"{what} {spec}: CUDA is not available here ({why}); use {what} cpu, or run on a "
                             f"machine with an NVIDIA GPU and a CUDA build of torch.")
        n = torch.cuda.device_count()
        if dev.index is not None and dev.index >= n:
            raise ValueError(f"{what} {spec}: this machine has {n} GPU{'s' if n != 1 else ''} (cuda:0..cuda:{n - 1}).")
    elif dev.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"{what} {spec}: MPS is not available here; use {what} cpu.")
    elif dev.type not in ("cpu", "cuda", "mps"):
        raise ValueError(f"{what} {spec}: volsmpl runs on cpu or cuda, not {dev.type}.")
    return dev
