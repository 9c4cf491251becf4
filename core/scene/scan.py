"""A user's scene file as a point cloud: any mesh or point-cloud format trimesh reads (ply, obj, off, stl, glb,
xyz...) or a .npy / .npz / .txt / .csv array of points, in metres.

    pts = read_scan("scan.ply", units="mm", n_surface=65536)    # (N, 3) float64, metres
    pts = to_y_up(pts, "z")                                     # a z-up scan in the Y-up frame
    check_cloud(pts, "scene")                                   # clear errors for empty / NaN / wrong shape

A mesh is sampled on its surface (n_surface area-weighted points); a point cloud is read as it is.

A scene of any size is read once with `open_scan` and its points are then taken where they matter, at a density
given in metres rather than as a count for the whole scene:

    scan = open_scan("temple.ply", units="mm").to_y_up("z")    # a mesh or a cloud, metres, Y up
    pts = scan.points(spacing=0.03, box=(lo, hi))               # (N, 3): one point per 3 cm inside the box
    overview = scan.overview(65536)                             # the whole scene, for checks and the floor

A mesh's faces that reach into the box are sampled at one point per spacing^2 of area (so 3 cm gives ~1,100
points per square metre of surface, a lantern in a 124 m temple as densely as a cup on a table); a cloud is cropped
to the box and thinned to one point per spacing-sized voxel (the point nearest the voxel's centre). A region that
would need more than `max_points` points is refused, naming a larger spacing that fits, never cut silently.
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


class Scan:
    """A scene file read once (`open_scan`): a mesh (`vertices` (V, 3), `faces` (F, 3)) or a cloud (`vertices`
    (N, 3), `faces` None), in metres, in the file's axes until `to_y_up`."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray | None, path: str = "scene", option: str = "--scene"):
        try:
            self.vertices = check_cloud(vertices, "scene")
        except ValueError as e:
            raise ValueError(f"{option} {path}: {e}") from None
        self.faces = None if faces is None else np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        self.path, self.option = str(path), option

    @property
    def is_mesh(self) -> bool:
        return self.faces is not None

    def to_y_up(self, up: str) -> Scan:
        """The same scene in our Y-up frame (`to_y_up`)."""
        return Scan(to_y_up(self.vertices, up), self.faces, self.path, self.option)

    def bounds(self) -> np.ndarray:
        """(2, 3): the lowest and highest coordinates."""
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    def overview(self, n: int = 65536, seed: int = 0) -> np.ndarray:
        """About n points of the whole scene (a mesh's area-weighted surface samples; a cloud's random subset, or all
        of it when smaller), for checks of size, up axis and floor. Shape: -> (<= n, 3)."""
        if self.is_mesh:
            return sample_surface(self._mesh(), n, seed=seed)[0]
        if len(self.vertices) <= n:
            return self.vertices
        return self.vertices[np.random.default_rng(seed).choice(len(self.vertices), n, replace=False)]

    def points(self, spacing: float = 0.03, box=None, seed: int = 0, max_points: int = 2_000_000) -> np.ndarray:
        """The scene's points inside `box` ((lo (3,), hi (3,)) in the scan's frame; None: everywhere) at one point per
        `spacing` metres (module docstring). Shape: -> (N, 3) float64."""
        spacing = float(spacing)
        if not (np.isfinite(spacing) and spacing > 0):
            raise ValueError(f"the point spacing must be a positive number of metres, got {spacing}")
        lo, hi = (self.bounds() if box is None else (np.asarray(box[0], float), np.asarray(box[1], float)))
        if self.is_mesh:
            part = self._clipped(lo, hi, spacing)
            if part is None:
                return np.zeros((0, 3))
            area = float(part.area)
            n = int(np.ceil(area / spacing ** 2))
            self._refuse_over(n, max_points, spacing, area=area)
            pts = sample_surface(part, max(n, 1), seed=seed)[0]
            return pts[((pts >= lo - 1e-9) & (pts <= hi + 1e-9)).all(1)]
        pts = self.vertices[((self.vertices >= lo) & (self.vertices <= hi)).all(1)]
        if len(pts) == 0:
            return pts
        cell = np.floor((pts - lo) / spacing).astype(np.int64)
        off = np.linalg.norm(pts - (lo + (cell + 0.5) * spacing), axis=1)
        order = np.lexsort((off, cell[:, 2], cell[:, 1], cell[:, 0]))   # per voxel, the point nearest its centre first
        cs = cell[order]
        first = np.r_[True, (np.diff(cs, axis=0) != 0).any(1)]
        self._refuse_over(int(first.sum()), max_points, spacing)
        return pts[order[first]]

    def _refuse_over(self, n: int, max_points: int, spacing: float, area: float | None = None) -> None:
        if n <= max_points:
            return
        fit = spacing * np.sqrt(n / max_points) * 1.05
        what = f"{area:,.0f} m^2 of surface" if area is not None else f"{n:,} occupied voxels"
        raise ValueError(f"{self.option} {self.path}: {what} in the region at {100 * spacing:g} cm spacing make "
                         f"{n:,} points (more than {max_points:,}): give a spacing of {100 * fit:.1f} cm or more")

    def _clipped(self, lo: np.ndarray, hi: np.ndarray, spacing: float):
        """The faces that reach into the box as a mesh, the faces that cross its sides split in four
        (trimesh.remesh.subdivide) until none is longer than a sixteenth of the box's largest side (or 4 spacings),
        so that a 100 m floor triangle does not count its whole area for a 2 m box; None when no face reaches in."""
        import trimesh

        v, f = self.vertices, self.faces
        target = max(4 * spacing, float((hi - lo).max()) / 16.0, 1e-6)
        for _ in range(64):
            tri = v[f]
            f = f[((tri.max(1) >= lo) & (tri.min(1) <= hi)).all(1)]
            if not len(f):
                return None
            tri = v[f]
            crosses = ~((tri.min(1) >= lo) & (tri.max(1) <= hi)).all(1)
            big = crosses & (np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(1) > target)
            if not big.any():
                break
            v, split = trimesh.remesh.subdivide(v, f[big])
            f = np.vstack([f[~big], split])
        part = trimesh.Trimesh(v, f, process=False)
        return part if part.area > 0 else None

    def _mesh(self):
        import trimesh
        if not hasattr(self, "_tm"):
            self._tm = trimesh.Trimesh(self.vertices, self.faces, process=False)
        return self._tm


