"""Body placements of the egocentric app: a person of the default body posed plausibly in a generated room.

`place(room_seed, activity, rng)` returns a `Placement` (world-frame SMPL parameters) for one of ACTIVITIES:

- 'standing', 'walking' (a phase of the motion app's walk cycle), 'crouching' (squatting or kneeling): the lowest
  vertex 1 mm above the floor, on a free floor spot;
- 'sitting': on a chair, stool or sofa place, knees solved by bisection so the feet reach the floor, the back in
  front of the backrest, then lowered onto the seat until it touches;
- 'leaning_table': torso bent forward, palms on the table top (the hoi rig's inverse kinematics), feet on the floor;
- 'leaning_wall': torso tilted back, slid back against a wall until it touches;
- 'reaching_shelf': standing in front of a shelf, one palm brought in front of its opening (inverse kinematics);
- 'lying': supine on a bed, head below the pillows, lowered onto the mattress until it touches.

Every placement is checked exactly (`penetration`, room_checks.py: winding numbers by libigl and open3d, or by
torch's MeshQuery where they do not import): no body vertex inside a closed scene component and no scene point
(the room's vertices and its dense surface sample `room_cloud`, 1 point per cm²) inside the posed body, deeper
than PEN_TOL; the support parts (SUPPORT) within CONTACT_TOL of their support.
A placement that fails is drawn again. Conventions: world Y up, metres; body frame as `core/body/rig.py` (facing +Z).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from volsmpl.body.rig import Rig, jitter, named_euler, set_joints
from volsmpl.body.poses import BODY_JOINTS, euler_to_body_pose
from volsmpl.body.shapes import sample_betas
from .room_checks import BodyMesh, load_room, penetration, room_cloud, surface_distance

ACTIVITIES = ("standing", "walking", "sitting", "leaning_table", "leaning_wall", "crouching", "reaching_shelf",
              "lying")
#: body parts that rest on the activity's support, and what the support is
SUPPORT = {"standing": (("left_foot", "right_foot"), "floor"), "walking": (("left_foot", "right_foot"), "floor"),
           "crouching": (("left_foot", "right_foot", "left_shin", "right_shin"), "floor"),
           "reaching_shelf": (("left_foot", "right_foot"), "floor"),
           "sitting": (("pelvis", "left_thigh", "right_thigh"), "seat"), "lying": (("pelvis", "chest"), "bed"),
           "leaning_wall": (("pelvis", "belly", "chest"), "wall"), "leaning_table": (("left_hand", "right_hand"), "table")}
SEAT_CATEGORIES = ("chair", "stool", "sofa")
CONTACT_TOL = 0.02   # support parts within 2 cm of their support
PEN_TOL = 0.003      # scene points / body vertices may lie at most 3 mm inside the other
FLOOR_GAP = 0.001    # the lowest vertex of a standing body 1 mm above the floor
TRIES = 12


@dataclass
class Placement:
    """A posed body in a room, world frame: `body(betas=, global_orient=, body_pose=, transl=)` gives it.
    contact: distance (m) of the support parts to the support; support: what it rests on."""

    room_seed: int
    activity: str
    betas: np.ndarray
    global_orient: np.ndarray
    body_pose: np.ndarray
    transl: np.ndarray
    support: str
    contact: float


# ----------------------------------------------------------------------------------------------- scene geometry
@lru_cache(maxsize=1)
def default_body():
    """The default body and its partition (part labels per vertex), built once."""
    import volsmpl
    body = volsmpl.create_body()
    return body, volsmpl.Partition(body)


# ----------------------------------------------------------------------------------------------- helpers
def _yaw(direction) -> np.ndarray:
    """Rotation about Y taking +Z to the horizontal direction (x, z) of `direction`."""
    return Rotation.from_euler("y", np.arctan2(direction[0], direction[-1])).as_matrix()


def _idx(*joints):
    return [BODY_JOINTS.index(j) for j in joints]


class _Ctx:
    """One placement attempt: the body of these betas, its rig and posing in the body frame."""

    def __init__(self, room, cloud, betas):
        self.body, self.partition = default_body()
        self.room, self.cloud, self.betas = room, cloud, betas
        self.rig = Rig(self.body, self.partition, torch.as_tensor(betas).reshape(1, -1))
        self.labels = self.partition.vertex_labels.numpy()
        self.names = self.partition.table.part_names
        self.faces = np.asarray(self.body.faces)
        self.J0 = self.rig.rest_joints[0].numpy()

    def pose(self, G: np.ndarray, body_pose: np.ndarray) -> np.ndarray:
        """Body-frame vertices (V, 3) float64 of root rotation G (3, 3) and body_pose (69,)."""
        go = torch.as_tensor(Rotation.from_matrix(G).as_rotvec(), dtype=torch.float32)[None]
        with torch.no_grad():
            out = self.body(betas=self.rig.betas, global_orient=go,
                            body_pose=torch.as_tensor(body_pose, dtype=torch.float32)[None])
        return out.vertices[0].double().numpy()

    def parts(self, v: np.ndarray, *parts) -> np.ndarray:
        return v[np.isin(self.labels, [self.names.index(p) for p in parts])]

    def clean(self, vw: np.ndarray) -> bool:
        return max(penetration(vw, self.faces, self.room, self.cloud)) <= PEN_TOL

    def settle(self, vw: np.ndarray, d: np.ndarray, span: float = 0.12) -> float | None:
        """The offset s along unit d at which the body first touches the scene (the last clean s, to 0.5 mm);
        None when it is not clean at s = 0 or touches nothing within span."""
        body = BodyMesh(vw, self.faces)
        strict = lambda s: max(penetration(vw, self.faces, self.room, self.cloud, body, s * d)) <= 1e-4  # noqa: E731
        if not strict(0.0):
            return None
        good, bad = 0.0, None
        for s in np.arange(0.015, span + 1e-9, 0.015):
            if not strict(s):
                bad = s
                break
            good = s
        if bad is None:
            return None
        while bad - good > 5e-4:
            mid = 0.5 * (good + bad)
            good, bad = (mid, bad) if strict(mid) else (good, mid)
        return good

    def finish(self, activity, G, body_pose, R, p, support_mesh, floor: bool) -> Placement | None:
        """World parameters of x_world = R x_body + p, after the exact checks (None when they fail)."""
        vw = self.pose(G, body_pose) @ R.T + p
        if not self.clean(vw):
            return None
        parts, support = SUPPORT[activity]
        pv = self.parts(vw, *parts)
        contact = float(pv[:, 1].min() - self.room.floor_y) if floor else surface_distance(pv, support_mesh)
        if not -1e-6 <= contact <= CONTACT_TOL:
            return None
        go = Rotation.from_matrix(R @ G).as_rotvec()
        transl = R @ self.J0 + p - self.J0
        return Placement(self.room.seed, activity, np.asarray(self.betas, np.float32), go.astype(np.float32),
                         np.asarray(body_pose, np.float32), transl.astype(np.float32), support, contact)

    def on_floor(self, v_b: np.ndarray, R: np.ndarray, xz) -> np.ndarray:
        """Translation putting the body's root over floor point xz (2,), lowest vertex FLOOR_GAP above the floor."""
        r = R @ self.rig.rest_joints[0].numpy()
        return np.array([xz[0] - r[0], self.room.floor_y + FLOOR_GAP - v_b[:, 1].min(), xz[1] - r[2]])

    def free_spot(self, rng, clearance: float = 0.35) -> np.ndarray | None:
        free, xs, zs = self.room.free_grid(clearance)
        ii, jj = np.nonzero(free)
        if not len(ii):
            return None
        k = rng.integers(len(ii))
        return np.array([xs[jj[k]], zs[ii[k]]]) + rng.uniform(-0.025, 0.025, 2)


