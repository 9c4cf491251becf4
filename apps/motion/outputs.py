"""What a motion run gives to take away: each walk's bodies in its record and as a mesh file, in the input's units
and axes (volsmpl.apps.outputs).

    rec["body"] = walk_body(walk, lift=sc.lift, units="mm", up="z")     # the whole walk, every frame
    path = write_walk_mesh(out, f"{sc.name}_0", "volsmpl", rec["body"], body)   # OUT/meshes/<scene>_0/volsmpl_walk.ply
    pub = publish(rec, out, f"{sc.name}_0", "volsmpl", body, save=True)     # results.json's record, mesh written

The record (`walk_body`) holds the full per-frame parameters in a compact form, not a few key frames: `betas`
(once), and per frame `transl` (3), `global_orient` (3) and `body_pose` (69), rounded to 1e-5 (m, rad; the
vertices they give are within ~0.05 mm of the walk's): fed to `volsmpl.body.create_body()` they give the walk's
bodies in the scan's frame turned Y up, in metres (`params_frame`; the floor's height, `lift`, is in `transl`),
and `pelvis` holds the pelvis per frame in the input's units and axes (--units, --up:
volsmpl.apps.outputs.to_input_frame). An 80-frame walk's body takes ~50 KB of JSON.

The mesh file (`write_walk_mesh`) holds the bodies at every MESH_EVERY-th frame and the last, one .ply per walk
(OUT/meshes/<scene>_<k>/<kind>_walk.ply, volsmpl.apps.outputs.mesh_path), in the input's units and axes, made from
the record itself: a record reused by --resume gives the same file as the run that made it.
"""
from __future__ import annotations

import numpy as np
import torch

__all__ = ["MESH_EVERY", "body_vertices", "mesh_frames", "publish", "walk_body", "write_walk_mesh"]

MESH_EVERY = 10   # frames between the bodies of a walk's mesh file (1/3 s at 30 fps)
PARAMS_FRAME = "volsmpl body: the scan turned Y up (--up), metres, not shifted"


def _r(x, nd: int = 5):
    return np.round(x.detach().cpu().double().numpy(), nd).tolist()


def walk_body(walk, lift: float = 0.0, units: str = "m", up: str = "y") -> dict:
    """The bodies of a walk of one sequence as a JSON record (module docstring). `lift`: the height (metres) the
    scene's points were lowered by to put the floor at y = 0, added back to `transl` and the pelvis."""
    from volsmpl.apps.outputs import to_input_frame

    up_shift = torch.tensor([0.0, float(lift), 0.0], dtype=walk.transl.dtype, device=walk.transl.device)
    pelvis = walk.joints[0, :, 0] + up_shift
    return {"frames": int(walk.body_pose.shape[1]), "betas": _r(walk.betas[0]),
            "transl": _r(walk.transl[0] + up_shift), "global_orient": _r(walk.global_orient[0]),
            "body_pose": _r(walk.body_pose[0]), "params_frame": PARAMS_FRAME, "lift_m": round(float(lift), 6),
            "pelvis": np.round(to_input_frame(pelvis, units, up), 5).tolist(), "units": units, "up": up}


def mesh_frames(frames: int, every: int = MESH_EVERY) -> list[int]:
    """The frames a walk's mesh file holds: every `every`-th and the last."""
    return sorted(set(range(0, int(frames), int(every))) | {int(frames) - 1})


def body_vertices(body, rec: dict, frames) -> torch.Tensor:
    """The vertices (n, V, 3) of a walk record's bodies at `frames`, through `body` (volsmpl.body.create_body()),
    in the record's params frame (metres, Y up)."""
    like = body.v_template
    idx = list(frames)

    def t(key):
        return torch.as_tensor(np.asarray(rec[key], dtype=np.float64)[idx], dtype=like.dtype, device=like.device)

    betas = torch.as_tensor(np.asarray(rec["betas"], np.float64), dtype=like.dtype, device=like.device)
    with torch.no_grad():
        out = body(betas=betas[None].expand(len(idx), -1), global_orient=t("global_orient"),
                   body_pose=t("body_pose"), transl=t("transl"))
    return out.vertices


def write_walk_mesh(out, case: str, kind: str, rec: dict, body, every: int = MESH_EVERY) -> str:
    """Write the walk record `rec`'s bodies at mesh_frames (one mesh: the bodies one after another, each with the
    body's faces) as OUT/meshes/<case>/<kind>_walk.ply in the record's units and axes; returns the path relative to
    `out`."""
    from pathlib import Path

    from volsmpl.apps.outputs import mesh_path, write_mesh

    frames = mesh_frames(rec["frames"], every)
    V = body_vertices(body, rec, frames).detach().cpu().double().numpy()
    faces = np.asarray(body.faces, dtype=np.int64)
    n, nv = V.shape[:2]
    F = np.concatenate([faces + i * nv for i in range(n)])
    path = write_mesh(mesh_path(out, case, kind, "walk"), V.reshape(-1, 3), F, units=rec["units"], up=rec["up"])
    return Path(path).relative_to(Path(out)).as_posix()


def publish(rec: dict, out, case: str, kind: str, body, save: bool) -> dict:
    """The record as results.json lists it. With `save` (a user's scene, or --save-meshes): with its `body` and its
    mesh file written from that body (`mesh`: {path relative to `out`, frames}), the same for a record made now or
    reused by --resume; without: without its body (the generated rooms' table keeps results.json small; the case
    store keeps the body, so that a later --resume --save-meshes writes the meshes without walking again)."""
    if not save:
        return {k: v for k, v in rec.items() if k != "body"}
    if not rec.get("body"):   # a walk that failed: no bodies
        return dict(rec)
    path = write_walk_mesh(out, case, kind, rec["body"], body)
    return {**rec, "mesh": {"path": path, "frames": mesh_frames(rec["body"]["frames"])}}
