"""The learned surface of a volume as a mesh: marching cubes of its level set on a grid around one body, and the
argument checks every kind's `extract_mesh` shares (a wrong resolution, body index or padding is refused in one line
instead of failing deep inside or silently giving a wrong mesh).

    mesh = level_set_mesh(body.volume, out, resolution=128)     # what Volume.extract_mesh returns
"""
from __future__ import annotations

import math
import numbers

import torch

from volsmpl.body.view import select_body


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


@torch.no_grad()
def level_set_mesh(volume, out, resolution: int = 128, body_index: int = 0, padding: float = 0.05):
    """Marching cubes of a volume's level set (SDF models: zero; occupancy models: `volume.level`) of body
    `body_index` of `out`, on a resolution^3 grid over its vertices' box grown by `padding` metres.

    Shape: out with B bodies -> trimesh.Trimesh (world frame, triangles wound outward). RuntimeError when the
    field does not cross the level in the box (an untrained or broken model).
    """
    import trimesh
    from skimage.measure import marching_cubes

    resolution, body_index, padding = check_extract_args(out, resolution, body_index, padding)
    v = out.vertices[body_index].detach()
    lo, hi = v.amin(0) - padding, v.amax(0) + padding
    axes = [torch.linspace(float(lo[i]), float(hi[i]), resolution, dtype=v.dtype, device=v.device) for i in range(3)]
    grid = torch.stack(torch.meshgrid(*axes, indexing="ij"), dim=-1).reshape(-1, 3)
    sub = select_body(out, body_index)
    field = volume.query(sub, grid[None])[0].reshape(resolution, resolution, resolution).cpu().numpy()
    if volume.is_sdf:
        field = -field  # positive inside, like occupancy
    level = -volume.level if volume.is_sdf else volume.level
    if not (field.min() < level < field.max()):
        raise RuntimeError("the field has no level-set crossing in the body's box: the model is untrained or broken.")
    spacing = ((hi - lo) / (resolution - 1)).cpu().numpy()
    verts, faces, _, _ = marching_cubes(field, level=level, spacing=tuple(spacing))
    # skimage winds triangles outward when the field grows inward only after a flip
    return trimesh.Trimesh(verts + lo.cpu().numpy(), faces[:, ::-1], process=False)
