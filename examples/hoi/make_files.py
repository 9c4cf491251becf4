"""How the files of this example were made; run from the repository root: `python examples/hoi/make_files.py`.

The person, the camera and where the mug sits come from case hold_cup_0008 of the generated interaction database
(`volsmpl.apps.hoi.database.make_case(8, seed=0)`, deterministic); the mug is our own, made of trimesh primitives in
the cup template's frame (resting on y = 0, handle towards +X; millimetres) and drawn in its left hand for
the mask.

    mug.obj     a mug (body: a 32-sided cylinder, 82 mm across, 95 mm high; handle: a torus), millimetres
    pose.json   the body in the camera frame: betas, global_orient, body_pose, transl (metres)
    camera.json the camera matrix and the image size {"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "image_size": [H, W]}
    mask.png    the mug's mask in the image (white on black)
    object_pose.json  a first stage's estimate of the mug's pose (camera frame, metres): the database case's init.object
                (its truth turned by up to 30 deg and moved), at the mug's own size: the projection kept
"""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import torch
import trimesh
from scipy.spatial.transform import Rotation

HERE = Path(__file__).parent


def mug_mm() -> trimesh.Trimesh:
    """A mug in the cup template's frame: bounding box 120 x 95 x 82 mm (width with handle, height, depth)."""
    body = trimesh.creation.cylinder(radius=41.0, height=95.0, sections=32)
    body.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))  # its axis along y
    body.apply_translation([-19.0, 47.5, 0.0])
    handle = trimesh.creation.torus(22.0, 6.0, major_sections=24, minor_sections=8)  # in the xy plane
    handle.apply_translation([32.0, 47.5, 0.0])
    return trimesh.util.concatenate([body, handle])


def main() -> None:
    import volsmpl
    from volsmpl.apps.hoi import database as db

    case = db.make_case(8, seed=0)
    mug = mug_mm()
    mug.export(HERE / "mug.obj")
    # the body in the camera frame: the database's body (transl 0) moved by truth.human = (1, R, t) about its root
    body = volsmpl.create_body()
    h = case.truth["human"]
    with torch.no_grad():
        root = body(betas=case.body["betas"][None], body_pose=torch.zeros(1, 69)).joints[0, 0].double().numpy()
    R_go = Rotation.from_rotvec(case.body["global_orient"].double().numpy()).as_matrix()
    pose = {"betas": case.body["betas"].tolist(),
            "global_orient": Rotation.from_matrix(h.rotation @ R_go).as_rotvec().tolist(),
            "body_pose": case.body["body_pose"].tolist(),
            "transl": (h.rotation @ root + h.translation - root).tolist()}
    (HERE / "pose.json").write_text(json.dumps(pose, indent=1) + "\n")
    (HERE / "camera.json").write_text(json.dumps({"K": case.K.tolist(), "image_size": list(case.image_size)}) + "\n")
    o = case.init["object"]  # scaled about the camera centre: at scale 1 its translation is t / s
    (HERE / "object_pose.json").write_text(json.dumps({"rotation": o.rotation.tolist(),
                                                       "translation": (o.translation / o.scale).tolist()}) + "\n")
    # the mask: the mug where the database's cup is (truth.object), filled triangle by triangle
    v = case.truth["object"].apply(np.asarray(mug.vertices) / 1000.0)
    uv = (v @ case.K.T)[:, :2] / v[:, 2:]
    mask = np.zeros(case.image_size, np.uint8)
    for tri in np.round(uv[np.asarray(mug.faces)] * 16).astype(np.int32):  # one by one: their union
        cv2.fillConvexPoly(mask, tri, 255, cv2.LINE_8, shift=4)
    cv2.imwrite(str(HERE / "mask.png"), mask)


if __name__ == "__main__":
    main()
