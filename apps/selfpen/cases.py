"""The self-intersection case set: named recipes of self-intersecting bodies and their data file.

Each recipe names joint angles (x, y, z Euler radians per joint, signs as in volsmpl.body.poses;
joints left out stay at the T-pose) and a shape drawn from the default body's population
(`sample_betas` with a seed, height and gender range). `generate_cases` turns every recipe into
betas (10), global_orient (3) and body_pose (69) (rounded to 6 decimals, so the file regenerates
bit-identically) and verifies with the exact triangle counter that the body self-intersects
(pose-induced collisions > 0, see `triangles.body_collisions`).

    python -m volsmpl.apps.selfpen.cases            # rewrite cases.json
    python -m volsmpl.apps.selfpen.cases --check    # verify cases.json is what the recipes give
    cases = load_cases()                            # list of Case

A case file (this one or a user's, e.g. examples/selfpen/my_bodies.json) holds body parameters only: no
translation, units or up axis. Its bodies are volsmpl's default body in volsmpl's frame (metres, Y up).
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

CASES_FILE = Path(__file__).resolve().parent / "cases.json"
NUM_BETAS, POSE_DIM = 10, 69
DECIMALS = 6


@dataclass(frozen=True)
class Recipe:
    """A self-intersecting body: joint Euler angles and a population shape.

    joints: joint name -> (x, y, z) radians; seed/height/gender: arguments of sample_betas
    (height in metres, gender 0 = male .. 1 = female); yaw: global rotation about +Y (radians).
    """

    name: str
    description: str
    joints: dict
    seed: int
    height: tuple = (1.38, 2.03)
    gender: tuple = (0.0, 1.0)
    yaw: float = 0.0


def _r(name, description, seed, height=(1.38, 2.03), gender=(0.0, 1.0), yaw=0.0, **joints):
    return Recipe(name, description, joints, seed, height, gender, yaw)


ARMS_DOWN_L, ARMS_DOWN_R = (0.0, 0.0, -1.35), (0.0, 0.0, 1.35)

RECIPES = (
    _r("forearm_through_torso_left", "left forearm folded into the belly", 1,
       left_shoulder=(0.0, -0.55, -1.25), left_elbow=(0.0, -2.5, 0.0), right_shoulder=ARMS_DOWN_R),
    _r("forearm_through_torso_right", "right forearm folded into the chest", 2, height=(1.75, 2.03), gender=(0.0, 0.4),
       right_shoulder=(0.0, 0.7, 1.0), right_elbow=(0.0, 2.55, 0.0), left_shoulder=ARMS_DOWN_L),
    _r("hands_through_thighs", "both arms pressed down, hands inside the thighs", 3, gender=(0.6, 1.0),
       left_shoulder=(0.0, -0.15, -1.5), right_shoulder=(0.0, 0.15, 1.5)),
    _r("seated_hands_in_thighs", "sitting, hands pushed into the thighs", 4, height=(1.45, 1.7),
       left_hip=(-1.55, 0.0, 0.1), right_hip=(-1.55, 0.0, -0.1), left_knee=(1.55, 0.0, 0.0), right_knee=(1.55, 0.0, 0.0),
       left_shoulder=(0.0, -0.55, -1.3), right_shoulder=(0.0, 0.55, 1.3), left_elbow=(0.0, -0.3, 0.0), right_elbow=(0.0, 0.3, 0.0)),
    _r("crossed_legs_standing", "standing, left leg crossed through the right", 5,
       left_hip=(-0.2, 0.0, -0.45), right_hip=(0.1, 0.0, 0.3), left_shoulder=ARMS_DOWN_L, right_shoulder=ARMS_DOWN_R),
    _r("crossed_legs_seated", "sitting, right thigh crossed through the left", 6, gender=(0.5, 1.0),
       left_hip=(-1.5, 0.0, 0.0), right_hip=(-1.7, 0.0, 0.45), left_knee=(1.5, 0.0, 0.0), right_knee=(1.4, 0.0, 0.0),
       left_shoulder=ARMS_DOWN_L, right_shoulder=ARMS_DOWN_R),
    _r("arm_through_head", "right arm raised, forearm bent through the head", 7, height=(1.6, 1.9),
       right_shoulder=(0.8, -0.6, -1.6), right_elbow=(0.0, -1.6, 0.0), left_shoulder=ARMS_DOWN_L),
    _r("forearm_through_shoulder", "left forearm raised across the chest into the right shoulder", 8, gender=(0.0, 0.5),
       left_shoulder=(0.0, -1.3, -0.1), left_elbow=(0.0, -2.5, 0.0), left_wrist=(0.0, 0.0, 0.5), right_shoulder=ARMS_DOWN_R),
    _r("deep_squat", "deep squat, calves inside the thighs", 9,
       left_hip=(-1.9, 0.0, 0.35), right_hip=(-1.9, 0.0, -0.35), left_knee=(2.6, 0.0, 0.0), right_knee=(2.6, 0.0, 0.0),
       left_ankle=(-0.5, 0.0, 0.0), right_ankle=(-0.5, 0.0, 0.0), spine1=(0.35, 0.0, 0.0),
       left_shoulder=(0.0, -1.2, -0.6), right_shoulder=(0.0, 1.2, 0.6)),
    _r("sitting_on_heels", "kneeling back onto the heels, heels inside the buttocks", 10, height=(1.38, 1.65),
       left_hip=(0.0, 0.0, 0.05), right_hip=(0.0, 0.0, -0.05), left_knee=(3.0, 0.0, 0.0), right_knee=(3.0, 0.0, 0.0),
       left_ankle=(1.1, 0.0, 0.0), right_ankle=(1.1, 0.0, 0.0), left_shoulder=ARMS_DOWN_L, right_shoulder=ARMS_DOWN_R),
    _r("knee_into_chest", "left thigh pulled through the belly", 11, gender=(0.0, 0.3),
       left_hip=(-2.3, 0.0, 0.0), left_knee=(1.6, 0.0, 0.0), spine1=(0.5, 0.0, 0.0), spine2=(0.3, 0.0, 0.0),
       left_shoulder=ARMS_DOWN_L, right_shoulder=ARMS_DOWN_R),
    _r("arms_crossed_deep", "arms folded through each other and the chest", 12, height=(1.8, 2.03),
       left_shoulder=(0.0, -1.2, -1.0), right_shoulder=(0.0, 1.2, 1.0), left_elbow=(0.0, -2.4, 0.0), right_elbow=(0.0, 2.4, 0.0)),
    _r("forward_bend_arms_in_legs", "bent forward, arms hanging into the thighs", 14,
       spine1=(0.69, 0.0, 0.0), spine2=(0.64, 0.0, 0.0), spine3=(0.8, 0.0, 0.0),
       left_shoulder=(0.0, -1.7, -0.99), right_shoulder=(0.0, 1.61, -0.31)),
    _r("head_into_forearm", "head tilted into the raised, bent left forearm", 15, height=(1.5, 1.75),
       neck=(0.0, 0.0, -0.4), head=(0.0, 0.0, -0.3), left_shoulder=(0.8, 0.6, 1.6), left_elbow=(0.0, 2.0, 0.0),
       right_shoulder=ARMS_DOWN_R),
    _r("crossed_ankles", "ankles crossed, left foot through the right shin", 16, gender=(0.4, 1.0),
       left_hip=(0.0, 0.0, -0.35), right_hip=(0.0, 0.0, 0.2), left_knee=(0.3, 0.0, 0.0),
       left_shoulder=ARMS_DOWN_L, right_shoulder=ARMS_DOWN_R),
    _r("hand_behind_into_buttock", "right arm swung back and down, hand inside the buttock", 17, height=(1.7, 2.03),
       right_shoulder=(0.0, 1.03, 2.03), right_elbow=(0.0, 1.04, 0.0), left_shoulder=(0.0, 0.0, -0.79)),
    _r("elbows_into_waist", "elbows pressed into the waist, forearms forward", 18, gender=(0.0, 1.0), yaw=0.5,
       left_shoulder=(0.0, 0.2, -1.55), right_shoulder=(0.0, -0.2, 1.55), left_elbow=(0.0, -1.5, 0.0), right_elbow=(0.0, 1.5, 0.0)),
)


@dataclass
class Case:
    """One body to repair: betas (10,), global_orient (3,), body_pose (69,) float32 tensors."""

    name: str
    betas: torch.Tensor
    global_orient: torch.Tensor
    body_pose: torch.Tensor
    description: str = ""
    collisions: int | None = None  # pose-induced triangle pairs recorded when the file was generated
    extra: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------------------- building
def _round(x) -> list:
    return [round(float(v), DECIMALS) + 0.0 for v in np.asarray(x, np.float64).ravel()]


def build_case(recipe: Recipe) -> dict:
    """Recipe -> JSON-able dict (name, description, betas, global_orient, body_pose); no verification."""
    from volsmpl.body.poses import BODY_JOINTS, euler_to_body_pose
    from volsmpl.body.shapes import sample_betas

    euler = np.zeros((1, 23, 3))
    for joint, angles in recipe.joints.items():
        if joint not in BODY_JOINTS:
            raise ValueError(f"recipe {recipe.name!r}: unknown joint {joint!r}; joints are {BODY_JOINTS}")
        euler[0, BODY_JOINTS.index(joint)] = angles
    betas = sample_betas(1, NUM_BETAS, seed=recipe.seed, height_range=recipe.height, gender_range=recipe.gender)[0]
    return {"name": recipe.name, "description": recipe.description, "betas": _round(betas.numpy()),
            "global_orient": _round([0.0, recipe.yaw, 0.0]), "body_pose": _round(euler_to_body_pose(euler)[0].numpy())}


def generate_cases(body=None, recipes=RECIPES, log=None) -> list[dict]:
    """Build every recipe and count its pose-induced triangle collisions (stored as 'collisions') and
    those between two parts the self-penetration loss may push apart ('collidable': not the same part,
    not kinematic neighbours or COAP's ignored pairs, see optimize.count_collidable).

    Raises ValueError when a recipe has no collidable collision: the case set must only hold bodies a
    volumetric self-penetration loss can act on (folds at joints alone do not count).
    """
    from volsmpl import create_body
    from volsmpl.body.partition import Partition
    from .triangles import body_collisions, count_collidable

    body = body or create_body()
    part = Partition(body)
    labels, mask = part.face_labels.cpu().numpy(), part.collision_mask.cpu().numpy()
    out = []
    for r in recipes:
        d = build_case(r)
        c = case_from_dict(d)
        pairs = body_collisions(body, c.betas, c.global_orient, c.body_pose)["pairs"]
        n, k = len(pairs), count_collidable(pairs, labels, mask)
        if k == 0:
            raise ValueError(f"recipe {r.name!r} has {n} pose-induced intersecting triangle pairs on the default body but "
                             f"none between parts that may collide; change its angles so the limbs really cross")
        d["collisions"], d["collidable"] = n, k
        out.append(d)
        if log:
            log(f"{r.name:28s} {n:5d} intersecting triangle pairs, {k:5d} between collidable parts")
    return out


def cases_to_json(cases: list[dict]) -> str:
    """Deterministic text of a case list (one case per line)."""
    lines = [json.dumps(c, separators=(", ", ": ")) for c in cases]
    return '{"version": 1, "cases": [\n' + ",\n".join(lines) + "\n]}\n"


# ---------------------------------------------------------------------------------------- loading
#: the largest joint rotation (radians) of an axis-angle pose: 2 pi (a rotation by more is the same as one by less);
#: and the largest shape coefficient accepted (the shape space's coefficients are in standard deviations: 3 is rare)
MAX_ANGLE, MAX_BETA = 2 * np.pi, 10.0


def _check_plausible(vals: dict, where: str) -> None:
    """A pose in degrees or shape coefficients of another scale are refused: one line naming the field."""
    for key in ("global_orient", "body_pose"):
        angles = np.linalg.norm(vals[key].numpy().reshape(-1, 3), axis=1)
        if angles.max() > MAX_ANGLE:
            j = int(angles.argmax())
            raise ValueError(f"{where}: '{key}' turns joint {j} by {angles.max():.3g} rad (axis-angle in radians, at "
                             f"most 2 pi): is it in degrees? multiply by pi / 180")
    b = float(np.abs(vals["betas"].numpy()).max())
    if b > MAX_BETA:
        raise ValueError(f"{where}: 'betas' reaches {b:.3g}; shape coefficients are in standard deviations of the "
                         f"shape space (|beta| <= {MAX_BETA:g}; 3 is already rare): betas of another model or scale?")


def case_from_dict(d: dict, where: str = "case") -> Case:
    """Validate one case dict (name, betas (10), global_orient (3), body_pose (69), finite) -> Case."""
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected an object with name, betas, global_orient, body_pose; got {type(d).__name__}")
    name = d.get("name")
    if not isinstance(name, str) or not name:
        raise ValueError(f"{where}: missing 'name' (a non-empty string)")
    where = f"{where} {name!r}"
    sizes = {"betas": NUM_BETAS, "global_orient": 3, "body_pose": POSE_DIM}
    vals = {}
    for key, n in sizes.items():
        if key not in d:
            raise ValueError(f"{where}: missing '{key}' ({n} numbers)")
        try:
            a = np.asarray(d[key], dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise ValueError(f"{where}: '{key}' must be a list of {n} numbers ({e})") from None
        if a.ndim != 1 or a.size != n:
            hint = " (SMPL body_pose: 23 joints x 3 axis-angle)" if key == "body_pose" else ""
            raise ValueError(f"{where}: '{key}' must have {n} numbers{hint}, got shape {a.shape}")
        if not np.isfinite(a).all():
            bad = np.nonzero(~np.isfinite(a))[0].tolist()
            raise ValueError(f"{where}: '{key}' contains NaN or Inf at indices {bad[:8]}")
        vals[key] = torch.as_tensor(a, dtype=torch.float32)
    _check_plausible(vals, where)
    return Case(name=name, description=str(d.get("description", "")), collisions=d.get("collisions"), **vals)


def load_cases(path: str | Path = CASES_FILE, names: list[str] | None = None) -> list[Case]:
    """Read and validate a case file ({"cases": [...]} or a bare list); optionally keep only `names` (in that order)."""
    from volsmpl.apps.checks import read_json

    path = Path(path)
    if path == CASES_FILE and not path.exists():
        raise FileNotFoundError(f"case file not found: {path} (regenerate the default one with "
                                f"`python -m volsmpl.apps.selfpen.cases`)")
    data = read_json(path, "case file", "--case-file")
    items = data.get("cases") if isinstance(data, dict) else data
    if not isinstance(items, list) or not items:
        raise ValueError(f"{path}: expected a non-empty list of cases (or {{\"cases\": [...]}})")
    cases = [case_from_dict(d, f"{path.name} case {i}") for i, d in enumerate(items)]
    seen = set()
    for c in cases:
        if c.name in seen:
            raise ValueError(f"{path}: case name {c.name!r} appears twice")
        seen.add(c.name)
    if names:
        by = {c.name: c for c in cases}
        missing = [n for n in names if n not in by]
        if missing:
            raise ValueError(f"unknown case(s) {missing}; {path.name} holds {sorted(by)}")
        cases = [by[n] for n in names]
    return cases


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="regenerate (or --check) the self-intersection case file")
    p.add_argument("--out", default=str(CASES_FILE))
    p.add_argument("--check", action="store_true", help="compare with the file instead of writing it")
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    text = cases_to_json(generate_cases(log=print))
    if a.check:
        same = Path(a.out).exists() and Path(a.out).read_text() == text
        print("identical" if same else f"{a.out} differs from the recipes")
        return 0 if same else 1
    Path(a.out).write_text(text)
    print(f"wrote {len(RECIPES)} cases to {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
