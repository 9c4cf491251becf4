"""The furnished room as data, and its queries: `Room` with its `Item`s, `Seat`s and `Surface`s.

A Room (built by `rooms.make_room(seed)`) holds placed items in a rectangular interior (x in [-W/2, W/2],
z in [-D/2, D/2], floor at y = 0) closed by four walls WALL_THICKNESS thick over a floor slab FLOOR_THICKNESS
thick; no ceiling. Its methods give:

- geometry: `interior`, `bounds`, `structure` (floor slab and walls), `mesh` (one trimesh, optional per-face
  item labels), `render_meshes` (coloured meshes for `volsmpl.viz.render`, optional cutaway);
- affordances: `seats`, `walls`, `supports`;
- free space: `clearance` (exact horizontal distance to the nearest floor item's footprint or wall, 0 inside),
  `free_grid` on a GRID_CELL (5 cm) grid, `path_clearance`, `sample_start_goal`, `sample_viewpoint` (with a
  line-of-sight test: open3d's ray cast, or `volsmpl.geometry.triangle_queries.first_hits` in torch where open3d does not import).

The layout generator that places the items is in `furnish.py`; seeds, `make_room` and the cached scene cloud in
`rooms.py`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from .objects import ObjectTemplate

WALL_THICKNESS = 0.12
FLOOR_THICKNESS = 0.10
GRID_CELL = 0.05  # metres per free-space grid cell


# --------------------------------------------------------------------------------------------- records
@dataclass
class Item:
    """A placed object: `template` in its canonical frame, `transform` (4, 4) canonical -> world (a rotation
    about Y and a translation), `mesh` in the world frame; `on` is the index of the supporting item (None: floor)."""

    name: str
    category: str
    template: ObjectTemplate
    transform: np.ndarray
    mesh: trimesh.Trimesh
    on: int | None = None

    @property
    def obb(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Oriented bounding box: centre (3,), axes (3, 3) as columns, half extents (3,)."""
        lo, hi = self.template.mesh.bounds
        R, t = self.transform[:3, :3], self.transform[:3, 3]
        return R @ (0.5 * (lo + hi)) + t, R.copy(), 0.5 * (hi - lo)

    def footprint(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Floor rectangle: centre (2,) (x, z), axes (2, 2) rows (unit, in x-z), half sizes (2,)."""
        c, R, h = self.obb
        return c[[0, 2]], R[[0, 2]][:, [0, 2]].T, h[[0, 2]]

    def region_points(self, name: str, n: int = 256, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Points and normals of a named region (ObjectTemplate.regions) in the world frame. Shape: (n, 3) each."""
        p, nrm = self.template.region_points(name, n, seed)
        R, t = self.transform[:3, :3], self.transform[:3, 3]
        return p @ R.T + t, nrm @ R.T


@dataclass
class Seat:
    """A place to sit: `position` (3,) on the seat surface, `height` above the floor, `facing` (3,) unit horizontal."""

    item: int
    category: str
    position: np.ndarray
    height: float
    facing: np.ndarray


@dataclass
class Surface:
    """A planar rectangle to lean on or stand things on: centre (3,), outward `normal` (3,), in-plane unit `axes`
    (2, 3) and `half_size` (2,) along them; `item` is the item index (-1: a wall)."""

    name: str
    item: int
    center: np.ndarray
    normal: np.ndarray
    axes: np.ndarray
    half_size: np.ndarray


# ----------------------------------------------------------------------------------------- free-space helper
def _rect_distance(p: np.ndarray, rects) -> np.ndarray:
    """Exact distance from points (N, 2) to the nearest rectangle (0 inside); +inf without rectangles."""
    out = np.full(len(p), np.inf)
    for c, A, h in rects:
        local = np.abs((p - c) @ A.T)
        out = np.minimum(out, np.linalg.norm(np.maximum(local - h, 0.0), axis=1))
    return out


# --------------------------------------------------------------------------------------------- room
@dataclass
class Room:
    """A furnished room. Build with make_room(seed).

    Attributes:
        seed, kind: the generator's seed and room kind (ROOM_KINDS).
        size: (3,) interior width (x), height (y), depth (z) in metres; interior x in [-W/2, W/2], z in [-D/2, D/2].
        items: the placed Items (floor items first, then table-top items).
        floor_y: 0.0; wall_thickness: WALL_THICKNESS.
    """

    seed: int
    kind: str
    size: np.ndarray
    items: list[Item]
    floor_y: float = 0.0
    wall_thickness: float = WALL_THICKNESS
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    # ---------------------------------------------------------------- geometry
    @property
    def interior(self) -> np.ndarray:
        """(2, 3) min/max corner of the free interior (floor to wall top)."""
        W, H, D = self.size
        return np.array([[-W / 2, 0.0, -D / 2], [W / 2, H, D / 2]])

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) min/max corner of the whole scene, walls and floor slab included."""
        t = self.wall_thickness
        return self.interior + np.array([[-t, -FLOOR_THICKNESS, -t], [t, 0.0, t]])

    def structure(self) -> list[tuple[str, trimesh.Trimesh]]:
        """The floor slab (under the interior) and the four walls (closed boxes, reaching down past the slab)."""
        (x0, _, z0), (x1, H, z1) = self.interior
        t, ft = self.wall_thickness, FLOOR_THICKNESS
        b = lambda lo, hi: trimesh.creation.box(bounds=np.array([lo, hi], dtype=np.float64))  # noqa: E731
        return [("floor", b([x0, -ft, z0], [x1, 0.0, z1])),
                ("wall_back", b([x0 - t, -ft, z0 - t], [x1 + t, H, z0])),
                ("wall_front", b([x0 - t, -ft, z1], [x1 + t, H, z1 + t])),
                ("wall_left", b([x0 - t, -ft, z0], [x0, H, z1])),
                ("wall_right", b([x1, -ft, z0], [x1 + t, H, z1]))]

    def mesh(self, return_labels: bool = False):
        """The whole scene as one trimesh (closed components, vertices not merged), world frame.

        Returns: the mesh, and with return_labels=True also (F,) int labels: the item index per face, -1 floor,
        -2 walls.
        """
        if "mesh" not in self._cache:
            parts = self.structure()
            meshes = [m for _, m in parts] + [it.mesh for it in self.items]
            labels = [np.full(len(parts[0][1].faces), -1)] + [np.full(len(m.faces), -2) for _, m in parts[1:]]
            labels += [np.full(len(it.mesh.faces), i) for i, it in enumerate(self.items)]
            offs = np.cumsum([0] + [len(m.vertices) for m in meshes])
            v = np.concatenate([m.vertices for m in meshes])
            f = np.concatenate([m.faces + o for m, o in zip(meshes, offs[:-1])])
            self._cache["mesh"] = (trimesh.Trimesh(v, f, process=False), np.concatenate(labels))
        m, lab = self._cache["mesh"]
        return (m, lab) if return_labels else m

    def render_meshes(self, cutaway_yaw: float | None = None) -> list[tuple[np.ndarray, np.ndarray, tuple]]:
        """[(vertices, faces, rgb)] for `volsmpl.viz.render.render_scene` / `render_camera_view`: floor, walls, then the
        items in per-category colours. cutaway_yaw: the yaw (degrees) of an outside view, whose walls between the
        viewer and the room are left out."""
        out = []
        walls = {w.name: w.normal for w in self.walls()}
        for name, m in self.structure():
            if cutaway_yaw is not None and name in walls:
                a = np.radians(cutaway_yaw)
                if walls[name] @ np.array([-np.sin(a), 0.0, np.cos(a)]) < -0.3:  # the viewer is behind this wall
                    continue
            out.append((m.vertices, m.faces, (0.80, 0.72, 0.60) if name == "floor" else (0.88, 0.88, 0.86)))
        return out + [(it.mesh.vertices, it.mesh.faces, _COLOURS.get(it.category, (0.6, 0.6, 0.7)))
                      for it in self.items]

    # ---------------------------------------------------------------- affordances
    def seats(self) -> list[Seat]:
        """Every place to sit (chairs, stools, sofa places, bed edge), world frame."""
        out = []
        for i, it in enumerate(self.items):
            R, t = it.transform[:3, :3], it.transform[:3, 3]
            for s in it.template.seats():
                out.append(Seat(i, it.category, R @ s["position"] + t, float(s["height"] + t[1]), R @ s["facing"]))
        return out

    def walls(self) -> list[Surface]:
        """The four walls' inner faces (normals point into the room), for leaning placements."""
        (x0, _, z0), (x1, H, z1) = self.interior
        up = np.array([0.0, 1.0, 0.0])
        specs = [("wall_back", [0, 0, z0], [0, 0, 1], [1, 0, 0], x1 - x0),
                 ("wall_front", [0, 0, z1], [0, 0, -1], [-1, 0, 0], x1 - x0),
                 ("wall_left", [x0, 0, 0], [1, 0, 0], [0, 0, -1], z1 - z0),
                 ("wall_right", [x1, 0, 0], [-1, 0, 0], [0, 0, 1], z1 - z0)]
        return [Surface(name, -1, np.array(c, float) + up * H / 2, np.array(n, float),
                        np.stack([np.array(u, float), up]), np.array([length / 2, H / 2]))
                for name, c, n, u, length in specs]

    def supports(self) -> list[Surface]:
        """Horizontal surfaces of furniture (table tops, shelf boards, box tops, cart tops, seats...), world frame."""
        out = []
        for i, it in enumerate(self.items):
            R, t = it.transform[:3, :3], it.transform[:3, 3]
            for s in it.template.supports():
                c = s["center"].copy()
                c[1] = s["height"]
                out.append(Surface(f"{it.name}:{s['name']}", i, R @ c + t, np.array([0.0, 1.0, 0.0]),
                                   np.stack([R[:, 0], R[:, 2]]), s["half_size"].copy()))
        return out

    # ---------------------------------------------------------------- free space
    def _floor_rects(self):
        if "rects" not in self._cache:
            self._cache["rects"] = [it.footprint() for it in self.items if it.on is None]
        return self._cache["rects"]

    def clearance(self, xz) -> np.ndarray:
        """Exact horizontal distance (m) from floor points to the nearest floor item footprint or wall; 0 inside
        furniture or outside the interior. Shape: (N, 2) (x, z) -> (N,)."""
        p = np.asarray(xz, dtype=np.float64).reshape(-1, 2)
        (x0, _, z0), (x1, _, z1) = self.interior
        wall = np.min(np.stack([p[:, 0] - x0, x1 - p[:, 0], p[:, 1] - z0, z1 - p[:, 1]], 1), axis=1)
        return np.clip(np.minimum(wall, _rect_distance(p, self._floor_rects())), 0.0, None)

    def free_grid(self, clearance: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Free floor cells: True where the cell centre is farther than `clearance` from furniture and walls.

        Returns: free (nz, nx) bool (row i: z, column j: x), xs (nx,) and zs (nz,) cell-centre coordinates;
        cell (i, j) is centred at (xs[j], zs[i]), cells are GRID_CELL (5 cm) wide.
        """
        (x0, _, z0), (x1, _, z1) = self.interior
        xs = np.arange(x0 + GRID_CELL / 2, x1, GRID_CELL)
        zs = np.arange(z0 + GRID_CELL / 2, z1, GRID_CELL)
        X, Z = np.meshgrid(xs, zs)
        c = self.clearance(np.stack([X.ravel(), Z.ravel()], 1)).reshape(X.shape)
        return c > clearance, xs, zs

    def path_clearance(self, start, goal, step: float = 0.01) -> float:
        """Smallest clearance along the straight floor path start -> goal (3D points or (x, z)), sampled every
        `step` metres (the true minimum can be lower by at most step / 2)."""
        a, b = (np.asarray(p, dtype=np.float64) for p in (start, goal))
        a, b = (p[[0, 2]] if p.shape == (3,) else p for p in (a, b))
        k = max(2, int(np.ceil(np.linalg.norm(b - a) / step)) + 1)
        s = np.linspace(0.0, 1.0, k)[:, None]
        return float(self.clearance(a + s * (b - a)).min())

    def sample_start_goal(self, distance: float, clearance: float = 0.3, seed: int = 0, tol: float = 0.1,
                          blocked: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Draw free floor positions start, goal (y = floor_y) whose distance is within `tol` of `distance`, each
        farther than `clearance` from furniture and walls.

        Args:
            blocked: None: any; False: the straight path keeps `clearance`; True: it does not (an obstacle is
                in the way, for avoidance).

        Shape: -> start (3,), goal (3,).

        Raises: ValueError when no such pair exists (ask for a shorter distance or a smaller clearance).
        """
        free, xs, zs = self.free_grid(clearance)
        ii, jj = np.nonzero(free)
        cand = np.stack([xs[jj], zs[ii]], 1)
        rng = np.random.default_rng(seed)
        for _ in range(200 if len(cand) else 0):
            a = cand[rng.integers(len(cand))]
            d = np.linalg.norm(cand - a, axis=1)
            ok = np.flatnonzero(np.abs(d - distance) <= tol)
            for k in rng.permutation(ok)[:16]:
                if blocked is None or (self.path_clearance(a, cand[k]) <= clearance) == blocked:
                    to3 = lambda p: np.array([p[0], self.floor_y, p[1]])  # noqa: E731
                    return to3(a), to3(cand[k])
        raise ValueError(f"room {self.seed} ({self.size[0]:.1f} x {self.size[2]:.1f} m) has no free start/goal pair "
                         f"{distance} m apart with clearance {clearance} m (blocked={blocked}); ask for a shorter "
                         f"distance, a smaller clearance or another room.")

    def sample_viewpoint(self, target, distance=(0.8, 2.5), height=(1.4, 1.8), seed: int = 0,
                         clearance: float = 0.2, occlusion: bool = True) -> np.ndarray:
        """A camera position for an egocentric/third-person view of `target`: at a horizontal distance in
        `distance`, a height in `height` above the floor, inside the room, farther than `clearance` from furniture
        and walls, with a clear line of sight to within 0.25 m of the target (occlusion=True, a ray cast
        against the room mesh: open3d, or torch's exact `first_hits` without open3d).
        Shape: target (3,) -> eye (3,). Raises ValueError when none is found."""
        tgt = np.asarray(target, dtype=np.float64).reshape(3)
        rng = np.random.default_rng(seed)
        for _ in range(300):
            a, r, h = rng.uniform(0, 2 * np.pi), rng.uniform(*distance), rng.uniform(*height)
            eye = np.array([tgt[0] + r * np.sin(a), self.floor_y + h, tgt[2] + r * np.cos(a)])
            if self.clearance(eye[[0, 2]][None])[0] <= clearance:
                continue
            if occlusion and not self._line_of_sight(eye, tgt):
                continue
            return eye
        raise ValueError(f"no viewpoint {distance} m from {tgt.round(2).tolist()} in room {self.seed}; widen the "
                         f"distance range or lower the clearance.")

    def _line_of_sight(self, eye: np.ndarray, target: np.ndarray, slack: float = 0.25) -> bool:
        """Whether the ray from eye towards target meets the room mesh no nearer than `slack` before the target:
        open3d's ray cast (float32) where open3d imports, else `volsmpl.geometry.triangle_queries.first_hits` (exact, float64)."""
        from volsmpl.runtime.deps import open3d_or_none
        o3d = open3d_or_none()
        d = target - eye
        dist = np.linalg.norm(d)
        if o3d is None:
            import torch
            from volsmpl.geometry.triangle_queries import first_hits
            if "ray_triangles" not in self._cache:
                m = self.mesh()
                self._cache["ray_triangles"] = torch.as_tensor(np.asarray(m.vertices, np.float64)[m.faces])
            ray = torch.as_tensor(np.stack([eye, d / dist]).astype(np.float64))
            t_hit = float(first_hits(self._cache["ray_triangles"], ray[:1], ray[1:])[0])
            return bool(t_hit >= dist - slack)
        if "rays" not in self._cache:
            m = self.mesh()
            scene = o3d.t.geometry.RaycastingScene()
            scene.add_triangles(o3d.core.Tensor(m.vertices.astype(np.float32)),
                                o3d.core.Tensor(m.faces.astype(np.uint32)))
            self._cache["rays"] = scene
        ray = np.concatenate([eye, d / dist]).astype(np.float32)[None]
        t_hit = self._cache["rays"].cast_rays(o3d.core.Tensor(ray))["t_hit"].numpy()[0]
        return bool(t_hit >= dist - slack)


_COLOURS = {"chair": (0.55, 0.38, 0.25), "stool": (0.60, 0.45, 0.30), "table": (0.65, 0.50, 0.35),
            "sofa": (0.35, 0.45, 0.65), "bed": (0.70, 0.70, 0.85), "shelf": (0.50, 0.36, 0.25),
            "box": (0.75, 0.60, 0.40), "cart": (0.55, 0.58, 0.62), "cup": (0.90, 0.30, 0.30),
            "bottle": (0.30, 0.70, 0.50), "laptop": (0.30, 0.30, 0.35), "phone": (0.15, 0.15, 0.18),
            "ball": (0.95, 0.55, 0.15), "backpack": (0.25, 0.50, 0.40), "suitcase": (0.40, 0.25, 0.45)}
