"""The human–object interaction database (apps/hoi/database.py): determinism, exact ground truth, observations."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from volsmpl.apps.hoi import database as db
from volsmpl.apps.hoi.case import case_from_dict, case_to_dict, object_mesh

# several kinds: sitting (chair), lying (bed), two-hand grip (box), one-hand (bottle), feet (skateboard), table
INDICES = [0, 3, 4, 7, 10, 11]


@pytest.fixture(scope="module")
def cases():
    return {i: db.make_case(i, seed=0) for i in INDICES}


def _body_mesh(case):
    body, part = db._default_body()
    with torch.no_grad():
        out = body(**{k: v[None] for k, v in case.body.items()})
    return out, np.asarray(part.faces), part


def test_kinds_cycle():
    assert len(db.KIND_NAMES) >= 10
    assert {db.case_name(i).rsplit("_", 1)[0] for i in range(len(db.KIND_NAMES))} == set(db.KIND_NAMES)


def test_deterministic(cases):
    again = db.make_case(INDICES[1], seed=0)
    a = json.dumps(case_to_dict(cases[INDICES[1]]))
    assert json.dumps(case_to_dict(again)) == a
    other = db.make_case(INDICES[1], seed=1)
    assert json.dumps(case_to_dict(other)) != a


def test_roundtrip(cases):
    for case in cases.values():
        d = case_to_dict(case)
        back = case_from_dict(json.loads(json.dumps(d)))
        assert case_to_dict(back) == d


@pytest.mark.parametrize("i", INDICES)
def test_no_interpenetration_and_contact(cases, i):
    """Independent reference: libigl winding numbers (mesh_sdf sign='winding') in the camera frame."""
    from volsmpl.geometry.groundtruth import mesh_sdf, winding_number

    case = cases[i]
    out, fb, part = _body_mesh(case)
    vb = case.truth["human"].apply(out.vertices[0].double().numpy())
    mesh, regions = object_mesh(case)
    vo = case.truth["object"].apply(np.asarray(mesh.vertices))
    fo = np.asarray(mesh.faces)
    d = mesh_sdf(vb, fb, vo, sign="winding")
    assert d.min() >= -db.PEN_TOL - 1e-5, f"object vertex {-d.min() * 1000:.2f} mm inside the body"
    near = ((vb >= vo.min(0) - 0.02) & (vb <= vo.max(0) + 0.02)).all(1)
    if near.any():
        assert (winding_number(vo, fo, vb[near]) < 0.5).all(), "body vertices inside the object"
    # every listed contact: the part's vertices within 1 cm of the region's surface (exact distances)
    names = list(part.table.part_names)
    lab = np.asarray(part.vertex_labels)
    assert case.contacts and 0 <= case.contact_distance <= db.CONTACT_TOL
    for p, r in case.contacts:
        f = fo if r == "any" else fo[regions[r]]
        pts = vb[lab == names.index(p)]
        dist = np.abs(mesh_sdf(vo, f, pts, sign="raycast", check_closed=False)).min()
        assert dist <= db.CONTACT_TOL + 1e-5, f"{p}-{r}: {dist * 100:.2f} cm"


def test_keypoints(cases):
    for case in cases.values():
        out, _, _ = _body_mesh(case)
        X = case.truth["human"].apply(out.joints[0].double().numpy())
        K = case.K
        uv = np.stack([K[0, 0] * X[:, 0] / X[:, 2] + K[0, 2], K[1, 1] * X[:, 1] / X[:, 2] + K[1, 2]], 1)
        kp = case.keypoints_2d
        seen = kp[:, 2] > 0
        assert seen.sum() >= 12
        H, W = case.image_size
        assert (kp[seen, 0] >= -0.5).all() and (kp[seen, 0] <= W - 0.5).all()
        assert (kp[seen, 1] >= -0.5).all() and (kp[seen, 1] <= H - 0.5).all()
        err = np.abs(kp[seen, :2] - uv[seen])
        assert err.max() <= db.KP_NOISE_PX + 1e-3 and err.mean() > 0.1  # noisy, within the bound
        assert np.all((kp[seen, 2] > 0.7) & (kp[seen, 2] < 1.0))
        # unseen: behind the camera or outside the image
        inside = (X[:, 2] > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= H - 0.5)
        assert not (seen & ~inside).any()


def test_camera_and_silhouette(cases):
    for case in cases.values():
        mesh, _ = object_mesh(case)
        c = case.truth["object"].apply(np.asarray(mesh.vertices)).mean(0)
        assert 1.0 < np.linalg.norm(c) < 5.0
        fov = 2 * np.degrees(np.arctan(0.5 * case.image_size[1] / case.K[0, 0]))
        assert db.FOV_RANGE[0] - 1e-6 <= fov <= db.FOV_RANGE[1] + 1e-6
        s = case.silhouette
        assert 0 < len(s) <= db.SIL_MAX and np.allclose(s, np.round(s))
        # every silhouette pixel lies in the bounding box of the projected object
        X = case.truth["object"].apply(np.asarray(mesh.vertices))
        uv = X[:, :2] / X[:, 2:] * case.K[[0, 1], [0, 1]] + case.K[:2, 2]
        assert (s >= uv.min(0) - 1).all() and (s <= uv.max(0) + 1).all()


def test_init_depth_scale_ambiguity():
    """noise=0: the init differs from the truth only by a scaling about the camera centre -> same projections."""
    case = db.make_case(7, seed=0, noise=0.0)
    noisy = db.make_case(7, seed=0)
    mesh, _ = object_mesh(case)
    out, _, _ = _body_mesh(case)
    K = case.K
    for key, pts in (("object", np.asarray(mesh.vertices)), ("human", out.vertices[0].double().numpy())):
        t, i = case.truth[key].apply(pts), case.init[key].apply(pts)
        s = case.init[key].scale
        assert 0.7 <= s <= 1.3 and abs(s - 1) > 1e-6
        assert noisy.init[key].scale == s  # the same draws, noise on top
        np.testing.assert_allclose(i, s * t, rtol=1e-9, atol=1e-12)
        pt, pi = (x @ K.T for x in (t, i))
        np.testing.assert_allclose(pi[:, :2] / pi[:, 2:], pt[:, :2] / pt[:, 2:], atol=1e-6)
        # with noise: the rotation differs by at most the bound
        Rn = noisy.init[key].rotation @ case.truth[key].rotation.T
        ang = np.degrees(np.arccos(np.clip((np.trace(Rn) - 1) / 2, -1, 1)))
        assert ang <= db.ROT_NOISE_DEG[key] + 1e-6


def test_database(tmp_path):
    logs = []
    paths = db.make_database(2, seed=0, out=tmp_path, log=logs.append)
    assert [p.name for p in paths] == [f"{db.case_name(i)}.json" for i in range(2)]
    idx = json.loads((tmp_path / "index.json").read_text())
    assert idx["db_version"] == db.DB_VERSION
    assert [c["split"] for c in idx["cases"]] == ["tune", "test"]
    assert all((tmp_path / f"{c['name']}.png").is_file() for c in idx["cases"])
    assert len(logs) == 2
    mtime = paths[0].stat().st_mtime_ns
    db.make_database(2, seed=0, out=tmp_path, log=logs.append)  # kept, not regenerated
    assert len(logs) == 2 and paths[0].stat().st_mtime_ns == mtime
    loaded = db.load_database(tmp_path)
    assert [c.name for c in loaded] == [db.case_name(0), db.case_name(1)]
    assert loaded[0].image == f"{loaded[0].name}.png"
    assert db.load_database(tmp_path, split="test")[0].name == db.case_name(1)
    assert db.database_folder(3).name == f"v{db.DB_VERSION}_seed3"


def test_the_silhouette_of_a_closed_mesh_is_its_whole_projection():
    """A box turned obliquely 2 m before the camera: its silhouette is the convex hull of its projected corners
    (a convex body), filled by OpenCV as one polygon, the reference; each front triangle covers a back one, so one
    fillPoly of all the triangles would keep only the pixels covered an odd number of times."""
    import cv2
    import trimesh
    from scipy.spatial.transform import Rotation

    from volsmpl.apps.hoi.case_geometry import project, raster_mask

    box = trimesh.creation.box(extents=(0.4, 0.3, 0.5))
    v = box.vertices @ Rotation.from_euler("xyz", [25, 35, 10], degrees=True).as_matrix().T + [0.1, -0.05, 2.0]
    K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])
    got = raster_mask(K, (480, 640), v, np.asarray(box.faces))
    uv, _ = project(K, v)
    ref = np.zeros((480, 640), np.uint8)
    cv2.fillConvexPoly(ref, cv2.convexHull(np.round(uv * 16).astype(np.int32)), 1, lineType=cv2.LINE_8, shift=4)
    inter, union = int((got & ref).sum()), int((got | ref).sum())
    assert inter / union > 0.99 and ref.sum() > 10000
