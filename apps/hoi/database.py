"""The interaction database of the human–object app: generated cases with exact ground truth.

The paper evaluates on the "interaction database" of Wang et al. (100 in-the-wild images with first-stage
estimates), which cannot be redistributed; this module generates its stand-in. Every case is one person with
one object, designed by an interaction recipe (apps/hoi/interactions.py; `KIND_NAMES`: sitting on a chair, a
stool or a sofa, lying on a bed, holding a box or a ball with both hands, holding a bat, a bottle, a cup or a
phone in one hand, standing on a skateboard, leaning on a table, pushing a cart), then:

1. resolved exactly: the object slides along the contact normal (or the hands' gap is re-solved for two-hand
   grips) until no object vertex is deeper than 1 mm in the posed body mesh (`mesh_signed_distance`, exact) and no
   body vertex is inside the object (winding numbers), with the required contacts within 1 cm (`CONTACT_TOL`);
   the contact pairs kept are (part, region) pairs whose surfaces are within 1 cm;
2. seen by a pinhole camera at 1.5-4 m (480 x 640, 50-65 deg horizontal FoV) looking at the pair; the camera
   frame is the world of the case (apps/hoi/case.py): truth.human maps the body frame (the body model's output,
   transl 0) into it, truth.object the template frame (both scale 1);
3. observed: keypoints_2d = the 24 true joints projected, plus Gaussian pixel noise (sd 1.5 px, clipped at
   `KP_NOISE_PX`), confidence ~0.9 (0 for joints behind the camera or outside the image); silhouette = up to
   2,000 pixels of the object's mask (its projected triangles filled with OpenCV; amodal: occlusion by the body is
   ignored, the mask is the whole object's);
4. given first-stage estimates (init) with a monocular method's errors: the human and the object each scaled
   about the camera centre by its own factor in [0.7, 1.3] (scale and translation together: the projection is
   unchanged, the depth-scale ambiguity), then rotated about their centroid (human up to 5 deg, object up to 30
   deg, random axis) and translated (a few cm, mostly in depth); `noise=0` keeps only the scaling.
5. rendered: the body and the object through the camera with the observed keypoints (`<name>.png`).

    from volsmpl.apps.hoi.database import make_case, make_database, load_database
    case = make_case(7)                      # deterministic in (index, seed): byte-identical JSON
    paths = make_database(100, seed=0)       # the user cache: <cache>/hoi/v<DB_VERSION>_seed0/
    cases = load_database(database_folder(0))
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from .case import HoiCase, Similarity, load_case, save_case
from .case_geometry import raster_mask
from .interactions import RECIPES, Recipe
from volsmpl.body.rig import Rig

# the generated data's version (its cache folder): the body-inside-object check counts winding numbers exactly
# (MeshQuery, float64) on the objects' touching components (open3d's float32 rays miscounted); the silhouette fills
# each triangle on its own (case_geometry.raster_mask: one fillPoly of them all kept 4,756 of the 12,969 pixels of
# the chair of sit_chair_0052, those covered an odd number of times)
DB_VERSION = 3
KIND_NAMES = tuple(RECIPES)
IMAGE_SIZE = (480, 640)  # (H, W)
FOV_RANGE = (50.0, 65.0)  # horizontal, degrees
DIST_RANGE = (1.5, 4.0)  # camera to the pair's centre, metres
KP_NOISE_SD, KP_NOISE_PX = 1.5, 4.0  # keypoint pixel noise: sd and the clip bound per coordinate
SIL_MAX = 2000
PEN_TOL = 1e-3  # object vertices may lie at most 1 mm inside the body mesh
CONTACT_TOL = 0.01  # contact pairs: surfaces within 1 cm
SCALE_RANGE = (0.7, 1.3)
ROT_NOISE_DEG = {"human": 5.0, "object": 30.0}
TRANS_NOISE_SD = np.array([0.015, 0.015, 0.05])  # metres, camera x, y, z (depth); clipped at 2 sd
ATTEMPTS = 6


# ----------------------------------------------------------------------------------------------- body
@lru_cache(maxsize=2)
def _default_body():
    import volsmpl
    body = volsmpl.create_body()
    return body, volsmpl.Partition(body)


def _body_and_partition(body):
    if body is None:
        return _default_body()
    import volsmpl
    part = getattr(body, "_hoi_partition", None)
    if part is None:
        part = volsmpl.Partition(body)
        body._hoi_partition = part
    return body, part


def _fingerprint(body) -> str:
    fp = getattr(body, "fingerprint", None)
    if fp:
        return str(fp)
    from volsmpl.body.fingerprint import fingerprint_of_model
    return fingerprint_of_model(body)


# ----------------------------------------------------------------------------------------------- exact checks
def _object_depth_in_body(vb: torch.Tensor, fb: torch.Tensor, vo: np.ndarray) -> float:
    """Smallest signed distance of the object's vertices to the body mesh (negative inside), metres."""
    from volsmpl.geometry.point_mesh_distance import mesh_signed_distance
    return float(mesh_signed_distance(vb, fb, torch.as_tensor(vo), closed=True).min())


