"""Random self-contact poses for training: limbs drawn from families of joint ranges that bring parts together.

Uniform joint angles (`poses.sample_euler`'s 'realistic' and 'extreme') rarely put a hand on the chest, a
thigh against the belly or one leg across the other; those are the poses the self-penetration and interaction
apps work on, and the ones where a trained volume errs most. Here each body draws, independently per arm and
for the legs, one family of angle ranges (left side written; the right side mirrors it, (x, -y, -z), as
JOINT_LIMITS does), uniform inside the family's ranges and clipped to JOINT_LIMITS; the joints a family leaves
out keep a realistic draw, and half the bodies bend the spine forward. Families (`ARM_FAMILIES`,
`LEG_FAMILIES`): arms across the torso, hands on hips or thighs, upper arm against the flank, hand to the head,
or free; legs in a deep squat, seated, seated cross-legged, crossed while standing, sitting on the heels, or
free. The ranges are broad families, not the validation split's poses (`volsmpl.contact_split`): those are
scored on their own bodies and query points, which training never sees.

    e = sample_contact_euler(8, seed=0)      # (8, 23, 3) Euler angles, poses.euler_to_body_pose(e) -> (8, 69)
"""
from __future__ import annotations

import numpy as np

from .poses import BODY_JOINTS, JOINT_LIMITS, sample_euler

__all__ = ["ARM_FAMILIES", "LEG_FAMILIES", "sample_contact_euler", "mirror"]

#: family -> (probability, {left joint: ((x lo, hi) | None, (y lo, hi) | None, (z lo, hi) | None)}); None: realistic
ARM_FAMILIES = {
    "across_torso": (0.30, {"left_shoulder": ((-0.3, 0.3), (-1.5, -0.6), (-1.3, -0.5)),
                            "left_elbow": (None, (-2.6, -1.5), None)}),
    "hand_on_hip_or_thigh": (0.25, {"left_shoulder": (None, (-0.8, 0.5), (-1.4, -0.8)),
                                    "left_elbow": (None, (-1.8, -0.2), None)}),
    "arm_against_flank": (0.15, {"left_shoulder": (None, (-0.3, 0.3), (-1.5, -1.3)),
                                 "left_elbow": (None, (-0.6, 0.0), None)}),
    "hand_to_head": (0.10, {"left_shoulder": (None, (-1.2, -0.2), (0.0, 1.0)),
                            "left_elbow": (None, (-2.6, -1.8), None)}),
    "free": (0.20, {}),
}
LEG_FAMILIES = {
    "deep_squat": (0.20, {"left_hip": ((-2.0, -1.4), None, (0.0, 0.4)), "left_knee": ((1.9, 2.4), None, None),
                          "left_ankle": ((-0.7, 0.5), None, None)}),
    "seated": (0.20, {"left_hip": ((-1.7, -1.3), None, None), "left_knee": ((1.2, 2.0), None, None)}),
    "cross_legged": (0.15, {"left_hip": ((-1.7, -1.3), (0.3, 0.6), (0.4, 0.8)), "left_knee": ((2.0, 2.4), None, None)}),
    "crossed_standing": (0.15, {"left_hip": ((-0.4, 0.1), None, (-0.45, -0.2))}),
    "on_heels": (0.10, {"left_hip": ((-0.6, 0.0), None, None), "left_knee": ((2.2, 2.4), None, None),
                        "left_ankle": ((0.2, 0.5), None, None)}),
    "free": (0.20, {}),
}
_SAME_LEGS = 0.7     # probability that both legs take the same family (each its own angles)
_SPINE_BEND = (0.5, "spine1", (0.0, 0.6))   # probability, joint, forward-bend range of its x angle


def mirror(joint: str) -> str:
    """The other side's joint name ('left_hip' <-> 'right_hip'); central joints map to themselves."""
    if joint.startswith("left_"):
        return "right_" + joint[5:]
    if joint.startswith("right_"):
        return "left_" + joint[6:]
    return joint


def _draw_family(families: dict, rng: np.random.Generator) -> str:
    names = list(families)
    p = np.array([families[n][0] for n in names])
    return names[rng.choice(len(names), p=p / p.sum())]


def _apply(e: np.ndarray, ranges: dict, right: bool, rng: np.random.Generator) -> None:
    """Overwrite the angles `ranges` sets (left-side ranges; mirrored for the right side) with uniform draws."""
    for joint, axes in ranges.items():
        j = BODY_JOINTS.index(mirror(joint) if right else joint)
        for a, r in enumerate(axes):
            if r is None:
                continue
            v = rng.uniform(*r)
            e[j, a] = -v if (right and a > 0) else v


def sample_contact_euler(n: int, seed: int | None = None) -> np.ndarray:
    """Self-contact-seeking joint angles (module docstring), (n, 23, 3), within JOINT_LIMITS; body i depends only
    on (seed, i)."""
    if not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"sample_contact_euler needs n >= 0 bodies, got {n!r}")
    out = np.empty((n, len(BODY_JOINTS), 3))
    base = np.random.SeedSequence(seed) if seed is not None else np.random.SeedSequence()
    limits = np.array([JOINT_LIMITS[j] for j in BODY_JOINTS])      # (23, 3, 2)
    for i, child in enumerate(base.spawn(n)):
        rng = np.random.default_rng(child)
        e = sample_euler(1, seed=int(rng.integers(2 ** 63)), mode="realistic")[0]
        for right in (False, True):
            _apply(e, ARM_FAMILIES[_draw_family(ARM_FAMILIES, rng)][1], right, rng)
        legs = _draw_family(LEG_FAMILIES, rng)
        other = legs if rng.random() < _SAME_LEGS else _draw_family(LEG_FAMILIES, rng)
        _apply(e, LEG_FAMILIES[legs][1], False, rng)
        _apply(e, LEG_FAMILIES[other][1], True, rng)
        p, joint, r = _SPINE_BEND
        if rng.random() < p:
            e[BODY_JOINTS.index(joint), 0] = rng.uniform(*r)
        out[i] = np.clip(e, limits[..., 0], limits[..., 1])
    return out
