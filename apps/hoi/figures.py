"""Figures of the human–object app: a figure per case and a summary bar chart (time per iteration and
collisions per kind). OpenCV drawing, headless.

The case figure has a row per placement: the first stage, the ground truth (where the case has one) and each
model kind's fit; a fit whose object is lost or that diverged is named in its row, not drawn (it spans
kilometres). Each row's columns are apps/hoi/views.py's: the camera view over the case's image, a close-up framed
on the contact and a side view of the body, with the object's vertices inside the body in red on top.
"""
from __future__ import annotations

import cv2
import numpy as np
import torch
from volsmpl.viz.render import save_png

from .case import Similarity
from .views import BODY, INSIDE, OBJECT, PlacementViews, body_facing

__all__ = ["BODY", "COLUMNS", "INSIDE", "NOT_DRAWN", "OBJECT", "case_geometry", "case_panel", "case_views",
           "coarse_body", "summary_plot"]

NOT_DRAWN = ("diverged", "object_lost")  # fit statuses (plausibility.judge_fit) whose placement is not drawn
COLUMNS = ("camera view", "contact close-up", "side of the body")
HEADER = 24  # pixels: the strip above each row (and the column titles) with its text
COARSE_TRIANGLES = 4000  # the body's triangles in the wide views


def _sim(s) -> Similarity:
    return s if isinstance(s, Similarity) else Similarity.from_dict(s, "placement")


def _inside(body_v: np.ndarray, faces, obj_v: np.ndarray) -> np.ndarray:
    """Object vertices inside the body mesh (exact mesh test), (N,) bool."""
    from volsmpl.geometry.point_mesh_distance import mesh_signed_distance

    d = mesh_signed_distance(torch.as_tensor(body_v), torch.as_tensor(np.asarray(faces)), torch.as_tensor(obj_v),
                             closed=True)
    return (d < 0).numpy()


def coarse_body(vertices: np.ndarray, faces, triangles: int = COARSE_TRIANGLES) -> tuple[np.ndarray, np.ndarray]:
    """The body mesh with about `triangles` triangles (open3d's quadric decimation), for the wide views: a figure's
    cost is its triangles. Returns (vertices, faces); the mesh as it is when it has no more."""
    import open3d as o3d

    if len(faces) <= triangles:
        return np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(vertices, np.float64)),
                                  o3d.utility.Vector3iVector(np.asarray(faces, np.int32)))
    m = m.simplify_quadric_decimation(target_number_of_triangles=triangles)
    return np.asarray(m.vertices), np.asarray(m.triangles, np.int64)


def case_geometry(problem, i: int = 0) -> dict:
    """What every view of case i of a Problem shares (before a placement moves it): the posed body (its frame) and
    its coarse copy, the object's mesh as given (its frame), its even vertices (the Problem's), the contact parts'
    vertices (body frame) and the body's front."""
    from .case import object_mesh, object_template

    case = problem.cases[i]
    v, faces = problem.body_v[i].double().cpu().numpy(), np.asarray(problem.faces.cpu())
    parts = [p[0] for p, c in zip(problem.pairs, problem.pair_case.tolist()) if c == i]
    mesh, _ = object_mesh(case, object_template(case))
    return {"body": (v, faces), "coarse": coarse_body(v, faces), "object": mesh,
            "object_points": np.asarray(problem.meshes[i].vertices, np.float64),
            "parts": torch.cat(parts).double().cpu().numpy() if parts else np.zeros((0, 3)),
            "facing": body_facing(case.body["global_orient"])}


def case_views(problem, sim: dict, i: int = 0, geometry: dict | None = None) -> PlacementViews:
    """The views of case i of a Problem placed by sim {'human', 'object'}: Similarity or its dict (a fit record's
    `human` / `object`); geometry: case_geometry(problem, i) when already made. The views' `share_inside` is the
    share of the object's (even) vertices inside the body."""
    g = geometry or case_geometry(problem, i)
    h, o = _sim(sim["human"]), _sim(sim["object"])
    (v, faces), (cv, cf) = g["body"], g["coarse"]
    v, cv = h.apply(v), h.apply(cv)
    points = o.apply(g["object_points"])
    inside = _inside(v, faces, points)
    views = PlacementViews(v, faces, o.apply(np.asarray(g["object"].vertices, np.float64)),
                           np.asarray(g["object"].faces), points[inside], h, g["parts"], g["facing"],
                           coarse=(cv, cf), obj_points=points)
    views.share_inside = float(inside.mean())
    return views


