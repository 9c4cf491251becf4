"""`volsmpl hoi make-case`: a case file (apps/hoi/case.py) from what a user has, without code.

    volsmpl hoi make-case --object mug.obj --units mm --category cup --body pose.json --image-size 480,640 \\
        --focal 600 --mask mask.png --contact right_hand:handle --out my_case.json
    volsmpl hoi fit --case my_case.json --model volsmpl

What it builds, from each input:

- the object: `--object` (any mesh file trimesh reads; `--units` m, cm or mm), stored by its path relative to the
  case file (nothing is copied). Its real size: `--category` one of the templates (volsmpl.scene.objects: the
  category's mean size is the scale prior), and/or `--size-m` (its largest bounding-box extent, metres: the scale
  prior; with it the category may be any name, e.g. teddy, tray).
- the human: `--body` (JSON: betas [10] (optional, zeros), global_orient [3], body_pose [69] axis-angle, transl
  [3], the body in the camera frame, metres) is placed as the database places its people: the body in its own frame
  (the body model's output with global_orient and transl 0: Y up, facing +Z), moved into the camera frame by
  init.human = (scale 1, R, t), the rotation of global_orient about the root joint and transl. Without
  `--body` the default body stands in the 'arms_down' pose, placed on `--keypoints` by PnP (OpenCV's solvePnP on
  the keypoints detected, confidence > 0; at least 6): the joint stage keeps the pose, so give `--body` for a close fit.
- keypoints_2d: `--keypoints` (JSON: 24 x [u, v, confidence] in SMPL joint order, pixels), or the body's 24 joints
  projected with the camera, confidence 1 (0 for a joint behind the camera or outside the image).
- the camera: `--image-size H,W` and `--focal F` (pixels; the principal point at the image centre ((W - 1) / 2,
  (H - 1) / 2) unless `--principal cx,cy`), or `--K` (JSON: the 3 x 3 matrix, or {"K": ..., "image_size": [H, W]}).
  A mask gives the image size too.
- the object's first-stage placement: `--object-pose` (JSON: rotation 3 x 3 and translation [3], camera frame,
  metres, of the mesh in metres; optional scale, default the scale prior). Without it, from `--mask`, PHOSA-style:
  upright and facing the camera (the template frame's +Y up in the image, +Z towards the camera: rotation
  diag(1, -1, -1)), at the scale prior, at the depth where the diagonal of its bounding box's width and height
  spans the diagonal of the mask's bounding box (z = sqrt((fx w)^2 + (fy h)^2) / sqrt(w_px^2 + h_px^2)), its
  bounding-box centre on the ray through the mask's centroid.
- the silhouette: up to 2,000 pixels of `--mask` (any image OpenCV reads; object pixels: those above half the
  format's maximum in the grey value, the largest colour channel, or the alpha channel when it is not all opaque),
  or, without a mask, the pixels of the object's projection as placed (the case's meta says so).
- contacts: `--contact PART:REGION`, repeatable; PART one of the partition's parts; REGION one of
    any                the whole mesh
    NAME               a region of the category's template (e.g. cup: handle, grasp, bottom), moved onto the mesh:
                       the template at its mean size stretched onto the mesh's bounding box (the mesh in the
                       template's frame, volsmpl.scene.objects: Y up, front +Z), a triangle of the mesh is in the
                       region when the template triangle nearest its centre is and lies within a tenth of the
                       mesh's largest extent
    faces=FILE         triangle ids of the mesh (0-based, as trimesh reads the file: a quad is two triangles)
    vertices=FILE      vertex ids of the mesh (0-based); the region is the triangles with all three selected
    auto               the object's surface nearest the part at the first-stage placement: the triangles within
                       AUTO_BAND (2 cm) of the nearest, by their distance to the part's vertices
  FILE: one integer per line ('#' comments) or a JSON list. The case stores each region by name as triangle ids
  (NAME, the file's stem, or near_PART for auto).

Every error a user can cause is a ValueError of one line naming the problem and the fix, raised before the work.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .case_geometry import (
    MIN_Z,
    auto_region,
    place_from_mask,
    project,
    raster_pixels,
    transfer_region,
)
from .case_inputs import (
    existing_file,
    json_object,
    numbers_option,
    read_body,
    read_camera,
    read_keypoints,
    read_mask,
    read_object_pose,
    read_selection,
)

__all__ = ["add_arguments", "run"]



def add_arguments(p) -> None:
    """The options of `volsmpl hoi make-case` on the hoi parser (its --out is the case file to write)."""
    g = p.add_argument_group("make-case (a case file from your own data; --out CASE.json)")
    g.add_argument("--object", default=None, help="make-case: the object's mesh file (any format trimesh reads)")
    g.add_argument("--units", default="m", help="make-case: units of the mesh file: m, cm or mm (default m)")
    g.add_argument("--category", default=None, help="make-case: the object's category: a template's (scale prior) "
                                                    "or any name with --size-m")
    g.add_argument("--size-m", default=None, help="make-case: the object's largest extent in metres (the scale prior)")
    g.add_argument("--body", default=None, help="make-case: JSON of betas, global_orient, body_pose, transl (camera "
                                                "frame, metres)")
    g.add_argument("--keypoints", default=None, help="make-case: JSON of 24 x [u, v, confidence] (SMPL order, pixels)")
    g.add_argument("--image-size", default=None, help="make-case: H,W in pixels")
    g.add_argument("--focal", default=None, help="make-case: focal length in pixels")
    g.add_argument("--principal", default=None, help="make-case: cx,cy in pixels (default the image centre)")
    g.add_argument("--K", default=None, help="make-case: JSON of the 3 x 3 camera matrix (or {\"K\", \"image_size\"})")
    g.add_argument("--object-pose", default=None, help="make-case: JSON of the object's rotation (3 x 3), translation "
                                                       "(3) and optional scale, camera frame, metres")
    g.add_argument("--mask", default=None, help="make-case: the object's mask image (the object: pixels above half "
                                                "the maximum value; an alpha channel that is not all opaque)")
    g.add_argument("--contact", action="append", default=None,
                   help="make-case: PART:REGION, repeatable; REGION: any, auto, a template region (handle...), "
                        "faces=FILE (triangle ids) or vertices=FILE (vertex ids); FILE: one 0-based id per line or a "
                        "JSON list")


def _contacts(specs, category: str) -> list:
    """--contact PART:REGION -> [(part, kind, value)], kind 'any' | 'auto' | 'named' | 'faces' | 'vertices'
    (value: the region's name or the selection's path). Checks the syntax, the files and the template's regions."""
    from volsmpl.scene.objects import CATEGORIES, REGIONS

    if not specs:
        raise ValueError("give at least one --contact PART:REGION (e.g. right_hand:auto): the joint stage pulls the "
                         "part onto the region")
    out = []
    for spec in specs:
        part, sep, region = str(spec).partition(":")
        if not sep or not part or not region:
            raise ValueError(f"--contact {spec!r}: give PART:REGION, e.g. right_hand:handle, right_hand:auto or "
                             f"right_hand:faces=sel.txt")
        if region in ("any", "auto"):
            out.append((part, region, region))
        elif region.startswith(("faces=", "vertices=")):
            kind, _, path = region.partition("=")
            existing_file(path, f"--contact {part}:{kind}=")
            out.append((part, kind, path))
        else:
            known = REGIONS.get(category, {}) if category in CATEGORIES else {}
            if region not in known:
                have = (f"the {category} template's regions: {', '.join(known)}" if known else
                        f"{category!r} is not a template, it has no named regions")
                raise ValueError(f"--contact {spec}: no region {region!r} ({have}); give one of those, any, auto, "
                                 f"faces=FILE or vertices=FILE")
            out.append((part, "named", region))
    return out