def _euler_pose(e: np.ndarray) -> np.ndarray:
    return euler_to_body_pose(e[None])[0].numpy()


def _standing_euler(rng) -> np.ndarray:
    e = named_euler(str(rng.choice(["arms_down", "arms_down", "a_pose", "hands_on_hips", "arms_crossed"])))
    e = jitter(e, rng, 0.06, ["spine1", "spine2", "spine3", "neck", "head", "left_shoulder", "right_shoulder",
                              "left_elbow", "right_elbow", "left_wrist", "right_wrist"])
    return jitter(e, rng, 0.03, ["left_hip", "right_hip", "left_knee", "right_knee"])


# ----------------------------------------------------------------------------------------------- activities
def _floor_activity(ctx: _Ctx, rng, activity: str) -> Placement | None:
    G = np.eye(3)
    if activity == "walking":
        from volsmpl.body.gait import walk_cycle
        orient, pose = walk_cycle(torch.tensor([rng.uniform(0.0, 1.0)], dtype=torch.float64))
        G = Rotation.from_rotvec(orient[0].numpy()).as_matrix()
        body_pose = pose[0].numpy()
    elif activity == "crouching":
        e = named_euler("squatting" if rng.random() < 0.7 else "kneeling")
        body_pose = _euler_pose(jitter(e, rng, 0.05))
    else:
        body_pose = _euler_pose(_standing_euler(rng))
    xz = ctx.free_spot(rng)
    if xz is None:
        return None
    R = _yaw([np.sin(a := rng.uniform(0, 2 * np.pi)), 0.0, np.cos(a)])
    v_b = ctx.pose(G, body_pose)
    return ctx.finish(activity, G, body_pose, R, ctx.on_floor(v_b, R, xz), None, floor=True)


