"""Argument checks shared by Volume.extract_mesh and MeshVolume.extract_mesh: a wrong resolution,
body index or padding is refused in one line instead of failing deep inside (or silently giving a wrong mesh)."""
from __future__ import annotations

import math
import numbers

#: largest marching-cubes grid: 512^3 points are 134 M queries (1.6 GB of float32 coordinates alone)
MAX_RESOLUTION = 512
MIN_RESOLUTION = 8


def check_extract_args(out, resolution, body_index, padding) -> tuple[int, int, float]:
    """(resolution, body_index, padding) as int, int, float; ValueError / TypeError naming the fix."""
    if isinstance(resolution, bool) or not isinstance(resolution, numbers.Integral):
        raise TypeError(f"extract_mesh: resolution must be an int (grid points per axis), got "
                        f"{type(resolution).__name__} {resolution!r}; e.g. resolution=128.")
    resolution = int(resolution)
    if resolution < MIN_RESOLUTION:
        raise ValueError(f"extract_mesh: resolution={resolution} is too coarse; use at least {MIN_RESOLUTION} (128 recommended).")
    if resolution > MAX_RESOLUTION:
        gb = resolution ** 3 * 3 * 4 / 1e9
        raise ValueError(f"extract_mesh: resolution={resolution} is above the limit {MAX_RESOLUTION} (its grid alone "
                         f"would take {gb:.1f} GB); use at most {MAX_RESOLUTION} (128 recommended).")
    if isinstance(body_index, bool) or not isinstance(body_index, numbers.Integral):
        raise TypeError(f"extract_mesh: body_index must be an int, got {type(body_index).__name__} {body_index!r}.")
    batch = int(out.vertices.shape[0])
    if not 0 <= int(body_index) < batch:
        raise ValueError(f"extract_mesh: body_index={int(body_index)} is out of range for a batch of {batch} "
                         f"bod{'y' if batch == 1 else 'ies'}; use 0..{batch - 1}.")
    if isinstance(padding, bool) or not isinstance(padding, numbers.Real):
        raise TypeError(f"extract_mesh: padding must be a number (metres), got {type(padding).__name__} {padding!r}.")
    if not (math.isfinite(float(padding)) and float(padding) > 0):
        raise ValueError(f"extract_mesh: padding={padding} must be positive (metres around the body's box; a "
                         f"box touching or inside the body gives an open or inside-out mesh); e.g. padding=0.05.")
    return resolution, int(body_index), float(padding)
