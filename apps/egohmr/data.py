"""The egocentric app's data: frames of a person in a generated room seen by a second person's head-mounted camera.

The real egocentric dataset of EgoHMR (supp. D.2) cannot be used here; this module generates its stand-in:

- scenes: the shared procedural rooms (`volsmpl.scene.make_room`); splits by scene: the room seeds 0..ROOM_COUNT-1
  are shuffled by the seed, the first ROOMS_PER_SPLIT['test'] go to test, the next ROOMS_PER_SPLIT['val'] to val,
  the rest to train (disjoint rooms);
- a person of the default body (shapes from the calibrated population) placed by `placement.place`: one of ACTIVITIES,
  touching its support (floor, seat, bed, wall, table top within 2 cm) without interpenetrating the scene (exact
  checks, see placement.py);
- VIEWS camera views per placement: the eye 0.8-2.5 m (horizontally) from the pelvis at 1.4-1.8 m above the floor with
  a clear line of sight (`Room.sample_viewpoint`), aimed at a body joint of the upper body plus Gaussian jitter
  (AIM_SD), rolled by a few degrees, 60-75 degrees horizontal field of view, IMAGE_SIZE (H, W); the legs are often out
  of view; at least MIN_VISIBLE joints in view. OpenCV axes (x right, y down, z forward);
- per frame: the SMPL parameters in the camera frame (`body(betas=, global_orient=, body_pose=, transl=)` gives
  camera-frame vertices), the exact camera-frame joints, noisy 2D keypoints with confidences, visibility, K, R, t.

Frames are generated in groups of VIEWS (one placement each), in order, each group cached on its own in the user cache
(`volsmpl.scene.cached`, name 'egohmr_<split>', DATA_VERSION), so `make_frames(split, n)` builds only the groups it
needs and a second call reads them back. Default sizes: 2,000 train, 200 val, 200 test frames.

Keypoint noise (a detector's errors): Gaussian, sd KP_SIGMA_PX per coordinate, growing linearly to
(1 + KP_BORDER_GAIN) x that within KP_BORDER_PX of the image border, clipped at KP_CLIP_SD sd; with probability
OUTLIER_P an outlier instead, OUTLIER_PX pixels away in a random direction. So every keypoint with conf > 0 lies within
KP_MAX_ERROR_PX of the true projection. conf = exp(-error / 40 px) + U(-0.05, 0.03), clipped to [0.05, 1]; joints out of
view (`visible` False: behind the camera or projecting outside [-0.5, W-0.5] x [-0.5, H-0.5]) have conf 0 and
keypoint (0, 0).

    frames = make_frames("train")                  # 2,000 EgoFrames (cached)
    pts = scene_points(frames[0], frames[0].joints[0])   # (20000, 3) camera-frame scene points in a 2 m cube
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
import trimesh
from scipy.spatial.transform import Rotation

from volsmpl.scene import ROOM_COUNT, cached, intrinsics_from_fov, look_at, subsample

from .evaluate import MIN_SCENE_POINTS
from .placement import ACTIVITIES, affords, default_body, place
from .room_checks import crop, load_room, room_cloud

__all__ = ["EgoFrame", "ACTIVITIES", "SPLITS", "make_frames", "scene_points", "scene_mesh", "frame_to_dict",
           "frame_from_dict", "check_frame", "split_rooms", "to_camera", "make_group"]

DATA_VERSION = 1
SPLITS = ("train", "val", "test")
DEFAULT_SIZE = {"train": 2000, "val": 200, "test": 200}
ROOMS_PER_SPLIT = {"test": 8, "val": 8}  # train: the other ROOM_COUNT - 16 rooms
GROUPS_PER_ROOM = {"train": 10, "val": 5, "test": 5}
VIEWS = 5
IMAGE_SIZE = (480, 640)  # (H, W)
FOV_RANGE = (60.0, 75.0)  # horizontal, degrees
CAM_DISTANCE = (0.8, 2.5)  # horizontal, eye to pelvis, metres
CAM_HEIGHT = (1.4, 1.8)  # above the floor
AIM_JOINTS = (0, 3, 6, 9, 12, 15, 16, 17)  # pelvis, spine, neck, head, shoulders
AIM_SD = 0.2  # metres, per axis
ROLL_SD_DEG = 3.0
MIN_VISIBLE = 6
MIN_EYE_BODY = 0.5  # metres from the eye to the nearest body vertex
KP_SIGMA_PX, KP_BORDER_PX, KP_BORDER_GAIN, KP_CLIP_SD = 2.0, 40.0, 2.0, 3.0
OUTLIER_P, OUTLIER_PX = 0.04, (15.0, 60.0)
KP_MAX_ERROR_PX = 60.0


@dataclass
class EgoFrame:
    """One egocentric frame. Camera frame: OpenCV axes; x_cam = R x_world + t.

    Shape: betas (10,), global_orient (3,), body_pose (69,), transl (3,): camera-frame SMPL parameters; joints
    (24, 3) camera frame; keypoints (24, 2) pixels, conf (24,), visible (24,) bool; K (3, 3); R (3, 3); t (3,)."""

    name: str
    split: str
    room_seed: int
    activity: str
    betas: np.ndarray
    global_orient: np.ndarray
    body_pose: np.ndarray
    transl: np.ndarray
    joints: np.ndarray
    keypoints: np.ndarray
    conf: np.ndarray
    visible: np.ndarray
    K: np.ndarray
    image_size: tuple
    R: np.ndarray
    t: np.ndarray


# ----------------------------------------------------------------------------------------------- splits
def split_rooms(split: str, seed: int = 0) -> list[int]:
    """The room seeds of a split (disjoint between splits), in generation order."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}.")
    perm = [int(s) for s in np.random.default_rng([int(seed), 7]).permutation(ROOM_COUNT)]
    nt, nv = ROOMS_PER_SPLIT["test"], ROOMS_PER_SPLIT["val"]
    return {"test": perm[:nt], "val": perm[nt:nt + nv], "train": perm[nt + nv:]}[split]


