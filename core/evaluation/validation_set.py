"""The fixed validation set: bodies the training sampler never draws and their query points, regenerated
bit-identically from a seed.

    from volsmpl.evaluation.validation_set import validation_bodies, pose_bodies, query_points
    bodies = validation_bodies(64)                               # betas / global_orient / body_pose / transl
    verts = pose_bodies(body, bodies)                            # (64, V, 3)
    points, is_surface = query_points(verts, body.faces)         # (64, 60000, 3), (60000,)

Bodies (`validation_bodies`), seed VAL_SEED by default. Body i is built from its own random stream
SeedSequence([seed, i]), so `validation_bodies(n)` is a prefix of `validation_bodies(m)` for n <= m:
  - pose: odd i < 2 * len(NAMED_POSES) take the named poses in NAMED_POSES order (all 12 at n >= 24);
    every other body an *extreme* pose (`sample_poses(mode='extreme')`: every joint angle uniform over its
    full anatomical range; training draws 'realistic' or 'mixed' poses from other seeds). At n=64: 12 named
    + 52 extreme.
  - shape: group (i // 2) % 4 of SHAPE_GROUPS: tall (>= 1.85 m), short (<= 1.55 m), male (gender <= 0.25),
    female (gender >= 0.75), drawn from the calibrated population by `sample_betas`.
  - global orientation uniform over SO(3) (upside-down bodies included); translation uniform in
    [-0.5, 0.5]^3 m.
Shapes come from the same population bank as training shapes (`sample_betas`, 1024 bodies): what training
never sees are the validation bodies themselves (their seeds), the named poses, the orientations, the
shape-group extremes and the extreme pose distribution.

Query points (`query_points`), per body, from a per-body torch.Generator (seed SeedSequence([seed, 1, i])),
float32, laid out [uniform | near-surface]:
  - round(n * (1 - surface_fraction)) points uniform in the body's axis-aligned bounding box padded by
    `bbox_padding` (5 cm) on every side;
  - the rest near the surface: area-weighted uniform samples on the posed mesh + isotropic Gaussian
    offsets N(0, sigma^2 I), sigma = 1 cm (the scale at which COAP's evaluation perturbs surface samples).
Defaults give the paper's 60k = 30k uniform + 30k near-surface. The box is the body's ("uniformly sampled
around the body"), not the model's part boxes, so models with different partitions see the same points.

`digest(tensors)` is the sha256 of the tensors' names, dtypes, shapes and bytes: equal digests mean
bit-identical sets (on the same numpy/scipy/torch stack).
"""
from __future__ import annotations

import hashlib
from typing import Dict, List

import numpy as np
import torch

__all__ = ["VAL_SEED", "SHAPE_GROUPS", "validation_labels", "validation_bodies", "digest", "pose_bodies",
           "query_points", "surface_samples", "sub_seed"]

#: seed of the validation set (PosePrior's 316 validation bodies in the paper). Training uses other seeds
#: (and 'realistic' or 'mixed' poses); do not train on bodies from this seed.
VAL_SEED = 316

#: shape groups of the validation set, cycled every 2 bodies: keyword arguments of `sample_betas`
SHAPE_GROUPS = {
    "tall": dict(height_range=(1.85, 3.0)),
    "short": dict(height_range=(0.0, 1.55)),
    "male": dict(gender_range=(0.0, 0.25)),
    "female": dict(gender_range=(0.75, 1.0)),
}


def sub_seed(*words: int) -> int:
    """A 32-bit seed derived from integers (independent streams per (seed, body, purpose))."""
    return int(np.random.SeedSequence([int(w) for w in words]).generate_state(1)[0])


