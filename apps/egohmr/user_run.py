"""A user's own frame and scene: `volsmpl egohmr sample --frame F.json --scene S [--units mm] [--up z] [--spacing M]`.

The frame file and the scene are read and checked first (userframe.py; user_checks.py on an overview of the whole
scene: its size against a person's, the up axis from its floor, the camera against the image, the camera's place in
the scene); only then are the network and the guides loaded. The network regresses the pelvis; the scene's points
in the 2 m cube around it are taken at --spacing metres (user_scene.py: only that part of a scan of any size is
sampled), and the network's and the guidance's fixed budgets drawn from them; the support term (--support) reads
the world's up from 'world_to_camera', else from the scene's floor (off, with a warning, where neither gives it).
Each guide's sample is scored by the exact tests on those points (collision ratio, contact; no ground truth, so no
joint errors) and judged (status.py).

What it writes to OUT (results.json after every guide, with the warnings the checks printed):

- results.json: per guide, the frame's record with its measures, status, `body` (bodies.py: params and joints, in
  the scene file's units and axes; the camera frame where the frame file gives no 'world_to_camera'; None for a
  diverged sample), `mesh` (its file, relative to OUT) and `pelvis` (the body's pelvis, camera frame, metres: the
  regressed one, results.json's `pelvis`, where the guidance did not move it); config.spacing and
  config.cube_points say how densely the scene was taken;
- meshes/<frame>/<guide>_body.ply: each guide's recovered body in the scene file's units and axes, overlaying it;
- frame_<name>.png (unless --render 0): per guide the camera view with the input keypoints by their confidence, the
  body and the scene points near it (those inside it in red), and a side view (figures.user_figure).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch


def up_rotation(frame, up=None) -> np.ndarray:
    """camera -> a Y-up frame for the side view: R^T of 'world_to_camera'; without it, the rotation taking the
    floor's up direction `up` (camera frame) to +y by the shortest arc, else a flip of y and z (a camera looking
    ahead, y down). Shape: -> (3, 3)."""
    if frame.has_world:
        return frame.world_to_camera[:3, :3].T
    if up is None:
        return np.diag([1.0, -1.0, -1.0])
    a, b = np.asarray(up, np.float64) / np.linalg.norm(up), np.array([0.0, 1.0, 0.0])
    v, c = np.cross(a, b), float(a @ b)
    if c < -0.999:
        return np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def camera_up(frame, up=None) -> np.ndarray | None:
    """The world's up direction in the camera frame (the support term's up): the second column of the rotation of
    'world_to_camera'; without it, the floor's up direction `up` (camera frame) the scene checks found, else None."""
    if frame.has_world:
        return np.asarray(frame.world_to_camera, np.float64)[:3, 1]
    return None if up is None else np.asarray(up, np.float64) / np.linalg.norm(up)


