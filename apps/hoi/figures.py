"""Figures of the human–object app: a panel per case (the image with the first-stage and fitted projections,
the fitted 3D pair from two views per model kind with the object vertices inside the body in red) and a summary
bar chart (time per iteration and collisions per kind). OpenCV drawing, headless."""
from __future__ import annotations

import cv2
import numpy as np
import torch

from volsmpl.viz.render import grid, render_camera_view, render_scene, save_png

from .case import Similarity

BODY, OBJECT, INSIDE = (0.78, 0.78, 0.78), (0.35, 0.55, 0.85), (0.9, 0.1, 0.1)
NOT_DRAWN = ("diverged", "object_lost")  # fit statuses (plausibility.judge_fit) whose placement is not drawn


def case_camera(case):
    """The case's pinhole (camera frame = world) as a kornia PinholeCamera."""
    from kornia.geometry.camera import PinholeCamera

    K = torch.eye(4, dtype=torch.float64)[None]
    K[0, :3, :3] = torch.as_tensor(case.K)
    H, W = case.image_size
    return PinholeCamera(K, torch.eye(4, dtype=torch.float64)[None], torch.tensor([float(H)]), torch.tensor([float(W)]))


def _placed(problem, sim: dict, i: int):
    sh, so = (Similarity.from_dict(_sim(sim[k]), k) for k in ("human", "object"))
    v = sh.apply(problem.body_v[i].cpu().numpy())
    o = so.apply(np.asarray(problem.meshes[i].vertices))
    return v, o


def _sim(s):
    return s if isinstance(s, dict) else s.to_dict()


def _inside(problem, sim: dict, i: int) -> np.ndarray:
    """Object vertices inside the placed body (exact mesh test), (N,) bool."""
    from volsmpl.geometry.point_mesh_distance import mesh_signed_distance

    v, o = _placed(problem, sim, i)
    d = mesh_signed_distance(torch.as_tensor(v), problem.faces.cpu(), torch.as_tensor(o), closed=True)
    return (d < 0).numpy()


def case_panel(path, problem, results: dict, i: int = 0, size: int = 320) -> None:
    """Case i of a Problem: [image or first-stage view, first-stage view] + per model [fitted camera view, fitted
    side view]."""
    case, faces, obj_faces = problem.cases[i], np.asarray(problem.faces.cpu()), np.asarray(problem.meshes[i].faces)
    cam = case_camera(case)
    images, labels = [], []
    if case.image and case.source is not None and (case.source / case.image).is_file():
        img = cv2.cvtColor(cv2.imread(str(case.source / case.image)), cv2.COLOR_BGR2RGB)
        images.append(img)
        labels.append("image")
    states = [("first stage", {k: _sim(s) for k, s in case.init.items()})]
    states += [(f"fit {m}", {"human": r.human, "object": r.object}) for m, r in results.items()
               if getattr(r, "status", None) not in NOT_DRAWN]
    lost = [f"{m}: {r.status}" for m, r in results.items() if getattr(r, "status", None) in NOT_DRAWN]
    for label, sim in states:
        v, o = _placed(problem, sim, i)
        ins = _inside(problem, sim, i)
        images.append(render_camera_view([(v, faces, BODY), (o, obj_faces, OBJECT)], cam,
                                         points=o[ins], point_colors=INSIDE))
        labels.append(f"{label} ({ins.mean() * 100:.1f}% inside)")
    up = np.diag([1.0, -1.0, -1.0])  # camera frame (y down, z forward) -> a Y-up frame for the side view
    centre = np.concatenate(_placed(problem, states[-1][1], i)).mean(0) @ up
    for label, sim in states[1:]:
        v, o = (x @ up for x in _placed(problem, sim, i))
        ins = _inside(problem, sim, i)
        images.append(render_scene([(v, faces, BODY), (o, obj_faces, OBJECT)], size=size,
                                   yaw=90.0, center=centre, points=o[ins], point_colors=INSIDE))
        labels.append(f"{label}, side")
    if lost:  # a fit that lost its object spans kilometres: named, not drawn
        images.append(np.full((size, size, 3), 255, np.uint8))
        labels.append("not drawn: " + ", ".join(lost))
    h = max(im.shape[0] for im in images)
    images = [cv2.resize(im, (int(im.shape[1] * size / h), size)) if im.shape[0] != size else im for im in images]
    w = max(im.shape[1] for im in images)
    images = [np.pad(im, ((0, 0), (0, w - im.shape[1]), (0, 0)), constant_values=255) for im in images]
    save_png(path, grid(images, labels, cols=len(states) + (1 if len(images) > 2 * len(states) - 1 else 0)))


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