def to_camera(R, t, J0, global_orient, transl) -> tuple[np.ndarray, np.ndarray]:
    """SMPL root parameters after the rigid map x -> R x + t: the root rotation acts about the rest pelvis J0 of the
    body's betas, so R' = R R_g and t' = R (J0 + transl) + t - J0.

    Shape: R (3, 3), t (3,), J0 (3,), global_orient (3,) axis-angle, transl (3,) -> (3,), (3,) float64."""
    R, J0 = np.asarray(R, np.float64), np.asarray(J0, np.float64)
    go = Rotation.from_matrix(R @ Rotation.from_rotvec(np.asarray(global_orient, np.float64)).as_matrix()).as_rotvec()
    return go, R @ (J0 + np.asarray(transl, np.float64)) + np.asarray(t, np.float64) - J0


def _pose(betas, go, pose, transl):
    body, _ = default_body()
    f = lambda x: torch.as_tensor(np.asarray(x), dtype=torch.float32)[None]  # noqa: E731
    with torch.no_grad():
        out = body(betas=f(betas), global_orient=f(go), body_pose=f(pose), transl=f(transl))
    return out.vertices[0].double().numpy(), out.joints[0].double().numpy()


def _rest_pelvis(betas) -> np.ndarray:
    body, _ = default_body()
    with torch.no_grad():
        return body(betas=torch.as_tensor(np.asarray(betas), dtype=torch.float32)[None]).joints[0, 0].double().numpy()


# ----------------------------------------------------------------------------------------------- views
def _project(K, X):
    """Pixels (N, 2), depth (N,), in view (N,) bool of camera-frame points X (N, 3)."""
    H, W = IMAGE_SIZE
    z = X[:, 2]
    uv = (X @ K.T)[:, :2] / np.where(z > 1e-9, z, 1.0)[:, None]
    vis = (z > 1e-3) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= H - 0.5)
    return uv, z, vis


