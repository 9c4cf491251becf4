"""The self-contact validation split of `volsmpl eval`: bodies in poses whose parts touch or pass through each other.

    from volsmpl.evaluation.contact_split import self_contact_bodies, self_contact_labels
    bodies = self_contact_bodies(16)        # betas / global_orient / body_pose / transl, like validation_bodies
    volsmpl eval --split self_contact       # or 'all' (default): the standard split, then this one

Poses (`SELF_CONTACT_POSES`, Euler angles per joint as `volsmpl.body.poses.NAMED_POSES`, all within JOINT_LIMITS):
the named 'arms_crossed' and 'hands_on_hips', and six built here: arms around the torso (hands on the flanks),
seated with the hands on the thighs, a deep squat (thighs against belly and upper arms), standing legs crossed
(thighs touching), seated cross-legged (feet crossed), sitting on the heels (calves pressed against the thighs).
These are the poses the self-penetration and interaction apps live on; the standard split has 12 named poses
and 52 extreme ones, few of them in contact.

Bodies (seed CONTACT_SEED, body i from its own stream SeedSequence([seed, i]), so a prefix of a longer set):
pose i % 8, exact for i < 8 and jittered for i >= 8 (N(0, 0.05^2) rad on the angles the pose sets, clipped to
the limits); shape group (i + i // 8) % 4 of `validation.SHAPE_GROUPS` (each pose in two groups); global
orientation uniform over SO(3) and translation uniform in [-0.5, 0.5]^3 m, as the standard split. Query points,
ground truth (cached) and metrics follow the standard protocol (`validation.query_points`, seeded by CONTACT_SEED;
`groundtruth_cache.ground_truth`; `metrics`), so the two splits compare column by column
(`evaluate_self_contact`; `volsmpl eval --split`).
"""
from __future__ import annotations

from typing import Dict, List

import numpy as np
import torch

from volsmpl.body.poses import BODY_JOINTS, JOINT_LIMITS, NAMED_POSES, euler_to_body_pose
from volsmpl.evaluation.validation_set import SHAPE_GROUPS, sub_seed

__all__ = ["CONTACT_SEED", "SELF_CONTACT_POSES", "N_CONTACT_BODIES", "self_contact_labels", "self_contact_bodies",
           "evaluate_self_contact"]

#: seed of the self-contact split (the standard split's is VAL_SEED = 316; training uses neither)
CONTACT_SEED = 317

#: joint -> (x, y, z) Euler radians (joints left out stay at the T-pose), every angle within JOINT_LIMITS
SELF_CONTACT_POSES = {
    "arms_crossed": NAMED_POSES["arms_crossed"],
    "hands_on_hips": NAMED_POSES["hands_on_hips"],
    "arms_around_torso": dict(left_shoulder=(0, -1.5, -0.7), right_shoulder=(0, 1.5, 0.7), left_elbow=(0, -2.2, 0),
                              right_elbow=(0, 2.2, 0)),
    "seated_hands_on_thighs": dict(left_hip=(-1.55, 0, 0.1), right_hip=(-1.55, 0, -0.1), left_knee=(1.55, 0, 0),
                                   right_knee=(1.55, 0, 0), left_shoulder=(0, -0.6, -1.2), right_shoulder=(0, 0.6, 1.2),
                                   left_elbow=(0, -0.9, 0), right_elbow=(0, 0.9, 0)),
    "deep_squat": dict(left_hip=(-2.0, 0, 0.3), right_hip=(-2.0, 0, -0.3), left_knee=(2.4, 0, 0), right_knee=(2.4, 0, 0),
                       left_ankle=(-0.7, 0, 0), right_ankle=(-0.7, 0, 0), spine1=(0.5, 0, 0), spine2=(0.3, 0, 0),
                       left_shoulder=(0, -1.2, -0.5), right_shoulder=(0, 1.2, 0.5)),
    "legs_crossed": dict(left_hip=(-0.25, 0, -0.45), right_hip=(-0.05, 0, 0.45), left_shoulder=(0, 0, -1.35),
                         right_shoulder=(0, 0, 1.35)),
    "seated_cross_legged": dict(left_hip=(-1.5, 0.5, 0.6), right_hip=(-1.5, -0.5, -0.6), left_knee=(2.3, 0, 0),
                                right_knee=(2.3, 0, 0)),
    "sitting_on_heels": dict(left_hip=(-0.4, 0, 0.1), right_hip=(-0.4, 0, -0.1), left_knee=(2.4, 0, 0),
                             right_knee=(2.4, 0, 0), left_ankle=(0.5, 0, 0), right_ankle=(0.5, 0, 0),
                             left_shoulder=(0, 0, -1.35), right_shoulder=(0, 0, 1.35)),
}
_JITTER = 0.05  # rad, sd of the jitter of the second copy of each pose