def open_scan(path, units: str = "m", option: str = "--scene") -> Scan:
    """A scene file (any format `read_scan` takes) as a `Scan` in metres, its own axes: a mesh keeps its triangles
    (sampled later where they matter), a cloud its points."""
    if units not in UNITS:
        raise ValueError(f"--units must be one of {', '.join(UNITS)}, got {units!r}")
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{option} {path}: no such file")
    if p.suffix.lower() in (".npy", ".npz", ".txt", ".csv"):
        return Scan(read_scan(p, units, option=option), None, path, option)
    mesh = _geometry(p, path, option)
    if isinstance(mesh, np.ndarray):
        return Scan(mesh * UNITS[units], None, path, option)
    return Scan(np.asarray(mesh.vertices, np.float64) * UNITS[units], np.asarray(mesh.faces), path, option)


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
    """The points of a file trimesh reads: a mesh's surface samples, a point cloud's points."""
    geom = _geometry(p, path, option)
    if isinstance(geom, np.ndarray):
        return geom
    return sample_surface(geom, n_surface, seed=seed)[0]


def _geometry(p: Path, path, option: str):
    """A file trimesh reads as one trimesh.Trimesh (a mesh) or an (N, 3) array (a cloud). A scene (glb, a
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
        return mesh
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


__all__ = ["UNITS", "Scan", "check_cloud", "from_y_up", "open_scan", "read_scan", "to_y_up"]