def _check_object_options(args):
    """The object's options: (mesh path, units, category, size_m or None)."""
    from volsmpl.scene.objects import CATEGORIES

    if args.object is None:
        raise ValueError("give the object's mesh file: --object FILE (obj, ply, stl, glb, off)")
    path = existing_file(args.object, "--object")
    if args.units not in ("m", "cm", "mm"):
        raise ValueError(f"--units {args.units!r}: give the mesh file's units, m, cm or mm")
    size = None
    if args.size_m is not None:
        size = numbers_option(args.size_m, "--size-m", 1, what=" (metres)")[0]
        if size <= 0:
            raise ValueError(f"--size-m {args.size_m}: give the object's largest extent in metres, a finite number > 0")
    category = (args.category or "").strip()
    if not category:
        if size is None:
            raise ValueError(f"give the object's --category (one of {', '.join(CATEGORIES)}) or its --size-m "
                             f"(largest extent, metres) with a --category name")
        raise ValueError("give a --category name with --size-m (any word, e.g. teddy)")
    if category not in CATEGORIES and size is None:
        raise ValueError(f"--category {category!r} is not a template ({', '.join(CATEGORIES)}): give its size too, "
                         f"--size-m (its largest extent in metres)")
    return path, args.units, category, size


def run(args) -> int:
    """`volsmpl hoi make-case` (module docstring): check every input, build the case, write --out, print one line."""
    import volsmpl
    from volsmpl.apps.checks import safe_name
    from volsmpl.body.fingerprint import fingerprint_of_model

    from .case import HoiCase, save_case

    x = _read_inputs(args)  # every check that needs no body
    body = volsmpl.create_body()
    partition = volsmpl.Partition(body)
    part_names = list(partition.table.part_names)
    for part, _, _ in x.contacts:
        if part not in part_names:
            raise ValueError(f"--contact {part}:...: {part!r} is not a body part; parts: {', '.join(part_names)}")
    params, human, kp, verts_cam = _human(x, body)
    obj, sil, n_sil = _object(args, x)
    labels = partition.vertex_labels.cpu().numpy()
    parts = {p: verts_cam[labels == part_names.index(p)] for p, kind, _ in x.contacts if kind == "auto"}
    regions, pairs, notes = _regions(x, obj, parts)
    out = Path(args.out)
    case = HoiCase(
        name=safe_name(out.stem), category=x.category, body=params, fingerprint=fingerprint_of_model(body), K=x.K,
        image_size=x.size, keypoints_2d=kp, silhouette=sil, contacts=pairs, init={"human": human, "object": obj},
        mesh_path=_relative(x.obj_path, out.parent), units=x.units, size_m=x.size_m, regions=regions,
        meta=_meta(args, n_sil, len(sil), x.keypoints is None))
    save_case(case, out)
    print(f"wrote {out}: {x.category} {x.obj_path.name} ({len(x.mesh.faces)} triangles, "
          f"{x.scale_prior * float(np.max(x.mesh.extents)):.3g} m at the scale prior), {case.meta['body']}, "
          f"{int((kp[:, 2] > 0).sum())}/24 keypoints, {len(sil)} silhouette pixels, object "
          f"{case.meta['object_placement']}, contacts {', '.join(notes)}")
    return 0


