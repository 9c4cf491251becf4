"""Procedural furnished indoor rooms, deterministic from an integer seed.

`make_room(seed)` builds a rectangular room (interior 3.2-8 m by 3.2-8 m, walls 2.5-3.0 m high and
WALL_THICKNESS thick, a floor slab FLOOR_THICKNESS thick; no ceiling) of one of ROOM_KINDS (chosen by seed % 4),
and furnishes it with templates from `objects.py`: sofas, beds, shelves and desks against walls; dining tables,
chairs (facing their table or desk), stools, boxes, carts and floor clutter (ball, backpack, suitcase) free-standing;
cups, bottles, laptops and phones on table tops. Interior: x in [-W/2, W/2], z in [-D/2, D/2], floor at y = 0.

Placement is rejection sampling on the floor footprints (rectangles rotated about Y): every floor item keeps
ITEM_GAP from every other and WALL_GAP from the walls (separating-axis test of the rectangles); table-top items stand
1 mm above the top, inside it, apart from each other. So no two items' oriented bounding boxes intersect.

Any non-negative seed gives a room; seeds 0 .. ROOM_COUNT-1 are the standard set (all distinct). Generation
takes ~0.1 s (one core); `room_points` caches its farthest-point-sampled scene cloud (see cache.py).

Free space: `Room.clearance` is the exact horizontal distance from floor points to the nearest floor item's
footprint or wall (0 inside); `free_grid` samples it on a GRID_CELL (5 cm) grid; `sample_start_goal`,
`path_clearance` and `sample_viewpoint` build on it.

Example:
    >>> room = make_room(7)
    >>> scene = room.mesh()                                   # one trimesh, world frame
    >>> start, goal = room.sample_start_goal(3.0, clearance=0.3, seed=0)
    >>> pts = room_points(7)["points"]                        # (16384, 3) FPS scene cloud, cached
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from .objects import ObjectTemplate, make_object

ROOM_VERSION = 1
ROOM_COUNT = 100
ROOM_KINDS = ("living", "bedroom", "dining", "office")
WALL_THICKNESS = 0.12
FLOOR_THICKNESS = 0.10
GRID_CELL = 0.05  # metres per free-space grid cell
ITEM_GAP = 0.08  # minimum horizontal gap between floor items
WALL_GAP = 0.02  # minimum gap between an item and a wall
_TRIES = 60


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


# --------------------------------------------------------------------------------------------- geometry helpers
def _yaw_transform(yaw: float, x: float, z: float, y: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]  # object +Z -> (sin yaw, 0, cos yaw)
    T[:3, 3] = [x, y, z]
    return T


def _rect(T: np.ndarray, template: ObjectTemplate):
    lo, hi = template.mesh.bounds
    R = T[:3, :3]
    c = (R @ (0.5 * (lo + hi)) + T[:3, 3])[[0, 2]]
    return c, R[[0, 2]][:, [0, 2]].T, 0.5 * (hi - lo)[[0, 2]]


def _rects_overlap(a, b, gap: float) -> bool:
    """Separating-axis test of two rotated rectangles (centre, axes rows, half sizes), each grown by gap / 2."""
    (ca, Aa, ha), (cb, Ab, hb) = a, b
    d = cb - ca
    for axis in np.concatenate([Aa, Ab]):
        ra = np.abs(Aa @ axis) @ ha + gap / 2
        rb = np.abs(Ab @ axis) @ hb + gap / 2
        if abs(d @ axis) > ra + rb:
            return False
    return True


def _rect_inside(r, lo: np.ndarray, hi: np.ndarray) -> bool:
    c, A, h = r
    reach = np.abs(A.T) @ h  # half extent of the rectangle along world x and z
    return bool((c - reach >= lo - 1e-9).all() and (c + reach <= hi + 1e-9).all())


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
        """[(vertices, faces, rgb)] for `volsmpl.render.render_scene` / `render_camera_view`: floor, walls, then the
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
        and walls, with a clear line of sight to within 0.25 m of the target (occlusion=True, open3d ray cast
        against the room mesh). Shape: target (3,) -> eye (3,). Raises ValueError when none is found."""
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
        import open3d as o3d

        if "rays" not in self._cache:
            m = self.mesh()
            scene = o3d.t.geometry.RaycastingScene()
            scene.add_triangles(o3d.core.Tensor(m.vertices.astype(np.float32)),
                                o3d.core.Tensor(m.faces.astype(np.uint32)))
            self._cache["rays"] = scene
        d = target - eye
        dist = np.linalg.norm(d)
        ray = np.concatenate([eye, d / dist]).astype(np.float32)[None]
        t_hit = self._cache["rays"].cast_rays(o3d.core.Tensor(ray))["t_hit"].numpy()[0]
        return bool(t_hit >= dist - slack)


_COLOURS = {"chair": (0.55, 0.38, 0.25), "stool": (0.60, 0.45, 0.30), "table": (0.65, 0.50, 0.35),
            "sofa": (0.35, 0.45, 0.65), "bed": (0.70, 0.70, 0.85), "shelf": (0.50, 0.36, 0.25),
            "box": (0.75, 0.60, 0.40), "cart": (0.55, 0.58, 0.62), "cup": (0.90, 0.30, 0.30),
            "bottle": (0.30, 0.70, 0.50), "laptop": (0.30, 0.30, 0.35), "phone": (0.15, 0.15, 0.18),
            "ball": (0.95, 0.55, 0.15), "backpack": (0.25, 0.50, 0.40), "suitcase": (0.40, 0.25, 0.45)}


# --------------------------------------------------------------------------------------------- generator
class _Placer:
    def __init__(self, size: np.ndarray, rng: np.random.Generator):
        W, _, D = size
        self.lo, self.hi = np.array([-W / 2, -D / 2]), np.array([W / 2, D / 2])
        self.rng = rng
        self.items: list[Item] = []
        self.rects: list = []
        self.counts: dict[str, int] = {}

    def template(self, category: str, scale=None) -> ObjectTemplate:
        return make_object(category, seed=int(self.rng.integers(2**31)), scale=scale)

    def _ok(self, r) -> bool:
        return (_rect_inside(r, self.lo + WALL_GAP, self.hi - WALL_GAP)
                and not any(_rects_overlap(r, q, ITEM_GAP) for q in self.rects))

    def _add(self, tpl: ObjectTemplate, T: np.ndarray, on: int | None = None) -> int:
        k = self.counts.get(tpl.category, 0)
        self.counts[tpl.category] = k + 1
        R, t = T[:3, :3], T[:3, 3]
        mesh = trimesh.Trimesh(tpl.mesh.vertices @ R.T + t, tpl.mesh.faces, process=False)
        self.items.append(Item(f"{tpl.category}_{k}", tpl.category, tpl, T, mesh, on))
        if on is None:
            self.rects.append(_rect(T, tpl))
        return len(self.items) - 1

    def try_pose(self, tpl: ObjectTemplate, yaw: float, x: float, z: float) -> int | None:
        T = _yaw_transform(yaw, x, z)
        return self._add(tpl, T) if self._ok(_rect(T, tpl)) else None

    def against_wall(self, tpl: ObjectTemplate, wall: int | None = None) -> int | None:
        w, _, d = tpl.extents
        for _ in range(_TRIES):
            k = int(self.rng.integers(4)) if wall is None else wall
            n = np.array([[0, 1], [-1, 0], [0, -1], [1, 0]][k], float)  # inward normal of back, right, front, left
            yaw = np.arctan2(n[0], n[1])  # the object's front (+Z) along n
            tangent = np.array([n[1], -n[0]])
            span = (self.hi - self.lo) @ np.abs(tangent)
            base = np.where(n > 0, self.lo, np.where(n < 0, self.hi, 0.0))  # the wall line
            slack = span / 2 - WALL_GAP - w / 2
            s = self.rng.uniform(-slack, slack) if slack > 0 else 0.0
            c = base * np.abs(n) + n * (WALL_GAP + 1e-3 + d / 2) + tangent * s
            i = self.try_pose(tpl, yaw, c[0], c[1])
            if i is not None:
                return i
        return None

    def free(self, tpl: ObjectTemplate, region: float = 1.0) -> int | None:
        for _ in range(_TRIES):
            yaw = self.rng.uniform(0, 2 * np.pi) if self.rng.random() < 0.5 else self.rng.integers(4) * np.pi / 2
            c = self.rng.uniform(self.lo * region, self.hi * region)
            i = self.try_pose(tpl, yaw, c[0], c[1])
            if i is not None:
                return i
        return None

    def facing(self, tpl: ObjectTemplate, anchor: int, side: np.ndarray, offset: float, gap: float) -> int | None:
        """Place tpl on the `side` (unit (2,) in the anchor's frame, x-z) of an anchor, `offset` along that side,
        `gap` from it, its front (+Z) towards the anchor."""
        a = self.items[anchor]
        ca, Aa, ha = a.footprint()
        reach = np.abs(side) @ ha
        d = tpl.extents[2]
        local = side * (reach + gap + d / 2) + np.array([side[1], -side[0]]) * offset
        c = ca + local @ Aa
        n = -(side @ Aa)  # facing the anchor
        return self.try_pose(tpl, np.arctan2(n[0], n[1]), c[0], c[1])

    def in_front(self, tpl: ObjectTemplate, anchor: int, gap: float) -> int | None:
        """Place tpl in front (+Z side) of an anchor, same orientation (a coffee table before a sofa)."""
        a = self.items[anchor]
        ca, Aa, ha = a.footprint()
        c = ca + Aa[1] * (ha[1] + gap + tpl.extents[2] / 2)
        yaw = np.arctan2(Aa[1][0], Aa[1][1])
        return self.try_pose(tpl, yaw, c[0], c[1])

    def on_top(self, tpl: ObjectTemplate, anchor: int, placed: list) -> int | None:
        a = self.items[anchor]
        top = [s for s in a.template.supports() if s["name"] == "top"]
        if not top:
            return None
        s = top[0]
        r = 0.5 * np.hypot(tpl.extents[0], tpl.extents[2])  # any yaw fits inside the top
        room = s["half_size"] - r - 0.02
        if (room <= 0).any():
            return None
        for _ in range(_TRIES):
            local = s["center"][[0, 2]] + self.rng.uniform(-room, room)
            yaw = self.rng.uniform(0, 2 * np.pi)
            R, t = a.transform[:3, :3], a.transform[:3, 3]
            c = R @ np.array([local[0], 0.0, local[1]]) + t
            T = _yaw_transform(yaw + np.arctan2(R[0, 2], R[2, 2]), c[0], c[2], s["height"] + t[1] + 1e-3)
            rr = _rect(T, tpl)
            if not any(_rects_overlap(rr, q, 0.03) for q in placed):
                placed.append(rr)
                return self._add(tpl, T, on=anchor)
        return None


def _chairs_around(P: _Placer, table: int, n: int) -> None:
    tw = P.items[table].template.extents[0]
    sides = []
    for k in range(n):
        if k < 4:
            sides.append((np.array([0.0, 1.0 if k % 2 == 0 else -1.0]), (k // 2 - 0.5) * tw / 2 if n > 2 else 0.0))
        else:
            sides.append((np.array([1.0 if k % 2 == 0 else -1.0, 0.0]), 0.0))
    for side, off in sides:
        P.facing(P.template("chair"), table, side, off, P.rng.uniform(0.05, 0.2))


_FILL = {"living": ["chair", "stool", "box", "shelf", "cart"], "bedroom": ["box", "shelf", "stool", "chair"],
         "dining": ["shelf", "stool", "box", "cart"], "office": ["shelf", "box", "cart", "chair"]}


def _furnish(kind: str, P: _Placer) -> None:
    rng, r = P.rng, P.rng.integers
    tables = []
    if kind == "living":
        sofa = P.against_wall(P.template("sofa"))
        coffee = P.template("table", scale=(0.7, 0.6, 0.7))
        t = P.in_front(coffee, sofa, rng.uniform(0.35, 0.55)) if sofa is not None else None
        tables += [t] if t is not None else []
        for _ in range(r(0, 3)):
            P.against_wall(P.template("shelf"))
        for _ in range(r(0, 3)):
            P.free(P.template("chair"))
        extras = ["stool"] * int(r(0, 2)) + ["box"] * int(r(0, 3)) + ["cart"] * int(r(0, 2))
    elif kind == "bedroom":
        P.against_wall(P.template("bed"))
        for _ in range(r(1, 3)):
            P.against_wall(P.template("shelf"))
        if rng.random() < 0.6:
            desk = P.against_wall(P.template("table", scale=(0.75, 1.0, 0.7)))
            if desk is not None:
                tables.append(desk)
                P.facing(P.template("chair"), desk, np.array([0.0, 1.0]), 0.0, rng.uniform(0.05, 0.2))
        extras = ["stool"] * int(r(0, 2)) + ["box"] * int(r(0, 4)) + ["suitcase"] * int(r(0, 2))
    elif kind == "dining":
        t = P.free(P.template("table"), region=0.4)
        if t is not None:
            tables.append(t)
            _chairs_around(P, t, int(r(2, 7)))
        for _ in range(r(0, 3)):
            P.against_wall(P.template("shelf"))
        extras = ["cart"] * int(r(0, 2)) + ["stool"] * int(r(0, 3)) + ["box"] * int(r(0, 2))
    else:  # office
        for _ in range(r(1, 3)):
            desk = P.against_wall(P.template("table", scale=(0.9, 1.0, 0.75)))
            if desk is not None:
                tables.append(desk)
                P.facing(P.template("chair"), desk, np.array([0.0, 1.0]), 0.0, rng.uniform(0.05, 0.2))
        for _ in range(r(1, 3)):
            P.against_wall(P.template("shelf"))
        if rng.random() < 0.5:
            P.against_wall(P.template("sofa"))
        extras = ["cart"] * int(r(0, 2)) + ["box"] * int(r(0, 4)) + ["stool"] * int(r(0, 2))
    extras += [str(c) for c in rng.choice(["ball", "backpack", "suitcase"], int(r(0, 3)))]
    area = float((P.hi - P.lo).prod())
    extras += [str(c) for c in rng.choice(_FILL[kind], int(area // 12))]  # bigger rooms get more furniture
    for cat in extras:
        wall = cat == "shelf" or cat in ("box", "cart", "chair") and rng.random() < 0.5
        (P.against_wall if wall else P.free)(P.template(cat))
    for t in tables:
        placed: list = []
        for cat in rng.choice(["cup", "bottle", "laptop", "phone", "cup"], int(r(0, 4))):
            P.on_top(P.template(str(cat)), t, placed)


def make_room(seed: int) -> Room:
    """Generate the furnished room of a seed (deterministic: the same seed gives byte-identical meshes).

    Args:
        seed: a non-negative int; the kind is ROOM_KINDS[seed % 4], sizes and furniture follow from the seed.

    Returns: a Room.

    Example:
        >>> room = make_room(3)
        >>> [it.category for it in room.items], room.size
    """
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}.")
    rng = np.random.default_rng([int(seed), ROOM_VERSION])
    kind = ROOM_KINDS[int(seed) % len(ROOM_KINDS)]
    size = np.array([rng.uniform(3.2, 8.0), rng.uniform(2.5, 3.0), rng.uniform(3.2, 8.0)])
    P = _Placer(size, rng)
    _furnish(kind, P)
    floor = [it for it in P.items if it.on is None]
    return Room(int(seed), kind, size, floor + [it for it in P.items if it.on is not None])


def room_points(seed: int, n: int = 16384, oversample: int = 4, cache: bool = True) -> dict[str, np.ndarray]:
    """The farthest-point-sampled surface cloud of a room, as the scene-constrained motion app uses it.

    Samples n * oversample area-uniform points on the surfaces one can see from inside (floor top, walls' inner
    faces, furniture; not the undersides resting on the floor, wall corners or walls below the floor), then keeps n by
    farthest-point sampling (open3d). Cached in the user cache (cache.py) by ROOM_VERSION and seed.

    Returns: {'points': (n, 3) float32, 'normals': (n, 3) float32, 'labels': (n,) int32 (item index, -1 floor,
    -2 walls)}.

    Example:
        >>> cloud = room_points(0)["points"]  # (16384, 3)
    """
    from .cache import cached
    from .points import farthest_point_sample, sample_surface

    def build():
        room = make_room(seed)
        mesh, labels = room.mesh(return_labels=True)
        nrm, ctr = mesh.face_normals, mesh.triangles_center
        (x0, _, z0), (x1, _, z1) = room.interior
        keep = ~((labels == -1) & (nrm[:, 1] < 0.9))  # floor slab: top face only
        keep &= ~((labels == -2) & ((ctr[:, 1] >= room.size[1] - 1e-6) | (ctr[:, 1] < 0)))  # wall tops, below floor
        inward = ((ctr[:, 0] - 0.5 * (x0 + x1)) * nrm[:, 0] + (ctr[:, 2] - 0.5 * (z0 + z1)) * nrm[:, 2]) < 0
        keep &= ~((labels == -2) & ~inward)  # wall faces looking out of the room
        keep &= ~((labels >= 0) & (nrm[:, 1] < -0.9) & (ctr[:, 1] < 1e-3))  # furniture bottoms on the floor
        p, nn, fid = sample_surface(mesh, n * oversample, seed=seed, faces=keep, return_faces=True)
        inside = ((p[:, 0] >= x0 - 1e-6) & (p[:, 0] <= x1 + 1e-6) & (p[:, 2] >= z0 - 1e-6) & (p[:, 2] <= z1 + 1e-6)
                  & (p[:, 1] >= -1e-6))  # drop the wall corners and the walls' feet beside the floor slab
        p, nn, fid = p[inside], nn[inside], fid[inside]
        idx = farthest_point_sample(p, n, seed=seed)
        return {"points": p[idx].astype(np.float32), "normals": nn[idx].astype(np.float32),
                "labels": labels[fid[idx]].astype(np.int32)}

    if not cache:
        return build()
    return cached(f"room_points_{n}_x{oversample}", ROOM_VERSION, seed, build)