def _body_inside_object(vo: np.ndarray, fo: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Winding numbers of body points w.r.t. the (closed, multi-component) object mesh > 1/2 (exact: several
    components take MeshQuery, volsmpl.geometry.point_mesh_distance.winding_numbers)."""
    from volsmpl.geometry.point_mesh_distance import winding_numbers
    w = winding_numbers(torch.as_tensor(vo), torch.as_tensor(fo), torch.as_tensor(pts, dtype=torch.float64), closed=True)
    return w.numpy() > 0.5


def _surface_distance(vo: np.ndarray, fo: np.ndarray, pts: np.ndarray) -> float:
    """Unsigned distance from points to a triangle set (min over the points)."""
    from volsmpl.geometry.point_mesh_distance import closest_points_on_triangles, nearest_faces
    v, f, p = torch.as_tensor(vo), torch.as_tensor(fo).long(), torch.as_tensor(pts, dtype=torch.float64)
    idx = nearest_faces(v, f, p)
    tri = v[f[idx]]
    q = closest_points_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])
    return float((p - q).norm(dim=-1).min())


class _Scene:
    """A posed body and the object (template mesh, placement) in the body frame."""

    def __init__(self, rig: Rig, recipe: Recipe):
        self.rig, self.recipe = rig, recipe
        self.set_pose(recipe.euler)
        self.vt = np.asarray(recipe.template.mesh.vertices, dtype=np.float64)
        self.ft = np.asarray(recipe.template.mesh.faces, dtype=np.int64)

    def set_pose(self, euler):
        self.euler = euler
        self.out = self.rig.pose(euler, self.recipe.global_R)
        self.vb = self.out.vertices[0].double()
        self.fb = torch.as_tensor(self.rig.partition.faces)

    def obj(self, t):
        return self.vt @ self.recipe.R_obj.T + t

    def clean(self, t) -> bool:
        vo = self.obj(t)
        vb = self.vb.numpy()
        lo, hi = vo.min(0) - 0.01, vo.max(0) + 0.01
        near = ((vb >= lo) & (vb <= hi)).all(1)
        if near.any() and _body_inside_object(vo, self.ft, vb[near]).any():
            return False
        return _object_depth_in_body(self.vb, self.fb, vo) >= -PEN_TOL


def _slide(scene: _Scene, t0: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The placement t0 + s d with the smallest s at which the pair is clean (to 0.25 mm, + 0.3 mm): touching."""
    def at(s):
        return t0 + s * d

    if scene.clean(at(0.0)):
        hi, lo, step = 0.0, None, 0.005
        while step <= 0.4:
            if not scene.clean(at(-step)):
                lo = -step
                break
            hi, step = -step, 2 * step
        if lo is None:
            raise RuntimeError("the object never meets the body along the contact normal")
    else:
        lo, hi, step = 0.0, None, 0.005
        while step <= 0.4:
            if scene.clean(at(step)):
                hi = step
                break
            lo, step = step, 2 * step
        if hi is None:
            raise RuntimeError("the object cannot be moved out of the body along the contact normal")
    while hi - lo > 2.5e-4:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if scene.clean(at(mid)) else (mid, hi)
    # a 0.3 mm margin: float32 ray tests cannot tell inside from outside on the surface itself
    return at(hi + 3e-4) if scene.clean(at(hi + 3e-4)) else at(hi)


def _grip(scene: _Scene, recipe: Recipe) -> np.ndarray:
    """Two-hand grip: re-solve the hands' gap until both palms touch the object's sides (0.3-6 mm clearance)."""
    g = recipe.grip
    axis, t = g["axis"], recipe.t_obj.copy()
    gap = g["width"] + 0.006
    euler = recipe.euler
    for _ in range(6):
        euler, err = g["solve"](gap, euler)
        scene.set_pose(euler)
        vb = scene.vb.numpy()
        vo = scene.obj(t)
        from volsmpl.geometry.point_mesh_distance import mesh_signed_distance
        cl = {s: float(mesh_signed_distance(torch.as_tensor(vo), torch.as_tensor(scene.ft),
                                            torch.as_tensor(scene.rig.part_vertices(vb, f"{s}_hand", f"{s}_forearm")),
                                            closed=True).min())
              for s in ("left", "right")}
        shift = 0.5 * (cl["right"] - cl["left"])  # towards the right hand when the left one is closer
        t = t - shift * axis
        mean = 0.5 * (cl["left"] + cl["right"])
        if 0.0003 <= mean <= 0.006 and scene.clean(t):
            return t
        gap -= 2 * (mean - 0.002)
    raise RuntimeError("the two-hand grip did not converge")


def resolve(rig: Rig, recipe: Recipe):
    """Touch without interpenetration; returns the scene (final pose), placement t, kept contacts, distances."""
    scene = _Scene(rig, recipe)
    t = _grip(scene, recipe) if recipe.grip is not None else _slide(scene, recipe.t_obj, recipe.push)
    vb = scene.vb.numpy()
    vo = scene.obj(t)
    # exact final checks, each from scratch
    if _object_depth_in_body(scene.vb, scene.fb, vo) < -PEN_TOL or _body_inside_object(vo, scene.ft, vb).any():
        raise RuntimeError("interpenetration left after resolution")
    # furniture stands on the person's floor: standing people within FLOOR_TOL of it, seated feet not below it
    if "floor" in recipe.info:
        gap = float(scene.rig.part_vertices(vb, "left_foot", "right_foot")[:, 1].min() - vo[:, 1].min())
        lo, hi = recipe.info["floor"]
        if not lo <= gap <= hi:
            raise RuntimeError(f"the feet are {gap * 100:.1f} cm above the object's floor")
    regions = recipe.template.regions
    kept, dists = [], []
    for part, region, required in recipe.contacts:
        if region != "any" and region not in regions:
            continue
        faces = scene.ft if region == "any" else scene.ft[regions[region]]
        dist = _surface_distance(vo, faces, rig.part_vertices(vb, part))
        if dist <= CONTACT_TOL:
            kept.append((part, region))
            dists.append(dist)
        elif required:
            raise RuntimeError(f"required contact {part}-{region} is {dist * 100:.1f} cm away")
    return scene, t, kept, dists


# ----------------------------------------------------------------------------------------------- camera, observations
def _random_rotation(rng, max_deg: float, noise: float) -> np.ndarray:
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    ang = np.radians(rng.uniform(0.0, max_deg)) * noise
    return Rotation.from_rotvec(axis * ang).as_matrix()


def _perturb(sim: Similarity, centroid: np.ndarray, rng, max_deg: float, noise: float) -> Similarity:
    """Scale about the camera centre (factor in SCALE_RANGE), rotate about the scaled centroid, translate."""
    s = rng.uniform(*SCALE_RANGE)
    Rn = _random_rotation(rng, max_deg, noise)
    dt = np.clip(rng.standard_normal(3), -2, 2) * TRANS_NOISE_SD * noise
    return Similarity(float(s * sim.scale), Rn @ sim.rotation,
                      s * (Rn @ (sim.translation - centroid) + centroid) + dt)


def _project(K: np.ndarray, x: np.ndarray):
    z = x[:, 2]
    uv = (x @ K.T)[:, :2] / np.where(np.abs(z) > 1e-9, z, 1e-9)[:, None]
    return uv, z


def _in_image(uv, z, size):
    H, W = size
    return (z > 0.05) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= H - 0.5)


