"""The human–object case: what the joint optimisation reads, as a documented JSON file.

A case is one image of a person with an object, after the first (independent) stage: the body's pose and shape
are known in its own frame, the object's mesh and category are known, and each is placed in the camera frame by a
similarity (scale, rotation, translation) that the first stage got only up to the depth–scale ambiguity of one
view. The joint stage (apps/hoi/fit.py) refines the two similarities.

Frames: the camera frame is the world (OpenCV axes: x right, y down, z forward; pixels by the intrinsics K).
The body frame is the body model's output (`body(betas, global_orient, body_pose, transl)`, metres). The object
frame is the template's (volsmpl.scene.objects: resting on y = 0, front +Z) or the mesh file's own, in metres after
`units`. A similarity maps a frame into the camera frame: x_cam = scale * R @ x + t.

JSON (format 'volsmpl-hoi-case', version 2; version-1 files read as they are):

    {"format": "volsmpl-hoi-case", "version": 2, "name": "cup_0007",
     "body": {"fingerprint": "dc5681ccaf7defe3", "betas": [10], "global_orient": [3], "body_pose": [69], "transl": [3]},
     "object": {"category": "cup", "template_seed": 7}            # a template of volsmpl.scene.objects, or
               {"category": "cup", "mesh": "mug.obj", "units": "mm",  # any mesh file trimesh reads (relative to the JSON)
                "size_m": 0.12,                                    # optional: its real largest extent (metres)
                "regions": {"handle": [12, 13, ...]}},             # optional: named regions, triangle ids of the file
     "camera": {"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "image_size": [H, W]},
     "keypoints_2d": [[u, v, confidence] x 24],                    # the body's 24 joints, SMPL order; confidence in [0, 1], 0: unseen
     "silhouette": [[u, v], ...],                                  # pixels of the object's mask (a sample of them)
     "contacts": [["right_hand", "grasp"], ...],                   # (body part, object region); region 'any': the whole mesh
     "init": {"human": SIM, "object": SIM},                        # first-stage estimates
     "truth": {"human": SIM, "object": SIM},                       # optional: the ground truth of a generated case
     "image": "cup_0007.png",                                      # optional: the rendered image, for figures
     "meta": {"kind": "hold_cup"}}                                 # optional: the producer's notes
    SIM = {"scale": s, "rotation": [[3 x 3]], "translation": [3]}

Body parts are the partition's (volsmpl.Partition(body).table.part_names); regions are the template's
(`ObjectTemplate.regions`), a mesh file's own `regions`, or 'any'.

Version 2 adds to a mesh file's object: `size_m`, the object's real largest bounding-box extent in metres (it sets
the scale prior in place of the category's mean size, volsmpl.scene.objects.SIZE_PRIOR), which lets the category be
any name (teddy, tray), not only a template's; and `regions`, {name: [triangle ids]} (0-based, the triangles as
trimesh reads the file with process=False: a quad is two triangles). A case that uses neither is written as
version 1 (`case_to_dict`), byte for byte as before. `volsmpl hoi make-case` (apps/hoi/make_case.py) writes a case
from a user's mesh, body, camera, mask and contacts.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

FORMAT, VERSION = "volsmpl-hoi-case", 2
READS = (1, 2)  # the versions this volsmpl reads
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
ANY_REGION = "any"


@dataclass
class Similarity:
    """x_cam = scale * rotation @ x + translation."""

    scale: float
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Shape: (..., 3) -> (..., 3)."""
        return self.scale * np.asarray(x) @ self.rotation.T + self.translation

    def to_dict(self) -> dict:
        return {"scale": float(self.scale), "rotation": np.asarray(self.rotation).tolist(),
                "translation": np.asarray(self.translation).tolist()}

    @classmethod
    def from_dict(cls, d, where: str) -> "Similarity":
        if not isinstance(d, dict) or not {"scale", "rotation", "translation"} <= set(d):
            raise ValueError(f"{where} must be an object with 'scale', 'rotation' (3 x 3) and 'translation' (3)")
        s = float(d["scale"])
        R = np.asarray(d["rotation"], dtype=np.float64)
        t = np.asarray(d["translation"], dtype=np.float64)
        if R.shape != (3, 3) or t.shape != (3,):
            raise ValueError(f"{where}: rotation must be 3 x 3 and translation 3 numbers, got {R.shape} and {t.shape}")
        if not (np.isfinite(s) and s > 0 and np.isfinite(R).all() and np.isfinite(t).all()):
            raise ValueError(f"{where}: scale must be > 0 and every number finite")
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-4 or np.linalg.det(R) < 0:
            raise ValueError(f"{where}: rotation is not a rotation matrix (R^T R = I, det 1)")
        return cls(s, R, t)