def _spec(i: int, seed: int) -> dict:
    names = list(SELF_CONTACT_POSES)
    P = len(names)
    return {"pose": names[i % P], "jitter": i >= P, "shape": list(SHAPE_GROUPS)[(i + i // P) % len(SHAPE_GROUPS)],
            "seed": sub_seed(seed, i)}


def self_contact_labels(n: int = 16, seed: int = CONTACT_SEED) -> List[str]:
    """'contact:<pose>[~]/<shape>' per body of `self_contact_bodies(n, seed)` ('~': jittered copy)."""
    return [f"contact:{s['pose']}{'~' if s['jitter'] else ''}/{s['shape']}" for s in (_spec(i, seed) for i in range(n))]


def _euler(name: str, rng: np.random.Generator | None) -> np.ndarray:
    """(1, 23, 3) Euler angles of a self-contact pose, optionally jittered on the angles it sets (within limits)."""
    e = np.zeros((1, 23, 3))
    for joint, angles in SELF_CONTACT_POSES[name].items():
        j = BODY_JOINTS.index(joint)
        e[0, j] = angles
        if rng is not None:
            lim = np.asarray(JOINT_LIMITS[joint])
            e[0, j] = np.clip(e[0, j] + rng.normal(0.0, _JITTER, 3) * (np.asarray(angles) != 0), lim[:, 0], lim[:, 1])
    return e


def self_contact_bodies(n: int = 16, seed: int = CONTACT_SEED, num_betas: int = 10) -> Dict[str, torch.Tensor]:
    """The self-contact split (module docstring), float32 CPU tensors, bit-identical for equal (n, seed, num_betas),
    body i independent of n.

    Shape: -> betas (n, num_betas), global_orient (n, 3), body_pose (n, 69), transl (n, 3).
    """
    from scipy.spatial.transform import Rotation

    from volsmpl.body.shapes import sample_betas

    if not isinstance(n, int) or n < 1:
        raise ValueError(f"self_contact_bodies needs n >= 1 bodies, got {n!r}.")
    betas, orient, pose, transl = [], [], [], []
    for i in range(n):
        spec = _spec(i, seed)
        s = spec["seed"]
        pose.append(euler_to_body_pose(_euler(spec["pose"], np.random.default_rng(sub_seed(s, 0)) if spec["jitter"] else None)))
        betas.append(sample_betas(1, num_betas=num_betas, seed=sub_seed(s, 1), **SHAPE_GROUPS[spec["shape"]]))
        rng = np.random.default_rng(sub_seed(s, 2))
        orient.append(Rotation.random(1, random_state=rng).as_rotvec())
        transl.append(rng.uniform(-0.5, 0.5, size=(1, 3)))
    f32 = dict(dtype=torch.float32)
    return {"betas": torch.cat(betas).to(**f32), "global_orient": torch.as_tensor(np.concatenate(orient), **f32),
            "body_pose": torch.cat(pose).to(**f32), "transl": torch.as_tensor(np.concatenate(transl), **f32)}


#: bodies of the self-contact split at the standard protocol (each pose exact and jittered)
N_CONTACT_BODIES = 2 * len(SELF_CONTACT_POSES)


def evaluate_self_contact(path, config, random_init: dict | None = None, body=None):
    """`volsmpl.evaluation.run.evaluate_checkpoint` on the self-contact split: min(config.n_bodies, 16) bodies, their query
    points and ground truth seeded by CONTACT_SEED, no timing (the standard split's resources hold for it).
    Returns the EvalResult named '<name> [self-contact]', extra['split'] = 'self_contact', per-body pose labels."""
    import dataclasses

    from volsmpl.evaluation.run import evaluate_checkpoint

    cfg = dataclasses.replace(config, n_bodies=min(config.n_bodies, N_CONTACT_BODIES), seed=CONTACT_SEED, timing=False)
    num_betas = body.num_betas if body is not None else 10
    res = evaluate_checkpoint(path, config=cfg, body=body, random_init=random_init,
                              bodies=self_contact_bodies(cfg.n_bodies, CONTACT_SEED, num_betas=num_betas))
    res.name = f"{res.name} [self-contact]"
    res.extra["split"] = "self_contact"
    res.per_body["label"] = self_contact_labels(cfg.n_bodies, CONTACT_SEED)
    return res
