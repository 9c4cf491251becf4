"""The egocentric app without open3d and libigl: each torch path (volsmpl.geometry.triangle_queries) against the open3d / libigl
answer it replaces, on a generated room and the default body, and a generated placement group and the contact
metric with open3d and libigl made unimportable, as on a CUDA machine without them."""
from __future__ import annotations

import sys

import numpy as np
import pytest
import torch

import volsmpl
from volsmpl.apps.egohmr import data, metrics, room_checks
from volsmpl.geometry.triangle_queries import first_hits
from volsmpl.scene import make_room

o3d = pytest.importorskip("open3d", reason="the references are open3d's ray casts and distances")
pytest.importorskip("igl", reason="the item inside test's reference is libigl's generalised winding number")
from volsmpl.geometry.groundtruth import raycasting_scene, winding_number  # noqa: E402

ROOM = 3  # a generated room with touching items (carts with overlapping parts, laptops on tables)


@pytest.fixture(autouse=True, scope="module")
def one_thread():
    """One torch thread: MeshQuery's many small CPU ops gain nothing from a second thread and lose much on a busy
    machine (thread barriers)."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def _without_open3d(fn, *args):
    """fn(*args) with open3d and libigl unimportable (room caches cleared before and after)."""
    mp = pytest.MonkeyPatch()
    room_checks.room_solids.cache_clear()
    room_checks.load_room.cache_clear()
    try:
        mp.setitem(sys.modules, "open3d", None)
        mp.setitem(sys.modules, "igl", None)
        return fn(*args)
    finally:
        mp.undo()
        room_checks.room_solids.cache_clear()
        room_checks.load_room.cache_clear()


def _room_rays(room, n: int, seed: int = 0):
    """n eye/target pairs uniform in the room's interior at 0.2-2 m height."""
    rng = np.random.default_rng(seed)
    (x0, _, z0), (x1, _, z1) = room.interior
    pick = lambda: np.stack([rng.uniform(x0, x1, n), rng.uniform(0.2, 2.0, n), rng.uniform(z0, z1, n)], 1)  # noqa: E731
    return pick(), pick()


def test_first_hits_on_a_cube_and_in_chunks():
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    tri = torch.as_tensor(box.vertices[box.faces])
    o = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-2.0, 0.1, 0.2], [-2.0, 3.0, 0.0], [2.0, 0.0, 0.0]],
                     dtype=torch.float64)
    d = torch.tensor([[1.0, 0, 0], [0, 0, -2.0], [1, 0, 0], [1, 0, 0], [1, 0, 0]], dtype=torch.float64)
    t = first_hits(tri, o, d)
    # from the centre: 0.5 m; |d| = 2: 0.25; from outside: the near face at 1.5 m; a miss; the box behind the ray
    assert t[:3].tolist() == [0.5, 0.25, 1.5] and torch.isinf(t[3:]).all()
    assert torch.equal(first_hits(tri, o, d, chunk=5), t)
    flat = torch.tensor([[[0.0, 0, 1], [1, 0, 1], [0, 1, 1]]], dtype=torch.float64)  # a ray in its plane misses it
    assert torch.isinf(first_hits(flat, torch.tensor([[-1.0, 0.2, 1.0]]), torch.tensor([[1.0, 0.0, 0.0]]))).all()
    with pytest.raises(ValueError, match="origins and directions"):
        first_hits(tri, o, d[:2])


def test_first_hits_match_open3d_ray_casts_in_a_room():
    room = make_room(ROOM)
    m = room.mesh()
    eye, tgt = _room_rays(room, 400)
    d = (tgt - eye) / np.linalg.norm(tgt - eye, axis=1, keepdims=True)
    ref = raycasting_scene(m.vertices, m.faces).cast_rays(
        o3d.core.Tensor(np.concatenate([eye, d], 1).astype(np.float32)))["t_hit"].numpy()
    t = first_hits(torch.as_tensor(m.vertices[m.faces]), torch.as_tensor(eye), torch.as_tensor(d), chunk=1 << 12)
    t = t.numpy()
    hit = np.isfinite(ref)
    assert np.array_equal(hit, np.isfinite(t)) and 300 < hit.sum() < 400
    assert np.abs(t[hit] - ref[hit]).max() < 5e-6  # open3d casts float32 rays over up to 8 m