def _keypoints(uv, vis, rng) -> tuple[np.ndarray, np.ndarray]:
    """Detector-like keypoints and confidences of true pixels uv (J, 2) (see the module docstring)."""
    H, W = IMAGE_SIZE
    border = np.minimum.reduce([uv[:, 0] + 0.5, W - 0.5 - uv[:, 0], uv[:, 1] + 0.5, H - 0.5 - uv[:, 1]])
    sd = KP_SIGMA_PX * (1.0 + KP_BORDER_GAIN * np.clip(1.0 - border / KP_BORDER_PX, 0.0, 1.0))
    noise = np.clip(rng.standard_normal(uv.shape), -KP_CLIP_SD, KP_CLIP_SD) * sd[:, None]
    a = rng.uniform(0, 2 * np.pi, len(uv))
    out = np.stack([np.cos(a), np.sin(a)], 1) * rng.uniform(*OUTLIER_PX, len(uv))[:, None]
    off = np.where((rng.random(len(uv)) < OUTLIER_P)[:, None], out, noise)
    err = np.linalg.norm(off, axis=1)
    conf = np.clip(np.exp(-err / 40.0) + rng.uniform(-0.05, 0.03, len(uv)), 0.05, 1.0)
    kp = np.where(vis[:, None], uv + off, 0.0)
    return kp.astype(np.float32), np.where(vis, conf, 0.0).astype(np.float32)


def _view(room, verts_w, joints_w, rng):
    """One camera (K, R, t) looking at the body, or None when no good view was found."""
    for _ in range(30):
        try:
            eye = room.sample_viewpoint(joints_w[0], distance=CAM_DISTANCE, height=CAM_HEIGHT,
                                        seed=int(rng.integers(2 ** 31)), clearance=0.2)
        except ValueError:
            return None
        if np.linalg.norm(verts_w - eye, axis=1).min() < MIN_EYE_BODY:
            continue
        aim = joints_w[AIM_JOINTS[rng.integers(len(AIM_JOINTS))]] + rng.normal(0.0, AIM_SD, 3)
        E = look_at(torch.as_tensor(eye), torch.as_tensor(aim, dtype=torch.float64))[0].numpy()
        roll = Rotation.from_euler("z", np.clip(rng.normal(0.0, ROLL_SD_DEG), -10, 10), degrees=True).as_matrix()
        R, t = roll @ E[:3, :3], roll @ E[:3, 3]
        K = intrinsics_from_fov(IMAGE_SIZE, rng.uniform(*FOV_RANGE), dtype=torch.float64)[0].numpy()
        if _project(K, joints_w @ R.T + t)[2].sum() >= MIN_VISIBLE:
            return K, R, t
    return None


