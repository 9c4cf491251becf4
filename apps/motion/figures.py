"""Pictures of the motion app: a top-down plan per scene (OpenCV drawing), cropped to the walks.

`topdown` draws, in the scene's horizontal axes in metres (the file's own: x and z for --up y, x and y for --up z;
ticks and grid lines every 0.1-50 m), the part of the scene the walks cover plus a margin (CROP_MARGIN_M): floor
points light grey, the obstacle points (above the floor, below a person's height) as dots shaded by height (light:
low, dark: high; a colour bar in the legend), the furniture footprints of a generated room, the start (filled
circle) and goal (cross) of every pair with its number, and the pelvis path of every model. Each model has its own
colour (a kind's own for its first weight, another for each further one) and line style (solid, dashed, dotted,
dash-dot) and a line width that decreases in the legend's order, the thinner drawn on top, so that paths that
coincide all stay visible (the widest shows as a rim around the others).
"""
from __future__ import annotations

import math

import numpy as np

COLOURS = {"volsmpl": (30, 110, 230), "coap": (240, 130, 20), "mesh": (30, 160, 60)}   # RGB
EXTRA = [(160, 60, 200), (200, 40, 120), (90, 90, 90), (0, 160, 160), (120, 80, 20)]
STYLES = ("solid", "dashed", "dotted", "dashdot")
WIDTHS = (9, 6, 3, 2, 1)     # px, by the paths' order: the thinner drawn on top
CROP_MARGIN_M = 0.9          # metres around the walks (the body reaches ~0.6 m from its pelvis)
TOP_HEIGHT_M = 2.0           # obstacle dots are shaded from 0 (light) to this height (dark)
_PATTERNS = {"solid": None, "dashed": (14, 8), "dotted": (1, 7), "dashdot": (14, 5, 1, 5)}   # on, off, ... px
_FONT = 0  # cv2.FONT_HERSHEY_SIMPLEX


def _colours(labels) -> dict:
    """label -> RGB: a kind's own colour (COLOURS) for its first label (volsmpl, coap_w0.1, ...), EXTRA for the
    others (COAP's other weights), so that no two labels share one."""
    out, used, extra = {}, set(), iter(EXTRA * 4)
    for label in labels:
        base = label.split("_w")[0]
        if base in COLOURS and base not in used:
            out[label] = COLOURS[base]
            used.add(base)
        else:
            out[label] = next(extra)
    return out


def _height_rgb(h: np.ndarray) -> np.ndarray:
    """Obstacle shading by height above the floor: light tan at 0, dark brown at TOP_HEIGHT_M and above."""
    t = np.clip(np.asarray(h, float) / TOP_HEIGHT_M, 0.0, 1.0)[:, None]
    lo, hi = np.array([225.0, 205.0, 165.0]), np.array([70.0, 45.0, 30.0])
    return np.round(lo + (hi - lo) * t).astype(np.uint8)


def _nice_step(span: float, ticks: int = 6) -> float:
    raw = span / ticks
    for s in (0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 2.5, 5.0, 10.0, 20.0, 25.0, 50.0):
        if s >= raw:
            return s
    return 10.0 ** math.ceil(math.log10(raw))