def test_line_of_sight_without_open3d_gives_open3d_answers():
    room = make_room(ROOM)
    m = room.mesh()
    eye, tgt = _room_rays(room, 300, seed=1)
    dist = np.linalg.norm(tgt - eye, axis=1)
    rays = np.concatenate([eye, (tgt - eye) / dist[:, None]], 1).astype(np.float32)
    ref = raycasting_scene(m.vertices, m.faces).cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy() >= dist - 0.25
    got = _without_open3d(lambda: [room._line_of_sight(e, g) for e, g in zip(eye, tgt)])
    assert np.array_equal(got, ref) and ref.sum() >= 30 and (~ref).sum() >= 10
    assert "ray_triangles" in room._cache and "rays" not in room._cache  # the torch path answered


@pytest.fixture(scope="module")
def body_mesh():
    b = volsmpl.create_body()
    with torch.no_grad():
        v = b().vertices[0].double().numpy()
    return v, np.asarray(b.faces)


def test_body_mesh_windings_and_distances_match_open3d(body_mesh):
    v, f = body_mesh
    rng = np.random.default_rng(2)
    lo, hi = v.min(0) - 0.05, v.max(0) + 0.05
    p = lo + rng.random((20000, 3)) * (hi - lo)
    ref = room_checks.BodyMesh(v, f)  # open3d: signed crossings along 3 rays, BVH distances
    mesh = _without_open3d(room_checks.BodyMesh, v, f)
    assert not hasattr(mesh, "scene")  # the torch path (MeshQuery)
    w, d, w_ref, d_ref = mesh.winding(p), mesh.distances(p), ref.winding(p), ref.distances(p)
    off = d_ref > 1e-5  # away from the surface (all of these points are)
    assert np.array_equal(w[off], w_ref[off]) and 500 < (w_ref >= 1).sum() < 5000
    assert np.abs(d - d_ref).max() < 1e-6
    assert abs(mesh.depth(p) - ref.depth(p)) < 1e-6 and ref.depth(p) > 0.05


def test_item_inside_tests_match_libigl():
    room = make_room(ROOM)
    rng = np.random.default_rng(3)
    solids = _without_open3d(room_checks.RoomSolids, room)
    n_in = 0
    for k, ((lo, hi), mesh) in enumerate(solids.items):
        q = lo + rng.random((2000, 3)) * (hi - lo)
        ref = winding_number(mesh.vertices, mesh.faces, q) > 0.5  # libigl's generalised winding number
        got = _without_open3d(solids.inside, k, q)
        assert np.array_equal(got, ref), (k, int((got != ref).sum()))
        n_in += int(ref.sum())
    assert n_in > 1000


def test_surface_distance_and_penetration_match_open3d(body_mesh):
    """The body standing 5 cm deep in items (feet at the centre of each item's top) and in the floor: the
    penetration depths (body in items / floor, room points in the body) and the distance to the item, with and
    without open3d and libigl."""
    v, f = body_mesh
    room = make_room(ROOM)
    cloud = room_checks.room_cloud(ROOM)
    tops = [(0.5 * (it.mesh.bounds[0] + it.mesh.bounds[1]), it.mesh) for it in room.items[:4]]
    depths = []
    for (cx, _, cz), item in tops:
        for y in (item.bounds[1][1] - 0.05, -0.05):
            vs = v + np.array([cx, y, cz]) - [v[:, 0].mean(), v[:, 1].min(), v[:, 2].mean()]
            ref = room_checks.penetration(vs, f, room, cloud)
            got = _without_open3d(room_checks.penetration, vs, f, room, cloud)
            assert np.allclose(got, ref, rtol=0, atol=1e-6), (got, ref)
            depths.append(ref)
        ref_d = room_checks.surface_distance(vs, item)
        assert abs(_without_open3d(room_checks.surface_distance, vs, item) - ref_d) < 1e-6
    assert sum(min(d) > 0.01 for d in depths) >= 4


def _contact_reference(vertices, mesh, threshold=0.02) -> bool:
    """Independent reference: open3d's distance within the threshold, or libigl's generalised winding number of the
    room mesh above 1/2 (robust where components touch)."""
    d = raycasting_scene(mesh.vertices, mesh.faces).compute_distance(o3d.core.Tensor(vertices.astype(np.float32)))
    return bool((d.numpy() <= threshold).any() or (winding_number(mesh.vertices, mesh.faces, vertices) > 0.5).any())


