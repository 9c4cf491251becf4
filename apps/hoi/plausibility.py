"""Is a human–object case plausible? Checks of a case's data against the body and the image, made before any fit,
and the judge of a finished fit, made without ground truth.

Before the fit (`check_case_data`): what cannot be right is refused in one line naming the field and the likely
fix; what is merely unusual becomes a warning. The limits, from the generated database (`volsmpl hoi make-db
--seed 0`, 100 cases): its objects' first-stage size lies within 0.68-1.55x of the category's mean real size
(volsmpl.scene.objects.SIZE_PRIOR), their geometry's centre within 0.5 of the mesh's extent from its origin, the gap
between the first-stage object and body within 1.23 m (median 0.13 m), the principal point at the image centre.

    object size (first-stage scale x the mesh's extent, metres) / the category's mean size:
        outside [1/10, 10] -> refused, naming the units that would bring it to 1 (`"units": "mm"`); outside [1/3, 3] -> warning
    the mesh's geometry from its origin: > 5 extents and > 1 m -> refused (rotations turn about the origin); > 2 extents -> warning
    the first-stage object's nearest vertex from the first-stage body: > 3 m -> refused; > 1.5 m -> warning
    the principal point (cx, cy) outside the image -> refused (a camera matrix for another image size?);
        more than a tenth of the image from its centre -> warning (calibrated cameras: a few %; a 4:3 image's
        image_size given as [W, H]: 17 %)
    detected keypoints (confidence > 0) outside the image: more than half -> refused; any -> warning; all within 3
        pixels of one another (normalised [0, 1] coordinates) -> refused
    silhouette pixels outside the image: more than half -> refused

After the fit (`judge_fit`), each fit gets a status, `converged` or one of
    diverged          a step made the fit's numbers or loss non-finite, or the final loss is over 10x the first
    object_lost       the object ends more than 1 m from the body and 0.5 m farther than it started
    worse_than_start  more of the object inside the body (+2 points of collision %), or the object 5 cm farther from
                      the body than at the start
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["check_case_data", "judge_fit", "GOOD", "LIMITS"]

#: the statuses of a fit that worked
GOOD = ("converged",)

LIMITS = {
    "size_refuse": 10.0, "size_warn": 3.0,            # object size / the category's mean size
    "origin_refuse": 5.0, "origin_refuse_m": 1.0, "origin_warn": 2.0,   # geometry centre from origin, in extents
    "gap_refuse_m": 3.0, "gap_warn_m": 1.5,           # first-stage object from body
    "pp_warn": 0.1,                                   # principal point from the image centre, share of the image
    "loss_growth": 10.0, "lost_m": 1.0, "lost_more_m": 0.5, "worse_collision_pct": 2.0, "worse_gap_m": 0.05,
}
_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def _units_fix(case, extent_m: float, size: float) -> str:
    """The hint of a mis-sized object: the units that bring it nearest its category's size."""
    if case.mesh_path is None:
        return "check init.object.scale"
    raw = extent_m / _UNITS[case.units]  # the extent in the file's own numbers
    best = min(_UNITS, key=lambda u: abs(math.log(raw * _UNITS[u] * case.init["object"].scale / size)))
    if best != case.units:
        return f"is the mesh in {best}? set \"units\": \"{best}\" in the case's object"
    return "check the mesh's units and init.object.scale"