def _text(img: np.ndarray, text: str, x: int, y: int, scale: float = 0.5, bold: int = 1) -> None:
    cv2.putText(img, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, scale, (20, 20, 20), bold, cv2.LINE_AA)


def _strip(width: int, text: str) -> np.ndarray:
    strip = np.full((HEADER, width, 3), 255, np.uint8)
    _text(strip, text, 6, HEADER - 7)
    return strip


def _image(case) -> np.ndarray | None:
    if case.image and case.source is not None and (case.source / case.image).is_file():
        img = cv2.imread(str(case.source / case.image))
        return None if img is None else cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return None


def case_panel(path, problem, results: dict, i: int = 0, size: int = 300) -> None:
    """Case i of a Problem (module docstring): rows of [camera view, contact close-up, side view], each titled with
    its placement and the share of the object's vertices inside the body; `results`: kind -> fit record (with
    `human`, `object`, `status`, and `after`)."""
    case = problem.cases[i]
    image = _image(case)
    rows = [("first stage", case.init, {})]
    if case.truth is not None:
        rows.append(("ground truth", case.truth, {}))
    rows += [(f"fit {m}", {"human": r.human, "object": r.object}, r) for m, r in results.items()]
    width = size * len(COLUMNS)
    side = None  # the first stage's side of the body, kept for every row (close-up and side view)
    geometry = case_geometry(problem, i)
    out = [np.concatenate([_strip(size, t) for t in COLUMNS], axis=1)]
    for label, sim, r in rows:
        status = getattr(r, "status", None)
        if status in NOT_DRAWN:  # a fit that lost its object spans kilometres: named, not drawn
            out.append(_strip(width, f"{label}: {status}, not drawn ({getattr(r, 'status_why', '')})"[:110]))
            continue
        views = case_views(problem, sim, i, geometry)
        after = getattr(r, "after", {}) or {}
        note = f", contact {after['contact_cm']:.1f} cm" if after.get("contact_cm") is not None else ""
        out.append(_strip(width, f"{label}: {views.share_inside * 100:.1f}% of the object inside the body{note}"
                                 + (f" [{status}]" if status not in (None, "converged") else "")))
        side = side or views.object_side()
        panels = [views.camera_view(case.K, image, size), views.close_up(size, side),
                  views.side_view(size, side)]
        for p in panels:  # a thin frame between the panels
            p[:, -1] = p[-1, :] = 200
        out.append(np.concatenate(panels, axis=1))
    save_png(path, np.concatenate(out, axis=0))


def summary_plot(path, summary: dict) -> None:
    """Bars per model kind: ms per iteration (log scale) and object vertices inside the body after the fit (%)."""
    names = list(summary)
    H, W, pad = 360, 220 * 2 + 60, 40
    img = np.full((H, W, 3), 255, np.uint8)
    cols = [(70, 130, 200), (230, 160, 40), (90, 170, 90), (150, 90, 170)]
    panels = [("ms / iteration (log)", [summary[m].get("ms_per_iter") for m in names], True),
              ("collision % after", [summary[m].get("collision_pct") for m in names], False)]
    for p, (title, vals, log) in enumerate(panels):
        x0 = pad + p * (W // 2)
        cv2.putText(img, title, (x0 - 20, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        good = [v for v in vals if v is not None and np.isfinite(v) and v > 0]
        top = max(good) if good else 1.0
        for i, (m, v) in enumerate(zip(names, vals)):
            if v is None or not np.isfinite(v):
                continue
            frac = (np.log10(max(v, 1e-3)) + 1) / (np.log10(top) + 1) if log else v / top
            hgt = int(max(0.0, frac) * (H - 120))
            x = x0 + i * 55
            cv2.rectangle(img, (x, H - 60 - hgt), (x + 40, H - 60), cols[i % len(cols)], -1)
            cv2.putText(img, f"{v:.3g}", (x, H - 66 - hgt), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
            cv2.putText(img, m, (x, H - 40), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
    save_png(path, img)