def _contact_bodies(v, room, m):
    """Bodies (B, V, 3) for the contact metric: dropped at random places (in the air, on furniture, sunk into it),
    standing 1 cm and 3 cm above the floor in free space (decided by the distance alone), and shrunk to 2 cm
    inside walls, the floor slab and items farther than 3 cm from their surfaces (decided by the inside test)."""
    rng = np.random.default_rng(ROOM)
    (x0, _, z0), (x1, _, z1) = room.interior
    n = 8
    off = np.stack([rng.uniform(x0, x1, n), rng.uniform(-0.3, 1.0, n), rng.uniform(z0, z1, n)], 1)
    feet = v - [v[:, 0].mean(), v[:, 1].min(), v[:, 2].mean()]
    bodies = list(feet[None] + off[:, None])
    xz = np.stack([rng.uniform(x0, x1, 4000), rng.uniform(z0, z1, 4000)], 1)
    free = xz[room.clearance(xz) > 1.0][0]
    bodies += [feet + [free[0], room.floor_y + lift, free[1]] for lift in (0.01, 0.03)]
    lo, hi = m.bounds
    p = lo + rng.random((20000, 3)) * (hi - lo)
    d = raycasting_scene(m.vertices, m.faces).compute_distance(o3d.core.Tensor(p.astype(np.float32))).numpy()
    deep = p[(d > 0.03) & (winding_number(m.vertices, m.faces, p) > 0.5)]
    tiny = 0.01 * (v - v.mean(0))
    bodies += [tiny + c for c in deep[rng.choice(len(deep), 3, replace=False)]]
    return np.stack(bodies)


def test_contact_without_open3d_matches_open3d_distances_and_libigl(body_mesh):
    """Bodies in the room (_contact_bodies) and a generated frame's body, in contact and lifted off its support."""
    v, _ = body_mesh
    room = make_room(ROOM)
    m = room.mesh()
    V = _contact_bodies(v, room, m)
    ref = np.array([_contact_reference(x, m) for x in V])
    assert 4 <= ref[:8].sum() <= 7 and ref[8:].tolist() == [True, False, True, True, True]
    got = _without_open3d(metrics.contact, V, [m] * len(V))
    assert np.array_equal(got, ref), np.flatnonzero(got != ref)
    assert np.array_equal(metrics.contact(V, [m] * len(V)), ref)  # open3d's path
    frame = data.make_frames("test", 1)[0]
    b = volsmpl.create_body()
    with torch.no_grad():
        vf = b(betas=torch.as_tensor(frame.betas, dtype=torch.float32)[None],
               global_orient=torch.as_tensor(frame.global_orient, dtype=torch.float32)[None],
               body_pose=torch.as_tensor(frame.body_pose, dtype=torch.float32)[None],
               transl=torch.as_tensor(frame.transl, dtype=torch.float32)[None]).vertices.double().numpy()
    scene = data.scene_mesh(frame)
    for lift in (0.0, 0.5):  # in contact with its support; moved 0.5 m along the camera's -y
        vl = vf - [0, lift, 0]
        assert _without_open3d(metrics.contact, vl, [scene])[0] == _contact_reference(vl[0], scene)
        assert metrics.contact(vl, [scene])[0] == _contact_reference(vl[0], scene)  # open3d's own answer here


def test_a_placement_group_without_open3d_or_libigl_is_unchanged():
    """make_group end to end (placement with settling, penetration checks, surface distance, camera views): the
    same frames with and without open3d and libigl; the contact distance to float32 rounding."""
    ref = data.make_group("test", 1, seed=0)  # leaning_wall: settled by bisection on exact penetration tests
    got = _without_open3d(data.make_group, "test", 1, 0)
    assert str(ref["activity"]) == "leaning_wall"
    for k in ref:
        if k == "contact":
            assert abs(float(got[k]) - float(ref[k])) < 1e-6
        else:
            assert np.array_equal(got[k], ref[k]), k


def test_contact_in_open_air_is_no_contact_with_and_without_open3d():
    """A point set in open air (> 3 cm from every surface, outside every component by libigl's winding number) is in
    no contact; one point deep inside a component makes it one. open3d's parity occupancy, used here before, called
    73 of these 20,000 random points of room 3 inside (rays through touching components)."""
    m = make_room(ROOM).mesh()
    lo, hi = m.bounds
    p = lo + np.random.default_rng(7).random((20000, 3)) * (hi - lo)
    d = raycasting_scene(m.vertices, m.faces).compute_distance(o3d.core.Tensor(p.astype(np.float32))).numpy()
    w = winding_number(m.vertices, m.faces, p)
    air, deep = p[(d > 0.03) & (w < 0.5)], p[(d > 0.03) & (w > 0.5)]
    assert len(air) > 5000 and len(deep) > 100
    both = np.stack([air[:10000], np.concatenate([air[:9999], deep[:1]])])
    assert metrics.contact(both, [m, m]).tolist() == [False, True]
    assert _without_open3d(metrics.contact, both, [m, m]).tolist() == [False, True]
