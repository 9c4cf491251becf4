"""The hand-made human–object case the hoi tests share: a ball at the right hand of a standing body, with its first
stage and ground truth (importable as `hoi_cases`: the tests folder is on the path)."""
from __future__ import annotations

import numpy as np
import torch
from volsmpl.apps.hoi.case import FORMAT, VERSION
from volsmpl.body.fingerprint import fingerprint_of_model
from volsmpl.scene.objects import make_object

__all__ = ["R_CAM", "ball_case"]

R_CAM = np.diag([1.0, -1.0, -1.0])  # body Y-up, facing +Z -> camera y down, facing the camera


def _rot(axis_angle):
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(axis_angle).as_matrix()


def ball_case(body, human_factor=1.2, object_factor=0.8, object_rot=(0.0, 0.35, 0.0)) -> dict:
    """A ball touching the right hand of a standing body 3 m in front of the camera; first-stage estimates scaled
    about the camera centre (the depth-scale ambiguity) and the ball turned by `object_rot`."""
    with torch.no_grad():
        out = body(betas=torch.zeros(1, 10), body_pose=torch.zeros(1, 69))
    joints = out.joints[0, :24].numpy().astype(np.float64)
    tmpl = make_object("ball", seed=0)
    radius = tmpl.mesh.extents[1] / 2
    hand = joints[21]  # right wrist
    centre = hand + np.array([-0.05, -radius - 0.04, 0.0])  # below the hand: the palm side when the arm hangs
    v = out.vertices[0].numpy()
    # move the ball down until it clears the body by 5 mm (exact distances of its vertices)
    from volsmpl.geometry.point_mesh_distance import mesh_signed_distance
    faces = torch.as_tensor(np.asarray(body.faces))
    for _ in range(100):
        verts = tmpl.mesh.vertices - [0, radius, 0] + centre
        d = mesh_signed_distance(torch.as_tensor(v, dtype=torch.float64), faces, torch.as_tensor(verts))
        if float(d.min()) > 0.005:
            break
        centre = centre + np.array([0.0, -0.005, 0.0])
    t_h = np.array([0.0, 0.2, 3.0])
    truth_h = {"scale": 1.0, "rotation": R_CAM, "translation": t_h}
    obj_t = R_CAM @ (centre - [0, radius, 0]) + t_h
    truth_o = {"scale": 1.0, "rotation": R_CAM, "translation": obj_t}
    K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])

    def proj(x):
        return np.stack([600 * x[:, 0] / x[:, 2] + 319.5, 600 * x[:, 1] / x[:, 2] + 239.5], -1)

    j_cam = joints @ R_CAM.T + t_h
    kp = np.concatenate([proj(j_cam), np.full((24, 1), 0.9)], 1)
    o_cam = tmpl.mesh.vertices @ R_CAM.T + obj_t
    sil = proj(o_cam)[:: max(1, len(o_cam) // 300)]
    sim = lambda s, R, t: {"scale": s, "rotation": np.asarray(R).tolist(), "translation": list(t)}  # noqa: E731
    return {
        "format": FORMAT, "version": VERSION, "name": "ball_at_hand",
        "body": {"fingerprint": fingerprint_of_model(body), "betas": [0.0] * 10, "global_orient": [0.0] * 3,
                 "body_pose": [0.0] * 69, "transl": [0.0] * 3},
        "object": {"category": "ball", "template_seed": 0},
        "camera": {"K": K.tolist(), "image_size": [480, 640]},
        "keypoints_2d": kp.tolist(), "silhouette": sil.tolist(), "contacts": [["right_hand", "grasp"]],
        "init": {"human": sim(human_factor, R_CAM, t_h * human_factor),
                 "object": sim(object_factor, _rot(object_rot) @ R_CAM, obj_t * object_factor)},
        "truth": {k: sim(v["scale"], v["rotation"], v["translation"]) for k, v in (("human", truth_h), ("object", truth_o))},
    }