@dataclass
class HoiCase:
    """One case (module docstring). body: tensors betas (10,), global_orient (3,), body_pose (69,), transl (3,)."""

    name: str
    category: str
    body: dict
    fingerprint: str
    K: np.ndarray
    image_size: tuple
    keypoints_2d: np.ndarray  # (24, 3)
    silhouette: np.ndarray  # (S, 2)
    contacts: list
    init: dict  # {'human': Similarity, 'object': Similarity}
    truth: dict | None = None
    template_seed: int | None = None
    mesh_path: str | None = None
    units: str = "m"
    size_m: float | None = None  # the object's real largest extent (metres): sets the scale prior (a mesh file only)
    regions: dict = field(default_factory=dict)  # {name: triangle ids (R,) int64} of a mesh file's own regions
    image: str | None = None
    meta: dict = field(default_factory=dict)  # free-form notes of the producer (e.g. the database's kind), kept in the JSON
    source: Path | None = field(default=None, repr=False)  # folder of the JSON (relative paths)


def _array(d: dict, key: str, shape, where: str) -> np.ndarray:
    if key not in d:
        raise ValueError(f"{where}: '{key}' is missing")
    a = np.asarray(d[key], dtype=np.float64)
    if a.shape != shape and not (shape[0] is None and a.ndim == len(shape) and a.shape[1:] == shape[1:]):
        raise ValueError(f"{where}: '{key}' must have shape {shape}, got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{where}: '{key}' contains NaN or Inf")
    return a


