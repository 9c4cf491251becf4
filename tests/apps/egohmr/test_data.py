"""The egocentric app's data generator (apps/egohmr/data.py, placement.py), checked against independent references:
libigl's exact generalised winding numbers and open3d distances for interpenetration and contact, kornia's projection
for visibility, the body model for the camera-frame parameters."""
import json

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

import volsmpl
from volsmpl.apps.egohmr import data, placement
from volsmpl.geometry.groundtruth import mesh_sdf, winding_number
from volsmpl.scene import make_room, sample_surface
from volsmpl.scene.camera import project
from kornia.geometry.camera import PinholeCamera

TOL_DEPTH = 0.005  # interpenetration tolerance of the issue (5 mm)


@pytest.fixture(scope="module")
def body():
    b = volsmpl.create_body()
    return b, volsmpl.Partition(b).vertex_labels.numpy(), volsmpl.Partition(b).table.part_names


@pytest.fixture(scope="module")
def frames():
    return data.make_frames("test", n=10)


@pytest.fixture(scope="module")
def group():
    return data.make_group("val", 0, seed=0)


def _pose(body, betas, go, pose, transl):
    f = lambda x: torch.as_tensor(np.asarray(x), dtype=torch.float32)[None]  # noqa: E731
    with torch.no_grad():
        out = body(betas=f(betas), global_orient=f(go), body_pose=f(pose), transl=f(transl))
    return out.vertices[0].double().numpy(), out.joints[0].double().numpy()


def _parts(v, labels, names, *parts):
    return v[np.isin(labels, [names.index(p) for p in parts])]


# ----------------------------------------------------------------------------------------------- determinism, splits
def test_group_deterministic_and_seeded(group):
    again = data.make_group("val", 0, seed=0)
    assert set(again) == set(group)
    for k in group:
        np.testing.assert_array_equal(again[k], group[k])
    other = data.make_group("val", 0, seed=1)
    assert not np.array_equal(other["transl"], group["transl"])


def test_make_frames_cached_prefix(frames):
    assert [f.name for f in frames] == [f"test_{i:04d}" for i in range(10)]
    again = data.make_frames("test", n=3)
    for a, b in zip(again, frames[:3]):
        np.testing.assert_array_equal(a.keypoints, b.keypoints)
        np.testing.assert_array_equal(a.transl, b.transl)
    for f in frames:
        data.check_frame(f)


def test_splits_use_disjoint_rooms(frames):
    rooms = {s: set(data.split_rooms(s, 0)) for s in data.SPLITS}
    assert not rooms["train"] & rooms["val"] and not rooms["train"] & rooms["test"] and not rooms["val"] & rooms["test"]
    assert len(rooms["train"] | rooms["val"] | rooms["test"]) == data.ROOM_COUNT
    assert {f.room_seed for f in frames} <= rooms["test"]


# ----------------------------------------------------------------------------------------------- camera-frame parameters
def test_camera_parameters_reproduce_world_body(body, group):
    b = body[0]
    vw, _ = _pose(b, group["betas"], group["global_orient_world"], group["body_pose"], group["transl_world"])
    for v in range(data.VIEWS):
        R, t = group["R"][v], group["t"][v]
        vc, jc = _pose(b, group["betas"], group["global_orient"][v], group["body_pose"], group["transl"][v])
        assert np.abs(vw @ R.T + t - vc).max() < 1e-5
        assert np.abs(jc - group["joints"][v]).max() < 1e-5


def test_to_camera_rotates_about_the_rest_pelvis(body):
    b = body[0]
    rng = np.random.default_rng(3)
    betas, go, pose, tr = rng.normal(size=10), rng.normal(size=3), 0.2 * rng.normal(size=69), rng.normal(size=3)
    R, t = Rotation.random(random_state=4).as_matrix(), rng.normal(size=3)
    with torch.no_grad():
        J0 = b(betas=torch.as_tensor(betas, dtype=torch.float32)[None]).joints[0, 0].double().numpy()
    go2, tr2 = data.to_camera(R, t, J0, go, tr)
    v1, _ = _pose(b, betas, go, pose, tr)
    v2, _ = _pose(b, betas, go2, pose, tr2)
    assert np.abs(v1 @ R.T + t - v2).max() < 1e-5


