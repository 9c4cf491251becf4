"""The learned surface of a volume as a mesh: marching cubes of its level set on a grid around one body.

    mesh = level_set_mesh(body.volume, out, resolution=128)     # what Volume.extract_mesh returns
"""
from __future__ import annotations

import torch

from .body_view import select_body
from .extract_args import check_extract_args


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
