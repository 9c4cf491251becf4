"""The layout generator of the procedural rooms: which furniture a room kind gets and where it goes.

`furnish_room(kind, size, rng)` furnishes an empty interior of `size` (W, H, D) with templates from `objects.py`:
sofas, beds, shelves and desks against walls; dining tables, chairs (facing their table or desk), stools, boxes,
carts and floor clutter (ball, backpack, suitcase) free-standing; cups, bottles, laptops and phones on table tops.

Placement is rejection sampling on the floor footprints (rectangles rotated about Y): every floor item keeps
ITEM_GAP from every other and WALL_GAP from the walls (separating-axis test of the rectangles); table-top items stand
1 mm above the top, inside it, apart from each other. So no two items' oriented bounding boxes intersect. All
randomness comes from the rng, so a seeded rng gives byte-identical rooms (see `rooms.make_room`).
"""
from __future__ import annotations

import numpy as np
import trimesh

from .objects import ObjectTemplate, make_object
from .room import Item

ITEM_GAP = 0.08  # minimum horizontal gap between floor items
WALL_GAP = 0.02  # minimum gap between an item and a wall
_TRIES = 60


# --------------------------------------------------------------------------------------------- footprints
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


def furnish_room(kind: str, size: np.ndarray, rng: np.random.Generator) -> list[Item]:
    """Furnish an empty room of a kind (one of `rooms.ROOM_KINDS`) and interior size (W, H, D) in metres.

    Returns: the placed Items, floor items first, then table-top items (their `on` indexes this list).
    """
    P = _Placer(size, rng)
    _furnish(kind, P)
    floor = [it for it in P.items if it.on is None]
    return floor + [it for it in P.items if it.on is not None]
