"""Part tables: how a SMPL-family kinematic tree is merged into ~15 rigid parts (COAP's scheme).

Each kept joint k owns one part: its own vertices plus those of every merged joint whose nearest
kept ancestor is k. Merges follow COAP (Mihajlovic et al. 2022):

SMPL (24 joints) -> 16 parts, SMPL-H (52) -> 16 parts: head into neck, toes into feet, spine1 into
pelvis, collars into spine3, hands/fingers into wrists.
SMPL-X (55) -> 15 parts: as SMPL-H, and additionally spine3 into spine2; jaw and eyes go with the
head into the neck part.

| part | SMPL/SMPL-H joint | SMPL-X joint | merged joints (SMPL / SMPL-X) |
|------|-------------------|--------------|-------------------------------|
| pelvis | 0 | 0 | spine1 (3) |
| left_thigh, right_thigh | 1, 2 | 1, 2 | |
| left_shin, right_shin | 4, 5 | 4, 5 | |
| belly | 6 | 6 | - / spine3 (9), collars (13, 14) |
| left_foot, right_foot | 7, 8 | 7, 8 | toes (10, 11) |
| chest | 9 | - | collars (13, 14) |
| head | 12 | 12 | head (15); SMPL-X: jaw, eyes (22-24) |
| left/right_upper_arm | 16, 17 | 16, 17 | |
| left/right_forearm | 18, 19 | 18, 19 | |
| left/right_hand | 20, 21 | 20, 21 | hands (SMPL 22, 23; SMPL-H 22-51; SMPL-X 25-54) |
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BODY_TYPES = {24: "smpl", 52: "smplh", 55: "smplx"}

_KEPT = {
    "smpl": (0, 1, 2, 4, 5, 6, 7, 8, 9, 12, 16, 17, 18, 19, 20, 21),
    "smplh": (0, 1, 2, 4, 5, 6, 7, 8, 9, 12, 16, 17, 18, 19, 20, 21),
    "smplx": (0, 1, 2, 4, 5, 6, 7, 8, 12, 16, 17, 18, 19, 20, 21),
}
_PART_NAMES = {
    0: "pelvis", 1: "left_thigh", 2: "right_thigh", 4: "left_shin", 5: "right_shin", 6: "belly",
    7: "left_foot", 8: "right_foot", 9: "chest", 12: "head", 16: "left_upper_arm", 17: "right_upper_arm",
    18: "left_forearm", 19: "right_forearm", 20: "left_hand", 21: "right_hand",
}
# COAP's extra joint pairs never counted as self-penetration (besides parent-child parts), in joint ids
# of the 22 shared body joints; mapped to parts through the merges.
_SELFPEN_IGNORED_JOINT_PAIRS = (
    (1, 2), (1, 3), (2, 3), (3, 9), (9, 15), (9, 16), (9, 17), (12, 6), (12, 16), (12, 17), (13, 6),
    (13, 12), (14, 6), (14, 12), (0, 6), (0, 9), (0, 16), (0, 17), (6, 16), (6, 17),
)


@dataclass(frozen=True)
class PartTable:
    """Joint-to-part mapping of one body type.

    body_type: 'smpl' | 'smplh' | 'smplx'; num_joints: J kinematic joints;
    part_joints: (K,) joint whose transform defines part k; joint_to_part: (J,) part of every joint;
    part_parents: (K,) parent part (-1 for the root); part_names: (K,) names;
    collision_mask: (K, K) bool, True where two parts may penetrate each other (not the same part,
    not kinematically adjacent, not one of COAP's ignored pairs).
    """

    body_type: str
    num_joints: int
    part_joints: tuple
    joint_to_part: tuple
    part_parents: tuple
    part_names: tuple
    collision_mask: np.ndarray

    @property
    def num_parts(self) -> int:
        return len(self.part_joints)

    def to_dict(self) -> dict:
        return {"body_type": self.body_type, "num_joints": self.num_joints, "part_joints": list(self.part_joints),
                "part_names": list(self.part_names), "part_parents": list(self.part_parents)}


def make_part_table(parents) -> PartTable:
    """Build the part table for a kinematic tree.

    Args:
        parents: (J,) parent joint ids (parents[0] = -1), J in {24 (SMPL), 52 (SMPL-H), 55 (SMPL-X)}.
    """
    parents = [int(p) for p in np.asarray(parents).reshape(-1)]
    J = len(parents)
    if J not in BODY_TYPES:
        raise ValueError(f"unsupported body with {J} joints: volsmpl supports SMPL (24), SMPL-H (52) and SMPL-X (55); "
                         f"MANO (16) and FLAME (5) have no full body to partition.")
    body_type = BODY_TYPES[J]
    parents[0] = -1
    kept = _KEPT[body_type]
    part_of_kept = {j: k for k, j in enumerate(kept)}

    def owner(j: int) -> int:
        while j not in part_of_kept:
            j = parents[j]
        return j

    joint_to_part = tuple(part_of_kept[owner(j)] for j in range(J))
    part_parents = tuple(-1 if parents[j] < 0 else joint_to_part[parents[j]] for j in kept)
    K = len(kept)
    mask = ~np.eye(K, dtype=bool)
    for k, p in enumerate(part_parents):
        if p >= 0:
            mask[k, p] = mask[p, k] = False
    for a, b in _SELFPEN_IGNORED_JOINT_PAIRS:
        pa, pb = joint_to_part[a], joint_to_part[b]
        mask[pa, pb] = mask[pb, pa] = False
    mask.setflags(write=False)
    return PartTable(body_type=body_type, num_joints=J, part_joints=tuple(kept), joint_to_part=joint_to_part,
                     part_parents=part_parents, part_names=tuple(_PART_NAMES[j] for j in kept), collision_mask=mask)