def _sitting(ctx: _Ctx, rng) -> Placement | None:
    seats = [s for s in ctx.room.seats() if s.category in SEAT_CATEGORIES]
    if not seats:
        return None
    seat = seats[rng.integers(len(seats))]
    item = ctx.room.items[seat.item]
    tmpl, TR, Tt = item.template, item.transform[:3, :3], item.transform[:3, 3]
    hip = -1.45 - 0.15 * rng.random()
    ab = rng.uniform(0.05, 0.15)
    e = set_joints(named_euler("sitting"), left_hip=(hip, 0, ab), right_hip=(hip, 0, -ab),
                   spine1=(rng.uniform(-0.1, 0.15), 0, 0), left_shoulder=(0, -0.35, -1.2),
                   right_shoulder=(0, 0.35, 1.2), left_elbow=(0, -0.9, 0), right_elbow=(0, 0.9, 0))
    e = jitter(e, rng, 0.05, ["spine2", "spine3", "neck", "head", "left_shoulder", "right_shoulder",
                              "left_elbow", "right_elbow", "left_wrist", "right_wrist"])
    G = np.eye(3)
    target = seat.height - ctx.room.floor_y - rng.uniform(0.005, 0.02)  # feet just above the floor when seated

    def drop(knee):
        ek = e.copy()
        ek[_idx("left_knee", "right_knee"), 0] = knee
        ek[_idx("left_ankle", "right_ankle"), 0] = float(np.clip(-(hip + knee), -0.7, 0.5))
        v = ctx.pose(G, _euler_pose(ek))
        return float(ctx.parts(v, "pelvis")[:, 1].min() - ctx.parts(v, "left_foot", "right_foot")[:, 1].min()), ek, v

    lo, hi = 0.7, -hip + 0.02
    if drop(hi)[0] <= target:
        lo = hi
    for _ in range(10):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if drop(mid)[0] < target else (lo, mid)
    _, e, v = drop(lo)
    # in the template frame (body +Z = the seat's facing): x_template = x_body + q
    pos_t = TR.T @ (seat.position - Tt)
    sv = tmpl.mesh.vertices[tmpl.mesh.faces[tmpl.regions["seat"]]].reshape(-1, 3)
    pelvis = ctx.parts(v, "pelvis")
    q = np.zeros(3)
    q[0] = pos_t[0] - pelvis[:, 0].mean() + rng.uniform(-0.03, 0.03)
    if "back" in tmpl.regions:
        back_front = tmpl.mesh.vertices[tmpl.mesh.faces[tmpl.regions["back"]]].reshape(-1, 3)[:, 2].max()
        q[2] = back_front + rng.uniform(0.01, 0.04) - ctx.parts(v, "pelvis", "belly", "chest")[:, 2].min()
        calves = ctx.parts(v, "left_shin", "right_shin")
        calves = calves[calves[:, 1] < pelvis[:, 1].min()]
        q[2] = max(q[2], sv[:, 2].max() + 0.02 - calves[:, 2].min())  # the seat's front edge behind the calves
    else:
        q[2] = 0.5 * (sv[:, 2].min() + sv[:, 2].max()) - pelvis[:, 2].mean() - 0.06
    q[1] = sv[:, 1].max() + 0.03 - pelvis[:, 1].min()
    p = TR @ q + Tt
    body_pose = _euler_pose(e)
    s = ctx.settle(v @ TR.T + p, np.array([0.0, -1.0, 0.0]))
    if s is None:
        return None
    return ctx.finish("sitting", G, body_pose, TR, p - [0.0, s, 0.0], item.mesh, floor=False)


