"""Pictures of the motion app: a top-down plan per scene (OpenCV drawing) with the scene's obstacle points, the
furniture footprints (generated rooms), start and goal of every pair, and the pelvis path of every model."""
from __future__ import annotations

import numpy as np

COLOURS = {"volsmpl": (30, 120, 230), "coap": (230, 120, 30), "mesh": (40, 170, 60)}   # RGB
EXTRA = [(160, 60, 200), (200, 40, 120), (90, 90, 90), (0, 160, 160)]


def _colour(label: str, i: int):
    return COLOURS[label] if label in COLOURS else EXTRA[i % len(EXTRA)]


def topdown(scene, paths: dict, pairs=None, size: int = 640, path=None) -> np.ndarray:
    """scene: scenes.MotionScene; paths: label -> list of (T, 2) pelvis (x, z) paths; pairs: [(start, goal)].
    Returns an RGB image (size, size + legend) and writes it as PNG where `path` is given."""
    import cv2

    pts = np.asarray(scene.points)
    xz = pts[:, [0, 2]]
    lo, hi = xz.min(0) - 0.2, xz.max(0) + 0.2
    scale = (size - 20) / float((hi - lo).max())

    def px(p):
        p = (np.asarray(p, float).reshape(-1, 2) - lo) * scale + 10
        return np.round(p).astype(np.int32)

    img = np.full((size, size + 170, 3), 255, np.uint8)
    h = pts[:, 1] - scene.floor_y
    for q in px(xz[scene.floor]):
        img[q[1], q[0]] = (225, 225, 225)
    obst = (~scene.floor) & (h > 0.05) & (h < 1.8)
    for q, hh in zip(px(xz[obst]), h[obst]):
        c = int(200 - 120 * min(hh / 1.8, 1.0))
        cv2.circle(img, (int(q[0]), int(q[1])), 1, (c, c, c), -1)
    room = getattr(scene, "room", None)
    if room is not None:
        for it in room.items:
            if it.on is None:
                c, A, hs = it.footprint()
                corners = np.array([c + A[0] * sx * hs[0] + A[1] * sz * hs[1] for sx, sz in
                                    ((-1, -1), (1, -1), (1, 1), (-1, 1))])
                cv2.polylines(img, [px(corners)], True, (120, 120, 120), 1, cv2.LINE_AA)
    for i, (label, ps) in enumerate(paths.items()):
        col = _colour(label, i)
        for p in ps:
            cv2.polylines(img, [px(p)], False, col, 2, cv2.LINE_AA)
        y = 20 + 18 * i
        cv2.line(img, (size + 10, y), (size + 35, y), col, 3)
        cv2.putText(img, label, (size + 40, y + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    for k, (s, g) in enumerate(pairs or []):
        (sx, sy), (gx, gy) = px(s)[0], px(g)[0]
        cv2.circle(img, (int(sx), int(sy)), 5, (20, 160, 20), -1)
        cv2.drawMarker(img, (int(gx), int(gy)), (210, 20, 20), cv2.MARKER_CROSS, 12, 2)
        cv2.putText(img, str(k), (int(sx) + 6, int(sy) - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (20, 120, 20), 1)
    y = 20 + 18 * len(paths) + 10
    cv2.circle(img, (size + 22, y), 5, (20, 160, 20), -1)
    cv2.putText(img, "start", (size + 40, y + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    cv2.drawMarker(img, (size + 22, y + 18), (210, 20, 20), cv2.MARKER_CROSS, 12, 2)
    cv2.putText(img, "goal", (size + 40, y + 23), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    cv2.putText(img, scene.name, (10, size - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (20, 20, 20), 1, cv2.LINE_AA)
    if path is not None:
        from volsmpl.viz.render import save_png
        save_png(path, img)
    return img
