"""The model registry, the shared sign convention and the exact 'mesh' kind, against independent references
(open3d's exact distances, trimesh's closest points, finite differences, hand-computed losses)."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

import volsmpl
from volsmpl.geometry.groundtruth import mesh_sdf
from volsmpl.geometry.point_mesh_distance import closest_points_on_triangles, mesh_signed_distance, nearest_faces
from volsmpl.volume.models import MODELS, kind_of_config, learned_models, model_kind, parse_models
from volsmpl.volume.self_penetration import reduce_selfpen

from conftest import random_pose


def test_registry_names_every_kind_once():
    assert list(MODELS) == ["volsmpl", "coap", "mesh"]
    assert learned_models() == ("volsmpl", "coap")
    assert model_kind("volsmpl").output == "sdf" and model_kind("coap").output == "occupancy"
    assert not model_kind("mesh").learned and model_kind("mesh").default_checkpoint is None
    assert kind_of_config({"model": "coap"}) == "coap" and kind_of_config({}) == "volsmpl"
    assert parse_models("mesh, volsmpl,mesh") == ["mesh", "volsmpl"]
    with pytest.raises(ValueError, match="available: volsmpl, coap, mesh"):
        model_kind("leap")
    with pytest.raises(ValueError, match="not a network"):
        model_kind("mesh").build_network(16)
    with pytest.raises(ValueError, match="comma-separated"):
        parse_models("volsmpl,leap")


@pytest.mark.parametrize("name", ["volsmpl", "coap", "mesh"])
def test_every_kind_attaches_and_reports_its_name(body, name):
    vol = volsmpl.attach_volume(body, model=name, pretrained=False) if model_kind(name).learned \
        else volsmpl.attach_volume(body, model=name)
    assert vol.kind == name and body.volume is vol


def test_closest_points_match_trimesh():
    g = torch.Generator().manual_seed(0)
    tri = torch.randn(200, 3, 3, generator=g, dtype=torch.float64)
    p = torch.randn(200, 3, generator=g, dtype=torch.float64) * 2
    ours = closest_points_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])
    ref = trimesh.triangles.closest_point(tri.numpy(), p.numpy())
    assert np.abs(ours.numpy() - ref).max() < 1e-9


def _box():
    m = trimesh.creation.box((2.0, 1.0, 0.5))
    return torch.tensor(m.vertices), torch.tensor(m.faces)


def test_mesh_signed_distance_of_a_box_by_hand():
    v, f = _box()
    p = torch.tensor([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.9, 0.1, 0.0], [1.5, 1.0, 0.25 + 0.3]], dtype=torch.float64)
    expect = torch.tensor([-0.25, 1.0, -0.1, (0.5 ** 2 + 0.5 ** 2 + 0.3 ** 2) ** 0.5], dtype=torch.float64)
    for backend in ("open3d", "torch"):
        assert torch.allclose(mesh_signed_distance(v, f, p, backend=backend), expect, atol=1e-6)


def test_nearest_face_backends_agree(body):
    out = body(**random_pose(1, seed=3))
    p = out.vertices[0, ::50] + 0.03 * torch.randn(out.vertices[0, ::50].shape, generator=torch.Generator().manual_seed(1))
    faces = torch.as_tensor(body.faces)
    a = nearest_faces(out.vertices[0], faces, p, backend="open3d")
    b = nearest_faces(out.vertices[0], faces, p, backend="torch")
    tri = out.vertices[0][faces]
    da = (closest_points_on_triangles(p, *tri[a].unbind(1)) - p).norm(dim=-1)
    db = (closest_points_on_triangles(p, *tri[b].unbind(1)) - p).norm(dim=-1)
    assert torch.allclose(da, db, atol=1e-6)  # ties may pick other faces at the same distance


def test_mesh_kind_matches_open3d_exact_signed_distance(body):
    vol = volsmpl.attach_volume(body, model="mesh")
    out = body(**random_pose(2, seed=5))
    g = torch.Generator().manual_seed(2)
    near = out.vertices[:, ::40] + 0.02 * torch.randn(out.vertices[:, ::40].shape, generator=g)
    far = torch.rand(2, 300, 3, generator=g) * 2 - 1
    pts = torch.cat([near, far], dim=1)
    ours = vol.query(out, pts)
    for b in range(2):
        ref = mesh_sdf(out.vertices[b].double(), body.faces, pts[b].double(), sign="winding")
        assert torch.allclose(ours[b].double(), ref, atol=1e-5)
        assert (ours[b] < 0).sum() > 10  # the test must see inside points
    assert torch.equal(vol.signed(out, pts), ours) and torch.equal(vol.occupied(ours), ours < 0)


def test_mesh_kind_gradients_match_finite_differences(body):
    body64 = volsmpl.create_body().double()
    vol = volsmpl.attach_volume(body64, model="mesh")
    pose = {k: v.double() for k, v in random_pose(1, seed=7).items()}
    pose["body_pose"].requires_grad_(True)
    out = body64(**pose)
    g = torch.Generator().manual_seed(4)
    pts = (out.vertices[0, ::600].detach() + 0.02 * torch.randn(out.vertices[0, ::600].shape, generator=g,
                                                                dtype=torch.float64)).requires_grad_(True)
    d = vol.query(out, pts)
    gp, gpose = torch.autograd.grad(d.sum(), [pts, pose["body_pose"]])
    eps = 1e-6
    for i in range(3):  # points: each coordinate
        e = torch.zeros_like(pts)
        e[:, i] = eps
        fd = (vol.query(out, pts.detach() + e) - vol.query(out, pts.detach() - e))[0] / (2 * eps)
        assert torch.allclose(gp[:, i], fd, atol=1e-5)
    for j in (0, 5, 12, 40):  # pose entries: the vertices' gradient reaches the pose
        e = torch.zeros_like(pose["body_pose"])
        e[0, j] = eps
        hi = vol.query(body64(**dict(pose, body_pose=pose["body_pose"].detach() + e)), pts.detach()).sum()
        lo = vol.query(body64(**dict(pose, body_pose=pose["body_pose"].detach() - e)), pts.detach()).sum()
        assert float(gpose[0, j]) == pytest.approx(float(hi - lo) / (2 * eps), abs=1e-5)


def test_signed_convention_of_coap_is_monotone_with_zero_at_the_level(body):
    vol = volsmpl.attach_volume(body, model="coap", pretrained=False)
    occ = torch.tensor([[0.0, 0.25, 0.5, 0.75, 1.0]])
    s = vol.to_signed(occ)
    assert torch.equal(s, torch.tensor([[0.5, 0.25, 0.0, -0.25, -0.5]]))
    assert torch.equal(vol.occupied(occ), s < 0)
    # the paper's collision term for COAP (supp. D.2): occupancy where inside, 0 elsewhere
    assert torch.allclose(vol.penetration(occ), torch.tensor([[0.0, 0.0, 0.0, 0.75, 1.0]]))


def test_selfpen_reduction_on_a_hand_made_field():
    # 3 parts; only parts 0 and 2 may collide. Sample 0 inside 0 and 2, sample 1 inside 0 and 1, sample 2 inside 2 only.
    mask = torch.tensor([[False, False, True], [False, False, False], [True, False, False]])
    part = torch.tensor([[[-0.01, -0.02, 0.05], [0.03, -0.01, 0.04], [-0.02, 0.03, -0.01]]])  # (1, K, M)
    samples = [torch.arange(9.0).reshape(3, 3)]
    tau = 0.01
    loss, kept = reduce_selfpen(part, part < 0, mask, samples, lambda p, inv: (torch.sigmoid(-p / tau) * inv).sum(),
                                return_points=True)
    expect = torch.sigmoid(torch.tensor(0.01 / tau)) + torch.sigmoid(torch.tensor(0.02 / tau))
    assert float(loss[0]) == pytest.approx(float(expect), rel=1e-6)
    assert torch.equal(kept[0], samples[0][:1])


def test_mesh_selfpen_finds_a_crossed_arm_and_pushes_it_out(body):
    from volsmpl.apps.selfpen.cases import load_cases

    case = load_cases(names=["arm_through_head"])[0]
    vol = volsmpl.attach_volume(body, model="mesh")
    pose = case.body_pose.reshape(1, -1).clone().requires_grad_(True)
    out = body(betas=case.betas.reshape(1, -1), global_orient=case.global_orient.reshape(1, 3), body_pose=pose)
    loss, kept = vol.selfpen_loss(out, generator=torch.Generator().manual_seed(0), return_points=True)
    assert kept[0].shape[0] > 0 and float(loss[0].detach()) > 0
    (grad,) = torch.autograd.grad(loss.sum(), pose)
    moved = pose.detach() - 0.05 * grad / grad.norm()
    out2 = body(betas=case.betas.reshape(1, -1), global_orient=case.global_orient.reshape(1, 3), body_pose=moved)
    after = vol.selfpen_loss(out2, generator=torch.Generator().manual_seed(0))
    assert float(after[0].detach()) < float(loss[0].detach())


def test_the_registry_says_which_kinds_decode_pairs_by_grouped_matmuls(monkeypatch):
    """With pair_decoder 'grouped', VolumetricSMPL's query decodes its pairs by grouped matmuls where this torch
    has them; the registry, not the network's attributes, says which kinds can."""
    import torch

    import volsmpl
    from volsmpl.volume.models import model_kind

    assert model_kind("volsmpl").grouped and not model_kind("coap").grouped and not model_kind("mesh").grouped
    body = volsmpl.create_body()
    vol = volsmpl.attach_volume(body, model="volsmpl")
    vol.pair_decoder = "grouped"
    calls = []
    decode = vol.net.decode_grouped
    monkeypatch.setattr(vol.net, "decode_grouped", lambda *a, **k: calls.append(1) or decode(*a, **k))
    with torch.no_grad():
        out = body()
        vol.query(out, out.vertices[0, ::50] + 0.005)
    assert bool(calls) == vol.net.grouped_supported(torch.float32, "cpu")
