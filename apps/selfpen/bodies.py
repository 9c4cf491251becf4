"""The bodies a self-intersection repair gives a user: each case record's starting and repaired body, and their
mesh files.

A case file holds body parameters only (betas, global_orient, body_pose; cases.py), no translation, units or axes:
its bodies are volsmpl's, in its frame (metres, Y up), and so are the joints and the mesh files written here.
Everything is made from the pose the case record holds (a record reused by --resume included), so the files always
belong to the record beside them:

    r.start_params, r.body, r.meshes = take_away(body, case, r.body_pose, "volsmpl", out=args.out).values()

Mesh files (with `out`): OUT/meshes/<case>/<kind>_before.ply (the case's pose) and <kind>_after.ply (the repaired
pose, rebuilt from the record's rounded parameters), written atomically (volsmpl.apps.outputs.write_mesh).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from volsmpl.apps.outputs import body_record, mesh_path, write_mesh

from .cases import CASES_FILE, Case

__all__ = ["DECIMALS", "UNITS", "UP", "pose_body", "take_away", "writes_meshes"]

#: the frame of a case file's bodies and of everything written from them; parameters are kept to 6 decimals
UNITS, UP, DECIMALS = "m", "y", 6


def pose_body(body, betas, global_orient, body_pose):
    """The body output (batch 1, no gradient) of one pose, on the body's device. Shapes: (10,), (3,), (69,)."""
    dev = body.v_template.device
    rows = [torch.as_tensor(np.asarray(x, np.float32)).reshape(1, -1).to(dev) for x in (betas, global_orient, body_pose)]
    with torch.no_grad():
        return body(betas=rows[0], global_orient=rows[1], body_pose=rows[2])


def writes_meshes(case_file, save_meshes: bool) -> bool:
    """Whether a run writes mesh files: always for a user's own case file, for the shipped cases with --save-meshes."""
    return bool(save_meshes) or Path(case_file).resolve() != CASES_FILE.resolve()


def take_away(body, case: Case, final_pose, kind: str, out=None) -> dict:
    """{start_params, body, meshes} of one repaired case: the case's parameters, the repaired body
    (volsmpl.apps.outputs.body_record: params and joints) at `final_pose` (69,) rounded to DECIMALS, and, with `out`,
    the before / after mesh files (paths relative to OUT; {} without `out`). A record without a final pose (an empty
    list) left the case's pose as it was."""
    pose = case.body_pose if len(final_pose) == 0 else final_pose
    pose = np.round(np.asarray(torch.as_tensor(pose, dtype=torch.float64).cpu(), np.float64), DECIMALS)
    before = pose_body(body, case.betas, case.global_orient, case.body_pose)
    after = pose_body(body, case.betas, case.global_orient, pose)
    start = body_record(before, 0, UNITS, UP)["params"]
    repaired = body_record(after, 0, UNITS, UP)
    meshes = {}
    if out is not None:
        for what, output in (("before", before), ("after", after)):
            path = write_mesh(mesh_path(out, case.name, kind, what), output.vertices[0], body.faces, UNITS, UP)
            meshes[what] = path.relative_to(Path(out)).as_posix()
    return {"start_params": start, "body": repaired, "meshes": meshes}
