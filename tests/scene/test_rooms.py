"""Procedural rooms: determinism, distinct layouts, no overlaps (independent 3D box and mesh tests), free space,
start/goal sampling, seats, walls, supports, viewpoints and the cached scene cloud."""
from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from volsmpl.geometry.boxes import boxes_overlap
from volsmpl.geometry.groundtruth import winding_number
from volsmpl.scene.rooms import ROOM_KINDS, make_room, room_points

SEEDS = range(30)


@pytest.fixture(scope="module")
def rooms():
    t = time.perf_counter()
    out = [make_room(s) for s in SEEDS]
    return out, (time.perf_counter() - t) / len(out)


def _fingerprint(room):
    return room.mesh().vertices.tobytes()


def test_deterministic_distinct_and_fast(rooms):
    rs, per_room = rooms
    assert per_room < 1.0, f"{per_room:.2f} s per room"
    assert _fingerprint(make_room(5)) == _fingerprint(rs[5])
    assert len({_fingerprint(r) for r in rs}) == 30
    assert len({tuple(np.round(r.size, 6)) for r in rs}) == 30
    assert {r.kind for r in rs} == set(ROOM_KINDS)
    for r in rs:
        assert 3.0 <= r.size[0] <= 8.0 and 3.0 <= r.size[2] <= 8.0
        assert len(r.items) >= 3
        m = r.mesh()
        assert m.is_watertight  # closed components
    with pytest.raises(ValueError, match="non-negative int"):
        make_room(-1)


def test_no_box_overlaps(rooms):
    """Independent 3D test: the items' oriented boxes (from the mesh vertices in each item's frame) pairwise
    disjoint (volsmpl.geometry.boxes SAT, checked against LP elsewhere), and every mesh inside the interior."""
    for r in rooms[0]:
        K = len(r.items)
        G = np.stack([it.transform for it in r.items])
        lo, hi = np.zeros((K, 3)), np.zeros((K, 3))
        for i, it in enumerate(r.items):
            local = (it.mesh.vertices - it.transform[:3, 3]) @ it.transform[:3, :3]
            lo[i], hi[i] = local.min(0), local.max(0)
        ov = boxes_overlap(torch.tensor(G)[None], torch.tensor(lo)[None], torch.tensor(hi)[None])[0]
        ov = ov.numpy() & ~np.eye(K, dtype=bool)
        assert not ov.any(), (r.seed, [(r.items[i].name, r.items[j].name) for i, j in zip(*np.nonzero(ov))])
        (x0, _, z0), (x1, H, z1) = r.interior
        for it in r.items:
            (a, b) = it.mesh.bounds
            assert a[0] >= x0 and b[0] <= x1 and a[2] >= z0 and b[2] <= z1 and a[1] >= -1e-9 and b[1] < H, it.name
            if it.on is None:
                assert abs(a[1]) < 1e-9  # stands on the floor
            else:
                top = r.items[it.on].mesh.bounds[1][1]
                assert a[1] > top - 1e-9  # rests on its support


def test_no_mesh_overlaps(rooms):
    """Independent mesh test: surface samples of every item are outside every other item (winding number)."""
    for r in rooms[0][:6]:
        samples = [np.asarray(it.mesh.sample(150, seed=0)) for it in r.items]
        for j, it in enumerate(r.items):
            others = np.concatenate([s for i, s in enumerate(samples) if i != j])
            w = winding_number(it.mesh.vertices, it.mesh.faces, others, fast=True)
            assert (w < 0.5).all(), (r.seed, it.name)


def _reference_clearance(room, xz):
    """Brute force: distance to dense samples of each floor item's footprint rectangle (from its vertices) and
    to the walls."""
    pts = []
    for it in room.items:
        if it.on is not None:
            continue
        local = (it.mesh.vertices - it.transform[:3, 3]) @ it.transform[:3, :3]
        lo, hi = local.min(0), local.max(0)
        u, v = np.meshgrid(np.linspace(lo[0], hi[0], 120), np.linspace(lo[2], hi[2], 120))
        loc = np.stack([u.ravel(), np.zeros(u.size), v.ravel()], 1)
        pts.append((loc @ it.transform[:3, :3].T + it.transform[:3, 3])[:, [0, 2]])
    pts = np.concatenate(pts)
    d = np.sqrt(((xz[:, None] - pts[None]) ** 2).sum(-1)).min(1)
    (x0, _, z0), (x1, _, z1) = room.interior
    wall = np.minimum.reduce([xz[:, 0] - x0, x1 - xz[:, 0], xz[:, 1] - z0, z1 - xz[:, 1]])
    return np.clip(np.minimum(d, wall), 0, None)