def styled_polyline(img, pts, colour, width: int, style: str = "solid") -> None:
    """A polyline (pixel (n, 2)) drawn in `style` (solid, dashed, dotted, dashdot) and `width` px, in place."""
    import cv2

    p = np.asarray(pts, float).reshape(-1, 2)
    col = tuple(int(c) for c in colour)
    pattern = _PATTERNS[style]
    if pattern is None or len(p) < 2:
        cv2.polylines(img, [np.round(p).astype(np.int32)], False, col, width, cv2.LINE_AA)
        return
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    q = np.arange(0.0, s[-1] + 1e-9, 1.0)                                  # resampled every pixel
    xy = np.stack([np.interp(q, s, p[:, 0]), np.interp(q, s, p[:, 1])], 1)
    period = float(sum(pattern))
    edges = np.cumsum(pattern)
    on = (np.searchsorted(edges, np.mod(q, period), side="right") % 2) == 0
    if style == "dotted":
        for x, y in np.round(xy[on]).astype(int):
            cv2.circle(img, (int(x), int(y)), max(1, (width + 1) // 2), col, -1, cv2.LINE_AA)
        return
    runs = np.flatnonzero(np.diff(np.r_[0, on.astype(int), 0]))
    for a, b in zip(runs[::2], runs[1::2]):
        if b - a >= 2:
            cv2.polylines(img, [np.round(xy[a:b]).astype(np.int32)], False, col, width, cv2.LINE_AA)


def topdown(scene, paths: dict, pairs=None, size: int = 640, path=None, up: str = "y") -> np.ndarray:
    """scene: scenes.MotionScene (floor at y = 0); paths: label -> list of (T, 2) pelvis (x, z) paths; pairs:
    [(start, goal)] (x, z); up: the input's up axis ('z': the file's horizontal axes are x and y = -z). Returns an
    RGB image and writes it as PNG where `path` is given (module docstring)."""
    import cv2

    flip = -1.0 if up == "z" else 1.0            # (x, z) -> the file's (x, b): b = z (y up) or y = -z (z up)
    names = ("x", "z") if up == "y" else ("x", "y")

    def ab(p):
        p = np.asarray(p, float).reshape(-1, 2)
        return np.stack([p[:, 0], flip * p[:, 1]], 1)

    keep = [ab(p) for ps in paths.values() for p in ps] + [ab(q) for pr in (pairs or []) for q in pr]
    every = np.concatenate(keep) if keep else ab(np.asarray(scene.points)[:, [0, 2]])
    lo, hi = every.min(0) - CROP_MARGIN_M, every.max(0) + CROP_MARGIN_M
    centre, span = 0.5 * (lo + hi), np.maximum(hi - lo, 2.0)
    lo, hi = centre - span / 2, centre + span / 2
    scale = size / float(span.max())
    W, H = (int(v) for v in np.round(span * scale))
    L, T, B, R = 64, 30, 48, 210                   # margins: tick labels, title, axis label, legend
    img = np.full((T + H + B, L + W + R, 3), 255, np.uint8)
    plot = np.full((H, W, 3), 255, np.uint8)       # the plot area, drawn apart: nothing spills into the margins

    def px(p):   # the file's (a, b) metres -> the plot's pixel (column, row), b upwards
        p = np.asarray(p, float).reshape(-1, 2)
        return np.stack([(p[:, 0] - lo[0]) * scale, (hi[1] - p[:, 1]) * scale], 1)

    step = _nice_step(float(span.max()))
    for axis in (0, 1):                            # grid lines and tick labels
        for v in np.arange(math.ceil(lo[axis] / step) * step, hi[axis] + 1e-9, step):
            c, r = px([v, lo[1]] if axis == 0 else [lo[0], v])[0]
            text = f"{v:g}" if step >= 1 else f"{v:.2f}".rstrip("0").rstrip(".")
            if axis == 0:
                cv2.line(plot, (int(c), 0), (int(c), H), (236, 236, 236), 1)
                cv2.putText(img, text, (L + int(c) - 10, T + H + 16), _FONT, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
            else:
                cv2.line(plot, (0, int(r)), (W, int(r)), (236, 236, 236), 1)
                cv2.putText(img, text, (6, T + int(r) + 4), _FONT, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
    cv2.putText(img, f"{names[0]} (m)", (L + W // 2 - 16, T + H + 38), _FONT, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    cv2.putText(img, f"{names[1]} (m)", (4, T - 10), _FONT, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    cv2.putText(img, f"{scene.name}: top view, {names[0]} right, {names[1]} up", (L + 70, T - 10), _FONT, 0.45,
                (20, 20, 20), 1, cv2.LINE_AA)

    pts = np.asarray(scene.points, float)
    h = pts[:, 1] - scene.floor_y
    q = px(ab(pts[:, [0, 2]]))
    inside = (q[:, 0] >= 0) & (q[:, 0] < W) & (q[:, 1] >= 0) & (q[:, 1] < H)
    fl = inside & scene.floor
    plot[q[fl, 1].astype(int), q[fl, 0].astype(int)] = (222, 222, 222)
    obst = np.flatnonzero(inside & ~scene.floor & (h > 0.05) & (h < 1.8))
    obst = obst[np.argsort(h[obst])]               # the highest drawn last
    for (c, r), rgb in zip(q[obst], _height_rgb(h[obst])):
        cv2.circle(plot, (int(c), int(r)), 2, tuple(int(v) for v in rgb), -1)
    room = getattr(scene, "room", None)
    if room is not None:
        for it in room.items:
            if it.on is None:
                c, A, hs = it.footprint()
                corners = np.array([c + A[0] * sx * hs[0] + A[1] * sz * hs[1] for sx, sz in
                                    ((-1, -1), (1, -1), (1, 1), (-1, 1))])
                cv2.polylines(plot, [np.round(px(ab(corners))).astype(np.int32)], True, (130, 130, 130), 1,
                              cv2.LINE_AA)
    legend, colours = [], _colours(paths)
    for i, (label, ps) in enumerate(paths.items()):
        col, style, width = colours[label], STYLES[i % len(STYLES)], WIDTHS[min(i, len(WIDTHS) - 1)]
        legend.append((label, col, style, width))
        for p in ps:
            styled_polyline(plot, px(ab(p)), col, width, style)
    for k, (s, g) in enumerate(pairs or []):
        (sx, sy), (gx, gy) = px(ab(s))[0], px(ab(g))[0]
        cv2.circle(plot, (int(sx), int(sy)), 6, (20, 20, 20), -1, cv2.LINE_AA)
        cv2.circle(plot, (int(sx), int(sy)), 4, (255, 255, 255), -1, cv2.LINE_AA)
        cv2.drawMarker(plot, (int(gx), int(gy)), (20, 20, 20), cv2.MARKER_TILTED_CROSS, 14, 3)
        if len(pairs) > 1:
            cv2.putText(plot, str(k), (int(sx) + 7, int(sy) - 5), _FONT, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    img[T:T + H, L:L + W] = plot
    cv2.rectangle(img, (L, T), (L + W, T + H), (90, 90, 90), 1)

    x0, y = L + W + 16, T + 14                     # the legend
    for label, col, style, width in legend:
        styled_polyline(img, [(x0, y), (x0 + 44, y)], col, width, style)
        cv2.putText(img, label, (x0 + 52, y + 5), _FONT, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
        y += 22
    cv2.circle(img, (x0 + 22, y), 6, (20, 20, 20), -1, cv2.LINE_AA)
    cv2.circle(img, (x0 + 22, y), 4, (255, 255, 255), -1, cv2.LINE_AA)
    cv2.putText(img, "start", (x0 + 52, y + 5), _FONT, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    cv2.drawMarker(img, (x0 + 22, y + 20), (20, 20, 20), cv2.MARKER_TILTED_CROSS, 14, 3)
    cv2.putText(img, "goal", (x0 + 52, y + 25), _FONT, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    y += 48
    cv2.putText(img, "obstacle height", (x0, y), _FONT, 0.42, (20, 20, 20), 1, cv2.LINE_AA)
    bar = _height_rgb(np.linspace(0, TOP_HEIGHT_M, 120))
    img[y + 8:y + 20, x0:x0 + 120] = bar[None]
    cv2.putText(img, "0", (x0 - 2, y + 34), _FONT, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
    cv2.putText(img, f"{TOP_HEIGHT_M:g} m", (x0 + 104, y + 34), _FONT, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
    cv2.rectangle(img, (x0, y + 44), (x0 + 12, y + 52), (222, 222, 222), -1)
    cv2.putText(img, "floor", (x0 + 18, y + 53), _FONT, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
    if len(legend) > 1:
        cv2.putText(img, "wider lines below", (x0, y + 76), _FONT, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
    if path is not None:
        from volsmpl.viz.render import save_png
        save_png(path, img)
    return img