def _pick(ctx: _Ctx, rng, category: str):
    """One of the room's items of `category`, drawn by rng; None when the room has none (rng not drawn then)."""
    items = [it for it in ctx.room.items if it.category == category]
    return items[rng.integers(len(items))] if items else None


def _lying(ctx: _Ctx, rng) -> Placement | None:
    item = _pick(ctx, rng, "bed")
    if item is None:
        return None
    tmpl, TR, Tt = item.template, item.transform[:3, :3], item.transform[:3, 3]
    G = Rotation.from_euler("x", -90, degrees=True).as_matrix()  # supine, head towards the headboard (-Z)
    e = set_joints(named_euler("arms_down"), left_shoulder=(0, 0, -1.15), right_shoulder=(0, 0, 1.15))
    e = jitter(e, rng, 0.04, ["spine1", "spine2", "spine3", "left_shoulder", "right_shoulder", "left_elbow",
                              "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip"])
    hips = _idx("left_hip", "right_hip")
    e[hips, 0] = np.clip(e[hips, 0], -0.05, 0.0)
    e = set_joints(e, neck=(rng.uniform(0.0, 0.25), rng.uniform(-0.3, 0.3), 0))
    v = ctx.pose(G, _euler_pose(e))
    pil = [i for i, n in enumerate(tmpl.component_names) if n.startswith("pillow")]
    pv = tmpl.mesh.vertices[tmpl.mesh.faces[np.isin(tmpl.component, pil)]].reshape(-1, 3)
    mv = tmpl.mesh.vertices[tmpl.mesh.faces[tmpl.regions["seat"]]].reshape(-1, 3)
    half_w = 0.5 * (mv[:, 0].max() - mv[:, 0].min())
    q = np.array([0.5 * (mv[:, 0].min() + mv[:, 0].max()) - ctx.parts(v, "pelvis")[:, 0].mean()
                  + rng.uniform(-1, 1) * max(half_w - 0.4, 0.0),
                  mv[:, 1].max() + 0.03 - v[:, 1].min(),
                  pv[:, 2].max() + 0.015 - ctx.parts(v, "head")[:, 2].min()])
    p = TR @ q + Tt
    s = ctx.settle(v @ TR.T + p, np.array([0.0, -1.0, 0.0]))
    if s is None:
        return None
    return ctx.finish("lying", G, _euler_pose(e), TR, p - [0.0, s, 0.0], item.mesh, floor=False)