def case_from_dict(d: dict, source: Path | None = None) -> HoiCase:
    """Validate and build a case from its JSON object (clear ValueError naming the field on any problem)."""
    from volsmpl.scene.objects import CATEGORIES

    where = f"case {d.get('name', '?')!r}" if isinstance(d, dict) else "case"
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise ValueError(f"{where} is not a human-object case (expected \"format\": \"{FORMAT}\")")
    if d.get("version") not in READS:
        raise ValueError(f"{where} has version {d.get('version')!r}; this volsmpl reads versions "
                         f"{', '.join(map(str, READS))}")
    b, o, cam = d.get("body"), d.get("object"), d.get("camera")
    if not isinstance(b, dict) or not isinstance(o, dict) or not isinstance(cam, dict):
        raise ValueError(f"{where}: 'body', 'object' and 'camera' must be objects")
    body = {k: torch.as_tensor(_array(b, k, (n,), f"{where} body"), dtype=torch.float32)
            for k, n in (("betas", 10), ("global_orient", 3), ("body_pose", 69), ("transl", 3))}
    if ("mesh" in o) == ("template_seed" in o):
        raise ValueError(f"{where}: 'object' needs exactly one of 'mesh' (a file) or 'template_seed' (a template)")
    size_m = _size(o, where)
    category = o.get("category")
    if category not in CATEGORIES and not ("mesh" in o and size_m is not None and isinstance(category, str)
                                           and category.strip()):
        raise ValueError(f"{where}: unknown object category {category!r}; known: {', '.join(CATEGORIES)} (another "
                         f"name needs a mesh file and its size: \"size_m\" in the object)")
    regions = _regions(o, where)
    units = o.get("units", "m")
    if units not in UNITS:
        raise ValueError(f"{where}: object units {units!r} unknown; use one of {', '.join(UNITS)}")
    K = _array(cam, "K", (3, 3), f"{where} camera")
    size = tuple(int(x) for x in cam.get("image_size", ()))
    if len(size) != 2 or min(size) < 1:
        raise ValueError(f"{where}: camera 'image_size' must be [H, W], got {cam.get('image_size')!r}")
    contacts = d.get("contacts", [])
    if not isinstance(contacts, list) or any(not (isinstance(c, (list, tuple)) and len(c) == 2) for c in contacts):
        raise ValueError(f"{where}: 'contacts' must be a list of [body part, object region] pairs")
    init = d.get("init")
    if not isinstance(init, dict):
        raise ValueError(f"{where}: 'init' (the first-stage estimates of 'human' and 'object') is missing")
    kp = _array(d, "keypoints_2d", (24, 3), where)
    if ((kp[:, 2] < 0) | (kp[:, 2] > 1)).any():  # a weight: -1 for 'missing' flipped the term's sign
        raise ValueError(f"{where}: 'keypoints_2d' confidences (third column) must lie in [0, 1], got "
                         f"{kp[:, 2].min():g}..{kp[:, 2].max():g}; give 0 for joints not detected")
    truth = d.get("truth")
    return HoiCase(
        name=str(d.get("name", "case")), category=category, body=body, fingerprint=str(b.get("fingerprint", "")),
        K=K, image_size=size, keypoints_2d=kp,
        silhouette=_array(d, "silhouette", (None, 2), where), contacts=[tuple(map(str, c)) for c in contacts],
        init={k: Similarity.from_dict(init.get(k), f"{where} init.{k}") for k in ("human", "object")},
        truth=None if truth is None else {k: Similarity.from_dict(truth.get(k), f"{where} truth.{k}")
                                          for k in ("human", "object")},
        template_seed=None if "template_seed" in o and o["template_seed"] is None else o.get("template_seed"),
        mesh_path=o.get("mesh"), units=units, size_m=size_m, regions=regions, image=d.get("image"),
        meta=dict(d.get("meta") or {}), source=source)


def _size(o: dict, where: str) -> float | None:
    """The object's optional 'size_m' (a mesh file only): a finite length > 0, or None."""
    if o.get("size_m") is None:
        return None
    if "mesh" not in o:
        raise ValueError(f"{where}: 'size_m' goes with a mesh file; a template's size is its own (drop 'size_m')")
    try:
        size = float(o["size_m"])
    except (TypeError, ValueError):
        size = float("nan")
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"{where}: object 'size_m' {o['size_m']!r} must be a finite length > 0 (metres, the "
                         f"object's largest extent)")
    return size


def _regions(o: dict, where: str) -> dict:
    """The object's optional 'regions' (a mesh file only): {name: sorted unique triangle ids (R,) int64}."""
    regions = o.get("regions") or {}
    if regions and "mesh" not in o:
        raise ValueError(f"{where}: 'regions' goes with a mesh file; a template has its own (drop 'regions')")
    try:
        items = list(regions.items())
    except AttributeError:
        raise ValueError(f"{where}: object 'regions' must be an object {{name: [triangle ids]}}") from None
    out = {}
    for name, ids in items:
        a = np.asarray(ids)
        if name == ANY_REGION or not name:
            raise ValueError(f"{where}: object region name {name!r} is reserved or empty; give the region another name")
        if a.ndim != 1 or len(a) == 0 or not (np.issubdtype(a.dtype, np.integer) and (a >= 0).all()):
            raise ValueError(f"{where}: object region {name!r} must be a non-empty list of triangle ids (integers "
                             f">= 0)")
        out[str(name)] = np.unique(a.astype(np.int64))
    return out


