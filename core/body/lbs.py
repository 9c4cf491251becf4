"""Linear blend skinning for SMPL-format bodies, as pure batched functions.

Conventions (SMPL's): pose is axis-angle per joint, relative to the parent, expressed in the rest
(T-pose) frame; joint 0 is the root; ``parents[j] < j``; ``parents[0] == -1``.
"""
from __future__ import annotations

import torch
from kornia.geometry.conversions import axis_angle_to_rotation_matrix


def rodrigues(pose: torch.Tensor) -> torch.Tensor:
    """Axis-angle to rotation matrices, differentiable at the identity.

    Args:
        pose: (..., J*3) or (..., J, 3) axis-angle.
    Returns:
        (..., J, 3, 3)
    """
    if pose.shape[-1] != 3:
        pose = pose.reshape(*pose.shape[:-1], -1, 3)
    return axis_angle_to_rotation_matrix(pose)


def shape_blend(v_template: torch.Tensor, shapedirs: torch.Tensor, betas: torch.Tensor) -> torch.Tensor:
    """Shaped rest vertices.

    Args:
        v_template: (V, 3); shapedirs: (V, 3, NB); betas: (B, nb) with nb <= NB.
    Returns:
        (B, V, 3)
    """
    nb = betas.shape[-1]
    return v_template + torch.einsum("bl,vcl->bvc", betas, shapedirs[..., :nb])


def pose_blend(rot_mats: torch.Tensor, posedirs: torch.Tensor | None) -> torch.Tensor | float:
    """Pose-corrective offsets from the non-root joint rotations.

    Args:
        rot_mats: (B, J, 3, 3); posedirs: (P, V*3) with P = (J-1)*9, or None when all zero.
    Returns:
        (B, V, 3), or 0.0 when posedirs is None.
    """
    if posedirs is None:
        return 0.0
    B = rot_mats.shape[0]
    eye = torch.eye(3, dtype=rot_mats.dtype, device=rot_mats.device)
    feat = (rot_mats[:, 1:] - eye).reshape(B, -1)
    return (feat @ posedirs).reshape(B, -1, 3)


def kinematic_levels(parents) -> tuple[torch.Tensor, torch.Tensor, list[int]]:
    """The non-root joints ordered by depth in the kinematic tree, for forward kinematics by depth.

    Every parent of a joint at depth d lies at depth d - 1, so one batched product per depth composes the chain
    (8 on SMPL's tree, against 23 joint by joint). Register `order` and `parent` as buffers of the module that
    poses, so that they sit on its device (a host index on a GPU costs a copy and a wait each call).

    Args: parents: (J,) parent indices, -1 for a root (a list of ints or a long tensor).
    Returns: order (J - r,) long: the joints with a parent, depth 1 first; parent (J - r,) long: their parents;
        sizes: the number of joints at each depth 1, 2, ... (host ints: `order.split(sizes)`).
    Example:
        >>> kinematic_levels([-1, 0, 0, 1])
        (tensor([1, 2, 3]), tensor([0, 0, 1]), [2, 1])
    """
    par = parents.tolist() if isinstance(parents, torch.Tensor) else [int(p) for p in parents]
    depth = [0 if p < 0 else -1 for p in par]
    for _ in range(len(par)):
        todo = [j for j, p in enumerate(par) if depth[j] < 0 and depth[p] >= 0]
        if not todo:
            break
        for j in todo:
            depth[j] = depth[par[j]] + 1
    if min(depth, default=0) < 0:
        raise ValueError(f"parents {par} do not form a tree: joints {[j for j, d in enumerate(depth) if d < 0]} "
                         f"have no path to a root (parent -1).")
    order = sorted((j for j in range(len(par)) if par[j] >= 0), key=lambda j: (depth[j], j))
    sizes = [sum(1 for j in order if depth[j] == d) for d in range(1, max(depth, default=0) + 1)]
    return (torch.tensor(order, dtype=torch.long), torch.tensor([par[j] for j in order], dtype=torch.long), sizes)


def _depths(levels, device):
    """(joints, parents) index pairs of each depth of `levels` (kinematic_levels' triple), on `device`."""
    order, parent, sizes = levels
    return zip(order.to(device).split(sizes), parent.to(device).split(sizes))


def chain_rotations(rot_mats: torch.Tensor, levels) -> torch.Tensor:
    """World rotation of each joint frame: the products of the relative rotations along the chain.

    Shape: rot_mats (B, J, 3, 3), levels: kinematic_levels(parents) -> (B, J, 3, 3).
    """
    glob = rot_mats.clone()
    for idx, pidx in _depths(levels, rot_mats.device):
        glob[:, idx] = glob[:, pidx] @ rot_mats[:, idx]
    return glob


def rigid_chain(rot_mats: torch.Tensor, joints: torch.Tensor, parents, levels=None):
    """Forward kinematics.

    Args:
        rot_mats: (B, J, 3, 3) relative rotations; joints: (B, J, 3) rest joint locations;
        parents: (J,) parent indices, parents[0] = -1 (a list of ints or a long tensor);
        levels: kinematic_levels(parents) when the caller holds them (on the device: no host-device copy);
            computed from `parents` otherwise.
    Returns:
        global_rot: (B, J, 3, 3) rotation of each joint frame in the world;
        posed_joints: (B, J, 3) joint locations after posing (root at its rest location);
        skin_transforms: (B, J, 4, 4) transforms taking rest-pose points to posed points.
    """
    B, J = joints.shape[:2]
    levels = kinematic_levels(parents) if levels is None else levels
    glob, posed = rot_mats.clone(), joints.clone()
    for idx, pidx in _depths(levels, joints.device):
        pr = glob[:, pidx]
        glob[:, idx] = pr @ rot_mats[:, idx]
        posed[:, idx] = posed[:, pidx] + (pr @ (joints[:, idx] - joints[:, pidx])[..., None])[..., 0]
    # x_posed = R_j (x_rest - J_j) + posed_J_j
    t = posed - (glob @ joints[..., None])[..., 0]
    skin = torch.zeros(B, J, 4, 4, dtype=joints.dtype, device=joints.device)
    skin[..., :3, :3] = glob
    skin[..., :3, 3] = t
    skin[..., 3, 3] = 1.0
    return glob, posed, skin


def skin_vertices(vertices: torch.Tensor, weights: torch.Tensor, skin: torch.Tensor) -> torch.Tensor:
    """Blend per-joint transforms and apply them.

    Args:
        vertices: (B, V, 3) rest vertices (shaped and pose-corrected); weights: (V, J);
        skin: (B, J, 4, 4).
    Returns:
        (B, V, 3)
    """
    B, J = skin.shape[:2]
    T = (weights @ skin.reshape(B, J, 16)).reshape(B, -1, 4, 4)
    return (T[..., :3, :3] @ vertices[..., None])[..., 0] + T[..., :3, 3]