def _read_inputs(args):
    """Every input read and checked before the work (the body, the placements, the regions): a namespace of the
    object's path, mesh (metres), units, category, size_m and scale prior, the contacts, the selections' triangle
    ids, the body file's arrays, the keypoints, the mask, the camera K and the image size."""
    from types import SimpleNamespace

    from .case import object_size_m, read_object_mesh

    if Path(args.out).suffix.lower() != ".json":
        raise ValueError(f"--out {args.out}: make-case writes a case file; give its path ending in .json")
    obj_path, units, category, size_m = _check_object_options(args)
    contacts = _contacts(args.contact, category)
    if args.body is None and args.keypoints is None:
        raise ValueError("give the person: --body FILE (pose in the camera frame) and/or --keypoints FILE (24 x "
                         "[u, v, confidence])")
    body = read_body(args.body) if args.body is not None else None
    keypoints = read_keypoints(args.keypoints) if args.keypoints is not None else None
    mask = read_mask(args.mask) if args.mask is not None else None
    K, size = read_camera(args, None if mask is None else mask.shape)
    if args.object_pose is None and mask is None:
        raise ValueError("give the object's first-stage placement: --object-pose FILE and/or --mask FILE")
    if args.object_pose is not None:
        json_object(args.object_pose, "--object-pose", "the object pose file")  # missing or not JSON: now
    mesh = read_object_mesh(obj_path, units, f"--object {obj_path}")
    selections = {}
    for part, kind, value in contacts:
        if kind in ("faces", "vertices"):
            ids = read_selection(value, "triangle" if kind == "faces" else "vertex", f"--contact {part}:{kind}=")
            n = len(mesh.faces) if kind == "faces" else len(mesh.vertices)
            if ids.max() >= n:
                raise ValueError(f"--contact {part}:{kind}={value}: id {int(ids.max())} but the mesh has {n} "
                                 f"{'triangles' if kind == 'faces' else 'vertices'} (0-based ids 0..{n - 1})")
            faces = ids if kind == "faces" else np.nonzero(np.isin(np.asarray(mesh.faces), ids).all(axis=1))[0]
            if len(faces) == 0:
                raise ValueError(f"--contact {part}:vertices={value}: no triangle has all three vertices selected; "
                                 f"select the vertices of whole triangles")
            selections[value, kind] = faces
    return SimpleNamespace(obj_path=obj_path, mesh=mesh, units=units, category=category, size_m=size_m,
                           scale_prior=object_size_m(category, size_m) / float(np.max(mesh.extents)),
                           contacts=contacts, selections=selections, body=body, keypoints=keypoints, mask=mask,
                           K=K, size=size)