def case_to_dict(case: HoiCase) -> dict:
    """The JSON object of a case (inverse of case_from_dict)."""
    obj = {"category": case.category}
    if case.mesh_path is not None:
        obj.update(mesh=case.mesh_path, units=case.units)
        if case.size_m is not None:
            obj["size_m"] = float(case.size_m)
        if case.regions:
            obj["regions"] = {k: np.asarray(v).tolist() for k, v in case.regions.items()}
    else:
        obj["template_seed"] = case.template_seed
    # version 1 when nothing of version 2 is used: the database's files and the fits' keys stay as they were
    version = VERSION if case.size_m is not None or case.regions else 1
    d = {"format": FORMAT, "version": version, "name": case.name,
         "body": {"fingerprint": case.fingerprint, **{k: v.tolist() for k, v in case.body.items()}},
         "object": obj, "camera": {"K": case.K.tolist(), "image_size": list(case.image_size)},
         "keypoints_2d": case.keypoints_2d.tolist(), "silhouette": case.silhouette.tolist(),
         "contacts": [list(c) for c in case.contacts], "init": {k: s.to_dict() for k, s in case.init.items()}}
    if case.truth is not None:
        d["truth"] = {k: s.to_dict() for k, s in case.truth.items()}
    if case.image is not None:
        d["image"] = case.image
    if case.meta:
        d["meta"] = case.meta
    return d


def load_case(path) -> HoiCase:
    """Read and validate a case file."""
    from volsmpl.apps.checks import read_json

    path = Path(path)
    d = read_json(path, "case file", "--case")
    try:
        return case_from_dict(d, path.parent)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def save_case(case: HoiCase, path) -> None:
    """Write a case file atomically."""
    import os
    import tempfile

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(case_to_dict(case), fh)
    os.replace(tmp, path)


def object_template(case: HoiCase):
    """The case's object template (volsmpl.scene.objects.ObjectTemplate), or None when the case names a mesh file."""
    from volsmpl.scene.objects import make_object

    return make_object(case.category, seed=case.template_seed) if case.mesh_path is None else None


def mesh_file(case: HoiCase) -> Path | None:
    """The path of the case's object mesh file (relative paths from the JSON's folder); None for a template.
    FileNotFoundError when it is missing."""
    if case.mesh_path is None:
        return None
    p = Path(case.mesh_path)
    if not p.is_absolute() and case.source is not None:
        p = case.source / p
    if not p.is_file():
        raise FileNotFoundError(f"case {case.name!r}: object mesh {p} not found (a path relative to the case file's "
                                f"folder, or absolute)")
    return p


def mesh_digest(case: HoiCase) -> str | None:
    """sha256 of the object mesh file's bytes (None for a template): part of a fit's key, so an edited or
    replaced file is fitted anew rather than served from OUT/cases/."""
    from volsmpl.io.outputs import file_sha256

    p = mesh_file(case)
    return None if p is None else file_sha256(p)


def read_object_mesh(path, units: str = "m", where: str = "the object mesh"):
    """A mesh file as a trimesh.Trimesh in metres, its triangles as trimesh reads them (process=False: the file's
    order, a quad as two triangles), the ids that a case's `regions` name. ValueError naming the file and the fix
    for an unreadable file, one without triangles or with NaN / Inf vertices, or unknown units."""
    import trimesh

    if units not in UNITS:
        raise ValueError(f"{where}: units {units!r} unknown; use one of {', '.join(UNITS)}")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as e:  # trimesh raises many kinds for unreadable files
        raise ValueError(f"{where}: cannot read the object mesh {path} ({e}); use a common format (obj, ply, stl, glb, "
                         f"off)") from e
    if len(getattr(mesh, "faces", ())) == 0:
        raise ValueError(f"{where}: the object mesh {path} has no triangles (a point cloud?); give a triangle mesh")
    if not np.isfinite(mesh.vertices).all():
        raise ValueError(f"{where}: the object mesh {path} has NaN or Inf vertices")
    return trimesh.Trimesh(np.asarray(mesh.vertices) * UNITS[units], np.asarray(mesh.faces), process=False)


