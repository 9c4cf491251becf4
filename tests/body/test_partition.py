"""Partition: labels, part frames, boxes, surface samples; batched, against exact references."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from volsmpl.body.partition import Partition, face_labels
from conftest import random_pose


@pytest.fixture(scope="module")
def part(body):
    return Partition(body)


def test_every_vertex_in_exactly_one_part(body, part):
    V = body.v_template.shape[0]
    lab = part.vertex_labels
    assert lab.shape == (V,) and lab.min() >= 0 and lab.max() < part.num_parts
    counts = torch.bincount(lab, minlength=part.num_parts)
    assert (counts > 0).all() and counts.sum() == V
    # tight face sets partition the faces; extended sets contain the tight ones
    all_tight = np.concatenate(part.tight_face_ids)
    assert np.array_equal(np.sort(all_tight), np.arange(len(body.faces)))
    for t, e in zip(part.tight_face_ids, part.extended_face_ids):
        assert np.isin(t, e).all() and len(e) > len(t)


def test_face_labels_majority():
    faces = np.array([[0, 1, 2], [0, 1, 3], [2, 3, 4], [4, 4, 4]])
    vlab = np.array([5, 5, 7, 9, 1])
    assert face_labels(faces, vlab).tolist() == [5, 5, 1, 1]  # [5,5,7]->5, [5,5,9]->5, [7,9,1]->min=1


def test_part_frames_match_skinning(body, part):
    """G_k's rotation is the joint's world rotation (= the rotation of the LBS transform), its origin the joint."""
    out = body(**random_pose(3, seed=4))
    G = part.part_transforms(out.full_pose, out.joints)
    j = part.part_joints
    assert torch.allclose(G[..., :3, :3], out.joint_transforms[:, j, :3, :3], atol=1e-5)
    assert torch.allclose(G[..., :3, 3], out.joints[:, j], atol=1e-6)
    eye = torch.eye(3).expand_as(G[..., :3, :3])
    assert torch.allclose(G[..., :3, :3].transpose(-1, -2) @ G[..., :3, :3], eye, atol=1e-5)


def test_canonicalize_roundtrip(body, part):
    out = body(**random_pose(2, seed=5))
    G = part.part_transforms(out.full_pose, out.joints)
    x = torch.randn(2, 50, 3)
    local = Partition.canonicalize(x, G)
    back = Partition.uncanonicalize(local, G)
    assert torch.allclose(back, x[:, None].expand_as(back), atol=1e-5)
    # the joint of part k sits at the origin of its frame
    jl = Partition.canonicalize(out.joints[:, part.part_joints], G)
    idx = torch.arange(part.num_parts)
    assert torch.allclose(jl[:, idx, idx], torch.zeros(2, part.num_parts, 3), atol=1e-5)


@pytest.mark.parametrize("method", ["loop", "scatter"])
def test_boxes_contain_part_vertices(body, part, method):
    out = body(**random_pose(2, scale=0.6, seed=6))
    G = part.part_transforms(out.full_pose, out.joints)
    bmin, bmax = part.boxes(out.vertices, G, method=method)
    local = Partition.canonicalize(out.vertices, G)  # (B, K, V, 3)
    for k in range(part.num_parts):
        sel = part.vertex_labels == k
        lv = local[:, k, sel]
        assert (lv >= bmin[:, k, None]).all() and (lv <= bmax[:, k, None]).all()
        # padding: tight extent grows by exactly 12.5 %
        tight = lv.amax(1) - lv.amin(1)
        assert torch.allclose(bmax[:, k] - bmin[:, k], tight * 1.125, atol=1e-5)
        assert torch.allclose(bmax[:, k] + bmin[:, k], lv.amax(1) + lv.amin(1), atol=1e-5)  # centred on the tight box


def test_surface_samples_on_mesh(body, part):
    out = body(**random_pose(1, seed=7))
    pts = part.surface_points(out.vertices)  # fixed set
    assert pts.shape == (1, part.num_parts, 1000, 3)
    mesh = trimesh.Trimesh(out.vertices[0].numpy(), body.faces, process=False)
    _, dist, tri = trimesh.proximity.closest_point(mesh, pts[0].reshape(-1, 3).numpy())
    assert dist.max() < 1e-4  # float32 barycentric interpolation at metre scale
    # the first half of each part's samples lies on its own (tight) faces
    tri = tri.reshape(part.num_parts, 1000)
    flab = part.face_labels.numpy()
    for k in range(part.num_parts):
        assert (flab[tri[k, :500]] == k).mean() > 0.97  # closest face may be a neighbour on shared edges


def test_surface_samples_reproducible(body):
    a, b, c = Partition(body, seed=0), Partition(body, seed=0), Partition(body, seed=1)
    assert torch.equal(a.sample_faces, b.sample_faces) and torch.equal(a.sample_bary, b.sample_bary)
    assert not torch.equal(a.sample_faces, c.sample_faces)
    out = body(**random_pose(2))
    g1, g2 = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    assert torch.equal(a.surface_points(out.vertices, g1), a.surface_points(out.vertices, g2))


def test_area_weighting(body, part):
    """Samples per face follow face areas: compare sample counts with areas over a part (chi-square-like)."""
    out = body()
    g = torch.Generator().manual_seed(0)
    counts = torch.zeros(len(body.faces))
    for _ in range(20):
        f_ids, _ = part._draw(out.vertices, g)
        counts += torch.bincount(f_ids[0, 3, :500].reshape(-1), minlength=len(body.faces)).float()
    faces = part.tight_face_ids[3]
    areas = torch.as_tensor(trimesh.Trimesh(body.v_template.numpy(), body.faces, process=False).area_faces[faces]).float()
    expected = areas / areas.sum() * counts[faces].sum()
    # group faces into 10 area deciles and compare totals (robust to per-face noise)
    order = torch.argsort(areas)
    for chunk in order.chunk(10):
        assert abs(counts[faces][chunk].sum() - expected[chunk].sum()) < 0.15 * expected[chunk].sum() + 30


def test_draws_weigh_each_part_list_by_its_face_areas(body, part):
    """`_draw` (areas once per face, gathered per part) draws what the literal definition draws: an
    area-weighted choice over each part's own padded face list (tight, then extended), with the same generator."""
    out = body(**random_pose(2, seed=5))
    f_ids, _ = part._draw(out.vertices, torch.Generator().manual_seed(11))
    g = torch.Generator().manual_seed(11)
    v = out.vertices.detach()
    expect = []
    for pad, mask, n in ((part._tight_pad, part._tight_mask, part.n_samples // 2),
                         (part._ext_pad, part._ext_mask, part.n_samples - part.n_samples // 2)):
        tri = v[:, part.faces[pad]]                                          # (B, K, L, 3, 3)
        areas = 0.5 * torch.linalg.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :]).norm(dim=-1)
        probs = torch.where(mask, areas, torch.zeros_like(areas)).clamp_min(0).reshape(-1, pad.shape[1]).double()
        idx = torch.multinomial(probs, n, replacement=True, generator=g)
        expect.append(torch.gather(pad.repeat(2, 1), 1, idx).reshape(2, part.num_parts, n))
    assert torch.equal(f_ids, torch.cat(expect, dim=-1))


def test_batch_equals_items(body, part):
    p = random_pose(3, seed=8)
    out = body(**p)
    G = part.part_transforms(out.full_pose, out.joints)
    bmin, bmax = part.boxes(out.vertices, G)
    s = part.surface_points(out.vertices)
    for i in range(3):
        o = body(**{k: v[i:i + 1] for k, v in p.items()})
        Gi = part.part_transforms(o.full_pose, o.joints)
        mi, ma = part.boxes(o.vertices, Gi)
        assert torch.allclose(G[i], Gi[0], atol=1e-6)
        assert torch.allclose(bmin[i], mi[0], atol=1e-6) and torch.allclose(bmax[i], ma[0], atol=1e-6)
        assert torch.allclose(s[i], part.surface_points(o.vertices)[0], atol=1e-6)


def test_differentiable(body, part):
    p = {k: v.requires_grad_() for k, v in random_pose(1, seed=9).items()}
    out = body(**p)
    G = part.part_transforms(out.full_pose, out.joints)
    bmin, bmax = part.boxes(out.vertices, G)
    (bmin.sum() + bmax.sum() + part.surface_points(out.vertices).sum() + G.sum()).backward()
    for k in ("betas", "body_pose", "transl"):
        assert p[k].grad is not None and p[k].grad.abs().sum() > 0, k


@pytest.mark.parametrize("method", ["loop", "scatter"])
def test_box_gradients_match_finite_differences(body, part, method):
    """Each box bound is one vertex's coordinate in its part's frame: the analytic gradient with respect to the
    vertices and the frames equals central differences (float64; a pose without ties)."""
    out = body(**random_pose(2, scale=0.5, seed=12))
    G = part.part_transforms(out.full_pose, out.joints).detach().double()
    v = out.vertices.detach().double()
    w = torch.randn(2, part.num_parts, 3, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(1))

    def f(v, t):
        Gt = G.clone()
        Gt[..., :3, 3] = t
        lo, hi = part.boxes(v, Gt, method=method)
        return (w[..., 0] * lo).sum() + (w[..., 1] * hi).sum()

    v.requires_grad_()
    t = G[..., :3, 3].clone().requires_grad_()
    gv, gt = torch.autograd.grad(f(v, t), (v, t))
    eps = 1e-6
    with torch.no_grad():
        for i, j, c in [(0, 5, 0), (1, 4000, 2), (0, 13000, 1)]:
            d = torch.zeros_like(v)
            d[i, j, c] = eps
            fd = (f(v + d, t) - f(v - d, t)) / (2 * eps)
            assert abs(fd - gv[i, j, c]) < 1e-6, (i, j, c, float(fd), float(gv[i, j, c]))
        for i, k, c in [(0, 3, 0), (1, 10, 2)]:
            d = torch.zeros_like(t)
            d[i, k, c] = eps
            fd = (f(v, t + d) - f(v, t - d)) / (2 * eps)
            assert abs(fd - gt[i, k, c]) < 1e-6, (i, k, c, float(fd), float(gt[i, k, c]))


def test_box_method_is_checked(body, part):
    out = body()
    with pytest.raises(ValueError, match="'loop' or 'scatter'"):
        part.boxes(out.vertices, part.part_transforms(out.full_pose, out.joints), method="padded")


def test_unsupported_bodies(body):
    class MANO:
        pass
    with pytest.raises(ValueError, match="not supported"):
        Partition(MANO())

    class Mapped:
        joint_mapper = object()
    with pytest.raises(ValueError, match="joint_mapper"):
        Partition(Mapped())

    class Other:
        faces = body.faces
    with pytest.raises(ValueError, match="not a SMPL-family"):
        Partition(Other())


def test_wrong_pose_size(body, part):
    out = body()
    with pytest.raises(ValueError, match="do not fit"):
        part.part_transforms(out.full_pose[:, :66], out.joints)


def test_draws_follow_the_generator_device(body, part):
    """A CPU generator given as torch.device('cpu') draws what the default generator draws; results sit on the
    vertices' device in their dtype."""
    v = body(**random_pose(2, seed=3)).vertices.detach()
    a = part.surface_points(v, torch.Generator().manual_seed(7))
    b = part.surface_points(v, torch.Generator(device=torch.device("cpu")).manual_seed(7))
    assert torch.equal(a, b) and a.dtype == v.dtype and a.device == v.device
    assert not torch.equal(a, part.surface_points(v, torch.Generator().manual_seed(8)))


@pytest.mark.cuda
def test_draws_on_cuda(body, part):
    """CUDA vertices: a CPU generator gives the CPU samples (moved), a CUDA generator deterministic CUDA samples."""
    v = body(**random_pose(2, seed=3)).vertices.detach()
    pc = part.to("cuda")
    try:
        vc = v.cuda()
        a = pc.surface_points(vc, torch.Generator().manual_seed(7))
        assert a.device.type == "cuda"
        assert torch.allclose(a.cpu(), part.cpu().surface_points(v, torch.Generator().manual_seed(7)), atol=1e-6)
        pc = part.to("cuda")
        b = pc.surface_points(vc, torch.Generator(device="cuda").manual_seed(7))
        c = pc.surface_points(vc, torch.Generator(device="cuda").manual_seed(7))
        assert b.device.type == "cuda" and torch.equal(b, c)
    finally:
        part.cpu()
