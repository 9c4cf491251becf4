"""Where and when a result was made, recorded the same way in every result JSON (`volsmpl eval`,
`volsmpl bench`, the apps) under the key 'meta'.

    from volsmpl.io.provenance import machine_info
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


#: written into an exported package (`git archive` has no .git) with the commit it was exported from
SOURCE_COMMIT = "SOURCE_COMMIT"


def git_commit(package_dir=None) -> Optional[str]:
    """Short commit hash of the code this package runs from: the commit named in its SOURCE_COMMIT file when it is
    an export (long CLI jobs run from one, so that edits of the checkout do not change what they run), else the
    HEAD of the git checkout it lies in; None when neither. package_dir: this package's folder (default)."""
    folder = Path(package_dir) if package_dir is not None else Path(__file__).resolve().parents[1]
    marker = folder / SOURCE_COMMIT
    if marker.is_file():
        return marker.read_text().strip() or None
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=folder,
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
