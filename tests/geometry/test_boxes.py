"""Oriented part boxes: SAT overlap vs an exact LP feasibility reference; overlap sampling."""
from __future__ import annotations

import numpy as np
import torch
from scipy.optimize import linprog
from scipy.spatial.transform import Rotation

from volsmpl.geometry.boxes import boxes_overlap, near_boxes, sample_overlaps, world_bounds


def _random_boxes(K, seed):
    rng = np.random.default_rng(seed)
    G = np.tile(np.eye(4), (K, 1, 1))
    G[:, :3, :3] = Rotation.random(K, random_state=seed).as_matrix()
    G[:, :3, 3] = rng.uniform(-1, 1, (K, 3))
    lo = rng.uniform(-0.6, 0.0, (K, 3))
    hi = lo + rng.uniform(0.05, 0.9, (K, 3))
    return torch.tensor(G), torch.tensor(lo), torch.tensor(hi)


def _lp_intersect(Ga, la, ha, Gb, lb, hb) -> bool:
    """Exact: is there x with la <= Ra^T(x - ta) <= ha and the same for b?"""
    A, b = [], []
    for G, lo, hi in ((Ga, la, ha), (Gb, lb, hb)):
        R, t = G[:3, :3], G[:3, 3]
        A += [R.T, -R.T]
        b += [hi + R.T @ t, -(lo + R.T @ t)]
    res = linprog(np.zeros(3), A_ub=np.vstack(A), b_ub=np.concatenate(b), bounds=[(None, None)] * 3, method="highs")
    return res.status == 0


def test_sat_matches_lp():
    K = 12
    for seed in range(4):
        G, lo, hi = _random_boxes(K, seed)
        ov = boxes_overlap(G[None], lo[None], hi[None])[0]
        assert torch.equal(ov, ov.T) and ov.diagonal().all()
        for i in range(K):
            for j in range(i + 1, K):
                assert bool(ov[i, j]) == _lp_intersect(G[i].numpy(), lo[i].numpy(), hi[i].numpy(),
                                                       G[j].numpy(), lo[j].numpy(), hi[j].numpy()), (seed, i, j)


def test_sat_edge_edge_case():
    """Two boxes whose corners are all outside each other but whose edges cross (a corner test misses it)."""
    G = torch.eye(4, dtype=torch.float64).repeat(2, 1, 1)
    G[1, :3, :3] = torch.tensor(Rotation.from_euler("y", 45, degrees=True).as_matrix())
    lo = torch.tensor([[-1.0, -0.1, -0.1], [-1.0, -0.1, -0.1]], dtype=torch.float64)
    hi = -lo
    assert boxes_overlap(G[None], lo[None], hi[None])[0, 0, 1]
    G[1, :3, 3] = torch.tensor([0.0, 0.5, 0.0], dtype=torch.float64)  # lifted apart along y
    assert not boxes_overlap(G[None], lo[None], hi[None])[0, 0, 1]


def test_sample_overlaps_inside_both():
    G, lo, hi = _random_boxes(10, 0)
    ov = boxes_overlap(G[None], lo[None], hi[None])[0]
    pairs = torch.triu(ov, 1).nonzero()
    assert len(pairs) > 0
    pts, pid = sample_overlaps(G, lo, hi, pairs, n_points=500, generator=torch.Generator().manual_seed(0))
    assert pts.shape[0] == pid.shape[0] > 0
    for (a, b), p in zip(pairs[pid].tolist(), pts):
        for k in (a, b):
            loc = G[k, :3, :3].T @ (p - G[k, :3, 3])
            assert (loc >= lo[k] - 1e-9).all() and (loc <= hi[k] + 1e-9).all()
    empty, eid = sample_overlaps(G, lo, hi, torch.zeros(0, 2, dtype=torch.long))
    assert empty.shape == (0, 3) and eid.shape == (0,)


