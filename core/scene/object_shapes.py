"""Procedural shape builders of the object templates: one function per category, trimesh primitives only.

Each builder `fn(parts, sizes, rng)` adds named closed components (boxes, cylinders, solids of revolution, tori,
cones) to a `Parts` collector, roughly inside [-w/2, w/2] x [0, h] x [-d/2, d/2] of the canonical frame (Y up,
front +Z; see `objects.py`), from the drawn sizes and an rng for discrete choices (stool legs, shelf boards...).
`BUILDERS` maps each category to its builder; `objects.make_object` concatenates the components, snaps the
bounding box to the drawn sizes and names the interaction regions. The geometry is this project's own procedural
work, released with it under Apache-2.0.
"""
from __future__ import annotations

import numpy as np
import trimesh

_Z_TO_Y = trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0])  # (x, y, z) -> (x, z, -y): Z axis to Y


# --------------------------------------------------------------------------------------------- primitives
def _box(lo, hi) -> trimesh.Trimesh:
    return trimesh.creation.box(bounds=np.array([lo, hi], dtype=np.float64))


def _cyl(radius: float, p0, p1, sections: int = 24) -> trimesh.Trimesh:
    return trimesh.creation.cylinder(radius=radius, segment=np.array([p0, p1], dtype=np.float64), sections=sections)


def _revolve_y(profile, sections: int = 32) -> trimesh.Trimesh:
    """Solid of revolution about +Y of a (radius, y) profile that starts and ends on the axis."""
    m = trimesh.creation.revolve(np.asarray(profile, dtype=np.float64), sections=sections)
    return m.apply_transform(_Z_TO_Y)


class Parts:
    """Named closed components, concatenated without merging vertices."""

    def __init__(self):
        self.names: list[str] = []
        self.meshes: list[trimesh.Trimesh] = []

    def add(self, name: str, mesh: trimesh.Trimesh) -> None:
        if mesh.volume < 0:
            mesh.invert()
        self.names.append(name)
        self.meshes.append(mesh)


# --------------------------------------------------------------------------------------------- builders
# Each builder gets the drawn sizes s (w: x, h: y, d: z extents, + extras) and an rng for discrete choices, and
# adds components roughly inside [-w/2, w/2] x [0, h] x [-d/2, d/2]; make_object then snaps the box exactly.
def _cup(p, s, rng):
    h, R = s["height"], s["depth"] / 2
    t, tb = 0.0045, 0.007
    p.add("body", _revolve_y([(0, 0), (R, 0), (R, h), (R - t, h), (R - t, tb), (0, tb)]))
    e = s["width"] - 2 * R  # handle reach
    b = min(0.0055, e / 4)
    a = max((e + t / 2) / 2 - b, 1.5 * b)
    tor = trimesh.creation.torus(a, b, major_sections=24, minor_sections=10)  # in the XY plane
    p.add("handle", tor.apply_translation([R - t / 2 + a + b, 0.5 * h, 0]))


def _bottle(p, s, rng):
    h, R = s["height"], s["width"] / 2
    rn = 0.37 * R
    p.add("body", _revolve_y([(0, 0), (R, 0), (R, 0.62 * h), (rn, 0.82 * h), (rn, 0.94 * h),
                              (1.15 * rn, 0.94 * h), (1.15 * rn, h), (0, h)]))


