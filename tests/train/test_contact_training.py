"""Self-contact in training: contact poses (volsmpl.body.poses), contact vertices and the queries around them
(volsmpl.body.contact_regions), and their wiring into the training batch; against brute force and exact distances."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

import volsmpl
from volsmpl.body.poses import sample_contact_euler
from volsmpl.body.poses import euler_to_body_pose, named_pose, sample_euler, within_limits
from volsmpl.body.contact_regions import contact_vertices
from volsmpl.train.queries import sample_contact_points
from volsmpl.train.batches import make_batch
from volsmpl.train.config import TrainConfig


@pytest.fixture(scope="module")
def body():
    return volsmpl.create_body()


def _posed(body, body_pose):
    with torch.no_grad():
        return body(body_pose=body_pose, betas=torch.zeros(body_pose.shape[0], body.num_betas)).vertices


def _brute_contact(v: np.ndarray, rest: np.ndarray, rows: np.ndarray, radius: float, gap: float) -> np.ndarray:
    """For the vertices `rows`, against every vertex: within radius posed and beyond gap at rest."""
    out = np.zeros(len(rows), dtype=bool)
    for s in range(0, len(rows), 256):
        i = rows[s:s + 256]
        d = np.linalg.norm(v[i, None] - v[None], axis=-1)
        r = np.linalg.norm(rest[i, None] - rest[None], axis=-1)
        out[s:s + 256] = ((d <= radius) & (r > gap)).any(1)
    return out


def test_contact_vertices_equal_brute_force(body):
    v = _posed(body, torch.cat([named_pose("sitting"), named_pose("t_pose")]))
    mask = contact_vertices(v, body.v_template, radius=0.01, rest_gap=0.1)
    # every vertex the k-d tree calls in contact, and 1,500 others, checked against all vertices
    others = np.random.default_rng(0).choice(np.flatnonzero(~mask[0].numpy()), 1500, replace=False)
    rows = np.concatenate([np.flatnonzero(mask[0].numpy()), others])
    ref = _brute_contact(v[0].double().numpy(), body.v_template.double().numpy(), rows, 0.01, 0.1)
    assert mask[0].sum() > 50 and np.array_equal(mask[0].numpy()[rows], ref)
    assert not mask[1].any()          # the rest pose touches itself nowhere: every near pair is near at rest
    with pytest.raises(ValueError, match="radius"):
        contact_vertices(v, body.v_template, radius=0.2, rest_gap=0.1)


def test_contact_methods_agree(body):
    """The torch method (every pair's distance; what a GPU batch uses) gives the k-d tree's mask, for a shared rest
    shape and for one rest shape per body."""
    v = _posed(body, torch.cat([named_pose("sitting"), named_pose("t_pose")]))
    ref = contact_vertices(v, body.v_template, method="kdtree")
    got = contact_vertices(v, body.v_template, method="torch")
    assert ref[0].sum() > 50 and torch.equal(got, ref)
    rest = torch.stack([body.v_template, body.v_template * 1.5])    # body 1 at rest 1.5x larger: fewer near pairs
    assert torch.equal(contact_vertices(v, rest, method="torch"), contact_vertices(v, rest, method="kdtree"))
    with pytest.raises(ValueError, match="method"):
        contact_vertices(v, body.v_template, method="grid")


@pytest.mark.cuda
def test_contact_vertices_on_cuda_match_the_kd_tree(body):
    """'auto' on CUDA takes the torch grid there: the k-d tree's mask on the CPU."""
    v = _posed(body, torch.cat([named_pose("sitting"), named_pose("t_pose")]))
    got = contact_vertices(v.cuda(), body.v_template.cuda())
    assert got.device.type == "cuda" and torch.equal(got.cpu(), contact_vertices(v, body.v_template, method="kdtree"))


def test_contact_poses_touch_more_than_realistic_ones(body):
    e = sample_contact_euler(16, seed=3)
    pose = euler_to_body_pose(e)
    assert within_limits(pose).all()
    assert np.array_equal(sample_contact_euler(4, seed=3), e[:4])          # body i depends on (seed, i) only
    assert not np.array_equal(sample_contact_euler(4, seed=4), e[:4])
    touch = contact_vertices(_posed(body, pose), body.v_template).sum(1).double()
    base = contact_vertices(_posed(body, euler_to_body_pose(sample_euler(16, seed=3))), body.v_template).sum(1).double()
    assert (touch > 0).float().mean() >= 0.9
    assert touch.mean() > 3 * base.mean()


def test_contact_fraction_replaces_whole_bodies_only():
    base = sample_euler(64, seed=7, mode="mixed")
    assert np.array_equal(sample_euler(64, seed=7, mode="mixed", contact_fraction=0.0), base)
    mix = sample_euler(64, seed=7, mode="mixed", contact_fraction=0.5)
    same = (mix == base).all(axis=(1, 2))
    assert 16 <= (~same).sum() <= 48                  # about half the bodies changed, each as a whole
    allc = sample_euler(64, seed=7, mode="mixed", contact_fraction=1.0)
    assert np.array_equal(allc[~same], mix[~same])    # the replaced ones are the contact stream's bodies
    with pytest.raises(ValueError, match="contact_fraction"):
        sample_euler(2, seed=0, contact_fraction=1.5)


def test_contact_points_sit_on_contact_vertices(body):
    v = _posed(body, torch.cat([named_pose("arms_crossed"), named_pose("t_pose")])).double()
    mask = contact_vertices(v, body.v_template)
    g = torch.Generator().manual_seed(0)
    pts = sample_contact_points(v, mask, 200, sigma=0.0, generator=g)
    d = torch.cdist(pts[0], v[0])                                           # each point is a vertex ...
    hit = d.argmin(1)
    assert d.min(1).values.max() < 1e-12 and mask[0, hit].all()            # ... in contact
    assert torch.cdist(pts[1], v[1]).min(1).values.max() < 1e-12            # no contact: any vertex
    off = sample_contact_points(v, mask, 4000, sigma=(0.005, 0.01), generator=g)[0]
    near = torch.cdist(off, v[0][mask[0]]).min(1).values
    assert near.median() < 0.02 and off.shape == (4000, 3)


def test_batch_contact_block_appends_and_keeps_the_rest(body):
    cfg = TrainConfig(steps=10, batch_size=2, n_uniform=8, n_surface=8, micro_batch=2, gt_rays=1)
    part = volsmpl.Partition(body)
    a = make_batch(cfg, body, part, 5)
    c = make_batch(dataclasses.replace(cfg, n_contact_surface=32, contact_sigma=(0.0,)), body, part, 5)
    n = a["points"].shape[1]
    assert c["points"].shape == (2, n + 32, 3) and torch.equal(c["points"][:, :n], a["points"])
    assert torch.allclose(c["sdf"][:, n:], torch.zeros(2, 32, dtype=c["sdf"].dtype), atol=1e-6)  # on the surface
    d = make_batch(dataclasses.replace(cfg, contact_fraction=1.0), body, part, 5)
    assert not torch.equal(d["params"]["body_pose"], a["params"]["body_pose"])
    cfg2 = TrainConfig.from_dict(dataclasses.replace(cfg, contact_fraction=0.25, n_contact_surface=16).to_dict())
    assert cfg2.contact_fraction == 0.25 and cfg2.contact_sigma == (0.005, 0.01)
    with pytest.raises(ValueError, match="contact_fraction"):
        TrainConfig(contact_fraction=2.0)