def _camera(rng, recipe: Recipe, pts: np.ndarray):
    from volsmpl.scene.camera import make_camera
    lo, hi = pts.min(0), pts.max(0)
    target = 0.5 * (lo + hi)
    radius = float(np.linalg.norm(pts - target, axis=1).max())
    fov = rng.uniform(*FOV_RANGE)
    H, W = IMAGE_SIZE
    half_v = np.arctan(np.tan(np.radians(fov) / 2) * H / W)
    need = 1.05 * radius / np.sin(half_v)
    dist = float(np.clip(rng.uniform(max(DIST_RANGE[0], need), max(DIST_RANGE[1], need + 0.1)), *DIST_RANGE))
    yaw = np.radians(rng.uniform(*recipe.yaw_range))
    pitch = np.radians(rng.uniform(5.0, 30.0))
    eye = target + dist * np.array([np.sin(yaw) * np.cos(pitch), np.sin(pitch), np.cos(yaw) * np.cos(pitch)])
    cam = make_camera(torch.as_tensor(eye), torch.as_tensor(target), IMAGE_SIZE, torch.tensor(fov, dtype=torch.float64))
    E = cam.extrinsics[0].numpy()
    K = cam.intrinsics[0, :3, :3].numpy()
    return cam, np.round(K, 9), np.round(E[:3, :3], 12), np.round(E[:3, 3], 12)