def run_user_frame(args, ckpts: dict) -> int:
    """A user's frame file and scene scan (module docstring)."""
    import volsmpl
    from scipy.spatial import cKDTree

    from volsmpl.apps.checks import warn
    from volsmpl.apps.progress import progress
    from volsmpl.apps.table import envelope, flag_cases, print_flagged, write_results
    from volsmpl.io.provenance import machine_info
    from volsmpl.scene import crop_cube

    from .bodies import FRAME_CAMERA, FRAME_SCENE, clear_meshes, world_bodies, write_body_mesh
    from .dataset import keypoint_input
    from .evaluate import GUIDE_CUBE, GUIDE_POINTS, draw
    from .figures import user_figure
    from .metrics import inside_masks
    from .options import options_of, parse_guides, scales_of
    from .pose import pose_body_finite
    from .run import guide_volumes, run_config
    from .status import GOOD, judge, measure
    from .train import load_model
    from .user_scene import cube_points, read_user_inputs, spacing_of, take

    guides = parse_guides(args.model)
    scales = scales_of(args, guides)
    out = Path(args.out)
    warnings: list = []
    frame, scan, up = read_user_inputs(args, warnings)
    spacing = spacing_of(args)
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
    t0 = time.perf_counter()
    region = cube_points(frame, scan, centre, max(GUIDE_CUBE, net.config.scene_size), spacing, seed=args.seed)
    n_cube = len(crop_cube(region, centre, GUIDE_CUBE)) if len(region) else 0
    cond_pts = take(region, centre, net.config.scene_size, net.config.scene_points, args.seed, spacing) - centre
    guide_pts = take(region, centre, GUIDE_CUBE, GUIDE_POINTS, args.seed + 7919, spacing)
    print(f"scene: {n_cube:,} points in the {GUIDE_CUBE:g} m cube around the estimated pelvis at {100 * spacing:.3g} "
          f"cm spacing ({time.perf_counter() - t0:.1f} s)")
    d = {"c_kp": c_kp, "pelvis_hat": pelvis, "betas_hat": betas,
         "scene_cond": torch.as_tensor(cond_pts, dtype=torch.float32, device=dev)[None],
         "guide_points": torch.as_tensor(guide_pts, dtype=torch.float32, device=dev)[None]}
    up_cam = camera_up(frame, up)
    support = args.support
    if up_cam is None:
        if support != "off" and any(g != "none" for g in guides):
            warn("egohmr", f"--support {support}: the frame file gives no 'world_to_camera' and the scene shows no "
                           f"clear floor, so the up direction is unknown: the support term is off", warnings)
        support = "off"
    else:
        from .support import support_mask

        d["up"] = torch.as_tensor(up_cam, dtype=torch.float32, device=dev)[None]
        d["support"] = torch.as_tensor(support_mask(guide_pts, up_cam), device=dev)[None]
    tree = cKDTree(guide_pts)
    faces = torch.as_tensor(body.faces, device=dev)
    summary, records, samples = {}, {}, {}
    vols = guide_volumes(args, guides, ckpts, dev)
    config = {**run_config(args, guides, ckpts, scales, 1, "user", vols), "frame": str(args.frame), "scene": str(args.scene),
              "units": args.units, "up": args.up, "spacing": spacing, "cube_points": n_cube,
              "bodies": FRAME_SCENE if frame.has_world else FRAME_CAMERA}
    figure = f"frame_{frame.name}.png"
    clear_meshes(out)
    for g in progress(guides, "egohmr guides", quiet=args.quiet, unit="guide"):
        t0 = time.perf_counter()
        opts = options_of(args, scales[g])
        opts.support = support
        x, placed, _ = draw(net, body, d, vols[g], opts, seed=args.seed, quiet=args.quiet,
                            desc=f"egohmr {g}: denoising")
        secs = time.perf_counter() - t0
        with torch.no_grad():
            posed = pose_body_finite(body, betas, x, placed)
        inside = inside_masks(posed.vertices, faces, d["guide_points"])
        checks = measure(x, posed.joints[:, :24], posed.vertices, faces, kp, d["guide_points"], inside)[0]
        status, why = judge(checks)
        inside = inside[0].cpu().numpy()
        v = posed.vertices[0].cpu().numpy()
        finite = checks["finite"]                      # a diverged sample: no collision ratio, contact, body or panel
        near = tree.query(v, k=1)[0] if finite else np.full(1, np.inf)
        summary[g] = {"n_frames": 1, "collision_ratio": float(inside.mean()) if finite else float("nan"),
                      "contact_pct": 100.0 * float((near <= 0.02).any() or inside.any()), "s_per_frame": secs,
                      "scale": scales[g]}
        bodies, world = world_bodies(body, frame, betas, x, placed, args.units, args.up)
        mesh = (write_body_mesh(out, frame.name, g, world[0], body.faces, args.units, args.up)
                if bodies[0] is not None else None)
        records[g] = [{"name": frame.name, **summary[g], **checks, "status": status, "status_why": why,
                       "body": bodies[0], "mesh": mesh, "pelvis": placed[0].tolist()}]
        if finite:
            samples[g] = (v, posed.joints[0, :24].cpu().numpy(), inside)
        print(f"{g:8s} collision {summary[g]['collision_ratio']:.4f}  contact {summary[g]['contact_pct']:.0f} %  "
              f"{secs:.2f} s  {status}" + (f"  -> {mesh}" if mesh else ""))
        flagged = flag_cases(records, "name", good=GOOD)
        result = envelope("egohmr", config, summary, None, records, machine_info(args.device), {},
                          flagged=flagged, warnings=warnings, pelvis=centre.tolist())
        write_results(out, result)   # after every guide: a run stopped early keeps the finished ones
    if args.render and samples:
        user_figure(out / figure, frame, samples, body.faces, guide_pts, up_rotation(frame, up))
        result["figures"] = {frame.name: figure}
        write_results(out, result)
    print_flagged(flagged)
    print(f"wrote {out / 'results.json'}")
    return 0


__all__ = ["run_user_frame", "up_rotation", "camera_up"]