def _leaning_wall(ctx: _Ctx, rng) -> Placement | None:
    wall = ctx.room.walls()[rng.integers(4)]
    if wall.half_size[0] < 0.8:
        return None
    tilt = rng.uniform(0.04, 0.15)
    G = Rotation.from_euler("x", -tilt).as_matrix()  # the torso leans back
    e = _standing_euler(rng)
    hips = _idx("left_hip", "right_hip")
    e[hips, 0] = tilt * rng.uniform(0.5, 1.0)  # the legs swung back under the body
    v = ctx.pose(G, _euler_pose(e))
    R = _yaw(wall.normal)
    u = rng.uniform(-1, 1) * (wall.half_size[0] - 0.6)
    base = wall.center + u * wall.axes[0]
    p = base + wall.normal * (0.03 - v[:, 2].min())
    p[1] = ctx.room.floor_y + FLOOR_GAP - v[:, 1].min()
    s = ctx.settle(v @ R.T + p, -wall.normal)
    if s is None:
        return None
    mesh = dict(ctx.room.structure())[wall.name]
    return ctx.finish("leaning_wall", G, _euler_pose(e), R, p - s * wall.normal, mesh, floor=False)


def _leaning_table(ctx: _Ctx, rng) -> Placement | None:
    item = _pick(ctx, rng, "table")
    if item is None:
        return None
    c, A, h = item.footprint()
    a = int(rng.random() < h[1] / (h[0] + h[1]))  # sides by length: the long sides more often
    n2 = A[a] * (1.0 if rng.random() < 0.5 else -1.0)
    lean = rng.uniform(0.25, 0.45)
    G = Rotation.from_euler("x", lean).as_matrix()  # torso forward
    e = set_joints(named_euler("arms_down"), left_hip=(-lean, 0, 0.03), right_hip=(-lean, 0, -0.03))
    e = jitter(e, rng, 0.04, ["spine1", "spine2", "spine3", "neck", "head"])
    v = ctx.pose(G, _euler_pose(e))
    top = float(item.mesh.vertices[:, 1].max())
    soles = float(v[:, 1].min())
    front = float(ctx.parts(v, "left_thigh", "right_thigh", "belly", "pelvis")[:, 2].max())
    y, z, half = soles + top - ctx.room.floor_y + 0.008, front + rng.uniform(0.12, 0.2), rng.uniform(0.18, 0.26)
    targets = {"left": {"p": [half, y, z], "n": [0, -1, 0], "f": [0.3, 0, 1]},
               "right": {"p": [-half, y, z], "n": [0, -1, 0], "f": [-0.3, 0, 1]}}
    e = set_joints(e.copy(), left_shoulder=(0, -1.0, -0.9), right_shoulder=(0, 1.0, 0.9))
    top_b = soles + top - ctx.room.floor_y
    for _ in range(3):  # the palm point on the top: raise it until no hand vertex is below the top
        e, err = ctx.rig.reach(e, G, targets)
        low = ctx.parts(ctx.pose(G, _euler_pose(e)), "left_hand", "right_hand")[:, 1].min()
        if err > 0.02 or low >= top_b + 0.002:
            break
        for t in targets.values():
            t["p"][1] += top_b + 0.004 - low
    if err > 0.02 or low < top_b + 0.002:
        return None
    Rj, Pj = ctx.rig.joints(e, G)
    pm = np.mean([ctx.rig.palm(Rj, Pj, s)[0].numpy() for s in ("left", "right")], axis=0)
    R = _yaw([-n2[0], 0.0, -n2[1]])  # facing the table
    lat = A[1 - a] * rng.uniform(-1, 1) * max(h[1 - a] - 0.3, 0.0)
    palm_xz = c + n2 * (h[a] - rng.uniform(0.06, 0.12)) + lat
    r = R @ pm
    p = np.array([palm_xz[0] - r[0], ctx.room.floor_y + FLOOR_GAP - soles, palm_xz[1] - r[2]])
    return ctx.finish("leaning_table", G, _euler_pose(e), R, p, item.mesh, floor=False)


