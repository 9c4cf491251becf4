"""The motion app's pictures (volsmpl.apps.motion.figures.topdown, measures.render_strip): the plan cropped to the
walks with every model's path visible where all coincide; the strip's penetrating points red only where the scene
enters the body."""
from __future__ import annotations

import numpy as np
import pytest
import volsmpl
from volsmpl.apps.motion import walk as W
from volsmpl.apps.motion.figures import COLOURS, topdown
from volsmpl.apps.motion.scenes import MotionScene


def _count(img, rgb, tol: int = 12) -> int:
    return int((np.abs(img.astype(int) - np.array(rgb)).max(-1) <= tol).sum())


def test_the_plan_is_cropped_to_the_walk_and_coinciding_paths_all_show():
    """A 100 x 100 m floor cloud and three identical 3 m paths: the plot spans the paths plus 0.9 m on each side
    (4.8 m, 640 px, and 2 m, the least, across: 267 px) instead of the whole floor, and each model's colour shows
    (each drawn thinner than the one under it)."""
    g = np.arange(-50.0, 50.0, 0.5)
    X, Z = np.meshgrid(g, g)
    pts = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], 1)
    sc = MotionScene("hall", pts.astype(np.float32), np.ones(len(pts), bool))
    p = np.stack([np.linspace(0.0, 3.0, 40), np.zeros(40)], 1)
    img = topdown(sc, {"volsmpl": [p], "coap": [p], "mesh": [p]}, [(p[0], p[-1])], size=640)
    assert img.shape == (30 + 267 + 48, 64 + 640 + 210, 3)
    plot = img[30:30 + 267, 64:64 + 640]
    for kind in ("volsmpl", "coap", "mesh"):
        assert _count(plot, COLOURS[kind]) > 50, kind


@pytest.fixture(scope="module")
def walk_and_body():
    body = volsmpl.create_body()
    hd, sp = W.straight_controls(1, 1, 1.3)
    return W.WalkModel(body)(hd, sp, frames=10), body


def test_the_strip_shows_the_points_inside_the_body_in_red(walk_and_body):
    """A wall of points across the walk's first frame (through the pelvis) puts points inside the body: red dots;
    the same wall 3 m away: obstacle dots neither near nor inside, no red."""
    walk, body = walk_and_body
    pel = walk.joints[0, 0, 0].detach().numpy()
    a, b = np.meshgrid(np.arange(-0.6, 0.6, 0.02), np.arange(0.05, 1.8, 0.02))
    wall = np.stack([pel[0] + a.ravel(), b.ravel(), np.full(a.size, pel[2])], 1)   # across +z, the walk's way
    floor = np.zeros(len(wall), bool)
    hit = W.render_strip(walk, body.faces, every=10, scene_points=wall, scene_floor=floor)
    away = W.render_strip(walk, body.faces, every=10, scene_points=wall + [3.0, 0, 0], scene_floor=floor)
    assert _count(hit, (220, 0, 0), tol=25) > 20
    assert _count(away, (220, 0, 0), tol=25) == 0