def check_case_data(case, mesh, body_vertices: np.ndarray, warn) -> None:
    """Refuse a case whose data cannot be right (ValueError, one line naming the field and the fix); `warn(text)`
    what is merely unusual. mesh: the object's mesh in its own frame (metres, after units); body_vertices (V, 3):
    the posed body in its own frame."""
    from scipy.spatial import cKDTree

    from .case import object_size_m

    name, L = f"case {case.name!r}", LIMITS
    where = f" ({case.source / case.mesh_path if case.source else case.mesh_path})" if case.mesh_path else ""
    extent = float(np.asarray(mesh.extents).max())
    size = object_size_m(case.category, case.size_m)
    placed = case.init["object"].scale * extent
    ratio = placed / size
    if not 1 / L["size_refuse"] <= ratio <= L["size_refuse"]:
        raise ValueError(f"{name}: the object{where} is {placed:.3g} m across as placed by init.object, a "
                         f"{case.category} is about {size:.2g} m: {_units_fix(case, extent, size)}")
    if not 1 / L["size_warn"] <= ratio <= L["size_warn"]:
        warn(f"{name}: the object is {placed:.3g} m across, {ratio:.2g}x a typical {case.category} ({size:.2g} m): "
             f"{_units_fix(case, extent, size)} (the scale prior pulls it towards the typical size)")
    off = float(np.linalg.norm(np.asarray(mesh.bounds).mean(axis=0)))
    if off > L["origin_refuse"] * extent and off > L["origin_refuse_m"]:
        raise ValueError(f"{name}: the object mesh{where} lies {off:.3g} m from its origin ({off / extent:.0f}x its "
                         f"size); rotations turn about the origin: recentre the mesh and move the offset into "
                         f"init.object.translation")
    if off > L["origin_warn"] * extent:
        warn(f"{name}: the object mesh lies {off:.3g} m from its origin ({off / extent:.1f}x its size); a mesh "
             f"centred on its origin fits better")
    vb = case.init["human"].apply(np.asarray(body_vertices, dtype=np.float64))
    vo = case.init["object"].apply(np.asarray(mesh.vertices, dtype=np.float64))
    gap = float(cKDTree(vb).query(vo[:: max(1, len(vo) // 2000)])[0].min())
    if gap > L["gap_refuse_m"]:
        raise ValueError(f"{name}: init.object places the object {gap:.3g} m from the body (init.human); an object a "
                         f"person interacts with lies within reach: check init.object.translation and the units")
    if gap > L["gap_warn_m"]:
        warn(f"{name}: init.object places the object {gap:.2f} m from the body; the fit pulls it to the contact")
    _check_camera(case, name, warn)


def _check_camera(case, name: str, warn) -> None:
    H, W = case.image_size
    K = case.K
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not (fx > 0 and fy > 0):
        raise ValueError(f"{name}: camera K has focal lengths fx {fx:g}, fy {fy:g}; give positive pixels")
    if not (0 <= cx <= W and 0 <= cy <= H):
        raise ValueError(f"{name}: camera K's principal point ({cx:g}, {cy:g}) lies outside the image (image_size "
                         f"[H, W] = [{H}, {W}]): a camera matrix for another image size, or image_size given as "
                         f"[W, H]?")
    if abs(cx - W / 2) > LIMITS["pp_warn"] * W or abs(cy - H / 2) > LIMITS["pp_warn"] * H:
        warn(f"{name}: camera K's principal point ({cx:g}, {cy:g}) is far from the image centre ({W / 2:g}, "
             f"{H / 2:g}); check K against image_size [H, W]")

    def outside(uv):
        return (uv[:, 0] < 0) | (uv[:, 0] > W) | (uv[:, 1] < 0) | (uv[:, 1] > H)

    kp = case.keypoints_2d[case.keypoints_2d[:, 2] > 0]
    if len(kp) > 1 and np.ptp(kp[:, :2], axis=0).max() < 3:
        raise ValueError(f"{name}: the detected keypoints (keypoints_2d) lie within {np.ptp(kp[:, :2], axis=0).max():.2g} pixels "
                         f"of one another: normalised [0, 1] coordinates? give pixels of the image [H, W] = [{H}, {W}]")
    if len(kp):
        out = outside(kp).mean()
        if out > 0.5:
            raise ValueError(f"{name}: {out:.0%} of the detected keypoints_2d lie outside the image [H, W] = "
                             f"[{H}, {W}]: keypoints of another image size, or (v, u) for (u, v)?")
        if out > 0:
            warn(f"{name}: {out:.0%} of the detected keypoints_2d lie outside the image")
    if len(case.silhouette) and outside(case.silhouette).mean() > 0.5:
        raise ValueError(f"{name}: most silhouette pixels lie outside the image [H, W] = [{H}, {W}]: give (u, v) "
                         f"pixels of this image")


def judge_fit(losses: list, numbers: list, before: dict, after: dict, stop: str = "") -> tuple[str, str]:
    """(status, why) of a finished fit (module docstring), from the loss at its first and last steps, every
    fitted number, the case's measures before and after (collision_pct, gap_cm) and the optimiser's stop rule
    (volsmpl.optim: 'diverged' when a step made the case's numbers or loss non-finite)."""
    L = LIMITS
    if stop == "diverged":
        return "diverged", "a step made the fit's numbers or loss non-finite (kept: the values before it); lower --lr"
    if not all(math.isfinite(x) for x in list(losses) + list(numbers)):
        return "diverged", "a loss or a fitted number is not finite"
    if losses and losses[-1] > L["loss_growth"] * max(losses[0], 1e-12):
        return "diverged", f"the loss grew from {losses[0]:.3g} to {losses[-1]:.3g}"
    gb, ga = before.get("gap_cm", 0.0) / 100, after.get("gap_cm", 0.0) / 100
    if ga > L["lost_m"] and ga > gb + L["lost_more_m"]:
        return "object_lost", f"the object ends {ga:.2f} m from the body (start {gb:.2f} m)"
    cb, ca = before.get("collision_pct", 0.0), after.get("collision_pct", 0.0)
    if ca > cb + L["worse_collision_pct"]:
        return "worse_than_start", f"{ca:.1f} % of the object inside the body (start {cb:.1f} %)"
    if ga > gb + L["worse_gap_m"]:
        return "worse_than_start", f"the object ends {ga * 100:.1f} cm from the body (start {gb * 100:.1f} cm)"
    return "converged", ""