def _reaching_shelf(ctx: _Ctx, rng) -> Placement | None:
    item = _pick(ctx, rng, "shelf")
    if item is None:
        return None
    tmpl, TR, Tt = item.template, item.transform[:3, :3], item.transform[:3, 3]
    lo, hi = tmpl.mesh.bounds
    boards = [s["height"] for s in tmpl.supports() if 0.5 <= s["height"] + Tt[1] <= 1.7]
    if not boards:
        return None
    y_t = min(boards[rng.integers(len(boards))] + rng.uniform(0.08, 0.25), hi[1] - 0.05)
    x_t = rng.uniform(-1, 1) * max(0.5 * (hi[0] - lo[0]) - 0.12, 0.0)
    target_w = TR @ np.array([x_t, y_t, hi[2] + rng.uniform(0.02, 0.06)]) + Tt
    side = "right" if rng.random() < 0.65 else "left"
    sgn = 1.0 if side == "left" else -1.0
    G = np.eye(3)
    e = _standing_euler(rng)
    v = ctx.pose(G, _euler_pose(e))
    R = TR @ Rotation.from_euler("y", np.pi).as_matrix()  # facing the shelf's front
    p_y = ctx.room.floor_y + FLOOR_GAP - v[:, 1].min()
    _, Pj = ctx.rig.joints(e, G)
    sh = Pj[16 if side == "left" else 17].numpy()
    t_b = np.array([sh[0] - sgn * rng.uniform(-0.05, 0.12), target_w[1] - p_y, sh[2] + rng.uniform(0.3, 0.48)])
    if np.linalg.norm(t_b - sh) > 0.62 or t_b[1] < sh[1] - 0.45:
        return None
    e0 = set_joints(e.copy(), **{f"{side}_shoulder": (0, -sgn * 1.0, sgn * -0.3), f"{side}_elbow": (0, -sgn * 0.3, 0)})
    f = np.array([0.0, 1.0, 0.3]) / np.linalg.norm([0.0, 1.0, 0.3])
    e, err = ctx.rig.reach(e0, G, {side: {"p": t_b, "n": [0.0, 0.0, 1.0], "f": f}})
    if err > 0.05:
        return None
    p = target_w - R @ t_b
    p[1] = p_y
    return ctx.finish("reaching_shelf", G, _euler_pose(e), R, p, None, floor=True)


def affords(room, activity: str) -> bool:
    """Whether a room has what an activity needs (a seat, a bed, a table, a shelf; every room has floor and walls)."""
    if activity not in ACTIVITIES:
        raise ValueError(f"unknown activity {activity!r}; use one of {ACTIVITIES}.")
    cats = {it.category for it in room.items}
    need = {"sitting": set(SEAT_CATEGORIES), "lying": {"bed"}, "leaning_table": {"table"},
            "reaching_shelf": {"shelf"}}.get(activity)
    return need is None or bool(cats & need)


def place(room_seed: int, activity: str, rng: np.random.Generator, tries: int = TRIES) -> Placement | None:
    """A checked placement of a seeded body doing `activity` in room `room_seed` (None after `tries` failures).

    Betas are drawn from the calibrated population (heights 1.5-1.85 m for lying, 1.45-2.0 m otherwise)."""
    room = load_room(int(room_seed))
    if not affords(room, activity):
        return None
    cloud = room_cloud(int(room_seed))
    hr = (1.5, 1.85) if activity == "lying" else (1.45, 2.0)
    for _ in range(tries):
        betas = sample_betas(1, seed=int(rng.integers(2 ** 31)), height_range=hr)[0].numpy()
        ctx = _Ctx(room, cloud, betas)
        if activity in ("standing", "walking", "crouching"):
            out = _floor_activity(ctx, rng, activity)
        else:
            out = {"sitting": _sitting, "lying": _lying, "leaning_wall": _leaning_wall,
                   "leaning_table": _leaning_table, "reaching_shelf": _reaching_shelf}[activity](ctx, rng)
        if out is not None:
            return out
    return None