def object_mesh(case: HoiCase, template=None):
    """The object's mesh in its own frame (metres) and its regions {name: triangle ids}: the template's, or a mesh
    file's own (the case's `regions`; empty when it names none).

    template: the case's object_template when already built. A mesh file must hold triangles with finite
    vertices (read_object_mesh); its units are converted by `units`; its regions' ids must be its triangles'."""
    if case.mesh_path is None:
        tmpl = template if template is not None else object_template(case)
        return tmpl.mesh, dict(tmpl.regions)
    p = mesh_file(case)
    mesh = read_object_mesh(p, case.units, f"case {case.name!r}")
    for name, ids in case.regions.items():
        if len(ids) and int(ids.max()) >= len(mesh.faces):
            raise ValueError(f"case {case.name!r}: object region {name!r} names triangle {int(ids.max())}, the mesh "
                             f"{p} has {len(mesh.faces)} (ids 0..{len(mesh.faces) - 1}): a selection of another mesh?")
    return mesh, dict(case.regions)


def object_size_m(category: str, size_m: float | None = None) -> float:
    """The object's real largest extent (metres) that its scale prior aims at: `size_m` (a case's) when given, else
    the category's mean size (volsmpl.scene.objects.SIZE_PRIOR, the largest of height, width and depth).

    Example:
        >>> object_size_m("cup"), object_size_m("teddy", 0.35)
        (0.12, 0.35)
    """
    from volsmpl.scene.objects import SIZE_PRIOR

    if size_m is not None:
        return float(size_m)
    prior = SIZE_PRIOR[category]
    return float(max(prior[k][0] for k in ("height", "width", "depth") if k in prior))


def object_size_spread(category: str, size_m: float | None = None) -> float:
    """The relative spread (std / mean) of the real largest extent that `object_size_m` gives: the category's
    (volsmpl.scene.objects.SIZE_PRIOR, the extent of the largest mean) when the size is the category's, 0 when
    `size_m` states it (a user's measured object).

    Example:
        >>> round(object_size_spread("sofa"), 3), object_size_spread("sofa", 1.8)
        (0.11, 0.0)
    """
    from volsmpl.scene.objects import SIZE_PRIOR

    if size_m is not None:
        return 0.0
    mean, std = max((SIZE_PRIOR[category][k] for k in ("height", "width", "depth") if k in SIZE_PRIOR[category]),
                    key=lambda m: m[0])
    return float(std / mean)


def is_handheld(case: HoiCase) -> bool:
    """Whether the case's object is one a person picks up: its category is one of volsmpl.scene.objects.HANDHELD,
    or, for a category of the user's own (outside SIZE_PRIOR), every contact is a hand's or a forearm's."""
    from volsmpl.scene.objects import HANDHELD, SIZE_PRIOR

    if case.category in SIZE_PRIOR:
        return case.category in HANDHELD
    return bool(case.contacts) and all(part.endswith(("_hand", "_forearm")) for part, _ in case.contacts)


def check_case(case: HoiCase, fingerprint: str, part_names, regions: dict) -> None:
    """A case fits the body in use and its object: same body fingerprint, known parts and regions."""
    if case.fingerprint and case.fingerprint != fingerprint:
        raise ValueError(f"case {case.name!r} was made for body {case.fingerprint}, this body is {fingerprint}; "
                         f"use the body it was made for or regenerate the case")
    for part, region in case.contacts:
        if part not in part_names:
            raise ValueError(f"case {case.name!r}: contact part {part!r} is not a body part; parts: {', '.join(part_names)}")
        if region != ANY_REGION and region not in regions:
            known = ", ".join([ANY_REGION, *regions])
            raise ValueError(f"case {case.name!r}: contact region {region!r} is not a region of the object; regions: {known}")
