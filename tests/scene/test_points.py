"""Point clouds: surface sampling, farthest-point sampling against a numpy reference, cube crops, subsampling."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.distance import pdist

from volsmpl.scene.points import crop_cube, farthest_point_loop, farthest_point_sample, sample_surface, subsample, to_torch


def _fps_reference(p: np.ndarray, n: int, start: int) -> np.ndarray:
    chosen = [start]
    d = np.linalg.norm(p - p[start], axis=1)
    for _ in range(n - 1):
        k = int(np.argmax(d))
        chosen.append(k)
        d = np.minimum(d, np.linalg.norm(p - p[k], axis=1))
    return np.sort(chosen)


def test_sample_surface_on_box_area_weighted():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    p, n = sample_surface(box, 20000, seed=0)
    assert p.shape == n.shape == (20000, 3)
    assert np.allclose(np.max(np.abs(p) / [0.5, 1.0, 1.5], axis=1), 1.0)  # on the surface
    axis = np.abs(n).argmax(1)
    frac = np.bincount(axis, minlength=3) / len(axis)
    area = np.array([2 * 3, 1 * 3, 1 * 2]) * 2 / 22.0  # faces normal to x, y, z
    assert np.abs(frac - area).max() < 0.015
    rows = np.arange(len(n))
    assert np.allclose(np.abs(n).max(1), 1.0) and (np.sign(n[rows, axis]) == np.sign(p[rows, axis])).all()  # outward
    p2, _ = sample_surface(box, 20000, seed=0)
    assert np.array_equal(p, p2) and not np.array_equal(p, sample_surface(box, 20000, seed=1)[0])


def test_sample_surface_subset_and_errors():
    box = trimesh.creation.box()
    top = np.flatnonzero(box.face_normals[:, 1] > 0.9)
    p, n, f = sample_surface(box, 500, seed=0, faces=top, return_faces=True)
    assert np.allclose(p[:, 1], 0.5) and np.isin(f, top).all()
    with pytest.raises(ValueError, match="zero total area"):
        sample_surface(box, 10, faces=np.zeros(len(box.faces), bool))
    with pytest.raises(ValueError, match="positive int"):
        sample_surface(box, 0)


def test_sample_surface_refuses_face_indices_outside_the_mesh():
    """faces=[0, 1, 12, -1] on the 12-face box (unchecked: faces 0 and 1 sampled, 12 and -1 silently dropped) and
    faces=[0.5, 1.7] (unchecked: 'zero total area') both stop in one line naming the problem."""
    box = trimesh.creation.box()
    with pytest.raises(ValueError, match=r"face indices must be in 0\.\.11 \(the mesh has 12 faces\), got -1\.\.12"):
        sample_surface(box, 10, faces=[0, 1, 12, -1])
    with pytest.raises(ValueError, match="integer face indices or a boolean mask"):
        sample_surface(box, 10, faces=np.array([0.5, 1.7]))
    _, _, f = sample_surface(box, 200, seed=0, faces=np.array([0, 11]), return_faces=True)  # valid: unchanged
    assert set(np.unique(f)) == {0, 11}
    with pytest.raises(ValueError, match="zero total area"):
        sample_surface(box, 10, faces=[])


def test_fps_matches_reference_and_spreads():
    p = np.random.default_rng(0).random((3000, 3))
    idx = farthest_point_sample(p, 200)  # start index 0
    assert idx.dtype == np.int64 and len(np.unique(idx)) == 200 and idx.min() >= 0 and idx.max() < 3000
    assert np.array_equal(idx, _fps_reference(p, 200, 0))
    start = int(np.random.default_rng(5).integers(3000))
    idx5 = farthest_point_sample(p, 200, seed=5)
    assert np.array_equal(idx5, _fps_reference(p, 200, start))
    assert np.array_equal(idx5, farthest_point_sample(p, 200, seed=5))
    rand = np.random.default_rng(1).choice(3000, 200, replace=False)
    assert pdist(p[idx]).min() > 2 * pdist(p[rand]).min()
    t = farthest_point_sample(torch.as_tensor(p), 10)
    assert np.array_equal(t, _fps_reference(p, 10, 0))


def test_torch_fps_picks_what_open3d_picks_ties_included(monkeypatch):
    """The torch loop (used where open3d does not import) against open3d itself: random points, and a grid with
    duplicated points, whose distances tie exactly."""
    import builtins
    grid = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, 9)] * 3), -1).reshape(-1, 3)
    clouds = [np.random.default_rng(2).random((4000, 3)), np.concatenate([grid, grid[:40]])]
    expected = [[farthest_point_sample(c, 300, seed=s) for s in (None, 4)] for c in clouds]
    real_import = builtins.__import__

    def no_open3d(name, *args, **kw):
        if name == "open3d":
            raise ImportError("No module named 'open3d'")
        return real_import(name, *args, **kw)

    monkeypatch.setattr(builtins, "__import__", no_open3d)
    for c, exp in zip(clouds, expected):
        for s, e in zip((None, 4), exp):
            assert np.array_equal(farthest_point_sample(c, 300, seed=s), e)  # through the fallback
    start = int(np.random.default_rng(4).integers(len(clouds[0])))
    assert np.array_equal(farthest_point_loop(clouds[0], 300, start), expected[0][1])
    with pytest.raises(ValueError, match="start index"):
        farthest_point_loop(clouds[0], 3, start=len(clouds[0]))


def test_fps_of_a_cloud_with_fewer_distinct_positions_than_n(monkeypatch):
    """50 points at 10 distinct positions, n = 12: open3d returned only 10 indices (it picks its last point again
    once all are at distance 0 and drops the repeats) and the torch loop returned index 0 three times. Now both
    return 12 distinct indices: all 10 positions, then the first duplicates not yet picked (input order)."""
    import builtins
    rng = np.random.default_rng(3)
    p = np.repeat(rng.random((10, 3)), 5, axis=0)[rng.permutation(50)]
    for seed in (None, 7):
        start = 0 if seed is None else int(np.random.default_rng(seed).integers(50))
        idx = farthest_point_sample(p, 12, seed=seed)
        assert len(idx) == 12 and len(np.unique(idx)) == 12 and len(np.unique(p[idx], axis=0)) == 10, idx
        assert np.array_equal(farthest_point_loop(p, 12, start), idx)
        assert np.array_equal(idx, np.sort(idx)) and start in idx
        assert len(subsample(p, 12, seed=seed, method="fps")) == 12
    real_import = builtins.__import__

    def no_open3d(name, *args, **kw):
        if name == "open3d":
            raise ImportError("No module named 'open3d'")
        return real_import(name, *args, **kw)

    expected = farthest_point_sample(p, 12, seed=7)
    monkeypatch.setattr(builtins, "__import__", no_open3d)
    assert np.array_equal(farthest_point_sample(p, 12, seed=7), expected)  # through the fallback


def test_fps_errors():
    with pytest.raises(ValueError, match="cannot pick"):
        farthest_point_sample(np.zeros((5, 3)), 6)
    with pytest.raises(ValueError, match="empty"):
        farthest_point_sample(np.zeros((0, 3)), 1)
    bad = np.zeros((4, 3))
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        farthest_point_sample(bad, 2)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        farthest_point_sample(np.zeros((4, 2)), 2)


def test_crop_cube_matches_numpy():
    rng = np.random.default_rng(0)
    p = rng.uniform(-3, 3, (20000, 3))
    p[:3] = [[1.0, 0.0, 0.0], [-1.0, 1.0, 1.0], [1.0 + 1e-9, 0, 0]]  # on the faces (kept) and just outside
    c = np.zeros(3)
    idx = crop_cube(p, c, 2.0)
    ref = np.flatnonzero((p >= c - 1.0).all(1) & (p <= c + 1.0).all(1))
    assert np.array_equal(idx, ref) and 0 in idx and 1 in idx and 2 not in idx
    c = np.array([0.5, -1.0, 2.0])
    assert np.array_equal(crop_cube(torch.as_tensor(p), torch.as_tensor(c), 1.5),
                          np.flatnonzero((np.abs(p - c) <= 0.75).all(1)))
    with pytest.raises(ValueError, match="size"):
        crop_cube(p, c, 0.0)
    with pytest.raises(ValueError, match="center"):
        crop_cube(p, [0, 0], 1.0)


def test_subsample_and_torch():
    p = np.random.default_rng(0).random((100, 3))
    idx = subsample(p, 40, seed=0)
    assert len(idx) == 40 and len(np.unique(idx)) == 40
    pad = subsample(p, 150, seed=0)
    assert len(pad) == 150 and set(pad) == set(range(100))
    f = subsample(p, 40, seed=2, method="fps")
    assert len(np.unique(f)) == 40
    with pytest.raises(ValueError, match="method"):
        subsample(p, 10, method="grid")
    tp, tn = to_torch(p, p * 2)
    assert tp.shape == (1, 100, 3) and tp.dtype == torch.float32 and torch.allclose(tn, 2 * tp)
