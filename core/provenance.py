"""Where and when a result was made, recorded the same way in every result JSON (`volsmpl eval`,
`volsmpl bench`, the apps) under the key 'meta'.

    from volsmpl.provenance import machine_info
    result["meta"] = machine_info("cpu", threads=1)
    # {'cpu': ..., 'cpu_count': 2, 'load_avg_1_5_15': [...], 'platform': ..., 'python': ..., 'torch': ...,
    #  'device': 'cpu', 'threads': 1, 'date': '2026-...', 'git_commit': 'c6352ed'} (+ 'gpu' on CUDA)
"""
from __future__ import annotations

import datetime
import os
import platform
import subprocess
from pathlib import Path
from typing import List, Optional

import torch

__all__ = ["machine_info", "git_commit", "load_avg", "cpu_name"]


def cpu_name() -> str:
    """The CPU's model name (/proc/cpuinfo), else platform.processor(), else 'unknown CPU'."""
    try:
        with open("/proc/cpuinfo") as fh:
            names = [ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")]
        if names:
            return names[0]
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def load_avg() -> Optional[List[float]]:
    """The system's 1, 5 and 15 minute load averages (None where unavailable)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def git_commit() -> Optional[str]:
    """Short commit hash of the source checkout this package runs from (None outside a git checkout)."""
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).resolve().parent,
                             capture_output=True, text=True, timeout=10)
        return (out.stdout.strip() or None) if out.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        return None


def machine_info(device="cpu", threads: Optional[int] = None) -> dict:
    """CPU model, cores, load, platform, python and torch versions, device (and GPU name on CUDA), torch
    CPU threads (None: this process's torch.get_num_threads()), local date and git commit."""
    info = {
        "cpu": cpu_name(), "cpu_count": os.cpu_count(), "load_avg_1_5_15": load_avg(),
        "platform": platform.platform(), "python": platform.python_version(), "torch": torch.__version__,
        "device": str(device), "threads": threads or torch.get_num_threads(),
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"), "git_commit": git_commit(),
    }
    if str(device).startswith("cuda") and torch.cuda.is_available():
        info["gpu"] = torch.cuda.get_device_name(torch.device(device))
    return info
