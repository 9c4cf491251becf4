"""Per-part evaluation points: the query-point sampling of COAP's released training code, the only written
protocol behind the paper's Table 1 numbers (`volsmpl eval --sampling parts`).

    points, is_surface = part_query_points(body, bodies)          # (B, 60000, 3), (60000,)

For every body and every part k of the body's partition (`volsmpl.body.partition.Partition`, boxes padded by 12.5 %
as the models' are), the same number of points per part:
  - uniform in part k's padded box (in the part's frame G_k, then posed: the box rotates with the part);
  - area-weighted uniform samples on part k's own faces (its 'tight' faces) + isotropic Gaussian offsets
    N(0, sigma^2 I), sigma = 1 cm.
So small parts (hands, feet) get as many points as the torso, and the uniform points lie in the part boxes,
close to the body, instead of the body's padded bounding box (`volsmpl.evaluation.validation_set.query_points`). Layout per
body: [uniform: part 0 | part 1 | ... | near-surface: part 0 | part 1 | ...], so `is_surface` splits the two
sets exactly as for the default sampling.

Where this differs from COAP's code, on purpose: its points are drawn afresh on every call (here from a
per-body generator seeded with SeedSequence([seed, 2, i]), so sets are reproducible and cacheable); its box is
shrunk by 1 mm (not done here); and its reported 'uniform' / 'surface' IoUs split the flattened, part-major
points at the half, which separates the first parts from the last ones and mixes both sets in each half; here
the split is by sampling set, as the paper's column names say.
"""
from __future__ import annotations

from typing import Dict

import torch

from volsmpl.evaluation.config import EvalConfig
from volsmpl.evaluation.validation_set import VAL_SEED, query_points, sub_seed, surface_samples

__all__ = ["part_query_points"]

#: bodies posed per forward pass (fixed, so that the points do not depend on a caller's batch size)
POSE_CHUNK = 16


def part_query_points(body, bodies: Dict[str, torch.Tensor], n_points: int = 60000, seed: int = VAL_SEED,
                      surface_fraction: float = 0.5, surface_sigma: float = 0.01, box_padding: float = 0.125):
    """Per-part evaluation queries (module docstring) of posed bodies.

    Args:
        body: the body model (its partition decides the parts; moved nowhere, posed on its device).
        bodies: dict of betas / global_orient / body_pose / transl (B, .), as `validation_bodies` returns.
        n_points: points per body; must be a multiple of the number of parts K (n_points / K per part, of
            which round(n_points / K * surface_fraction) near the surface).
        seed: body i samples from a generator seeded with SeedSequence([seed, 2, i]); bodies are posed 16 at a
            time (as `validation.pose_bodies` by default), so body i's points do not depend on the bodies after it.
        surface_sigma: std of the offsets of the near-surface points, metres. box_padding: relative padding
            of the part boxes (the models' 0.125).
    Returns:
        points (B, n_points, 3) float32 CPU; is_surface (n_points,) bool.

    Example:
        >>> pts, surf = part_query_points(create_body(), validation_bodies(2), n_points=1600)
        >>> pts.shape, int(surf.sum())
        (torch.Size([2, 1600, 3]), 800)
    """
    from volsmpl.body.partition import Partition

    part = Partition(body, n_samples=2, box_padding=box_padding).to(body.v_template.device)
    K = part.num_parts
    if not isinstance(n_points, int) or n_points < K or n_points % K:
        raise ValueError(f"per-part sampling needs points per body a positive multiple of the {K} parts, got "
                         f"{n_points!r}; e.g. --points {max(1, round(n_points / K)) * K if isinstance(n_points, int) else 60000}.")
    per = n_points // K
    n_surf = int(round(per * surface_fraction))
    n_unif = per - n_surf
    if n_surf == 0 or n_unif == 0:
        raise ValueError(f"per-part sampling of {n_points} points gives each of the {K} parts {per}, which leaves its "
                         f"{'near-surface' if n_surf == 0 else 'uniform'} set empty; give --points of at least {2 * K}.")
    faces = part.faces.cpu().long()
    tight = [faces[torch.as_tensor(ids, dtype=torch.long)] for ids in part.tight_face_ids]
    like = body.v_template
    B = len(bodies["betas"])
    out = torch.empty(B, n_points, 3, dtype=torch.float64)
    with torch.no_grad():
        for s in range(0, B, POSE_CHUNK):
            chunk = {k: v[s:s + POSE_CHUNK].to(like.device, like.dtype) for k, v in bodies.items()}
            posed = body(**chunk)
            G = part.part_transforms(posed.full_pose, posed.joints)
            box_min, box_max = part.boxes(posed.vertices, G)
            G, box_min, box_max, verts = (x.detach().cpu().double() for x in (G, box_min, box_max, posed.vertices))
            for j in range(verts.shape[0]):
                i = s + j
                g = torch.Generator().manual_seed(sub_seed(seed, 2, i))
                u = torch.rand(K, n_unif, 3, generator=g, dtype=torch.float64)
                local = box_min[j, :, None] + u * (box_max[j] - box_min[j])[:, None]   # (K, n_unif, 3) part frames
                world = torch.einsum("kij,knj->kni", G[j, :, :3, :3], local) + G[j, :, None, :3, 3]
                out[i, :K * n_unif] = world.reshape(-1, 3)
                surf = torch.cat([surface_samples(verts[j], f, n_surf, g) for f in tight])
                out[i, K * n_unif:] = surf + torch.randn(K * n_surf, 3, generator=g, dtype=torch.float64) * surface_sigma
    is_surface = torch.zeros(n_points, dtype=torch.bool)
    is_surface[K * n_unif:] = True
    return out.float(), is_surface


def evaluation_points(body, bodies: Dict[str, torch.Tensor], verts: torch.Tensor, cfg: EvalConfig):
    """The query points of an evaluation by `cfg.sampling`: points (B, n_points, 3), is_surface (n_points,).
    verts: the bodies posed (B, V, 3), for the body-box sampling; the per-part one poses them itself."""
    if cfg.sampling == "parts":
        return part_query_points(body, bodies, cfg.n_points, cfg.seed, cfg.surface_fraction, cfg.surface_sigma)
    return query_points(verts, body.faces, cfg.n_points, cfg.seed, cfg.surface_fraction, cfg.bbox_padding,
                        cfg.surface_sigma)
