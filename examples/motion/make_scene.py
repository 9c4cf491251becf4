"""Writes scene.ply, the example scene of `volsmpl motion --scene`: a 5 x 3.6 m floor with a pillar on the line
from the start to the goal, a crate beside it and a 20 cm lantern on a post, in millimetres with z up (as many
scanners and CAD tools write them), so that the example runs through --units mm and --up z. The floor lies at
z = 120 mm, not 0 (a scan's origin is rarely on its floor): the app finds it, and its outputs keep it.

    .venv/bin/python examples/motion/make_scene.py        # rewrites examples/motion/scene.ply (~2 KB)
"""
from pathlib import Path

import numpy as np
import trimesh


def box(lo, hi) -> trimesh.Trimesh:
    """An axis-aligned box between the corners lo and hi (mm)."""
    return trimesh.creation.box(bounds=np.array([lo, hi], dtype=np.float64))


FLOOR_Z = 120.0   # mm


def scene() -> trimesh.Trimesh:
    """The example scene (mm, z up): floor at z = FLOOR_Z, x -2500..2500, y -1800..1800."""
    f = FLOOR_Z
    floor = trimesh.Trimesh([[-2500, -1800, f], [2500, -1800, f], [2500, 1800, f], [-2500, 1800, f]],
                            [[0, 1, 2], [0, 2, 3]], process=False)
    pillar = box([-150, -150, f], [150, 150, f + 2200])        # on the line from start (-1000, 0) to goal (1000, 200)
    crate = box([-700, 650, f], [100, 1150, f + 700])          # beside it
    post = box([580, -370, f], [620, -330, f + 600])           # a 4 cm post ...
    lantern = box([500, -450, f + 600], [700, -250, f + 800])  # ... holding a 20 cm lantern
    return trimesh.util.concatenate([floor, pillar, crate, post, lantern])


if __name__ == "__main__":
    path = Path(__file__).with_name("scene.ply")
    scene().export(path, encoding="binary")
    print(f"wrote {path} ({path.stat().st_size:,} bytes)")