def _human(x, body):
    """The body in its own frame (global_orient and transl 0: Y up, facing +Z; float32 tensors of the case), its
    placement init.human (from the body file, or PnP on the keypoints), the keypoints (given, or the joints
    projected) and the posed vertices in the camera frame (V, 3), as the database's cases (apps/hoi/database.py)."""
    import torch
    from volsmpl.body.poses import named_pose

    b = x.body
    pose = named_pose("arms_down")[0].numpy() if b is None else b["body_pose"]
    params = {k: torch.as_tensor(np.asarray(v, dtype=np.float64), dtype=torch.float32)
              for k, v in {"betas": np.zeros(10) if b is None else b["betas"], "global_orient": np.zeros(3),
                           "body_pose": pose, "transl": np.zeros(3)}.items()}
    with torch.no_grad():
        posed = body(**{k: v[None] for k, v in params.items()})
    joints = posed.joints[0, :24].double().numpy()
    human = _pnp(joints, x.keypoints, x.K) if b is None else _placement(b, joints[0])
    kp = x.keypoints
    if kp is None:
        uv, z = project(x.K, human.apply(joints))
        H, W = x.size
        inside = (z > MIN_Z) & (uv[:, 0] >= 0) & (uv[:, 0] <= W) & (uv[:, 1] >= 0) & (uv[:, 1] <= H)
        kp = np.concatenate([np.where(z[:, None] > MIN_Z, uv, 0.0), inside[:, None].astype(np.float64)], axis=1)
    return params, human, kp, human.apply(posed.vertices[0].double().numpy())


def _object(args, x):
    """The object's first-stage similarity (--object-pose, or from the mask), and its silhouette: up to SIL_MAX
    pixels of the mask, or of its projection as placed (N, 2), with the count they were drawn from."""
    from .database import SIL_MAX

    mesh = x.mesh
    obj = (read_object_pose(args.object_pose, x.scale_prior) if args.object_pose is not None
           else place_from_mask(x.K, x.mask, mesh, x.scale_prior))
    if obj.apply(np.asarray(mesh.bounds).mean(axis=0)[None])[0, 2] <= MIN_Z:
        raise ValueError("the object's placement puts it behind the camera (z <= 0.05 m): check --object-pose's "
                         "translation (camera frame: z forward, metres)")
    if x.mask is not None:
        v, u = np.nonzero(x.mask)
        sil = np.stack([u, v], axis=1).astype(np.float64)
    else:
        sil = raster_pixels(x.K, x.size, obj.apply(mesh.vertices), np.asarray(mesh.faces))
        if len(sil) == 0:
            raise ValueError("the object as placed by --object-pose projects outside the image: check its "
                             "translation, the camera and --image-size")
    n = len(sil)
    if n > SIL_MAX:  # as the database: an even random sample
        sil = sil[np.sort(np.random.default_rng(0).choice(n, SIL_MAX, replace=False))]
    return obj, sil, n


