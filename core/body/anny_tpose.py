"""Anny side of the default-body export (`volsmpl.body.anny_export`): loading Anny with the export rig and
topology, sampling phenotypes from its calibrated shape distribution, and re-posing every sample from Anny's
rest A-pose into the SMPL-like T-pose (vertices and bone heads in SMPL axes).
"""
from __future__ import annotations

import numpy as np

from .anny_skeleton import (AGE_RANGE_YEARS, ANNY_TO_SMPL, ANNY_TOPOLOGY, ANNY_VERSION_REQUIRED, BATCH,
                            GENDER_RANGE, LEG_ABDUCTION_DEG)


# ----------------------------------------------------------------------------------------------------------------
# Anny model and phenotype sampling
# ----------------------------------------------------------------------------------------------------------------
def load_anny_model():
    """Anny with the export rig (default anny rig, jaw kept) and the eyes/tongue-free topology, float64, dense LBS.

    Returns:
        anny.Anny module (V=13348 vertices, 105 bones for anny 0.6.2).
    """
    import anny
    import torch
    from anny.models.model_data import RigConfig, _ANNY_RIG_MODIFIERS, _bones_to_remove_from_modifiers

    if anny.__version__ != ANNY_VERSION_REQUIRED:
        import warnings
        warnings.warn(f"anny {anny.__version__} found, the committed body was exported with {ANNY_VERSION_REQUIRED}")
    removed = _bones_to_remove_from_modifiers(list(_ANNY_RIG_MODIFIERS)) - {"jaw"}
    rig = RigConfig(base_rig="anny", bone_orientation="blender", root_identity_orientation=False,
                    bones_to_remove=frozenset(removed))
    model = anny.Anny(rig=rig, topology=ANNY_TOPOLOGY, skinning_method="lbs")
    return model.to(torch.float64)


def sample_phenotypes(model, n: int, seed: int) -> np.ndarray:
    """Draw n phenotypes from Anny's calibrated shape distribution, teens to elderly, both genders and mixes.

    Args:
        model: anny.Anny (its phenotype_labels must be the 6 default ones).
        n: number of samples.
        seed: RNG seed (torch RNG state is forked, the caller's is untouched).
    Returns:
        (n, 6) float64 array, columns in model.phenotype_labels order
        (gender, age, muscle, weight, height, proportions), each in [0, 1].
    """
    import torch
    from anny.shape_distribution import SimpleShapeDistribution

    kw = dict(dtype=model.dtype, device=model.device)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        dist = SimpleShapeDistribution(
            model,
            morphological_age_distribution=torch.distributions.Uniform(
                torch.tensor(AGE_RANGE_YEARS[0], **kw), torch.tensor(AGE_RANGE_YEARS[1], **kw)),
            gender_distribution=torch.distributions.Uniform(
                torch.tensor(GENDER_RANGE[0], **kw), torch.tensor(GENDER_RANGE[1], **kw)))
        _, pk = dist.sample(n)
    ph = torch.stack([pk[label] for label in model.phenotype_labels], dim=1)
    return ph.clamp(0.0, 1.0).cpu().numpy().astype(np.float64)


# ----------------------------------------------------------------------------------------------------------------
# T-pose
# ----------------------------------------------------------------------------------------------------------------
def _subtree_mask(parents, root: int) -> np.ndarray:
    """(J,) bool: bone `root` and all its descendants (parents listed before children)."""
    mask = np.zeros(len(parents), dtype=bool)
    mask[root] = True
    for b, p in enumerate(parents):
        if p >= 0 and mask[p]:
            mask[b] = True
    return mask


def minimal_rotation(a, b):
    """Batched smallest rotation taking direction a onto direction b.

    Args:
        a, b: (B, 3) torch tensors (need not be unit).
    Returns:
        (B, 3, 3) rotation matrices R with R @ a/|a| = b/|b| (a and b must not be opposite).
    """
    import torch

    a = a / a.norm(dim=-1, keepdim=True)
    b = b / b.norm(dim=-1, keepdim=True)
    v = torch.linalg.cross(a, b, dim=-1)
    c = (a * b).sum(-1)
    vx = torch.zeros(a.shape[0], 3, 3, dtype=a.dtype)
    vx[:, 0, 1], vx[:, 0, 2], vx[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    vx = vx - vx.transpose(1, 2)
    eye = torch.eye(3, dtype=a.dtype).expand_as(vx)
    return eye + vx + vx @ vx / (1.0 + c)[:, None, None]


def _rotation_about_axis(axis, angle):
    """(B, 3, 3) rotations of `angle` (B,) radians about the fixed unit `axis` (3,)."""
    import torch

    k = torch.as_tensor(axis, dtype=angle.dtype)
    kx = torch.tensor([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]], dtype=angle.dtype)
    s, c = torch.sin(angle)[:, None, None], torch.cos(angle)[:, None, None]
    return torch.eye(3, dtype=angle.dtype) + s * kx + (1 - c) * (kx @ kx)