def make_group(split: str, g: int, seed: int = 0) -> dict:
    """The VIEWS frames of placement group g of a split, as arrays (deterministic in split, g, seed; not cached):
    per view 'global_orient', 'transl', 'joints', 'keypoints', 'conf', 'visible', 'K', 'R', 't' (leading axis VIEWS);
    once 'room_seed', 'activity', 'betas', 'body_pose', the world-frame 'global_orient_world', 'transl_world' and
    'contact' (m, the support parts to their support)."""
    rooms = split_rooms(split, seed)
    per = GROUPS_PER_ROOM[split]
    room_seed = rooms[(g // per) % len(rooms)]
    room = load_room(room_seed)
    k = g % per + per * (g // (per * len(rooms)))
    afforded = [a for a in ACTIVITIES if affords(room, a)]
    rng = np.random.default_rng([int(seed), SPLITS.index(split), int(g), 24])
    for j in range(len(afforded) * 3):
        activity = afforded[(k + room_seed + j) % len(afforded)]
        pl = place(room_seed, activity, rng)
        if pl is None:
            continue
        verts_w, joints_w = _pose(pl.betas, pl.global_orient, pl.body_pose, pl.transl)
        views = [_view(room, verts_w, joints_w, rng) for _ in range(VIEWS)]
        if any(v is None for v in views):
            continue
        J0 = _rest_pelvis(pl.betas)
        out = {k_: [] for k_ in ("global_orient", "transl", "joints", "keypoints", "conf", "visible", "K", "R", "t")}
        for K, R, t in views:
            go, tr = to_camera(R, t, J0, pl.global_orient, pl.transl)
            _, joints = _pose(pl.betas, go, pl.body_pose, tr)
            uv, _, vis = _project(K, joints)
            kp, conf = _keypoints(uv, vis, rng)
            for key, val in (("global_orient", go), ("transl", tr), ("joints", joints), ("keypoints", kp),
                             ("conf", conf), ("visible", vis), ("K", K), ("R", R), ("t", t)):
                out[key].append(val)
        arrays = {key: np.stack(v) for key, v in out.items()}
        for key in ("global_orient", "transl", "joints", "K", "R", "t"):
            arrays[key] = arrays[key].astype(np.float32 if key in ("global_orient", "transl", "joints") else np.float64)
        arrays.update(room_seed=np.int64(room_seed), activity=np.array(activity), betas=pl.betas,
                      body_pose=pl.body_pose, contact=np.float64(pl.contact),
                      global_orient_world=pl.global_orient, transl_world=pl.transl)
        return arrays
    raise RuntimeError(f"no placement in room {room_seed} for group {g} of split {split!r} (seed {seed})")


def make_frames(split: str, n: int | None = None, seed: int = 0) -> list[EgoFrame]:
    """The first n frames of a split (n=None: DEFAULT_SIZE[split]), generated in groups of VIEWS and cached per
    group in the user cache (a second call reads them back). Deterministic in (split, seed).

    Example:
        >>> frames = make_frames("test", n=10)
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}.")
    n = DEFAULT_SIZE[split] if n is None else n
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 1:
        raise ValueError(f"n must be a positive int (or None for the split's {DEFAULT_SIZE[split]} frames), got {n!r}.")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}.")
    frames = []
    for g in range(-(-int(n) // VIEWS)):
        d = cached(f"egohmr_{split}", DATA_VERSION, f"{int(seed)}-g{g:05d}", lambda: make_group(split, g, int(seed)))
        for v in range(VIEWS):
            i = g * VIEWS + v
            if i >= n:
                break
            frames.append(EgoFrame(
                name=f"{split}_{i:04d}", split=split, room_seed=int(d["room_seed"]), activity=str(d["activity"]),
                betas=d["betas"].astype(np.float32), global_orient=d["global_orient"][v], body_pose=d["body_pose"].copy(),
                transl=d["transl"][v], joints=d["joints"][v], keypoints=d["keypoints"][v], conf=d["conf"][v],
                visible=d["visible"][v].astype(bool), K=d["K"][v], image_size=tuple(IMAGE_SIZE), R=d["R"][v],
                t=d["t"][v]))
    return frames


# ----------------------------------------------------------------------------------------------- scene
def scene_points(frame: EgoFrame, center, n: int = 20000, size: float = 2.0, seed: int = 0) -> np.ndarray:
    """n points on the room's surfaces (floor, walls, furniture) inside the axis-aligned cube of edge `size` (camera
    axes) centred at `center` (camera frame), drawn from the room's dense surface sample (`placement.room_cloud`:
    1 point per cm² of visible surface, cached per room): a random subset without replacement when the cube holds
    more than n, all of them plus random repeats when it holds fewer (but at least MIN_SCENE_POINTS).

    Shape: center (3,) -> (n, 3) float32, camera frame.
    Example:
        >>> pts = scene_points(frame, frame.joints[0])     # around the true pelvis
    """
    c = np.asarray(center.detach().cpu() if torch.is_tensor(center) else center, dtype=np.float64).reshape(-1)
    if c.shape != (3,) or not np.isfinite(c).all():
        raise ValueError(f"center must be 3 finite camera-frame coordinates in metres, got {c.tolist()}.")
    if not (isinstance(size, (int, float, np.floating)) and np.isfinite(size) and size > 0):
        raise ValueError(f"size must be a positive cube edge in metres, got {size!r}.")
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 1:
        raise ValueError(f"n must be a positive int, got {n!r}.")
    R, t = np.asarray(frame.R, np.float64), np.asarray(frame.t, np.float64)
    cw = R.T @ (c - t)
    reach = 0.5 * size * np.abs(R.T).sum(1)  # half extent of the rotated cube along the world axes
    p = crop(room_cloud(int(frame.room_seed)), cw - reach, cw + reach).astype(np.float64) @ R.T + t
    p = p[(np.abs(p - c) <= 0.5 * size).all(1)]
    if len(p) < MIN_SCENE_POINTS:
        raise ValueError(f"scene with no points near the body: the {size} m cube at {np.round(c, 3).tolist()} (camera "
                         f"frame) of frame {frame.name!r} holds {len(p)} scene points (< {MIN_SCENE_POINTS}); move the "
                         f"centre or give a denser scene.")
    return p[subsample(p, int(n), seed=seed)].astype(np.float32)


def scene_mesh(frame: EgoFrame) -> trimesh.Trimesh:
    """The frame's room mesh (closed components, walls and floor slab included) in the camera frame."""
    m = load_room(int(frame.room_seed)).mesh()
    v = np.asarray(m.vertices, np.float64) @ np.asarray(frame.R, np.float64).T + np.asarray(frame.t, np.float64)
    return trimesh.Trimesh(v, np.asarray(m.faces), process=False)


# ----------------------------------------------------------------------------------------------- files, checks
_ARRAYS = {"betas": (10,), "global_orient": (3,), "body_pose": (69,), "transl": (3,), "K": (3, 3), "R": (3, 3),
           "t": (3,)}


def frame_to_dict(frame: EgoFrame) -> dict:
    """A JSON-able dict of a frame (arrays as nested lists); frame_from_dict inverts it."""
    out = {}
    for f in fields(EgoFrame):
        v = getattr(frame, f.name)
        out[f.name] = v.tolist() if isinstance(v, np.ndarray) else list(v) if f.name == "image_size" else v
    out["room_seed"] = int(out["room_seed"])
    return out


def frame_from_dict(d: dict) -> EgoFrame:
    """An EgoFrame from frame_to_dict's dict (or a user's own JSON file of that form), checked by check_frame."""
    if not isinstance(d, dict):
        raise ValueError(f"a frame must be a dict with keys {[f.name for f in fields(EgoFrame)]}, got {type(d).__name__}.")
    missing = [f.name for f in fields(EgoFrame) if f.name not in d]
    if missing:
        raise ValueError(f"frame dict lacks {missing}; write every EgoFrame field (see frame_to_dict).")
    kw = dict(d)
    for k in ("betas", "global_orient", "body_pose", "transl", "joints", "keypoints", "conf", "K", "R", "t"):
        kw[k] = np.asarray(d[k], dtype=np.float64 if k in ("K", "R", "t") else np.float32)
    kw["visible"] = np.asarray(d["visible"], dtype=bool)
    kw["image_size"] = tuple(int(s) for s in d["image_size"])
    kw["room_seed"] = int(d["room_seed"])
    frame = EgoFrame(**{f.name: kw[f.name] for f in fields(EgoFrame)})
    check_frame(frame, num_joints=len(frame.joints))
    return frame


def check_frame(frame: EgoFrame, num_joints: int = 24) -> None:
    """Raise one clear ValueError for a malformed frame: wrong shapes or joint counts, NaN/inf values, a bad K (not
    [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0), a bad image size, R not a rotation, conf outside [0, 1]."""
    name = getattr(frame, "name", "?")
    shapes = dict(_ARRAYS, joints=(num_joints, 3), keypoints=(num_joints, 2), conf=(num_joints,),
                  visible=(num_joints,))
    for k, shape in shapes.items():
        a = np.asarray(getattr(frame, k))
        if a.shape != shape:
            hint = f" ({a.shape[0]} joints, expected {num_joints})" if k in ("joints", "keypoints", "conf",
                                                                             "visible") and a.ndim else ""
            raise ValueError(f"frame {name!r}: {k} has shape {a.shape}, expected {shape}{hint}; give "
                             f"{num_joints} SMPL joints in SMPL order.")
        if a.dtype != bool and not np.isfinite(a).all():
            raise ValueError(f"frame {name!r}: {k} contains NaN/inf; mark missing keypoints with conf 0 and "
                             f"keypoint (0, 0) instead.")
    size = tuple(frame.image_size)
    if len(size) != 2 or not all(isinstance(s, (int, np.integer)) and s > 0 for s in size):
        raise ValueError(f"frame {name!r}: image_size must be (H, W) positive ints, got {frame.image_size!r}.")
    K = np.asarray(frame.K, np.float64)
    if not (K[0, 0] > 0 and K[1, 1] > 0 and K[0, 1] == 0 and K[1, 0] == 0 and np.allclose(K[2], [0, 0, 1])):
        raise ValueError(f"frame {name!r}: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0 (pixels), "
                         f"got {K.round(3).tolist()}.")
    R = np.asarray(frame.R, np.float64)
    if not (np.allclose(R @ R.T, np.eye(3), atol=1e-5) and np.linalg.det(R) > 0):
        raise ValueError(f"frame {name!r}: R must be a rotation (orthonormal, det +1), the world -> camera rotation.")
    conf = np.asarray(frame.conf)
    if (conf < 0).any() or (conf > 1).any():
        raise ValueError(f"frame {name!r}: conf must lie in [0, 1], got values in [{conf.min()}, {conf.max()}].")