def _regions(x, obj, parts: dict):
    """The contact pairs [(part, region name)], the regions {name: triangle ids} and one note per pair. parts: the
    camera-frame vertices of each part whose region is `auto`."""
    from .case import ANY_REGION

    tris_cam = obj.apply(np.asarray(x.mesh.vertices))[np.asarray(x.mesh.faces)]
    regions, pairs, notes = {}, [], []
    for part, kind, value in x.contacts:
        if kind == "any":
            pairs.append((part, ANY_REGION))
            notes.append(f"{part}:any")
            continue
        if kind == "auto":
            name, ids = f"near_{part}", auto_region(tris_cam, parts[part])
        elif kind == "named":
            name, ids = value, transfer_region(x.mesh, x.category, value)
            if len(ids) == 0:
                raise ValueError(f"--contact {part}:{value}: no triangle of {x.obj_path} lies near the {x.category} "
                                 f"template's {value!r} (is the mesh in the template's frame: Y up, front +Z?); "
                                 f"select it yourself: {part}:faces=FILE, or {part}:auto")
        else:
            name, ids = Path(value).stem or kind, x.selections[value, kind]
        base, k = name, 2
        while name in regions and not np.array_equal(regions[name], ids):  # another selection of the same name
            name, k = f"{base}_{k}", k + 1
        regions[name] = np.asarray(ids, dtype=np.int64)
        pairs.append((part, name))
        notes.append(f"{part}:{name} ({len(ids)} triangles)")
    return regions, pairs, notes


def _placement(body_in: dict, root: np.ndarray):
    """The similarity that moves the body of `body_in`'s pose with global_orient and transl 0 onto it: the body model
    turns the body about its root joint (`root`, (3,)) by global_orient and adds transl, so x_cam = R x + (root -
    R root + transl)."""
    from scipy.spatial.transform import Rotation

    from .case import Similarity

    R = Rotation.from_rotvec(body_in["global_orient"]).as_matrix()
    return Similarity(1.0, R, root - R @ root + body_in["transl"])


def _pnp(joints: np.ndarray, kp: np.ndarray, K: np.ndarray):
    """The human's placement (scale 1) whose joints project onto the detected keypoints (OpenCV solvePnP)."""
    import cv2

    from .case import Similarity

    seen = kp[:, 2] > 0
    if seen.sum() < 6:
        raise ValueError(f"--keypoints: {int(seen.sum())} joints detected (confidence > 0); placing the default "
                         f"body needs 6 or more, or give --body")
    ok, rvec, tvec = cv2.solvePnP(joints[seen].astype(np.float64), kp[seen, :2].astype(np.float64), K, None,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok or not np.isfinite(tvec).all() or float(tvec[2, 0]) <= MIN_Z:
        raise ValueError("--keypoints: the default body cannot be placed on these keypoints (PnP failed or put it "
                         "behind the camera); give --body")
    return Similarity(1.0, cv2.Rodrigues(rvec)[0], tvec[:, 0])


def _relative(path: Path, folder: Path) -> str:
    """`path` relative to `folder` (the case file's), or absolute where no relative path exists."""
    import os

    try:
        return Path(os.path.relpath(path.resolve(), folder.resolve())).as_posix()
    except ValueError:  # another drive
        return path.resolve().as_posix()


def _meta(args, n_mask: int, n_sil: int, projected: bool) -> dict:
    """The case's notes: where each part of it came from."""
    body = f"body from {Path(args.body).name}" if args.body else "the default body ('arms_down') placed by PnP"
    return {"made_by": "volsmpl hoi make-case", "body": body,
            "keypoints": "projected from the body (confidence 1 in the image, 0 outside)" if projected
            else f"from {Path(args.keypoints).name}",
            "silhouette": (f"{n_sil} of the {n_mask} pixels of {Path(args.mask).name}" if args.mask else
                           f"the projection of the object as placed (no mask given): {n_sil} of {n_mask} pixels"),
            "object_placement": (f"from {Path(args.object_pose).name}" if args.object_pose else
                                 "from the mask (upright, depth from its size, centre on the mask's centroid)")}
