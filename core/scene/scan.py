"""A user's scene file as a point cloud: any mesh or point-cloud format trimesh reads (ply, obj, off, stl, glb,
xyz...) or a .npy / .npz / .txt / .csv array of points, in metres.

    pts = read_scan("scan.ply", units="mm", n_surface=65536)    # (N, 3) float64, metres
    pts = to_y_up(pts, "z")                                     # a z-up scan in the Y-up frame
    check_cloud(pts, "scene")                                   # clear errors for empty / NaN / wrong shape

A mesh is sampled on its surface (n_surface area-weighted points); a point cloud is read as it is.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .points import sample_surface

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def check_cloud(points, what: str = "scene") -> np.ndarray:
    """(N, 3) float64 of a cloud; ValueError naming the problem for a wrong shape, no points or NaN/Inf."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"the {what} cloud must be (N, 3), got shape {p.shape}")
    if len(p) == 0:
        raise ValueError(f"the {what} cloud is empty: give a mesh or a point cloud with points")
    if not np.isfinite(p).all():
        raise ValueError(f"the {what} cloud holds {int((~np.isfinite(p)).any(1).sum())} points with NaN or Inf "
                         f"coordinates; clean the file first")
    return p


def read_scan(path, units: str = "m", n_surface: int = 65536, seed: int = 0, option: str = "--scene") -> np.ndarray:
    """The points of a scene file in metres (module docstring). Shape: -> (N, 3) float64.
    option: the command-line option named in error messages."""
    if units not in UNITS:
        raise ValueError(f"--units must be one of {', '.join(UNITS)}, got {units!r}")
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{option} {path}: no such file")
    suffix = p.suffix.lower()
    if suffix in (".npy", ".npz", ".txt", ".csv"):
        if suffix in (".npy", ".npz"):
            z = _load_numbers(p, path, option)
        if suffix == ".npy":
            arr = z
        elif suffix == ".npz":
            if "points" not in z.files and len(z.files) != 1:  # never guess: the first array may be the colours
                raise ValueError(f"{option} {path}: the .npz holds arrays {', '.join(z.files)} and none is named "
                                 f"'points'; save the (N, 3) coordinates as points=... (np.savez(path, points=xyz))")
            arr = z["points"] if "points" in z.files else z[z.files[0]]
        else:
            try:
                arr = np.loadtxt(p, delimiter="," if suffix == ".csv" else None, ndmin=2)[:, :3]
            except ValueError as e:
                raise ValueError(f"{option} {path}: cannot read it as rows of numbers x y z ({e}); remove the header "
                                 f"line or start it with '#'") from None
        pts = check_cloud(arr)
    else:
        pts = check_cloud(_geometry_points(p, path, n_surface, seed, option))
    return pts * UNITS[units]


def _load_numbers(p: Path, path, option: str):
    """np.load of a .npy / .npz that holds numbers; a pickled one (Python objects) is refused naming the file."""
    try:
        return np.load(p, allow_pickle=False)
    except ValueError as e:
        if "allow_pickle" in str(e):
            raise ValueError(f"{option} {path}: the file holds pickled Python objects, not numbers; save the (N, 3) "
                             f"coordinates as a number array (np.save(path, xyz.astype(float)))") from None
        raise


def _geometry_points(p: Path, path, n_surface: int, seed: int, option: str) -> np.ndarray:
    """The points of a file trimesh reads: a mesh's surface samples, a point cloud's points. A scene (glb, a
    multi-object obj) is flattened with its node transforms; one that mixes meshes and point clouds is refused
    (sampled surfaces and raw points differ in density; trimesh's own flattening drops the clouds)."""
    import trimesh
    try:
        geom = trimesh.load(p, force=None)
    except Exception as e:  # noqa: BLE001 - any reader error is the file's problem
        raise ValueError(f"{option} {path}: cannot read it ({type(e).__name__}: {e})") from None
    parts = geom.dump() if isinstance(geom, trimesh.Scene) else [geom]
    meshes = [g for g in parts if isinstance(g, trimesh.Trimesh) and len(g.faces)]
    clouds = [g for g in parts if isinstance(g, (trimesh.PointCloud, trimesh.Trimesh)) and not any(g is m for m in meshes)
              and len(g.vertices)]   # a mesh file without faces (an obj of 'v' lines) is a cloud
    if meshes and clouds:
        raise ValueError(f"{option} {path}: the file holds {len(meshes)} mesh(es) and {len(clouds)} point cloud(s); "
                         f"export the meshes or the point clouds alone")
    if meshes:
        mesh = meshes[0] if len(meshes) == 1 else trimesh.util.concatenate(meshes)
        if not np.isfinite(mesh.vertices).all():
            raise ValueError(f"{option} {path}: the mesh has NaN or Inf vertices")
        if not mesh.area > 0:
            raise ValueError(f"{option} {path}: every triangle of the mesh has zero area; export the scene's surfaces")
        return sample_surface(mesh, n_surface, seed=seed)[0]
    if clouds:
        return np.concatenate([np.asarray(c.vertices) for c in clouds])
    if isinstance(geom, trimesh.Scene) or hasattr(geom, "vertices"):
        return np.zeros((0, 3))   # check_cloud: empty
    raise ValueError(f"{option} {path}: not a mesh or a point cloud ({type(geom).__name__})")


def to_y_up(points: np.ndarray, up: str) -> np.ndarray:
    """Points of a 'y'-up or 'z'-up scan in our Y-up frame: z-up (x, y, z) -> (x, z, -y). Shape: (N, 3) -> (N, 3)."""
    if up == "y":
        return points
    if up == "z":
        return np.stack([points[:, 0], points[:, 2], -points[:, 1]], 1)
    raise ValueError(f"--up must be 'y' or 'z', got {up!r}")


def from_y_up(points: np.ndarray, up: str) -> np.ndarray:
    """The inverse of `to_y_up`: points of our Y-up frame in a 'y'-up or 'z'-up file's axes, (x, y, z) -> (x, -z, y)
    for 'z'. Shape: (N, 3) -> (N, 3)."""
    if up == "y":
        return points
    if up == "z":
        return np.stack([points[:, 0], -points[:, 2], points[:, 1]], 1)
    raise ValueError(f"--up must be 'y' or 'z', got {up!r}")


__all__ = ["UNITS", "check_cloud", "from_y_up", "read_scan", "to_y_up"]
