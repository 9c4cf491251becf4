"""The pose vector the diffusion model works on, and the body posed from it.

A pose is the 24 SMPL rotations (global orientation in the camera frame, then the 23 body joints) in the
continuous 6D representation, flattened: x (B, 144). Translation and shape are regressed deterministically
(EgoHMR's split), so the body of a pose is `body(betas, axis-angle of x, transl)`.

    x = pose_vector(global_orient, body_pose)       # (B, 3), (B, 69) axis-angle -> (B, 144)
    go, bp = axis_angle(x)                           # back, (B, 3), (B, 69)
    J = pose_joints(body, betas, x, pelvis)          # (B, 24, 3) joints only (no skinning), pelvis placed at `pelvis`
    out = pose_body(body, betas, x, pelvis)          # the full forward output (vertices, joints, full_pose)
"""
from __future__ import annotations

import torch

from volsmpl.body.lbs import rigid_chain, shape_blend
from volsmpl.geometry.rotations import axis_angle_to_rotation_6d, rotation_6d_to_axis_angle, rotation_6d_to_matrix

NUM_JOINTS = 24
POSE_DIM = NUM_JOINTS * 6
#: SMPL joints of the hips and legs (the authors' code guides only these): hips, knees, ankles, feet
LEG_JOINTS = (1, 2, 4, 5, 7, 8, 10, 11)


def pose_vector(global_orient: torch.Tensor, body_pose: torch.Tensor) -> torch.Tensor:
    """Axis-angle global orientation (B, 3) and body pose (B, 69) -> 6D pose vector (B, 144)."""
    aa = torch.cat([global_orient, body_pose], dim=-1).reshape(*global_orient.shape[:-1], NUM_JOINTS, 3)
    return axis_angle_to_rotation_6d(aa).reshape(*global_orient.shape[:-1], POSE_DIM)


def check_pose(x: torch.Tensor) -> None:
    if x.shape[-1] != POSE_DIM:
        raise ValueError(f"a pose vector has {POSE_DIM} values (24 joints x 6D), got shape {tuple(x.shape)}")


def rotation_matrices(x: torch.Tensor) -> torch.Tensor:
    """Shape: (B, 144) -> (B, 24, 3, 3)."""
    check_pose(x)
    return rotation_6d_to_matrix(x.reshape(*x.shape[:-1], NUM_JOINTS, 6))


def axis_angle(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """6D pose vector (B, 144) -> global_orient (B, 3), body_pose (B, 69) in axis-angle."""
    check_pose(x)
    aa = rotation_6d_to_axis_angle(x.reshape(-1, NUM_JOINTS, 6)).reshape(-1, NUM_JOINTS * 3)
    return aa[:, :3], aa[:, 3:]


def rest_joints(body, betas: torch.Tensor) -> torch.Tensor:
    """The shaped rest-pose joints of `betas`. Shape: (B, 10) -> (B, 24, 3)."""
    v_shaped = shape_blend(body.v_template, body.shapedirs, betas)
    return torch.einsum("jv,bvc->bjc", body.J_regressor, v_shaped)


def pose_joints(body, betas: torch.Tensor, x: torch.Tensor, pelvis: torch.Tensor, rest=None) -> torch.Tensor:
    """Posed joints of the pose vectors with the pelvis joint at `pelvis` (forward kinematics only: no vertices).

    Shape: betas (B, 10), x (B, 144), pelvis (B, 3) -> (B, 24, 3). `rest`: the rest joints when known.
    """
    rest = rest_joints(body, betas) if rest is None else rest
    _, joints, _ = rigid_chain(rotation_matrices(x), rest, body.parent_list, body.chain_levels)
    return joints - joints[:, :1] + pelvis[:, None]


def transl_of(body, betas: torch.Tensor, pelvis: torch.Tensor, rest=None) -> torch.Tensor:
    """The SMPL `transl` that puts the pelvis joint at `pelvis` (the root rotates about the rest pelvis)."""
    rest = rest_joints(body, betas) if rest is None else rest
    return pelvis - rest[:, 0]


def pose_body(body, betas: torch.Tensor, x: torch.Tensor, pelvis: torch.Tensor):
    """The body forward output of pose vectors x (B, 144) with shape betas (B, 10), pelvis joint at pelvis (B, 3)."""
    go, bp = axis_angle(x)
    return body(betas=betas, global_orient=go, body_pose=bp, transl=transl_of(body, betas, pelvis))


def pose_body_finite(body, betas: torch.Tensor, x: torch.Tensor, pelvis: torch.Tensor):
    """`pose_body` of the frames whose pose, shape and pelvis are finite; the others (a diverged sample, which the
    body refuses) get NaN vertices and joints. Returns an object with `vertices` (B, V, 3) and `joints` (B, J, 3)."""
    from types import SimpleNamespace

    ok = torch.isfinite(x).all(-1) & torch.isfinite(betas).all(-1) & torch.isfinite(pelvis).all(-1)
    if bool(ok.all()):
        return pose_body(body, betas, x, pelvis)
    keep = ok[:, None]
    out = pose_body(body, torch.where(keep, betas, 0.0), torch.where(keep, x, identity_pose(len(x), x.dtype, x.device)),
                    torch.where(keep, pelvis, 0.0))
    nan = float("nan")
    return SimpleNamespace(vertices=torch.where(keep[:, :, None], out.vertices, nan),
                           joints=torch.where(keep[:, :, None], out.joints, nan))


def identity_pose(batch: int, dtype=torch.float32, device=None) -> torch.Tensor:
    """The rest pose as pose vectors. Shape: (batch, 144)."""
    z = torch.zeros(batch, NUM_JOINTS * 3, dtype=dtype, device=device)
    return pose_vector(z[:, :3], z[:, 3:])


def leg_mask(dtype=torch.float32, device=None) -> torch.Tensor:
    """(144,) 1 on the 6D entries of LEG_JOINTS, else 0."""
    m = torch.zeros(NUM_JOINTS, 6, dtype=dtype, device=device)
    m[list(LEG_JOINTS)] = 1.0
    return m.reshape(POSE_DIM)


__all__ = ["NUM_JOINTS", "POSE_DIM", "LEG_JOINTS", "pose_vector", "check_pose", "rotation_matrices", "axis_angle",
           "rest_joints", "pose_joints", "transl_of", "pose_body", "pose_body_finite", "identity_pose", "leg_mask"]
