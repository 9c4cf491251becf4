"""A user's own frame and scene: `volsmpl egohmr sample --frame F.json --scene S [--units mm] [--up z]`.

The frame file and the scene are read and checked first (userframe.py, user_checks.py: the scene's size against a
person's, the up axis from its floor, the camera against the image, the camera's place in the scene); only then are
the network and the guides loaded. Each guide's sample is scored by the exact tests on the scan's points (collision
ratio, contact; no ground truth, so no joint errors) and judged (status.py); results.json is written after every
guide, with the warnings the checks printed.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from .evaluate import GUIDE_CUBE, GUIDE_POINTS


def read_user_inputs(args, warnings: list):
    """The checked frame and its scene's points in the camera frame (metres): (UserFrame, (N, 3))."""
    from volsmpl.scene.scan import read_scan, to_y_up

    from .user_checks import check_camera, check_camera_place, check_extent, check_up
    from .userframe import camera_points, load_user_frame

    frame = load_user_frame(args.frame)
    where = f"--frame {args.frame}"
    check_camera(frame, where, warnings)
    raw = read_scan(args.scene, args.units, n_surface=1_000_000, seed=args.seed)
    check_extent(raw, args.units, args.scene, warnings)
    check_up(raw, args.up, frame.has_world, args.scene, warnings, seed=args.seed)
    world = to_y_up(raw, args.up)
    check_camera_place(frame, world, where, warnings)
    return frame, camera_points(frame, world)


def _crop(points: np.ndarray, centre: np.ndarray, n: int, seed: int) -> np.ndarray:
    from volsmpl.scene import crop_cube, subsample

    from .data import MIN_SCENE_POINTS

    c = points[crop_cube(points, centre, GUIDE_CUBE)]
    if len(c) < MIN_SCENE_POINTS:
        raise ValueError(f"the scene has {len(c)} points in the {GUIDE_CUBE:g} m cube around the estimated pelvis "
                         f"{np.round(centre, 2).tolist()} (camera frame, m): check --units and 'world_to_camera', or "
                         f"give a denser scan")
    return c[subsample(c, n, seed=seed)]


def run_user_frame(args, ckpts: dict) -> int:
    """A user's frame file and scene scan (module docstring)."""
    import volsmpl
    from scipy.spatial import cKDTree

    from volsmpl.apps.checks import warn
    from volsmpl.apps.table import envelope, flag_cases, print_flagged, write_results
    from volsmpl.io.provenance import machine_info
    from volsmpl.viz.render import grid, render_camera_view, save_png

    from .dataset import keypoint_input
    from .evaluate import draw
    from .figures import camera_of
    from .metrics import inside_masks
    from .options import options_of, parse_guides, scales_of
    from .pose import pose_body_finite
    from .run import guide_volumes, run_config
    from .status import GOOD, judge, measure
    from .train import load_model

    guides = parse_guides(args.model)
    scales = scales_of(args, guides)
    out = Path(args.out)
    warnings: list = []
    frame, scan = read_user_inputs(args, warnings)
    dev = torch.device(args.device)
    body = volsmpl.create_body().to(dev)
    net, _ = load_model(args.checkpoint, body)
    net.to(dev)
    kp = torch.as_tensor(keypoint_input(frame), device=dev)[None]
    with torch.no_grad():
        c_kp = net.keypoints(kp)
        pelvis, betas, _ = net.regress(c_kp)
    centre = pelvis[0].cpu().numpy().astype(np.float64)
    if centre[2] <= 0:
        warn("egohmr", f"--frame {args.frame}: the estimated pelvis lies behind the camera (z = {centre[2]:.2f} m): "
                       f"check the keypoints and 'K'", warnings)
    cond_pts = _crop(scan, centre, net.config.scene_points, args.seed) - centre
    guide_pts = _crop(scan, centre, GUIDE_POINTS, args.seed + 7919)
    d = {"c_kp": c_kp, "pelvis_hat": pelvis, "betas_hat": betas,
         "scene_cond": torch.as_tensor(cond_pts, dtype=torch.float32, device=dev)[None],
         "guide_points": torch.as_tensor(guide_pts, dtype=torch.float32, device=dev)[None]}
    tree = cKDTree(guide_pts)
    faces = torch.as_tensor(body.faces, device=dev)
    summary, records, panels = {}, {}, []
    cam = camera_of(frame.K, frame.image_size)
    vols = guide_volumes(args, guides, ckpts, dev)
    config = {**run_config(args, guides, ckpts, scales, 1, "user"), "frame": str(args.frame), "scene": str(args.scene),
              "units": args.units, "up": args.up}
    figure = f"frame_{frame.name}.png"
    for g in guides:
        t0 = time.perf_counter()
        x, _ = draw(net, body, d, vols[g], options_of(args, scales[g]), seed=args.seed)
        secs = time.perf_counter() - t0
        with torch.no_grad():
            posed = pose_body_finite(body, betas, x, pelvis)
        inside = inside_masks(posed.vertices, faces, d["guide_points"])
        checks = measure(x, posed.joints[:, :24], posed.vertices, faces, kp, d["guide_points"], inside)[0]
        status, why = judge(checks)
        inside = inside[0].cpu().numpy()
        v = posed.vertices[0].cpu().numpy()
        finite = checks["finite"]                      # a diverged sample: no collision ratio, contact or panel
        near = tree.query(v, k=1)[0] if finite else np.full(1, np.inf)
        summary[g] = {"n_frames": 1, "collision_ratio": float(inside.mean()) if finite else float("nan"),
                      "contact_pct": 100.0 * float((near <= 0.02).any() or inside.any()), "s_per_frame": secs,
                      "scale": scales[g]}
        records[g] = [{"name": frame.name, **summary[g], **checks, "status": status, "status_why": why}]
        if args.render and finite:
            red = np.tile([[0.9, 0.1, 0.1]], (int(inside.sum()), 1))
            grey = np.tile([[0.6, 0.6, 0.6]], (len(guide_pts) - int(inside.sum()), 1))
            img = render_camera_view([(v, body.faces, (0.35, 0.55, 0.9))], cam,
                                     points=np.concatenate([guide_pts[inside], guide_pts[~inside]]),
                                     point_colors=np.concatenate([red, grey]), point_radius=1)
            panels.append((img, f"{g}: {int(inside.sum())} scene points inside"))
        print(f"{g:8s} collision {summary[g]['collision_ratio']:.4f}  contact {summary[g]['contact_pct']:.0f} %  "
              f"{secs:.2f} s  {status}")
        flagged = flag_cases(records, "name", good=GOOD)
        result = envelope("egohmr", config, summary, None, records, machine_info(args.device), {},
                          flagged=flagged, warnings=warnings, pelvis=centre.tolist())
        write_results(out, result)   # after every guide: a run stopped early keeps the finished ones
    if panels:
        save_png(out / figure, grid([p[0] for p in panels], [p[1] for p in panels], cols=2))
        result["figures"] = {frame.name: figure}
        write_results(out, result)
    print_flagged(flagged)
    print(f"wrote {out / 'results.json'}")
    return 0


__all__ = ["read_user_inputs", "run_user_frame"]