def _box_obj(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    p.add("body", _box([-w / 2, 0, -d / 2], [w / 2, h, d / 2]))


def _ball(p, s, rng):
    r = s["height"] / 2
    p.add("body", trimesh.creation.icosphere(subdivisions=3, radius=r).apply_translation([0, r, 0]))


def _bat(p, s, rng):
    L, rb = s["height"], s["width"] / 2
    rh, rk = 0.0125, min(0.022, 0.9 * rb)
    p.add("body", _revolve_y([(0, 0), (rb, 0), (rb, 0.35 * L), (rh, 0.70 * L), (rh, L - 0.012), (rk, L - 0.012),
                              (rk, L), (0, L)], sections=24))


def _phone(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    p.add("body", _box([-w / 2, 0, -d / 2], [w / 2, h, d / 2]))


def _skateboard(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    t, rw, ww = 0.012, 0.027, 0.035
    p.add("deck", _box([-w / 2, h - t, -d / 2], [w / 2, h, d / 2]))
    for k, zc in enumerate((-(d / 2 - 0.17), d / 2 - 0.17)):
        for j, sx in enumerate((-1, 1)):
            xo, xi = sx * w / 2, sx * (w / 2 - ww)
            p.add(f"wheel{2 * k + j}", _cyl(rw, [xi, rw, zc], [xo, rw, zc], sections=20))
        p.add(f"axle{k}", _box([-w / 2 + ww, rw - 0.009, zc - 0.012], [w / 2 - ww, rw + 0.009, zc + 0.012]))
        p.add(f"riser{k}", _box([-0.04, rw + 0.009, zc - 0.03], [0.04, h - t, zc + 0.03]))


def _laptop(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    tb, tl = 0.015, 0.007
    th = float(np.clip(2 * np.arctan((h - tb) / d), np.radians(55), np.radians(85)))  # lid angle from horizontal
    L = d / (1 + np.cos(th))
    z0 = -d / 2 + L * np.cos(th)
    p.add("base", _box([-w / 2, 0, z0], [w / 2, tb, z0 + L]))
    lid = _box([-w / 2, 0, 0], [w / 2, L, tl])  # local (x, along the lid, screen normal)
    u, n = np.array([0, np.sin(th), -np.cos(th)]), np.array([0, np.cos(th), np.sin(th)])
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = [1, 0, 0], u, n
    T[:3, 3] = np.array([0, tb, z0]) - tl * n
    p.add("lid", lid.apply_transform(T))


def _backpack(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    hb, st, pd = h - 0.05, 0.02, 0.06  # body height, strap and pocket thickness
    p.add("body", _box([-w / 2, 0, -d / 2 + st], [w / 2, hb, d / 2 - pd]))
    p.add("pocket", _box([-0.35 * w, 0.05, d / 2 - pd], [0.35 * w, 0.5 * hb, d / 2]))
    for k, sx in enumerate((-1, 1)):
        x0, x1 = sorted((sx * 0.06, sx * 0.11))
        p.add(f"strap{k}", _box([x0, 0.1 * hb, -d / 2], [x1, 0.85 * hb, -d / 2 + st]))
        x0, x1 = sorted((sx * 0.03, sx * 0.045))
        p.add(f"handle_post{k}", _box([x0, hb, -0.01], [x1, h - 0.012, 0.01]))
    p.add("handle", _box([-0.045, h - 0.012, -0.01], [0.045, h, 0.01]))


def _suitcase(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    rw, hb = 0.025, h - 0.035
    p.add("body", _box([-w / 2, 2 * rw, -d / 2], [w / 2, hb, d / 2]))
    for k, (sx, sz) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
        x, z = sx * (w / 2 - 0.04), sz * (d / 2 - 0.04)
        p.add(f"wheel{k}", _cyl(rw, [x - 0.01, rw, z], [x + 0.01, rw, z], sections=16))
    zc = -d / 2 + 0.03
    for k, sx in enumerate((-1, 1)):
        x0, x1 = sorted((sx * 0.12, sx * 0.135))
        p.add(f"handle_post{k}", _box([x0, hb, zc - 0.0075], [x1, h - 0.012, zc + 0.0075]))
    p.add("handle", _box([-0.135, h - 0.012, zc - 0.012], [0.135, h, zc + 0.012]))


def _umbrella(p, s, rng):
    h, R = s["height"], s["width"] / 2
    ch, tip = 0.25, 0.03
    p.add("handle", _cyl(0.014, [0, 0, 0], [0, 0.12, 0], sections=16))
    p.add("shaft", _cyl(0.006, [0, 0.12, 0], [0, h - tip - ch, 0], sections=12))
    canopy = trimesh.creation.cone(R, ch, sections=32).apply_transform(_Z_TO_Y)
    p.add("canopy", canopy.apply_translation([0, h - tip - ch, 0]))
    p.add("tip", _cyl(0.004, [0, h - tip - 0.01, 0], [0, h, 0], sections=12))


def _chair(p, s, rng):
    w, h, d, sh = s["width"], s["height"], s["depth"], s["seat_height"]
    t, a = 0.04, 0.04  # seat thickness, leg side
    for k, sx in enumerate((-1, 1)):
        x0, x1 = sorted((sx * (w / 2 - a), sx * w / 2))
        p.add(f"leg_front{k}", _box([x0, 0, d / 2 - a], [x1, sh - t, d / 2]))
        p.add(f"leg_back{k}", _box([x0, 0, -d / 2], [x1, h, -d / 2 + a]))  # continues up as the back post
    p.add("seat", _box([-w / 2, sh - t, -d / 2 + a], [w / 2, sh, d / 2]))
    lo = sh + (0.10 if rng.random() < 0.5 else 0.25 * (h - sh))  # full or upper back panel
    p.add("back", _box([-w / 2 + a, lo, -d / 2 + 0.01], [w / 2 - a, h - 0.01, -d / 2 + 0.03]))


def _stool(p, s, rng):
    h, R = s["height"], s["width"] / 2
    t = 0.035
    p.add("seat", _cyl(R, [0, h - t, 0], [0, h, 0], sections=32))
    n = 3 if rng.random() < 0.4 else 4
    for k in range(n):
        ang = 2 * np.pi * k / n + np.pi / 4
        c = 0.62 * R * np.array([np.cos(ang), 0, np.sin(ang)])
        p.add(f"leg{k}", _cyl(0.016, c, c + [0, h - t, 0], sections=12))


def _table(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    t, a, inset = 0.03, 0.05, 0.03 + 0.05 * rng.random()
    p.add("top", _box([-w / 2, h - t, -d / 2], [w / 2, h, d / 2]))
    for k, (sx, sz) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
        x0, x1 = sorted((sx * (w / 2 - inset), sx * (w / 2 - inset - a)))
        z0, z1 = sorted((sz * (d / 2 - inset), sz * (d / 2 - inset - a)))
        p.add(f"leg{k}", _box([x0, 0, z0], [x1, h - t, z1]))


def _sofa(p, s, rng):
    w, h, d, sh = s["width"], s["height"], s["depth"], s["seat_height"]
    lh, aw, bd = 0.08, 0.14 + 0.06 * rng.random(), 0.20
    ah = min(sh + 0.18 + 0.06 * rng.random(), h - 0.05)
    for k, sx in enumerate((-1, 1)):
        x0, x1 = sorted((sx * (w / 2 - aw), sx * w / 2))
        p.add(f"arm{k}", _box([x0, lh, -d / 2], [x1, ah, d / 2]))
        for j, sz in enumerate((-1, 1)):
            lx0, lx1 = sorted((sx * (w / 2 - 0.10), sx * (w / 2 - 0.05)))
            lz0, lz1 = sorted((sz * (d / 2 - 0.10), sz * (d / 2 - 0.05)))
            p.add(f"leg{2 * k + j}", _box([lx0, 0, lz0], [lx1, lh, lz1]))
    p.add("back_base", _box([-w / 2 + aw, lh, -d / 2], [w / 2 - aw, sh, -d / 2 + bd]))
    p.add("back", _box([-w / 2 + aw, sh, -d / 2], [w / 2 - aw, h, -d / 2 + bd]))
    p.add("seat", _box([-w / 2 + aw, lh, -d / 2 + bd], [w / 2 - aw, sh, d / 2]))


def _bed(p, s, rng):
    w, h, d, sh = s["width"], s["height"], s["depth"], s["seat_height"]
    hb, mt = 0.05, 0.20  # headboard and mattress thickness
    p.add("headboard", _box([-w / 2, 0, -d / 2], [w / 2, h, -d / 2 + hb]))
    p.add("frame", _box([-w / 2, 0, -d / 2 + hb], [w / 2, sh - mt, d / 2]))
    p.add("mattress", _box([-w / 2 + 0.02, sh - mt, -d / 2 + hb], [w / 2 - 0.02, sh, d / 2 - 0.02]))
    n = 2 if w > 1.3 else 1
    pw = (w - 0.04 - 0.1 * (n + 1)) / n
    for k in range(n):
        x0 = -w / 2 + 0.02 + 0.1 + k * (pw + 0.1)
        p.add(f"pillow{k}", _box([x0, sh, -d / 2 + hb + 0.05], [x0 + pw, sh + 0.10, -d / 2 + hb + 0.45]))


def _shelf(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    t, bt = 0.02, 0.01
    for k, sx in enumerate((-1, 1)):
        x0, x1 = sorted((sx * (w / 2 - t), sx * w / 2))
        p.add(f"side{k}", _box([x0, 0, -d / 2], [x1, h, d / 2]))
    xi = w / 2 - t
    p.add("back", _box([-xi, 0, -d / 2], [xi, h - t, -d / 2 + bt]))
    p.add("bottom", _box([-xi, 0, -d / 2 + bt], [xi, 0.06, d / 2]))
    p.add("top", _box([-xi, h - t, -d / 2], [xi, h, d / 2]))
    n = int(rng.integers(2, 6))
    for k, y in enumerate(np.linspace(0.06, h - t, n + 2)[1:-1]):
        p.add(f"board{k}", _box([-xi, y - t / 2, -d / 2 + bt], [xi, y + t / 2, d / 2]))


def _cart(p, s, rng):
    w, h, d = s["width"], s["height"], s["depth"]
    rw, pt, r = 0.04, 0.03, 0.012  # wheel radius, platform thickness, post radius
    y_up = 0.62 * h + 0.1 * (h - 0.62 * h) * rng.random()
    p.add("platform_low", _box([-w / 2, 0.10, -d / 2], [w / 2, 0.10 + pt, d / 2]))
    p.add("platform_top", _box([-w / 2, y_up - pt, -d / 2], [w / 2, y_up, d / 2]))
    for k, (sx, sz) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
        x, z = sx * (w / 2 - 0.04), sz * (d / 2 - 0.06)
        p.add(f"wheel{k}", _cyl(rw, [x - 0.015, rw, z], [x + 0.015, rw, z], sections=16))
        p.add(f"mount{k}", _box([x - 0.015, 2 * rw, z - 0.02], [x + 0.015, 0.10, z + 0.02]))
        xp, zp = sx * (w / 2 - 0.03), sz * (d / 2 - 0.03)
        p.add(f"post{k}", _cyl(r, [xp, 0.10 + pt, zp], [xp, y_up - pt, zp], sections=12))
    zh = -d / 2 + 0.03
    for k, sx in enumerate((-1, 1)):
        xp = sx * (w / 2 - 0.03)
        p.add(f"handle_post{k}", _cyl(r, [xp, y_up, zh], [xp, h - 0.015, zh], sections=12))
    p.add("handle", _cyl(0.015, [-w / 2, h - 0.015, zh], [w / 2, h - 0.015, zh], sections=16))


BUILDERS = {"cup": _cup, "bottle": _bottle, "box": _box_obj, "ball": _ball, "bat": _bat, "phone": _phone,
             "skateboard": _skateboard, "laptop": _laptop, "backpack": _backpack, "suitcase": _suitcase,
             "umbrella": _umbrella, "chair": _chair, "stool": _stool, "table": _table, "sofa": _sofa, "bed": _bed,
             "shelf": _shelf, "cart": _cart}
