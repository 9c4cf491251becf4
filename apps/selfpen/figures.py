"""The figure of one repaired case: the body before and after each kind's repair, seen from its front (top row) and
its side (bottom row), with the colliding triangles in red.

The triangles are those of the exact counter (triangles.body_collisions: pose-induced intersecting pairs); they are
drawn in place and once more on top of the body, so that the parts buried inside another limb show too (seen
through the body). The views are in the body's own frame (its root rotation undone): the front view looks at the
body's front whatever its global orientation. Every panel of a row shares one scale, the body fills its panel's
height, and the panels are cropped to the widest body (or label) of the figure.

    render_case("out/render_case.png", body, case, {"volsmpl": result, "coap": result})
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from .triangles import body_collisions

__all__ = ["GREY", "HIGHLIGHT", "VIEWS", "case_panels", "render_case"]

HIGHLIGHT, GREY = (0.9, 0.1, 0.1), (0.75, 0.75, 0.75)
VIEWS = (("front", 0.0), ("side", 90.0))  # yaw (degrees) about the body's up axis
_FONT, _WHITE = cv2.FONT_HERSHEY_SIMPLEX, 255


def case_panels(body, case, results: dict) -> list:
    """[(label lines, vertices (V, 3), colliding pairs (P, 2))]: the case's body, then each kind's repaired body.
    Meshes kept by the repair (keep_meshes) are used as they are; otherwise (a reused record) they are made again
    from the case and the record's pose."""
    kept = [r for r in results.values() if r.vertices_before is not None]
    if kept:
        v0, p0 = kept[0].vertices_before, kept[0].pairs_before
    else:
        c = body_collisions(body, case.betas, case.global_orient, case.body_pose)
        v0, p0 = c["vertices"], c["pairs"]
    panels = [(("before", f"{len(p0)} pairs"), v0, p0)]
    for kind, r in results.items():
        if r.vertices_after is not None:
            v, p = r.vertices_after, r.pairs_after
        else:
            pose = r.body_pose if len(r.body_pose) else case.body_pose
            c = body_collisions(body, case.betas, case.global_orient, pose)
            v, p = c["vertices"], c["pairs"]
        panels.append(((f"after {kind}", f"{len(p)} pairs"), v, p))
    return panels


def _view(vertices: np.ndarray, global_orient, yaw: float) -> np.ndarray:
    """Vertices in the body's frame (root rotation undone), turned by `yaw` degrees about Y."""
    root = Rotation.from_rotvec(np.asarray(global_orient, np.float64).reshape(3))
    return (Rotation.from_euler("y", yaw, degrees=True) * root.inv()).apply(np.asarray(vertices, np.float64))


def _panel(v: np.ndarray, faces: np.ndarray, pairs: np.ndarray, extent: float, size: int) -> np.ndarray:
    """One body (already turned to the view), colliding faces red in place and drawn again on top."""
    from volsmpl.viz.render import render_scene

    marked = np.zeros(len(faces), bool)
    marked[np.asarray(pairs, np.int64).ravel()] = True
    col = np.tile(np.array(GREY), (len(faces), 1))
    col[marked] = HIGHLIGHT
    centre = np.r_[0.5 * (v[:, :2].min(0) + v[:, :2].max(0)), 0.0]
    img = render_scene([(v, faces, col)], size, extent=extent, center=centre, max_edge=None)
    if marked.any():
        top = render_scene([(v, faces[marked], HIGHLIGHT)], size, extent=extent, center=centre, max_edge=None)
        drawn = (top != _WHITE).any(-1)
        img[drawn] = top[drawn]
    return img


def _text_width(line: str, scale: float) -> int:
    return cv2.getTextSize(line, _FONT, scale, 1)[0][0]


def render_case(path, body, case, results: dict, size: int = 400, scale: float = 0.5) -> None:
    """Write the case's figure (module docstring) as a PNG: columns before and after each kind in `results`
    (kind -> RepairResult), rows front and side; each panel's label gives the colliding triangle pairs."""
    from volsmpl.viz.render import save_png

    faces = np.asarray(body.faces)
    panels = case_panels(body, case, results)
    rows = []
    for _, yaw in VIEWS:
        turned = [_view(v, case.global_orient, yaw) for _, v, _ in panels]
        extent = max(float(np.ptp(v[:, :2], axis=0).max()) for v in turned)
        rows.append([_panel(v, faces, p, extent, size) for v, (_, _, p) in zip(turned, panels)])
    title = (case.name, "red: colliding triangles")
    used = [np.flatnonzero((im != _WHITE).any(axis=(0, 2))) for row in rows for im in row]
    width = max([u[-1] - u[0] + 1 for u in used if len(u)] + [_text_width(t, scale) for lab, _, _ in panels
                                                                for t in lab]
                + [int(np.ceil(_text_width(t, scale) / len(panels))) for t in title]) + 24
    lo = max(0, (size - width) // 2)
    line_h = int(28 * scale) + 6
    head = 2 * line_h + 6
    tiles = []
    for (view, _), row in zip(VIEWS, rows):
        for (lab, _, _), im in zip(panels, row):
            tile = np.full((head + size, min(width, size), 3), _WHITE, np.uint8)
            tile[head:] = im[:, lo:lo + tile.shape[1]]
            for k, t in enumerate((f"{lab[0]} ({view})", lab[1])):
                cv2.putText(tile, t, (6, line_h * (k + 1)), _FONT, scale, (20, 20, 20), 1, cv2.LINE_AA)
            tiles.append(tile)
    cols = len(panels)
    grid = np.concatenate([np.concatenate(tiles[r * cols:(r + 1) * cols], axis=1) for r in range(len(VIEWS))], axis=0)
    band = np.full((head, grid.shape[1], 3), _WHITE, np.uint8)
    for k, t in enumerate(title):
        cv2.putText(band, t, (6, line_h * (k + 1)), _FONT, scale, (20, 20, 20), 1 + (k == 0), cv2.LINE_AA)
    save_png(path, np.concatenate([band, grid], axis=0))