# ----------------------------------------------------------------------------------------------- cases
def case_name(index: int) -> str:
    return f"{KIND_NAMES[index % len(KIND_NAMES)]}_{index:04d}"


def _build(index: int, seed: int, body, attempt: int):
    body, part = _body_and_partition(body)
    kind = KIND_NAMES[index % len(KIND_NAMES)]
    fn, category = RECIPES[kind]
    rng = np.random.default_rng([int(seed), int(index), int(attempt), 20250]) 
    from volsmpl.body.shapes import sample_betas
    hr = (1.5, 1.7) if kind == "lie_bed" else (1.5, 1.95)
    betas = sample_betas(1, seed=int(rng.integers(2 ** 31)), height_range=hr)
    template_seed = int(rng.integers(2 ** 31))
    rig = Rig(body, part, betas)
    recipe = fn(rig, rng, template_seed)
    scene, t, contacts, dists = resolve(rig, recipe)
    return body, part, kind, category, rng, betas, template_seed, recipe, scene, t, contacts, dists


def make_case(index: int, seed: int = 0, body=None, noise: float = 1.0, image_dir=None) -> HoiCase:
    """One case, deterministic in (index, seed). The kind cycles through KIND_NAMES with the index.

    noise: scale of the init's rotation and translation noise (0: only the depth-scale ambiguity).
    image_dir: where to write the rendered `<name>.png` (None: no image; case.image names it anyway).
    Extra attributes on the returned case: kind, contact_distance (metres, the largest over the kept pairs),
    contact_distances, truth_vertices (body, object in the camera frame)."""
    if not isinstance(index, (int, np.integer)) or index < 0:
        raise ValueError(f"index must be a non-negative int, got {index!r}")
    err = None
    for attempt in range(ATTEMPTS):
        try:
            built = _build(index, seed, body, attempt)
            break
        except RuntimeError as e:  # a design that did not resolve: draw again
            err = e
    else:
        raise RuntimeError(f"case {index} (seed {seed}) could not be generated in {ATTEMPTS} attempts: {err}")
    body, part, kind, category, rng, betas, template_seed, recipe, scene, t, contacts, dists = built
    out = scene.out
    vb = out.vertices[0].double().numpy()
    joints = out.joints[0].double().numpy()
    vo = scene.obj(t)
    cam, K, Rc, tc = _camera(rng, recipe, np.concatenate([vb, vo]))
    human = Similarity(1.0, Rc, tc)
    obj = Similarity(1.0, Rc @ recipe.R_obj, Rc @ t + tc)
    # observations
    jc = human.apply(joints)
    uv, z = _project(K, jc)
    uvn = uv + np.clip(rng.standard_normal(uv.shape) * KP_NOISE_SD, -KP_NOISE_PX, KP_NOISE_PX)
    conf = np.clip(0.9 + 0.04 * rng.standard_normal(24), 0.75, 0.99)
    seen = _in_image(uv, z, IMAGE_SIZE) & _in_image(uvn, z, IMAGE_SIZE)
    kp = np.concatenate([np.where(z[:, None] > 0.05, uvn, 0.0), np.where(seen, conf, 0.0)[:, None]], axis=1)
    voc = obj.apply(scene.vt)
    mask = raster_mask(K, IMAGE_SIZE, voc, scene.ft)
    vv, uu = np.nonzero(mask)
    pix = np.stack([uu, vv], axis=1).astype(np.float64)
    if len(pix) > SIL_MAX:
        pix = pix[np.sort(rng.choice(len(pix), SIL_MAX, replace=False))]
    # first-stage estimates
    init = {"human": _perturb(human, human.apply(vb).mean(0), rng, ROT_NOISE_DEG["human"], noise),
            "object": _perturb(obj, voc.mean(0), rng, ROT_NOISE_DEG["object"], noise)}
    name = case_name(index)
    case = HoiCase(
        name=name, category=category,
        body={"betas": betas[0].float(), "global_orient": out.global_orient[0].float(),
              "body_pose": out.body_pose[0].float(), "transl": torch.zeros(3)},
        fingerprint=_fingerprint(body), K=K, image_size=IMAGE_SIZE, keypoints_2d=np.round(kp, 6),
        silhouette=pix, contacts=contacts, init=init, truth={"human": human, "object": obj},
        template_seed=template_seed, image=f"{name}.png")
    case.kind = kind
    case.contact_distances = [float(d) for d in dists]
    case.contact_distance = float(max(dists)) if dists else float("nan")
    case.truth_vertices = (human.apply(vb), voc)
    if image_dir is not None:
        render_case(case, scene.rig.partition.faces.numpy(), cam, vb, scene.obj(t), scene.ft,
                    Path(image_dir) / case.image)
    return case