def test_near_boxes_keeps_every_point_in_a_box_and_packs_exactly():
    """world_bounds contain every placed box (points drawn inside the boxes, brute force) and touch their corners;
    near_boxes keeps every such point, packs each body's own points (rows distinct, packed == points[rows]) and
    drops points beyond the bounds."""
    rng = np.random.default_rng(3)
    B, K = 3, 5
    G = torch.eye(4, dtype=torch.float64).repeat(B, K, 1, 1)
    G[..., :3, :3] = torch.as_tensor(Rotation.random(B * K, random_state=4).as_matrix()).view(B, K, 3, 3)
    G[..., :3, 3] = torch.as_tensor(rng.normal(size=(B, K, 3)))
    lo = torch.as_tensor(-rng.uniform(0.05, 0.3, size=(B, K, 3)))
    hi = torch.as_tensor(rng.uniform(0.05, 0.3, size=(B, K, 3)))
    u = torch.as_tensor(rng.uniform(size=(B, K, 40, 3)))
    local = lo[:, :, None] + u * (hi - lo)[:, :, None]
    in_box = (local @ G[..., :3, :3].transpose(-1, -2) + G[..., None, :3, 3]).reshape(B, K * 40, 3)
    far = torch.as_tensor(rng.normal(size=(B, 300, 3))) * 0.2 + 10.0                # beyond every box
    pts = torch.cat([far[:, :150], in_box, far[:, 150:]], dim=1)
    wlo, whi = world_bounds(G, lo, hi)
    corners = torch.stack([torch.where(torch.tensor([i >> 2 & 1, i >> 1 & 1, i & 1], dtype=torch.bool), hi, lo)
                           for i in range(8)], dim=2)
    cw = corners @ G[..., :3, :3].transpose(-1, -2) + G[..., None, :3, 3]
    assert torch.allclose(wlo, cw.reshape(B, -1, 3).amin(1)) and torch.allclose(whi, cw.reshape(B, -1, 3).amax(1))
    packed, rows, valid = near_boxes(pts, G, lo, hi)
    assert packed.shape[1] == K * 40 and valid.all()
    for b in range(B):
        assert rows[b].unique().numel() == rows.shape[1]
        assert set(rows[b].tolist()) == set(range(150, 150 + K * 40))
    assert torch.equal(packed, torch.gather(pts, 1, rows[..., None].expand(-1, -1, 3)))
    # a body with fewer near points than another gets filler rows marked invalid
    pts2 = pts.clone()
    pts2[0, 150:170] = 10.0
    _, rows2, valid2 = near_boxes(pts2, G, lo, hi)
    assert valid2[0].sum() == K * 40 - 20 and valid2[1:].all() and not valid2[0, -20:].any()


def test_box_centred_coordinates_and_membership_far_from_the_origin():
    """box_centred + box_excess against the part-frame formula in float64, for bodies 10 km from the origin (the
    product is taken about the body's own origin, so float32 keeps sub-millimetre coordinates there)."""
    from volsmpl.geometry.boxes import box_centred
    from volsmpl.nn.analytic import box_excess
    K, N = 5, 400
    G, lo, hi = _random_boxes(K, 7)
    G[:, :3, 3] += torch.tensor([10000.0, -5000.0, 2500.0], dtype=torch.float64)
    g = torch.Generator().manual_seed(0)
    x = G[:, :3, 3].mean(0) + torch.randn(N, 3, generator=g, dtype=torch.float64)
    G, lo, hi, x = (a.float().double() for a in (G, lo, hi, x))   # the float32 inputs, exactly
    ref = torch.einsum("kji,nkj->nki", G[:, :3, :3], x[:, None] - G[:, :3, 3]) - 0.5 * (lo + hi)   # R^T (x - t) - c
    u, half = box_centred(x[None].float(), G[None].float(), lo[None].float(), hi[None].float())
    assert u.shape == (1, N, K, 3) and torch.allclose(half[0].double(), 0.5 * (hi - lo), atol=1e-7)
    assert (u[0].double() - ref).abs().max() < 1e-5            # x R - t R in float32 at 10 km would be off by ~1e-3
    inside = (ref.abs() <= 0.5 * (hi - lo)).all(-1)
    member = box_excess(u, half[:, None])[1][0] <= 0
    near = (ref.abs() - 0.5 * (hi - lo)).abs().amin(-1) < 1e-3   # within rounding of a face: either answer
    assert inside.any() and (~inside).any()
    assert torch.equal(member[~near], inside[~near])