# ----------------------------------------------------------------------------------------------- placements: contact and penetration
def _place(activity):
    """The first placement of an activity in the standard rooms 0, 1, ... that afford it (rng seed 11)."""
    for s in range(16):
        if placement.affords(make_room(s), activity):
            p = placement.place(s, activity, np.random.default_rng(11))
            if p is not None:
                return p
    return None


@pytest.fixture(scope="module")
def placements():
    return {a: _place(a) for a in placement.ACTIVITIES}


def test_every_activity_places(placements):
    assert all(p is not None for p in placements.values()), [a for a, p in placements.items() if p is None]


def _support_distance(activity, v, room, labels, names):
    """Independent contact measure: the support parts' distance to the activity's support (world frame)."""
    parts, _ = placement.SUPPORT[activity]
    pv = _parts(v, labels, names, *parts)
    if activity in ("standing", "walking", "crouching", "reaching_shelf"):
        return pv[:, 1].min() - room.floor_y
    if activity == "leaning_wall":
        (x0, _, z0), (x1, _, z1) = room.interior
        return min(pv[:, 0].min() - x0, x1 - pv[:, 0].max(), pv[:, 2].min() - z0, z1 - pv[:, 2].max())
    cats = {"sitting": placement.SEAT_CATEGORIES, "lying": ("bed",), "leaning_table": ("table",)}[activity]
    meshes = [it.mesh for it in room.items if it.category in cats]
    if activity == "leaning_table":  # both hands on the top
        return max(min(np.abs(mesh_sdf(m.vertices, m.faces, _parts(v, labels, names, h))).min() for m in meshes)
                   for h in ("left_hand", "right_hand"))
    return min(np.abs(mesh_sdf(m.vertices, m.faces, pv)).min() for m in meshes)


@pytest.mark.parametrize("activity", placement.ACTIVITIES)
def test_support_contact_and_no_interpenetration(activity, placements, body):
    b, labels, names = body
    p = placements[activity]
    assert p is not None
    room = make_room(p.room_seed)
    v, _ = _pose(b, p.betas, p.global_orient, p.body_pose, p.transl)
    d = _support_distance(activity, v, room, labels, names)
    assert -1e-4 <= d <= placement.CONTACT_TOL, (activity, d)
    _assert_no_interpenetration(v, b.faces, room.mesh())


def _assert_no_interpenetration(v, faces, scene):
    """Exact (libigl winding numbers): body vertices in the scene and scene points (vertices + fresh samples near the
    body) in the body, each at most TOL_DEPTH deep."""
    sv, sf = np.asarray(scene.vertices), np.asarray(scene.faces)
    inside = winding_number(sv, sf, v) > 0.5
    if inside.any():
        assert np.abs(mesh_sdf(sv, sf, v[inside], check_closed=False)).max() <= TOL_DEPTH
    pts, _ = sample_surface(scene, 400000, seed=123)
    pts = np.concatenate([sv, pts])
    lo, hi = v.min(0) - 0.01, v.max(0) + 0.01
    pts = pts[((pts >= lo) & (pts <= hi)).all(1)]
    if len(pts):
        assert mesh_sdf(v, faces, pts, sign="winding").min() >= -TOL_DEPTH


def test_frames_do_not_interpenetrate(frames, body):
    b = body[0]
    for f in frames[::5]:
        v, _ = _pose(b, f.betas, f.global_orient, f.body_pose, f.transl)
        _assert_no_interpenetration(v, b.faces, data.scene_mesh(f))


def test_penetration_detects_a_body_in_furniture(body, placements):
    b = body[0]
    p = placements["sitting"]
    room = make_room(p.room_seed)
    v, _ = _pose(b, p.betas, p.global_orient, p.body_pose, p.transl)
    sunk = v - [0.0, 0.05, 0.0]  # 5 cm into the seat
    assert max(placement.penetration(sunk, b.faces, room, placement.room_cloud(p.room_seed))) > 0.03