def render_case(case: HoiCase, body_faces, cam, vb, vo, fo, path) -> None:
    """The body (skin colour) and the object (blue) through the case's camera, observed keypoints in red."""
    from volsmpl.viz.render import draw_keypoints, render_camera_view, save_png
    img = render_camera_view([(vb, body_faces, (0.92, 0.72, 0.6)), (vo, fo, (0.35, 0.55, 0.9))], cam, max_edge=0.2)
    kp = case.keypoints_2d
    draw_keypoints(img, kp[:, :2], kp[:, 2] > 0, (220, 30, 30), 3)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    save_png(path, img)


# ----------------------------------------------------------------------------------------------- database
def database_folder(seed: int = 0) -> Path:
    from volsmpl.scene.cache import cache_dir
    return cache_dir() / "hoi" / f"v{DB_VERSION}_seed{seed}"


def make_database(n: int = 100, seed: int = 0, out=None, log=print, body=None) -> list[Path]:
    """Write n cases (<name>.json + <name>.png) and index.json into `out` (default database_folder(seed)).

    Cases already there (listed in an index.json of the same DB_VERSION and seed, with both files) are kept.
    index.json: {"format": "volsmpl-hoi-database", "db_version", "seed", "cases": [{"name", "kind", "category",
    "split" ('tune': the first half, 'test': the second), "contacts", "contact_distance"}]}."""
    import time
    out = database_folder(seed) if out is None else Path(out)
    out.mkdir(parents=True, exist_ok=True)
    index_path = out / "index.json"
    old = {}
    if index_path.is_file():
        try:
            d = json.loads(index_path.read_text())
            if d.get("db_version") == DB_VERSION and d.get("seed") == seed:
                old = {c["name"]: c for c in d.get("cases", [])}
        except (json.JSONDecodeError, KeyError, TypeError):
            old = {}
    entries, paths = [], []
    for i in range(n):
        name = case_name(i)
        jp, ip = out / f"{name}.json", out / f"{name}.png"
        split = "tune" if i < n // 2 else "test"
        if name in old and jp.is_file() and ip.is_file():
            entries.append({**old[name], "split": split})
            paths.append(jp)
            continue
        t0 = time.perf_counter()
        case = make_case(i, seed, body=body, image_dir=out)
        save_case(case, jp)
        entries.append({"name": name, "kind": case.kind, "category": case.category, "split": split,
                        "contacts": [list(c) for c in case.contacts], "contact_distance": round(case.contact_distance, 6)})
        paths.append(jp)
        if log:
            log(f"[hoi db] {name}: contact {case.contact_distance * 1000:.1f} mm, {time.perf_counter() - t0:.1f} s")
        _write_index(index_path, seed, entries)
    _write_index(index_path, seed, entries)
    return paths


def _write_index(path: Path, seed: int, entries: list) -> None:
    import os
    import tempfile
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump({"format": "volsmpl-hoi-database", "db_version": DB_VERSION, "seed": seed, "cases": entries}, fh, indent=1)
    os.replace(tmp, path)


def load_database(folder, split: str | None = None) -> list[HoiCase]:
    """The cases of a database folder in index order (optionally one split: 'tune' or 'test')."""
    folder = Path(folder)
    index_path = folder / "index.json"
    if not index_path.is_file():
        raise FileNotFoundError(f"{index_path} not found; build the database with make_database(out={str(folder)!r})")
    from volsmpl.apps.checks import read_json

    d = read_json(index_path, "the database index", "--db")
    if not isinstance(d, dict) or not isinstance(d.get("cases"), list):
        raise ValueError(f"{index_path} is not an interaction database index (no 'cases' list); rebuild it with "
                         f"`volsmpl hoi make-db --db {folder}`")
    cases = []
    for c in d["cases"]:
        if split is None or c.get("split") == split:
            case = load_case(folder / f"{c['name']}.json")
            case.kind, case.split, case.contact_distance = c.get("kind"), c.get("split"), c.get("contact_distance")
            cases.append(case)
    return cases
