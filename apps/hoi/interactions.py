"""Interaction recipes of the human–object database (apps/hoi/database.py): a pose, an object and its placement.

Each recipe `fn(rig, rng) -> Recipe` designs one kind of interaction in the body frame of an upright body
(Y up, facing +Z, the body model's output with transl 0): hand-designed joint angles (named poses where they
exist) with seeded variation inside `JOINT_LIMITS`, hands brought onto their contact places by a small inverse
kinematics (`Rig.reach` in rig.py: forward kinematics of the 24 joints in torch, angles bounded by the anatomical limits
through a sigmoid, so no solution leaves them), and the object template placed so that the body's contact
parts touch its contact region. The exact touching (and no interpenetration) is done by the database's
resolver: it slides the object along `Recipe.push` (the contact normal, pointing away from the body) until
the exact checks hold, or, for two-hand grips (`Recipe.grip`), re-solves the hands' gap.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from volsmpl.body.model import SMPL_JOINT_NAMES
from volsmpl.body.poses import BODY_JOINTS
from volsmpl.scene.objects import make_object

from volsmpl.body.rig import Rig, jitter, named_euler, set_joints

_J = {n: i for i, n in enumerate(SMPL_JOINT_NAMES)}
#: the interaction kinds: name -> (recipe function name, object category)
KINDS: dict[str, str] = {}


# ----------------------------------------------------------------------------------------------- recipes
@dataclass
class Recipe:
    """One designed interaction in the body frame: x_body = R_obj @ x_template + t_obj.

    push: unit direction the object slides along to separate from the body (the contact normal), or None
    for a two-hand grip (grip: {'axis': (3,) from the right palm to the left palm, 'targets': fn(gap) ->
    (euler, err)}, the hands' gap re-solved). contacts: [(part, region, required)]; optional pairs are kept
    in the ground truth only where they touch (within CONTACT_TOL)."""

    kind: str
    euler: np.ndarray
    global_R: np.ndarray
    template: object
    R_obj: np.ndarray
    t_obj: np.ndarray
    contacts: list
    push: np.ndarray | None = None
    grip: dict | None = None
    floor_y: float = 0.0  # body-frame height of the floor (informative)
    yaw_range: tuple = (-60.0, 60.0)  # camera yaw around the pair, degrees (0: in front of the body)
    info: dict = field(default_factory=dict)


def _rot_y(deg: float) -> np.ndarray:
    return Rotation.from_euler("y", deg, degrees=True).as_matrix()


def _soles(rig: Rig, v: np.ndarray) -> float:
    return float(rig.part_vertices(v, "left_foot", "right_foot")[:, 1].min())


def _bisect(f, lo: float, hi: float, target: float, n: int = 14) -> float:
    """x in [lo, hi] with f(x) = target for an increasing f (clamped at the ends)."""
    if f(hi) <= target:
        return hi
    if f(lo) >= target:
        return lo
    for _ in range(n):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < target else (lo, mid)
    return 0.5 * (lo + hi)


def _sit(kind: str, category: str):
    def recipe(rig: Rig, rng: np.random.Generator, template_seed: int) -> Recipe:
        tmpl = make_object(category, seed=template_seed)
        e = named_euler("sitting")
        hip = -1.45 - 0.15 * rng.random()
        spine = rng.uniform(-0.1, 0.15)
        e = set_joints(e, left_hip=(hip, 0, 0.12), right_hip=(hip, 0, -0.12), spine1=(spine, 0, 0),
                 left_shoulder=(0, -0.35, -1.2), right_shoulder=(0, 0.35, 1.2),
                 left_elbow=(0, -0.9, 0), right_elbow=(0, 0.9, 0))
        e = jitter(e, rng, 0.05, ["spine1", "spine2", "spine3", "neck", "head", "left_shoulder", "right_shoulder",
                                  "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_ankle", "right_ankle"])
        G = np.eye(3)
        seat = tmpl.seats()[int(rng.integers(len(tmpl.seats())))] if tmpl.seats() else None
        seat_h = seat["height"] if seat else float(tmpl.extents[1])

        def drop(knee):  # seat contact height minus the soles' height
            ek = set_joints(e.copy(), left_knee=(knee, 0, 0), right_knee=(knee, 0, 0))
            ek = set_joints(ek, left_ankle=(float(np.clip(-(hip + knee), -0.7, 0.5)), 0, 0),
                      right_ankle=(float(np.clip(-(hip + knee), -0.7, 0.5)), 0, 0))
            v = rig.pose(ek, G).vertices[0].double().numpy()
            return float(rig.part_vertices(v, "pelvis")[:, 1].min()) - _soles(rig, v), ek

        knee = _bisect(lambda k: drop(k)[0], 0.7, float(-hip) + 0.02, seat_h + 0.01, n=10)
        e = drop(knee)[1]
        v = rig.pose(e, G).vertices[0].double().numpy()
        back = rig.part_vertices(v, "pelvis", "belly", "chest")
        seat_lo, seat_hi = tmpl._region_box("seat")
        x_pos = 0.0 if seat is None else seat["position"][0]
        if "back" in tmpl.regions:  # the body's back a little in front of the backrest...
            back_front = tmpl._region_box("back")[1][2] if category == "chair" else seat_lo[2]
            tz = float(back[:, 2].min()) - rng.uniform(0.01, 0.04) - back_front
            # ...but the seat's front edge behind the calves (deep sofas: sitting forward)
            calves = rig.part_vertices(v, "left_shin", "right_shin")
            tz = min(tz, float(calves[calves[:, 1] < float(rig.part_vertices(v, "pelvis")[:, 1].min()), 2].min())
                     - 0.02 - seat_hi[2])
        else:  # stool: the seat's centre under the buttocks and upper thighs
            tz = float(rig.part_vertices(v, "pelvis")[:, 2].mean()) + 0.06 - 0.5 * (seat_lo[2] + seat_hi[2])
        ty = float(rig.part_vertices(v, "pelvis")[:, 1].min()) - seat_hi[1] + 0.02  # starts 2 cm into the seat
        t = np.array([-x_pos, ty, tz])
        return Recipe(kind, e, G, tmpl, np.eye(3), t,
                      [("pelvis", "seat", True), ("left_thigh", "seat", False), ("right_thigh", "seat", False),
                       ("chest", "back", False), ("belly", "back", False)],
                      push=np.array([0.0, -1.0, 0.0]), floor_y=ty, yaw_range=(-70.0, 70.0),
                      info={"floor": (-0.02, 0.15)})
    recipe.__name__ = kind
    return recipe


def lie_bed(rig: Rig, rng: np.random.Generator, template_seed: int) -> Recipe:
    tmpl = make_object("bed", seed=template_seed)
    G = Rotation.from_euler("x", -90, degrees=True).as_matrix()  # supine, head towards -Z (the headboard)
    e = named_euler("arms_down")
    e = set_joints(e, left_shoulder=(0, 0, -1.15), right_shoulder=(0, 0, 1.15))
    e = jitter(e, rng, 0.04, ["spine1", "spine2", "spine3", "left_shoulder", "right_shoulder", "left_elbow",
                              "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip"])
    e[[BODY_JOINTS.index("left_hip"), BODY_JOINTS.index("right_hip")], 0] = np.clip(
        e[[BODY_JOINTS.index("left_hip"), BODY_JOINTS.index("right_hip")], 0], -0.05, 0.0)
    sh = float(tmpl.sizes["seat_height"])
    comp_names = list(tmpl.component_names)
    pil = [i for i, n in enumerate(comp_names) if n.startswith("pillow")]
    pv = tmpl.mesh.vertices[tmpl.mesh.faces[np.isin(tmpl.component, pil)]].reshape(-1, 3)
    pz_hi = pv[:, 2].max()  # the pillows' foot-ward edge

    # the head on the mattress just foot-ward of the pillows (lying on the pillows would lift the shoulders)
    e = set_joints(e, neck=(rng.uniform(0.0, 0.25), rng.uniform(-0.3, 0.3), 0))
    v = rig.pose(e, G).vertices[0].double().numpy()
    tz = float(rig.part_vertices(v, "head")[:, 2].min()) - pz_hi - 0.015
    torso = rig.part_vertices(v, "pelvis")
    ty = float(torso[:, 1].min()) - sh + 0.02
    t = np.array([-float(torso[:, 0].mean()), ty, tz])
    return Recipe("lie_bed", e, G, tmpl, np.eye(3), t,
                  [("pelvis", "seat", True), ("chest", "seat", False), ("head", "any", False),
                   ("left_thigh", "seat", False), ("right_thigh", "seat", False), ("left_shin", "seat", False),
                   ("right_shin", "seat", False), ("left_upper_arm", "seat", False), ("right_upper_arm", "seat", False)],
                  push=np.array([0.0, -1.0, 0.0]), floor_y=ty, yaw_range=(40.0, 100.0))


def _standing(rng, sd=0.04):
    e = named_euler("arms_down")
    return jitter(e, rng, sd, ["spine1", "spine2", "spine3", "neck", "head", "left_hip", "right_hip"]), np.eye(3)


def _two_hands(kind: str, category: str):
    def recipe(rig: Rig, rng: np.random.Generator, template_seed: int) -> Recipe:
        tmpl = make_object(category, seed=template_seed)
        e, G = _standing(rng)
        for j in ("left_hip", "right_hip"):
            e[BODY_JOINTS.index(j), 0] = np.clip(e[BODY_JOINTS.index(j), 0], -0.1, 0.1)
        ext = tmpl.extents
        w = float(ext[0])
        _, P = rig.joints(e, G)
        P = P.numpy()
        v = rig.pose(e, G).vertices[0].double().numpy()
        front = float(rig.part_vertices(v, "belly", "chest")[:, 2].max())
        if category == "ball":
            yc = float(P[_J["spine3"], 1]) - rng.uniform(0.0, 0.15)
        else:
            yc = float(P[_J["spine1"], 1]) + rng.uniform(-0.05, 0.1)
        zc = front + rng.uniform(0.04, 0.09) + 0.5 * float(ext[2])
        # template centre (bbox centre) to body: rotation about y by a little yaw
        R = _rot_y(rng.uniform(-8, 8))
        c_t = np.array([0.0, 0.5 * ext[1], 0.0])
        t = np.array([0.0, yc, zc]) - R @ c_t
        axis = R @ np.array([1.0, 0.0, 0.0])
        fwd = R @ np.array([0.0, 0.0, 1.0])
        centre = R @ c_t + t
        off = 0.0 if category == "ball" else -0.02

        def solve(gap: float, start: np.ndarray):
            tg = {"left": {"p": centre + 0.5 * gap * axis + off * fwd, "n": -axis, "f": fwd},
                  "right": {"p": centre - 0.5 * gap * axis + off * fwd, "n": axis, "f": fwd}}
            return rig.reach(start, G, tg)

        e0 = set_joints(e.copy(), left_shoulder=(0, -0.9, -0.8), right_shoulder=(0, 0.9, 0.8),
                  left_elbow=(0, -1.0, 0), right_elbow=(0, 1.0, 0))
        return Recipe(kind, e0, G, tmpl, R, t,
                      [("left_hand", "grasp", True), ("right_hand", "grasp", True), ("chest", "any", False),
                       ("belly", "any", False)],
                      grip={"axis": axis, "solve": solve, "width": w}, floor_y=_soles(rig, v))
    recipe.__name__ = kind
    return recipe


def _one_hand(kind: str, category: str, region: str):
    def recipe(rig: Rig, rng: np.random.Generator, template_seed: int) -> Recipe:
        tmpl = make_object(category, seed=template_seed)
        side = "right" if rng.random() < 0.7 else "left"
        sgn = 1.0 if side == "left" else -1.0
        e, G = _standing(rng)
        _, P = rig.joints(e, G)
        P = P.numpy()
        sh = P[_J[f"{side}_shoulder"]]
        inward = np.array([-sgn, 0.0, 0.0])
        if category == "phone":  # in front of the chest, screen towards the face, palm behind it
            p = sh + np.array([-sgn * rng.uniform(0.08, 0.16), -rng.uniform(0.15, 0.25), rng.uniform(0.28, 0.36)])
            n = np.array([0.0, 0.45, 1.0]); n /= np.linalg.norm(n)
            f = np.array([-sgn * 0.3, 1.0, -0.45]); f -= (f @ n) * n; f /= np.linalg.norm(f)
        elif category == "bat":  # arm down-forward, bat across the palm pointing forward and down
            p = sh + np.array([sgn * 0.08, -rng.uniform(0.45, 0.52), rng.uniform(0.2, 0.28)])
            n = inward
            f = np.array([0.0, -1.0, 0.35]); f /= np.linalg.norm(f)
        else:  # cup, bottle: forearm forward, palm inwards, fingers forward
            p = sh + np.array([-sgn * rng.uniform(0.0, 0.06), -rng.uniform(0.28, 0.38), rng.uniform(0.3, 0.38)])
            n = inward
            f = np.array([0.0, 0.15, 1.0]); f /= np.linalg.norm(f)
        e0 = set_joints(e.copy(), **{f"{side}_shoulder": (0, sgn * -0.8, sgn * -1.0), f"{side}_elbow": (0, sgn * -1.2, 0)})
        e, err = rig.reach(e0, G, {side: {"p": p, "n": n, "f": f}})
        R_, P_ = rig.joints(e, G)
        pp, nn, ff = (x.numpy() for x in rig.palm(R_, P_, side))
        thumb = np.cross(nn, ff) * (-sgn)  # towards the thumb side of the hand
        ext = tmpl.extents
        if category in ("bottle", "cup"):  # upright, its side against the palm
            R = _rot_y(rng.uniform(0, 360)) if category == "bottle" else np.eye(3)
            if category == "cup":  # handle away from the palm, the body's side on the palm
                yaw = np.degrees(np.arctan2(nn[2], nn[0]))
                R = Rotation.from_euler("y", -yaw, degrees=True).as_matrix()
                r = float(tmpl.sizes["depth"]) / 2
                cx = float(ext[0]) / 2 - r  # the body's axis sits at x = -(width/2 - r) in the template
                axis_t = np.array([-cx, 0.0, 0.0])
            else:
                r, axis_t = float(ext[0]) / 2, np.zeros(3)
            y_mid = 0.5 * (0.1 + 0.62) * ext[1] if category == "bottle" else 0.5 * ext[1]
            c = pp + (r - 0.004) * nn  # axis point
            t = c - R @ (axis_t + np.array([0.0, y_mid, 0.0]))
        elif category == "phone":  # back (template -Y) on the palm, long side (template Z) along the fingers
            ey = -nn
            ez = -ff
            ex = np.cross(ey, ez)
            R = np.stack([ex, ey, ez], axis=1)
            t = pp + 0.002 * nn
        else:  # bat: its axis across the palm (thumb direction, tilted), handle region on the palm
            a = thumb + np.array([0.0, -0.35, 0.0])  # across the palm, tilted down
            a -= (a @ nn) * nn
            a /= np.linalg.norm(a)
            ax = np.cross(a, nn); ax /= np.linalg.norm(ax)
            R = np.stack([ax, -a, np.cross(ax, -a)], axis=1)  # template +Y (barrel -> handle) along -a
            L = float(ext[1])
            t = pp + (0.0125 - 0.003) * nn - R @ np.array([0.0, 0.84 * L, 0.0])  # handle radius 12.5 mm
        return Recipe(kind, e, G, tmpl, R, t,
                      [(f"{side}_hand", region, True), (f"{side}_forearm", "any", False)],
                      push=nn / np.linalg.norm(nn), floor_y=_soles(rig, rig.pose(e, G).vertices[0].double().numpy()),
                      yaw_range=(-60.0, 60.0), info={"ik_error": err, "side": side})
    recipe.__name__ = kind
    return recipe


def skateboard(rig: Rig, rng: np.random.Generator, template_seed: int) -> Recipe:
    tmpl = make_object("skateboard", seed=template_seed)
    ab, hip, knee = rng.uniform(0.12, 0.2), -rng.uniform(0.05, 0.3), rng.uniform(0.05, 0.45)
    e = named_euler("a_pose")
    e = set_joints(e, left_hip=(hip, 0, ab), right_hip=(hip, 0, -ab), left_knee=(knee, 0, 0), right_knee=(knee, 0, 0),
             left_ankle=(-(hip + knee), 0, -ab), right_ankle=(-(hip + knee), 0, ab))
    e = jitter(e, rng, 0.05, ["spine1", "spine2", "spine3", "neck", "head", "left_shoulder", "right_shoulder",
                              "left_elbow", "right_elbow"])
    G = np.eye(3)
    v = rig.pose(e, G).vertices[0].double().numpy()
    feet = rig.part_vertices(v, "left_foot", "right_foot")
    R = _rot_y(90.0)  # the board's length along the body's x
    ext = tmpl.extents
    top = float(ext[1])
    t = np.array([float(feet[:, 0].mean()), float(feet[:, 1].min()) - top + 0.01, float(feet[:, 2].mean())])
    return Recipe("skateboard", e, G, tmpl, R, t,
                  [("left_foot", "deck", True), ("right_foot", "deck", True)],
                  push=np.array([0.0, -1.0, 0.0]), floor_y=t[1], yaw_range=(-70.0, 70.0))


def _hands_on(kind: str, category: str, region: str):
    """Leaning on a table (palms on its top) or pushing a cart (palms on its handle)."""
    def recipe(rig: Rig, rng: np.random.Generator, template_seed: int) -> Recipe:
        tmpl = make_object(category, seed=template_seed)
        lean = rng.uniform(0.25, 0.45) if category == "table" else rng.uniform(0.05, 0.2)
        G = Rotation.from_euler("x", lean, degrees=False).as_matrix()  # torso forward
        e = named_euler("arms_down")
        e = set_joints(e, left_hip=(-lean, 0, 0.03), right_hip=(-lean, 0, -0.03))
        e = jitter(e, rng, 0.04, ["spine1", "spine2", "spine3", "neck", "head"])
        v = rig.pose(e, G).vertices[0].double().numpy()
        floor = _soles(rig, v)
        front = float(rig.part_vertices(v, "left_thigh", "right_thigh", "belly", "pelvis")[:, 2].max())
        ext = tmpl.extents
        if category == "table":
            top_y = floor + float(ext[1])
            half = rng.uniform(0.18, 0.26)
            z = front + rng.uniform(0.12, 0.2)
            targets = {"left": {"p": [half, top_y + 0.005, z], "n": [0, -1, 0], "f": [0.3, 0, 1]},
                       "right": {"p": [-half, top_y + 0.005, z], "n": [0, -1, 0], "f": [-0.3, 0, 1]}}
        else:
            hv = tmpl.mesh.vertices[tmpl.mesh.faces[tmpl.regions["handle"]]].reshape(-1, 3)
            top_y = floor + float(hv[:, 1].max()) - 0.015  # the bar's axis
            half = min(rng.uniform(0.16, 0.22), 0.5 * float(ext[0]) - 0.05)
            z = front + rng.uniform(0.1, 0.16)
            targets = {"left": {"p": [half, top_y + 0.005, z], "n": [0, -1, 0], "f": [0, 0, 1]},
                       "right": {"p": [-half, top_y + 0.005, z], "n": [0, -1, 0], "f": [0, 0, 1]}}
        e0 = set_joints(e.copy(), left_shoulder=(0, -1.0, -0.9), right_shoulder=(0, 1.0, 0.9))
        e, err = rig.reach(e0, G, targets)
        R_, P_ = rig.joints(e, G)
        palms = np.stack([rig.palm(R_, P_, s)[0].numpy() for s in ("left", "right")])
        if category == "table":
            tz = float(palms[:, 2].min()) - rng.uniform(0.06, 0.1) + 0.5 * float(ext[2])
            t = np.array([float(palms[:, 0].mean()) + rng.uniform(-0.1, 0.1), floor + 0.02, tz])
        else:
            # the cart stands on the person's floor; it slides along +Z (away from the body) onto the hands
            hz = 0.5 * (hv[:, 2].min() + hv[:, 2].max())
            t = np.array([float(palms[:, 0].mean()), floor, float(palms[:, 2].mean()) - hz])
        push = np.array([0.0, -1.0, 0.0]) if category == "table" else np.array([0.0, 0.0, 1.0])
        return Recipe(kind, e, G, tmpl, np.eye(3), t,
                      [("left_hand", region, True), ("right_hand", region, True)],
                      push=push, floor_y=floor, yaw_range=(-75.0, 75.0),
                      info={"ik_error": err, "floor": (-0.04, 0.04)})
    recipe.__name__ = kind
    return recipe


RECIPES = {
    "sit_chair": (_sit("sit_chair", "chair"), "chair"),
    "sit_stool": (_sit("sit_stool", "stool"), "stool"),
    "sit_sofa": (_sit("sit_sofa", "sofa"), "sofa"),
    "lie_bed": (lie_bed, "bed"),
    "hold_box": (_two_hands("hold_box", "box"), "box"),
    "carry_ball": (_two_hands("carry_ball", "ball"), "ball"),
    "hold_bat": (_one_hand("hold_bat", "bat", "handle"), "bat"),
    "hold_bottle": (_one_hand("hold_bottle", "bottle", "grasp"), "bottle"),
    "hold_cup": (_one_hand("hold_cup", "cup", "grasp"), "cup"),
    "hold_phone": (_one_hand("hold_phone", "phone", "back"), "phone"),
    "skateboard": (skateboard, "skateboard"),
    "lean_table": (_hands_on("lean_table", "table", "top"), "table"),
    "push_cart": (_hands_on("push_cart", "cart", "handle"), "cart"),
}
KINDS.update({k: c for k, (_, c) in RECIPES.items()})