# ----------------------------------------------------------------------------------------------- keypoints, visibility
def test_keypoints_within_noise_bound(frames):
    errs = []
    for f in frames:
        z = f.joints[:, 2]
        uv = (f.joints @ f.K.T)[:, :2] / z[:, None]
        seen = f.conf > 0
        np.testing.assert_array_equal(seen, f.visible)
        assert np.isfinite(f.keypoints).all() and (f.keypoints[~seen] == 0).all()
        assert ((f.conf >= 0) & (f.conf <= 1)).all()
        e = np.linalg.norm(f.keypoints[seen] - uv[seen], axis=1)
        assert e.max() <= data.KP_MAX_ERROR_PX + 1e-3
        errs.append(e)
    e = np.concatenate(errs)
    assert 0.5 * data.KP_SIGMA_PX < np.median(e) < 3 * data.KP_SIGMA_PX  # noisy, but detector-like


def test_visible_matches_kornia_projection(frames):
    for f in frames:
        jw = (f.joints.astype(np.float64) - f.t) @ f.R  # back to the world
        K4, E = torch.eye(4, dtype=torch.float64)[None], torch.eye(4, dtype=torch.float64)[None]
        K4[0, :3, :3], E[0, :3, :3], E[0, :3, 3] = torch.as_tensor(f.K), torch.as_tensor(f.R), torch.as_tensor(f.t)
        H, W = f.image_size
        cam = PinholeCamera(K4, E, torch.tensor([float(H)], dtype=torch.float64), torch.tensor([float(W)], dtype=torch.float64))
        _, _, vis = project(torch.as_tensor(jw)[None], cam)
        np.testing.assert_array_equal(vis[0].numpy(), f.visible)
        assert f.visible.sum() >= data.MIN_VISIBLE


# ----------------------------------------------------------------------------------------------- scene points
def test_scene_points_in_cube_and_on_surface(frames):
    import open3d as o3d
    f = frames[0]
    c = f.joints[0]
    p = data.scene_points(f, c, n=5000, size=2.0, seed=0)
    assert p.shape == (5000, 3) and p.dtype == np.float32
    assert (np.abs(p - c) <= 1.0 + 1e-5).all()
    assert len(np.unique(p, axis=0)) == 5000  # no repeats when the cube holds more
    m = data.scene_mesh(f)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(m.vertices.astype(np.float32)), o3d.core.Tensor(m.faces.astype(np.uint32)))
    assert scene.compute_distance(o3d.core.Tensor(p)).numpy().max() < 1e-3
    np.testing.assert_array_equal(p, data.scene_points(f, c, n=5000, size=2.0, seed=0))
    assert not np.array_equal(p, data.scene_points(f, c, n=5000, size=2.0, seed=1))


# ----------------------------------------------------------------------------------------------- errors, files
def test_clear_errors(frames):
    f = frames[0]
    with pytest.raises(ValueError, match="scene with no points near the body"):
        data.scene_points(f, f.joints[0] + [0.0, 0.0, 100.0])
    with pytest.raises(ValueError, match="center must be 3 finite"):
        data.scene_points(f, [0.0, np.nan, 1.0])
    with pytest.raises(ValueError, match="split must be one of"):
        data.make_frames("tests")
    with pytest.raises(ValueError, match="n must be a positive int"):
        data.make_frames("test", n=0)
    d = data.frame_to_dict(f)
    bad = dict(d, keypoints=d["keypoints"][:23], conf=d["conf"][:23], visible=d["visible"][:23])
    with pytest.raises(ValueError, match="23 joints, expected 24"):
        data.check_frame(data.EgoFrame(**{**vars(f), "keypoints": np.asarray(bad["keypoints"])}))
    kp = f.keypoints.copy()
    kp[3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN/inf"):
        data.check_frame(data.EgoFrame(**{**vars(f), "keypoints": kp}))
    with pytest.raises(ValueError, match="K must be"):
        data.check_frame(data.EgoFrame(**{**vars(f), "K": -f.K}))
    with pytest.raises(ValueError, match="lacks"):
        data.frame_from_dict({k: v for k, v in d.items() if k != "K"})


def test_frame_dict_round_trip(frames):
    f = frames[1]
    g = data.frame_from_dict(json.loads(json.dumps(data.frame_to_dict(f))))
    for k, v in vars(f).items():
        if isinstance(v, np.ndarray):
            np.testing.assert_allclose(getattr(g, k), v, rtol=0, atol=1e-6)
        else:
            assert getattr(g, k) == v