def tpose_world_rotations(heads, labels, parents):
    """World rotation of every bone that turns Anny's rest A-pose into the SMPL-like T-pose (Anny axes).

    Args:
        heads: (B, J, 3) rest bone heads (Anny world axes, Z-up, facing -Y).
        labels: list of J bone labels; parents: list of J parent indices (parents before children).
    Returns:
        (B, J, 3, 3) world rotations G (a bone's posed orientation = G @ rest orientation; its head follows
        its parent's transform).
    """
    import torch

    B, J = heads.shape[:2]
    G = torch.eye(3, dtype=heads.dtype).expand(B, J, 3, 3).clone()
    idx = {name: i for i, name in enumerate(labels)}

    def apply(root_bone, R):
        m = torch.as_tensor(_subtree_mask(parents, idx[root_bone]))
        G[:, m] = R[:, None] @ G[:, m]

    for x, sign in (("L", 1.0), ("R", -1.0)):
        target = torch.tensor([[sign, 0.0, 0.0]], dtype=heads.dtype).expand(B, 3)
        segments = ((f"upperarm01.{x}", f"lowerarm01.{x}"), (f"lowerarm01.{x}", f"wrist.{x}"),
                    (f"wrist.{x}", f"finger3-1.{x}"))
        for start, end in segments:
            # current direction of the segment = (rotation already applied to its start bone) @ rest direction
            d = (G[:, idx[start]] @ (heads[:, idx[end]] - heads[:, idx[start]])[..., None])[..., 0]
            apply(start, minimal_rotation(d, target))
        # legs: frontal-plane rotation about the hip (axis = Anny's Y, the front-back axis)
        d = heads[:, idx[f"foot.{x}"]] - heads[:, idx[f"upperleg01.{x}"]]
        current = torch.atan2(sign * d[:, 0], -d[:, 2])  # outward angle from vertical, radians
        delta = np.deg2rad(LEG_ABDUCTION_DEG) - current
        # rotation about +Y by phi moves -Z towards -X: outward for the left (+X) leg needs phi < 0
        R = _rotation_about_axis([0.0, 1.0, 0.0], -sign * delta)
        apply(f"upperleg01.{x}", R)
        apply(f"foot.{x}", R.transpose(1, 2))  # soles stay flat
    return G


def tposed_bodies(model, phenotypes: np.ndarray, batch: int = BATCH):
    """T-posed vertices and bone heads of the given phenotypes, in SMPL axes.

    Args:
        model: anny.Anny from `load_anny_model`.
        phenotypes: (N, 6) phenotype values.
        batch: samples per forward pass.
    Returns:
        verts (N, V, 3) float64, heads (N, J_anny, 3) float64 (posed bone heads), both SMPL axes, metres.
    """
    import torch

    labels, parents = list(model.bone_labels), list(model.bone_parents)
    R_conv = torch.as_tensor(ANNY_TO_SMPL, dtype=torch.float64)
    all_v, all_h = [], []
    with torch.no_grad():
        for i in range(0, len(phenotypes), batch):
            ph = torch.as_tensor(phenotypes[i:i + batch], dtype=model.dtype)
            b = ph.shape[0]
            coeffs = model._get_phenotype_blendshape_coefficients(
                ph, torch.zeros(b, len(model.local_change_labels), dtype=model.dtype),
                torch.zeros(b, len(model.facial_action_labels), dtype=model.dtype))
            rest = model.get_rest_model(coeffs)
            heads, rest_poses = rest["rest_bone_heads"], rest["rest_bone_poses"]
            G = tpose_world_rotations(heads, labels, parents)
            D = torch.eye(4, dtype=model.dtype).expand(b, len(labels), 4, 4).clone()
            D[..., :3, :3] = G @ rest_poses[..., :3, :3]
            D[:, 0, :3, 3] = heads[:, 0]
            T, W = model.get_bone_transforms(D, rest_poses, pose_parameterization="world-orient")
            v = model.get_skinned_vertices(rest["rest_vertices"], T)
            all_v.append((v @ R_conv.T).numpy())
            all_h.append((W[..., :3, 3] @ R_conv.T).numpy())
    return np.concatenate(all_v), np.concatenate(all_h)
