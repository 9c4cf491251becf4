"""Part tables: COAP's merges, part counts, collision mask."""
from __future__ import annotations

import numpy as np
import pytest

from volsmpl.body.model import SMPL_PARENTS
from volsmpl.body.part_table import make_part_table

SMPLX_PARENTS = list(SMPL_PARENTS[:22]) + [15, 15, 15] + \
    [20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38] + \
    [21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53]
SMPLH_PARENTS = list(SMPL_PARENTS[:22]) + \
    [20, 22, 23, 20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35] + \
    [21, 37, 38, 21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50]


def test_smpl_table():
    t = make_part_table(SMPL_PARENTS)
    assert t.body_type == "smpl" and t.num_parts == 16
    names = dict(zip(t.part_joints, t.part_names))
    jp = t.joint_to_part
    # COAP merges: head->neck, toes->feet, spine1->pelvis, collars->spine3, hands->wrists
    for merged, owner in [(15, 12), (10, 7), (11, 8), (3, 0), (13, 9), (14, 9), (22, 20), (23, 21)]:
        assert jp[merged] == jp[owner], (merged, owner)
    assert names[20] == "left_hand" and names[12] == "head"
    assert t.part_parents[t.part_joints.index(16)] == t.part_joints.index(9)  # upper arm hangs off the chest


def test_smplx_and_smplh_tables():
    x = make_part_table(SMPLX_PARENTS)
    assert x.body_type == "smplx" and x.num_parts == 15
    assert x.joint_to_part[9] == x.joint_to_part[6]  # spine3 into spine2
    assert all(x.joint_to_part[j] == x.joint_to_part[12] for j in (15, 22, 23, 24))  # jaw, eyes with the head
    assert all(x.joint_to_part[j] == x.joint_to_part[20] for j in range(25, 40))
    assert all(x.joint_to_part[j] == x.joint_to_part[21] for j in range(40, 55))
    h = make_part_table(SMPLH_PARENTS)
    assert h.body_type == "smplh" and h.num_parts == 16
    assert all(h.joint_to_part[j] == h.joint_to_part[20] for j in range(22, 37))


def test_collision_mask():
    t = make_part_table(SMPL_PARENTS)
    m = t.collision_mask
    K = t.num_parts
    assert (m == m.T).all() and not m.diagonal().any()
    p = {n: i for i, n in enumerate(t.part_names)}
    for k, par in enumerate(t.part_parents):  # kinematically adjacent parts never count
        if par >= 0:
            assert not m[k, par]
    assert not m[p["left_thigh"], p["right_thigh"]]      # COAP's ignored pair (1, 2)
    assert not m[p["pelvis"], p["left_upper_arm"]]      # (0, 16)
    assert m[p["left_forearm"], p["chest"]]             # forearm through the torso counts
    assert m[p["left_hand"], p["right_thigh"]]
    assert m[p["left_shin"], p["right_shin"]]
    assert m.sum() < K * (K - 1)


@pytest.mark.parametrize("J", [16, 5, 30])
def test_unsupported(J):
    with pytest.raises(ValueError, match="SMPL \\(24\\), SMPL-H \\(52\\) and SMPL-X \\(55\\)"):
        make_part_table(np.arange(-1, J - 1))
