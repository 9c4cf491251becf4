"""The recovered bodies a user takes away from `volsmpl egohmr sample`: records in results.json and mesh files.

A sample is a pose vector (pose.py) with the regressed shape and pelvis, in the camera frame. Each finite sample
gives a body record (volsmpl.apps.outputs.body_record) and, where asked, a mesh file (volsmpl.apps.outputs.write_mesh
at mesh_path(OUT, frame, guide, 'body')); a diverged one (NaN or Inf) gives neither (`body` None, its status says
why).

- A user's frame (`world_bodies`): the body moved rigidly into the scene file's world: params (`betas`,
  `global_orient`, `body_pose`, `transl`) of volsmpl's body in the Y-up world (metres: the scene file after --units
  and --up), fed to `volsmpl.body.create_body()` they give the body there; joints and the mesh file in the scene
  file's own units and axes (--units, --up), so they overlay the scan. Without 'world_to_camera' the scene file is in
  camera coordinates and so are they. The record's `frame` says which.
- A generated split (`compact_bodies`): per frame and guide, compact (params to 4 decimals, the 24 joints as one
  list to the millimetre), in the camera frame (metres, OpenCV axes), the frame the generated scenes are given in;
  mesh files only with --save-meshes, always made from the record's pose, so a record reused by --resume gives the
  same mesh as a new one.

`clear_meshes` removes an earlier run's body meshes from OUT before a run writes its own, so OUT never holds a mesh
that its results.json does not describe.

    recs, verts = world_bodies(body, frame, betas, x, pelvis, units="mm", up="z")   # per sample: record or None
    recs = compact_bodies(body, betas, x, pelvis)                                   # camera frame, compact
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

#: what a user frame's record says of its frame: with 'world_to_camera', and without
FRAME_SCENE = "scene: joints and mesh in the scene file's units and axes (--units, --up)"
FRAME_CAMERA = ("camera: the scene file is in camera coordinates; joints and mesh in its units and axes (--units, "
                "--up)")
#: what a generated split's bodies are given in (results.json's config.bodies)
FRAME_TABLE = "camera (metres, OpenCV axes: x right, y down, z forward); joints in SMPL order"


def posed(body, betas: torch.Tensor, x: torch.Tensor, pelvis: torch.Tensor, world_to_camera=None):
    """(BodyOutput of the finite samples, their indices): the bodies of pose vectors x (B, 144) with shape betas
    (B, 10) and pelvis (B, 3) in the camera frame, moved into the world of `world_to_camera` (4, 4) when given
    (root rotation R^T R_root, pelvis R^T (p - t): a rigid motion of the whole body)."""
    from volsmpl.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle

    from .pose import axis_angle, transl_of

    ok = (torch.isfinite(x).all(-1) & torch.isfinite(betas).all(-1) & torch.isfinite(pelvis).all(-1)).cpu()
    idx = ok.nonzero().flatten()
    if len(idx) == 0:
        return None, []
    dev = x.device
    x, betas, pelvis = x[idx.to(dev)], betas[idx.to(dev)], pelvis[idx.to(dev)]
    go, bp = axis_angle(x)
    if world_to_camera is not None:
        T = torch.as_tensor(np.asarray(world_to_camera), dtype=x.dtype, device=dev)
        R, t = T[:3, :3], T[:3, 3]
        go = matrix_to_axis_angle(R.T @ axis_angle_to_matrix(go))
        pelvis = (pelvis - t) @ R
    with torch.no_grad():
        out = body(betas=betas, global_orient=go, body_pose=bp, transl=transl_of(body, betas, pelvis))
    return out, idx.tolist()


def world_bodies(body, frame, betas, x, pelvis, units: str, up: str) -> tuple[list, list]:
    """Per sample of a user's frame: (its body record or None, its world vertices (V, 3) in the Y-up world, metres,
    or None) (module docstring). frame: userframe.UserFrame."""
    from volsmpl.apps.outputs import body_record

    out, idx = posed(body, betas, x, pelvis, frame.world_to_camera)
    recs, verts = [None] * len(x), [None] * len(x)
    for j, i in enumerate(idx):
        rec = body_record(out, j, units=units, up=up)
        rec["frame"] = FRAME_SCENE if frame.has_world else FRAME_CAMERA
        rec["params_frame"] = ("volsmpl body in the scene's Y-up world (metres)" if frame.has_world
                               else "volsmpl body in the camera frame (metres)")
        recs[i], verts[i] = rec, out.vertices[j].cpu().numpy()
    return recs, verts


def compact_bodies(body, betas, x, pelvis) -> tuple[list, list]:
    """Per sample of a generated split: (its compact record {params (4 decimals), joints (24, 3) to the millimetre}
    or None, its camera-frame vertices (V, 3) or None) (module docstring)."""
    from volsmpl.apps.outputs import body_record

    out, idx = posed(body, betas, x, pelvis)
    recs, verts = [None] * len(x), [None] * len(x)
    for j, i in enumerate(idx):
        rec = body_record(out, j, units="m", up="y")
        params = {k: np.round(v, 4).tolist() for k, v in rec["params"].items()}
        joints = np.round(out.joints[j, :24].cpu().numpy().astype(np.float64), 3).tolist()
        recs[i], verts[i] = {"params": params, "joints": joints}, out.vertices[j].cpu().numpy()
    return recs, verts


def write_body_mesh(out, frame_name: str, guide: str, vertices, faces, units: str = "m", up: str = "y") -> str:
    """Write one body's mesh (vertices in volsmpl's frame, metres, Y up) in the given units and axes; returns its
    path relative to OUT (results.json's `mesh`)."""
    from volsmpl.apps.outputs import mesh_path, write_mesh

    path = write_mesh(mesh_path(out, frame_name, guide, "body"), vertices, faces, units=units, up=up)
    return path.relative_to(Path(out)).as_posix()


def clear_meshes(out) -> int:
    """Remove the body meshes an earlier `volsmpl egohmr` run wrote under OUT/meshes/ (<frame>/<guide>_body.ply of
    the guides, volsmpl.apps.outputs.mesh_path) and the folders left empty; returns how many files went."""
    from .options import GUIDES

    root = Path(out) / "meshes"
    if not root.is_dir():
        return 0
    gone = 0
    for d in root.iterdir():
        if not d.is_dir():
            continue
        for g in GUIDES:
            f = d / f"{g}_body.ply"
            if f.is_file():
                f.unlink()
                gone += 1
        if not any(d.iterdir()):
            d.rmdir()
    if not any(root.iterdir()):
        root.rmdir()
    return gone


__all__ = ["FRAME_SCENE", "FRAME_CAMERA", "FRAME_TABLE", "posed", "world_bodies", "compact_bodies",
           "write_body_mesh", "clear_meshes"]
