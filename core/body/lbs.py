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


def rigid_chain(rot_mats: torch.Tensor, joints: torch.Tensor, parents):
    """Forward kinematics.

    Args:
        rot_mats: (B, J, 3, 3) relative rotations; joints: (B, J, 3) rest joint locations;
        parents: (J,) parent indices, parents[0] = -1: a list of ints (no host read), or a long tensor (read to the
            host once: on a GPU one wait for the device, where reading each parent waited J - 1 times).
    Returns:
        global_rot: (B, J, 3, 3) rotation of each joint frame in the world;
        posed_joints: (B, J, 3) joint locations after posing (root at its rest location);
        skin_transforms: (B, J, 4, 4) transforms taking rest-pose points to posed points.
    """
    B, J = joints.shape[:2]
    par = parents.tolist() if isinstance(parents, torch.Tensor) else [int(p) for p in parents]
    rel = joints.clone()
    rel[:, 1:] = joints[:, 1:] - joints[:, par[1:]]
    rots, locs = [rot_mats[:, 0]], [joints[:, 0]]
    for j in range(1, J):
        p = par[j]
        rots.append(rots[p] @ rot_mats[:, j])
        locs.append(locs[p] + (rots[p] @ rel[:, j, :, None])[..., 0])
    global_rot = torch.stack(rots, dim=1)
    posed_joints = torch.stack(locs, dim=1)
    # x_posed = R_j (x_rest - J_j) + posed_J_j
    t = posed_joints - (global_rot @ joints[..., None])[..., 0]
    skin = torch.zeros(B, J, 4, 4, dtype=joints.dtype, device=joints.device)
    skin[..., :3, :3] = global_rot
    skin[..., :3, 3] = t
    skin[..., 3, 3] = 1.0
    return global_rot, posed_joints, skin


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