def _body_spec(i: int, seed: int) -> dict:
    from volsmpl.body.poses import NAMED_POSES

    names = list(NAMED_POSES)
    group = list(SHAPE_GROUPS)[(i // 2) % len(SHAPE_GROUPS)]
    pose = f"named:{names[i // 2]}" if i % 2 == 1 and i // 2 < len(names) else "extreme"
    return {"pose": pose, "shape": group, "seed": sub_seed(seed, i)}


def validation_labels(n: int = 64, seed: int = VAL_SEED) -> List[str]:
    """Human-readable composition of `validation_bodies(n, seed)`: 'pose/shape' per body, e.g. 'named:sitting/short'."""
    return [f"{s['pose']}/{s['shape']}" for s in (_body_spec(i, seed) for i in range(n))]


def validation_bodies(n: int = 64, seed: int = VAL_SEED, num_betas: int = 10) -> Dict[str, torch.Tensor]:
    """The fixed validation set (see the module docstring for its composition).

    Args:
        n: number of bodies; seed: validation seed; num_betas: shape coefficients per body.
    Returns:
        dict of float32 CPU tensors: betas (n, num_betas), global_orient (n, 3), body_pose (n, 69),
        transl (n, 3). Bit-identical for equal (n, seed, num_betas); body i does not depend on n.
    """
    from scipy.spatial.transform import Rotation

    from volsmpl.body.poses import named_pose, sample_poses
    from volsmpl.body.shapes import sample_betas

    if not isinstance(n, int) or n < 1:
        raise ValueError(f"validation_bodies needs n >= 1 bodies, got {n!r}.")
    betas, orient, pose, transl = [], [], [], []
    for i in range(n):
        spec = _body_spec(i, seed)
        s = spec["seed"]
        if spec["pose"] == "extreme":
            pose.append(sample_poses(1, seed=sub_seed(s, 0), mode="extreme"))
        else:
            pose.append(named_pose(spec["pose"].split(":", 1)[1]))
        betas.append(sample_betas(1, num_betas=num_betas, seed=sub_seed(s, 1), **SHAPE_GROUPS[spec["shape"]]))
        rng = np.random.default_rng(sub_seed(s, 2))
        orient.append(Rotation.random(1, random_state=rng).as_rotvec())
        transl.append(rng.uniform(-0.5, 0.5, size=(1, 3)))
    f32 = dict(dtype=torch.float32)
    return {
        "betas": torch.cat(betas).to(**f32),
        "global_orient": torch.as_tensor(np.concatenate(orient), **f32),
        "body_pose": torch.cat(pose).to(**f32),
        "transl": torch.as_tensor(np.concatenate(transl), **f32),
    }


def digest(tensors) -> str:
    """sha256 hex digest of a tensor / array or a dict of them (names, dtypes, shapes and raw bytes, keys sorted)."""
    h = hashlib.sha256()
    items = sorted(tensors.items()) if isinstance(tensors, dict) else [("", tensors)]
    for name, t in items:
        a = t.detach().cpu().contiguous().numpy() if torch.is_tensor(t) else np.ascontiguousarray(t)
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def pose_bodies(body, bodies: Dict[str, torch.Tensor], batch_size: int = 16) -> torch.Tensor:
    """Posed vertices (B, V, 3) float32 CPU of the bodies (dict of betas/global_orient/body_pose/transl)."""
    like = body.v_template
    verts = []
    B = len(bodies["betas"])
    with torch.no_grad():
        for s in range(0, B, batch_size):
            chunk = {k: v[s:s + batch_size].to(like.device, like.dtype) for k, v in bodies.items()}
            verts.append(body(**chunk).vertices.float().cpu())
    return torch.cat(verts)


# ---------------------------------------------------------------------------------------------- query points
def surface_samples(vertices: torch.Tensor, faces: torch.Tensor, n: int, g: torch.Generator) -> torch.Tensor:
    """Area-weighted uniform samples on one mesh: vertices (V, 3) float64, faces (F, 3) long -> (n, 3)."""
    from volsmpl.body.partition import triangle_areas, uniform_barycentric

    fid = torch.multinomial(triangle_areas(vertices, faces), n, replacement=True, generator=g)
    bary = uniform_barycentric((n,), generator=g, dtype=torch.float64)
    return (bary[:, :, None] * vertices[faces[fid]]).sum(dim=1)


def query_points(vertices: torch.Tensor, faces, n_points: int = 60000, seed: int = VAL_SEED,
                 surface_fraction: float = 0.5, bbox_padding: float = 0.05, surface_sigma: float = 0.01):
    """Evaluation queries per body (module docstring): [uniform in the padded AABB | near-surface].

    Args:
        vertices (B, V, 3) posed bodies; faces (F, 3); n_points per body; seed: body i samples from a
        generator seeded with SeedSequence([seed, 1, i]), so its points do not depend on B or on batching.
    Returns:
        points (B, n_points, 3) float32; is_surface (n_points,) bool, True for the near-surface block.
    """
    v = torch.as_tensor(vertices).detach().cpu().to(torch.float64)
    if v.ndim != 3 or v.shape[-1] != 3:
        raise ValueError(f"vertices must be (B, V, 3), got {tuple(v.shape)}.")
    f = torch.as_tensor(np.asarray(faces), dtype=torch.long)
    n_surf = int(round(n_points * surface_fraction))
    n_unif = n_points - n_surf
    out = torch.empty(v.shape[0], n_points, 3, dtype=torch.float64)
    for i in range(v.shape[0]):
        g = torch.Generator().manual_seed(sub_seed(seed, 1, i))
        lo, hi = v[i].amin(0) - bbox_padding, v[i].amax(0) + bbox_padding
        out[i, :n_unif] = lo + torch.rand(n_unif, 3, generator=g, dtype=torch.float64) * (hi - lo)
        if n_surf:
            surf = surface_samples(v[i], f, n_surf, g)
            out[i, n_unif:] = surf + torch.randn(n_surf, 3, generator=g, dtype=torch.float64) * surface_sigma
    is_surface = torch.zeros(n_points, dtype=torch.bool)
    is_surface[n_unif:] = True
    return out.float(), is_surface