def test_clearance_and_grid(rooms):
    r = rooms[0][2]
    rng = np.random.default_rng(0)
    (x0, _, z0), (x1, _, z1) = r.interior
    xz = rng.uniform([x0, z0], [x1, z1], (300, 2))
    ref = _reference_clearance(r, xz)
    assert np.abs(r.clearance(xz) - ref).max() < 0.03  # reference sampled every <= 2 cm
    free, xs, zs = r.free_grid(0.0)
    assert free.shape == (len(zs), len(xs)) and np.allclose(np.diff(xs), 0.05)
    for it in r.items:  # the cell under each floor item's centre is occupied
        c = it.obb[0]
        assert not free[np.abs(zs - c[2]).argmin(), np.abs(xs - c[0]).argmin()]
    assert free.mean() > 0.3 and r.free_grid(0.3)[0].sum() < free.sum()


def test_start_goal(rooms):
    for r in rooms[0][:8]:
        for blocked in (None, False, True):
            try:
                a, b = r.sample_start_goal(2.5, clearance=0.25, seed=1, blocked=blocked)
            except ValueError:
                assert blocked is not None  # a room may have no blocked / no free straight pair
                continue
            assert a[1] == b[1] == 0.0
            assert abs(np.linalg.norm(a - b) - 2.5) <= 0.1 + 1e-9
            assert (_reference_clearance(r, np.stack([a[[0, 2]], b[[0, 2]]])) > 0.25 - 0.03).all()
            if blocked is not None:
                assert (r.path_clearance(a, b) <= 0.25) == blocked
    with pytest.raises(ValueError, match="no free start/goal"):
        rooms[0][0].sample_start_goal(50.0)


def test_seats_walls_supports(rooms):
    import open3d as o3d

    n_seats = 0
    for r in rooms[0][:12]:
        for s in r.seats():
            it = r.items[s.item]
            scene = o3d.t.geometry.RaycastingScene()
            scene.add_triangles(o3d.core.Tensor(it.mesh.vertices.astype(np.float32)),
                                o3d.core.Tensor(it.mesh.faces.astype(np.uint32)))
            d = scene.compute_distance(o3d.core.Tensor(s.position[None].astype(np.float32))).numpy()[0]
            assert d < 1e-4 and s.position[1] == pytest.approx(s.height)  # on the seat surface
            assert np.isclose(np.linalg.norm(s.facing), 1) and abs(s.facing[1]) < 1e-12
            assert np.allclose(s.facing, it.transform[:3, 2])  # the chair's front
            n_seats += 1
        walls = r.walls()
        assert len(walls) == 4
        for w in walls:
            assert np.dot(w.normal[[0, 2]], -w.center[[0, 2]]) > 0  # inward: towards the room centre
        for sp in r.supports():
            it = r.items[sp.item]
            if sp.name.endswith(":top") and it.category == "table":
                assert sp.center[1] == pytest.approx(it.mesh.bounds[1][1])
    assert n_seats >= 20


def test_viewpoint(rooms):
    r = rooms[0][6]
    tgt = r.seats()[0].position + [0, 0.3, 0]
    for seed in range(5):
        eye = r.sample_viewpoint(tgt, distance=(0.8, 2.5), height=(1.4, 1.8), seed=seed)
        d = np.linalg.norm((eye - tgt)[[0, 2]])
        assert 0.8 <= d <= 2.5 and 1.4 <= eye[1] <= 1.8
        assert r.clearance(eye[[0, 2]][None])[0] > 0.2


def test_room_points_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSMPL_CACHE", str(tmp_path))
    d = room_points(3, n=1024, oversample=3)
    assert d["points"].shape == (1024, 3) and d["normals"].shape == (1024, 3) and d["labels"].shape == (1024,)
    r = make_room(3)
    (x0, _, z0), (x1, H, z1) = r.interior
    p = d["points"]
    assert (p[:, 1] >= -1e-6).all() and (p[:, 1] <= H + 1e-5).all()
    assert (p[:, 0] >= x0 - 1e-5).all() and (p[:, 0] <= x1 + 1e-5).all()
    assert len(np.unique(p, axis=0)) == 1024
    assert set(np.unique(d["labels"])) <= set(range(-2, len(r.items)))
    assert (d["labels"] == -1).any() and (d["labels"] == -2).any() and (d["labels"] >= 0).any()
    assert list(tmp_path.rglob("*.npz"))
    again = room_points(3, n=1024, oversample=3)
    assert all(np.array_equal(again[k], d[k]) for k in d)
