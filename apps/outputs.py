"""What a user takes away from an app run: the fitted or recovered bodies (and objects) as records in results.json
and as mesh files, in the units and axes the input came in.

    rec["body"] = body_record(out, 0, units="mm", up="z")          # params (model frame) + joints (input frame)
    write_mesh(mesh_path(args.out, case, "volsmpl", "body"), out.vertices[0], body.faces, units="mm", up="z")

The body's parameters (`betas`, `global_orient`, `body_pose`, `transl`) are those of volsmpl's body in its own
frame (metres, Y up): fed back to `volsmpl.body.create_body()(...)` they give the same body. The joints and every
mesh file are in the input's frame: `units` (m, cm or mm) and `up` ('y' or 'z', volsmpl.scene.scan.from_y_up), so
they overlay the user's own files. Mesh files are written under OUT/meshes/<case>/<kind>_<what>.ply (a .obj
path writes OBJ), atomically.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["body_record", "to_input_frame", "mesh_path", "write_mesh"]


def _numpy(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def to_input_frame(points, units: str = "m", up: str = "y") -> np.ndarray:
    """Points in volsmpl's frame (metres, Y up) -> the input's units and axes. Shape: (N, 3) -> (N, 3) float64.

    Example:
        >>> to_input_frame([[0.0, 1.0, 0.0]], units="mm", up="z").round(6).tolist()   # Y up -> Z up, m -> mm
        [[0.0, 0.0, 1000.0]]
    """
    from volsmpl.scene.scan import UNITS, from_y_up

    if units not in UNITS:
        raise ValueError(f"units must be one of {', '.join(UNITS)}, got {units!r}")
    p = _numpy(points).reshape(-1, 3)
    return from_y_up(p, up) / UNITS[units]


def body_record(output, i: int = 0, units: str = "m", up: str = "y", joint_names=None) -> dict:
    """The i-th body of a `BodyOutput` as a JSON record: {params: {betas, global_orient, body_pose, transl} (volsmpl's
    body, metres, Y up), joints: {name: [x, y, z]} and pelvis (input frame), units, up}."""
    from volsmpl.body import SMPL_JOINT_NAMES

    names = tuple(joint_names or SMPL_JOINT_NAMES)
    joints = to_input_frame(output.joints[i], units, up)
    if len(names) < len(joints):
        names = names + tuple(f"joint{j}" for j in range(len(names), len(joints)))
    params = {k: _numpy(getattr(output, k)[i]).round(6).tolist()
              for k in ("betas", "global_orient", "body_pose", "transl")}
    return {"params": params, "params_frame": "volsmpl body (metres, Y up)",
            "joints": {n: joints[j].round(6).tolist() for j, n in enumerate(names[:len(joints)])},
            "pelvis": joints[0].round(6).tolist(), "units": units, "up": up}


def mesh_path(out, case: str, kind: str, what: str = "body", suffix: str = ".ply") -> Path:
    """OUT/meshes/<case>/<kind>_<what><suffix>, the case's name made file-safe (volsmpl.apps.checks.safe_name)."""
    from .checks import safe_name

    return Path(out) / "meshes" / safe_name(case) / f"{safe_name(kind)}_{safe_name(what)}{suffix}"


def write_mesh(path, vertices, faces, units: str = "m", up: str = "y") -> Path:
    """Write a mesh given in volsmpl's frame (metres, Y up) in the input's units and axes, as PLY (or OBJ for a .obj
    path), atomically; returns the path. Shape: vertices (V, 3), faces (F, 3) int."""
    import trimesh

    from volsmpl.io.outputs import write_atomic

    path = Path(path)
    kind = path.suffix.lower().lstrip(".")
    if kind not in ("ply", "obj"):
        raise ValueError(f"mesh files are .ply or .obj, got {path.name}")
    v = to_input_frame(vertices, units, up)
    f = _numpy(faces).astype(np.int64).reshape(-1, 3)
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"faces index vertices 0..{int(f.max())} but the mesh has {len(v)} vertices")
    data = trimesh.Trimesh(v, f, process=False).export(file_type=kind)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, data if isinstance(data, str) else bytes(data))
    return path
