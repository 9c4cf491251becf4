"""Loss terms of the human–object app on hand-made configurations, against exact references."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import trimesh

import volsmpl
from volsmpl.apps.hoi.losses import (body_query, contact_terms, keypoint_term, penetration, relative_similarity,
                                     scale_prior, silhouette_term, to_body_frame, to_camera)
from volsmpl.apps.hoi.problem import REGION_TRIANGLES, region_triangles
from volsmpl.geometry.groundtruth import mesh_sdf
from volsmpl.geometry.rotations import axis_angle_to_matrix


@pytest.fixture(scope="module")
def posed(body):
    with torch.no_grad():
        out = body(betas=torch.zeros(1, 10), body_pose=torch.zeros(1, 69))
    return out


def _thigh_points(body, out, depth: float, n: int = 50):
    """Points `depth` metres inside (depth > 0) or outside (< 0) the left thigh, along the inward vertex normals."""
    import trimesh
    p = volsmpl.Partition(body)
    ids = np.nonzero(p.vertex_labels.numpy() == list(p.table.part_names).index("left_thigh"))[0][::5][:n]
    v = out.vertices[0].numpy()
    nrm = trimesh.Trimesh(v, np.asarray(body.faces), process=False).vertex_normals[ids]
    return torch.as_tensor(v[ids] - depth * nrm, dtype=torch.float32)[None]


def test_contact_is_zero_when_touching_and_grows_with_the_gap():
    g = torch.Generator().manual_seed(0)
    q = torch.rand(1, 40, 3, generator=g) * torch.tensor([0.2, 0.0, 0.2])  # a patch of the plane y = 0
    up = torch.tensor([0.0, 1.0, 0.0]).expand(1, 40, 3)
    mask = torch.ones(1, 40, dtype=torch.bool)
    c, n, _, _ = contact_terms(q.clone(), -up, q, up, mask)
    assert float(c) == pytest.approx(0.0, abs=1e-9) and float(n) == pytest.approx(0.0, abs=1e-7)  # touching, opposite
    c2, n2, facing, _ = contact_terms(q + torch.tensor([0.0, 0.03, 0.0]), -up, q, up, mask)
    assert bool(facing.all()) and float(c2) == pytest.approx(0.03 ** 2, rel=1e-5)  # mean squared gap of 3 cm
    _, n3, _, _ = contact_terms(q + torch.tensor([0.0, 0.03, 0.0]), up, q, up, mask)
    assert float(n3) == pytest.approx(2.0, abs=1e-6)  # same direction: 1 + cos = 2


def test_contact_margin_counts_a_gap_within_it_as_touching():
    """The margin by hand: a plane patch 3 cm off its region costs (3 - m)^2 cm^2 with margin m < 3 cm and nothing,
    with a zero (finite) gradient, at m >= 3 cm; a patch on the region keeps a finite gradient; the pseudo-Huber
    applies to the shortened distance; a negative margin is refused."""
    g = torch.Generator().manual_seed(1)
    q = torch.rand(1, 30, 3, generator=g) * torch.tensor([0.2, 0.0, 0.2])
    up = torch.tensor([0.0, 1.0, 0.0]).expand(1, 30, 3)
    mask = torch.ones(1, 30, dtype=torch.bool)
    gap = torch.tensor([0.0, 0.03, 0.0])
    c, _, _, _ = contact_terms(q + gap, -up, q, up, mask, margin=0.01)
    assert float(c) == pytest.approx(0.02 ** 2, rel=1e-4)
    for p0, m in ((q + gap, 0.03), (q + gap, 0.05), (q.clone(), 0.01)):
        p = p0.clone().requires_grad_(True)
        c, _, _, _ = contact_terms(p, -up, q, up, mask, margin=m)
        c.backward()
        assert float(c) == pytest.approx(0.0, abs=1e-10)
        assert torch.isfinite(p.grad).all() and float(p.grad.abs().max()) < 1e-6
    h = 0.02
    c, _, _, _ = contact_terms(q + 2 * gap, -up, q, up, mask, huber=h, margin=0.01)  # 6 cm off, 5 cm counted
    assert float(c) == pytest.approx(2 * h ** 2 * (math.sqrt(1 + 0.05 ** 2 / h ** 2) - 1), rel=1e-4)
    with pytest.raises(ValueError, match="margin"):
        contact_terms(q + gap, -up, q, up, mask, margin=-0.01)


def test_contact_uses_only_region_points_facing_the_part():
    part = torch.tensor([[[0.0, 1.0, 0.0]]])
    n_part = torch.tensor([[[0.0, -1.0, 0.0]]])
    # two region points: one below the part facing up (towards it), one nearer but facing away
    q = torch.tensor([[[0.0, 0.9, 0.0], [0.0, 1.02, 0.0]]])
    nq = torch.tensor([[[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]])
    c, _, facing, _ = contact_terms(part, n_part, q, nq, torch.ones(1, 2, dtype=torch.bool))
    assert facing.tolist() == [[True, False]] and float(c) == pytest.approx(0.01, rel=1e-5)


def _plane_region(n=400, seed=0):
    """Points on the square [0, 0.4]^2 of the plane y = 0 (normals up) and its two triangles (wound upwards)."""
    g = torch.Generator().manual_seed(seed)
    q = torch.rand(1, n, 3, generator=g, dtype=torch.float64) * torch.tensor([0.4, 0.0, 0.4], dtype=torch.float64)
    a, b, c, d = ([0, 0, 0], [0.4, 0, 0], [0.4, 0, 0.4], [0, 0, 0.4])
    tris = torch.tensor([[a, c, b], [a, d, c]], dtype=torch.float64)[None]
    up = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64).expand(1, n, 3)
    return q, up, tris, torch.ones(1, n, dtype=torch.bool)


def test_contact_pulls_the_touching_patch_not_the_whole_part():
    """A coarse part (a block 10 cm thick) rests on the region with 5 % of its vertices: the contact patch's term is
    zero there, the plain Chamfer of the whole part is the mean squared height of its vertices (brute force)."""
    q, up, tris, mask = _plane_region()
    g = torch.Generator().manual_seed(1)
    xz = torch.rand(1, 200, 3, generator=g, dtype=torch.float64) * torch.tensor([0.2, 0.0, 0.2], dtype=torch.float64)
    xz = xz + torch.tensor([0.1, 0.0, 0.1], dtype=torch.float64)
    height = torch.full((1, 200), 0.1, dtype=torch.float64)
    height[0, :10] = 0.0  # the touching patch: 10 of 200 vertices
    part = xz + height[..., None] * torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
    down = -up[:, :200]
    c, n, _, patch = contact_terms(part, down, q, up, mask, fraction=0.05, region_tris=tris)
    assert float(c) == pytest.approx(0.0, abs=1e-12) and float(n) == pytest.approx(0.0, abs=1e-12)
    assert patch[0].nonzero()[:, 0].tolist() == list(range(10))
    whole, _, _, _ = contact_terms(part, down, q, up, mask, fraction=1.0, region_tris=tris)
    assert float(whole) == pytest.approx(float(height.square().mean()), rel=1e-9)
    # lifted by 2 cm the patch's term is the squared lift: the patch is the nearest 5 %, not a fixed set
    c2, _, _, _ = contact_terms(part + torch.tensor([0.0, 0.02, 0.0], dtype=torch.float64), down, q, up, mask,
                                fraction=0.05, region_tris=tris)
    assert float(c2) == pytest.approx(0.02 ** 2, rel=1e-9)


def test_contact_patch_is_the_vertices_facing_the_region():
    """Vertices crossing the region's surface sideways (distance 0, normals along it) are not the patch; the
    vertices whose normals oppose the region's are, here 1 cm inside it: the term is their squared depth."""
    q, up, tris, mask = _plane_region()
    side = torch.tensor([[[0.1, 0.0, 0.2], [0.12, 0.0, 0.2]]], dtype=torch.float64)  # on the plane, normals +x
    below = torch.tensor([[[0.2, -0.01, 0.2], [0.22, -0.01, 0.2]]], dtype=torch.float64)  # 1 cm deep, normals down
    part = torch.cat([side, below], dim=1)
    nrm = torch.tensor([[[1.0, 0, 0], [1.0, 0, 0], [0, -1.0, 0], [0, -1.0, 0]]], dtype=torch.float64)
    c, n, _, patch = contact_terms(part, nrm, q, up, mask, fraction=0.5, region_tris=tris)
    assert patch.tolist() == [[False, False, True, True]]
    assert float(c) == pytest.approx(0.01 ** 2, rel=1e-9) and float(n) == pytest.approx(0.0, abs=1e-12)


def test_contact_is_the_distance_to_the_region_surface_not_to_its_samples():
    """With the region's triangles the distance is exact on the surface (here: the height above the plane); to the
    sampled points alone it has the sampling's floor (brute force)."""
    q, up, tris, mask = _plane_region(n=16)
    g = torch.Generator().manual_seed(2)
    part = 0.05 + torch.rand(1, 30, 3, generator=g, dtype=torch.float64) * torch.tensor([0.3, 0.0, 0.3], dtype=torch.float64)
    part[..., 1] = 0.004
    down = -up[:, :1].expand(1, 30, 3)
    exact, _, _, _ = contact_terms(part, down, q, up, mask, region_tris=tris)
    assert float(exact) == pytest.approx(0.004 ** 2, rel=1e-9)
    sampled, _, _, _ = contact_terms(part, down, q, up, mask)
    brute = torch.cdist(part[0], q[0]).min(dim=1).values.square().mean()
    assert float(sampled) == pytest.approx(float(brute), rel=1e-9) and float(sampled) > 10 * float(exact)


def test_relative_similarity_is_the_object_in_the_body_frame():
    g = torch.Generator().manual_seed(3)
    x = torch.randn(1, 20, 3, generator=g, dtype=torch.float64)
    human = (torch.tensor([1.2], dtype=torch.float64),
             axis_angle_to_matrix(torch.tensor([[0.3, -1.1, 0.4]], dtype=torch.float64)),
             torch.tensor([[0.2, -0.1, 2.5]], dtype=torch.float64))
    obj = (torch.tensor([0.7], dtype=torch.float64),
           axis_angle_to_matrix(torch.tensor([[-0.5, 0.2, 0.9]], dtype=torch.float64)),
           torch.tensor([[0.4, 0.3, 3.1]], dtype=torch.float64))
    ref = to_body_frame(to_camera(x, *obj), *human)
    assert torch.allclose(to_camera(x, *relative_similarity(human, obj)), ref, atol=1e-12)


@pytest.mark.parametrize("kind", ["mesh", "volsmpl"])
def test_penetration_zero_apart_positive_inside_with_outward_gradient(body, posed, kind):
    vol = volsmpl.attach_volume(body, model=kind)
    query = body_query(vol, posed)
    outside = _thigh_points(body, posed, -0.03)
    mask = torch.ones(outside.shape[:2], dtype=torch.bool)
    assert mask.shape[1] == 50
    assert float(penetration(query, outside, mask).detach()) == 0.0
    inside = _thigh_points(body, posed, 0.015)
    t = torch.zeros(1, 3, requires_grad=True)
    pen = penetration(query, inside + t[:, None], mask)
    assert float(pen.detach()) > 0.005
    (g,) = torch.autograd.grad(pen.sum(), t)
    # the thigh's outward direction at these points: from the thigh's axis to the points
    centre = inside[0].mean(dim=0)
    outward = torch.nn.functional.normalize(inside[0] - centre, dim=-1).mean(dim=0)
    step = -g[0] / g[0].norm() * 0.01
    assert float(penetration(query, inside + step, mask).detach()) < float(pen.detach())
    assert g[0].norm() > 0 and torch.isfinite(outward).all()


def test_penetration_reads_the_body_frame_of_the_current_human_similarity(body, posed):
    """The object vertices enter the model in the frame the body was encoded in: the term at (s, R, t) equals the
    exact penetration depth into the body mesh placed by (s, R, t), divided by s (the paper's f(v / s_h))."""
    vol = volsmpl.attach_volume(body, model="mesh")
    s, R, t = torch.tensor([1.3]), axis_angle_to_matrix(torch.tensor([[0.3, -1.1, 0.4]])), torch.tensor([[0.2, -0.1, 2.5]])
    inside_body = _thigh_points(body, posed, 0.012)
    v_cam = to_camera(inside_body, s, R, t)
    assert torch.allclose(to_body_frame(v_cam, s, R, t), inside_body, atol=1e-6)
    mask = torch.ones(v_cam.shape[:2], dtype=torch.bool)
    ours = penetration(body_query(vol, posed), to_body_frame(v_cam, s, R, t), mask)
    placed = to_camera(posed.vertices, s, R, t)[0]
    ref = mesh_sdf(placed.double(), body.faces, v_cam[0].double(), sign="winding")
    assert float(ours) == pytest.approx(float(torch.relu(-ref).mean() / 1.3), rel=1e-4)


def test_scale_prior_and_keypoints_by_hand():
    assert torch.allclose(scale_prior(torch.tensor([1.2, 0.7]), 1.0), torch.tensor([0.2, 0.3]))
    K = torch.tensor([[[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]])
    X = torch.tensor([[[0.1, -0.2, 2.0], [0.0, 0.0, 4.0]]])
    uv = torch.stack([500 * X[0, :, 0] / X[0, :, 2] + 320, 500 * X[0, :, 1] / X[0, :, 2] + 240], dim=-1)
    kp = torch.cat([uv + torch.tensor([[5.0, 0.0], [0.0, 0.0]]), torch.tensor([[1.0], [1.0]])], dim=-1)[None]
    assert float(keypoint_term(X, kp, K)) == pytest.approx((5.0 / 500) ** 2 / 2, rel=1e-5)
    kp[0, 0, 2] = 0.0  # an unseen joint does not count
    assert float(keypoint_term(X, kp, K)) == pytest.approx(0.0, abs=1e-10)


def test_scale_prior_is_free_within_its_band_and_pulls_at_unit_slope_beyond():
    s = torch.tensor([0.95, 1.08, 1.3, 0.6], requires_grad=True)
    v = scale_prior(s, torch.tensor([1.0, 1.0, 1.0, 1.0]), torch.tensor([0.1, 0.1, 0.1, 0.0]))
    assert torch.allclose(v, torch.tensor([0.0, 0.0, 0.2, 0.4]), atol=1e-6)
    v.sum().backward()
    assert s.grad.tolist() == [0.0, 0.0, 1.0, -1.0]


def test_object_size_spread_by_hand():
    from volsmpl.apps.hoi.case import object_size_spread
    # sofa: width 2.000 +- 0.220 m is its largest extent; cup: width 0.120 +- 0.006 m (SIZE_PRIOR)
    assert object_size_spread("sofa") == pytest.approx(0.11)
    assert object_size_spread("cup") == pytest.approx(0.05)
    assert object_size_spread("sofa", 1.8) == 0.0  # a stated size has no spread


def test_silhouette_zero_on_the_mask_and_positive_off_it():
    K = torch.tensor([[[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]])
    X = torch.tensor([[[0.1, -0.2, 2.0], [0.0, 0.0, 4.0], [-0.1, 0.1, 3.0]]])
    uv = torch.stack([500 * X[0, :, 0] / X[0, :, 2] + 320, 500 * X[0, :, 1] / X[0, :, 2] + 240], dim=-1)[None]
    m3, m2 = torch.ones(1, 3, dtype=torch.bool), torch.ones(1, 3, dtype=torch.bool)
    assert float(silhouette_term(X, m3, uv, m2, K)) == pytest.approx(0.0, abs=1e-10)
    shifted = X + torch.tensor([0.05, 0.0, 0.0])
    assert float(silhouette_term(shifted, m3, uv, m2, K)) > 0



def test_silhouette_is_relative_to_the_silhouettes_spread():
    """By hand: pixels (0, 0) and (20, 0) (spread 10^2), one vertex projected to (10, 5) (125 px^2 from each):
    (125 + 125) / 100. Shrinking the whole picture (pixels and projected vertices) about the principal point keeps
    the value: a small object far away is charged as a large one near."""
    K = torch.tensor([[[100.0, 0, 0], [0, 100, 0], [0, 0, 1]]])
    one, two = torch.ones(1, 1, dtype=torch.bool), torch.ones(1, 2, dtype=torch.bool)
    sil = torch.tensor([[[0.0, 0.0], [20.0, 0.0]]])
    x = torch.tensor([[[0.10, 0.05, 1.0]]])  # (10, 5) px
    assert float(silhouette_term(x, one, sil, two, K)) == pytest.approx(2.5, rel=1e-5)
    far = x * torch.tensor([1.0, 1.0, 8.0])  # eight times as deep: projects to (1.25, 0.625)
    assert float(silhouette_term(far, one, sil / 8, two, K)) == pytest.approx(2.5, rel=1e-5)


def test_a_fine_region_keeps_a_fixed_budget_of_triangles_close_to_its_surface():
    """A 20,480-triangle sphere (r 0.11 m) is simplified to the budget; its triangles stay within 2 mm of the sphere
    (analytic), wound outwards; the contact term on them is within 1.5 mm (RMS distance) of the exact distances to
    the sphere of the same patch; a region within the budget keeps its own triangles."""
    r = 0.11
    sphere = trimesh.creation.icosphere(5, radius=r)
    tris = region_triangles(sphere, np.arange(len(sphere.faces)))
    assert len(sphere.faces) == 20480 and 0.9 * REGION_TRIANGLES <= len(tris) <= REGION_TRIANGLES
    assert np.abs(np.linalg.norm(tris, axis=-1) - r).max() < 2e-3
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    assert ((n * tris.mean(axis=1)).sum(-1) > 0).all()
    small = trimesh.creation.icosphere(3, radius=r)  # 1,280 triangles: as they are
    assert np.array_equal(region_triangles(small, np.arange(1280)), small.triangles)
    # part points 0.5-3 cm outside the sphere's top, normals towards its centre; the region's points: face centres
    g = np.random.default_rng(0)
    dirs = g.normal(size=(200, 3)) * [0.3, 1.0, 0.3] + [0, 2.0, 0]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    p = dirs * (r + g.uniform(0.005, 0.03, (200, 1)))
    pts, nrm = (torch.as_tensor(np.array(x))[None] for x in (sphere.triangles_center, sphere.face_normals))
    mask = torch.ones(pts.shape[:2], dtype=torch.bool)
    c, _, _, patch = contact_terms(torch.as_tensor(p)[None], torch.as_tensor(-dirs)[None], pts, nrm, mask, 0.2,
                                   torch.as_tensor(tris)[None])
    exact = ((np.linalg.norm(p, axis=1) - r) ** 2)[patch[0].numpy()].mean()
    assert abs(float(c) ** 0.5 - exact ** 0.5) < 1.5e-3 and int(patch[0].sum()) == 40


def test_the_terms_see_a_fixed_budget_whatever_the_mesh(body, tmp_path):
    """A mesh file of 20,480 triangles in contact as a whole ('any', two pairs): the contact term sees at most the
    budget of triangles per pair; the ball template's 1,280-triangle 'grasp' keeps exactly its own."""
    from volsmpl.apps.hoi.case import case_from_dict, object_template
    from volsmpl.apps.hoi.fit import FitConfig, Problem
    from volsmpl.body.fingerprint import fingerprint_of_model

    sim = {"scale": 1.0, "rotation": np.diag([1.0, -1.0, -1.0]).tolist(), "translation": [0.0, 0.2, 3.0]}
    d = {"format": "volsmpl-hoi-case", "version": 1, "name": "fine",
         "body": {"fingerprint": fingerprint_of_model(body), "betas": [0.0] * 10, "global_orient": [0.0] * 3,
                  "body_pose": [0.0] * 69, "transl": [0.0] * 3},
         "object": {"category": "ball", "template_seed": 0},
         "camera": {"K": [[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]], "image_size": [480, 640]},
         "keypoints_2d": [[300.0, 200.0, 1.0]] * 24, "silhouette": [[300.0, 250.0]],
         "contacts": [["right_hand", "grasp"], ["left_hand", "grasp"]], "init": {"human": sim, "object": sim}}
    vol = volsmpl.attach_volume(body, model="mesh")
    cfg = FitConfig(max_edge_frac=0.0)
    tmpl = object_template(case_from_dict(d))
    own = tmpl.mesh.triangles[tmpl.regions["grasp"]]
    prob = Problem(case_from_dict(d), body, vol, cfg)
    assert prob.reg_tri.shape == (2 * len(own), 3, 3) and np.allclose(prob.reg_tri[: len(own)].numpy(), own)
    trimesh.creation.icosphere(5, radius=0.11).export(tmp_path / "fine.ply")
    fine = {**d, "object": {"category": "ball", "mesh": "fine.ply"}, "contacts": [["right_hand", "any"]] * 2}
    prob = Problem(case_from_dict(fine, tmp_path), body, vol, cfg)
    per_pair = np.bincount(prob.tri_owner.numpy())
    assert len(per_pair) == 2 and per_pair.max() <= REGION_TRIANGLES and len(prob.reg_tri) == per_pair.sum()
    assert prob.reg_p.shape[1] == cfg.region_points and prob.part_v.shape[1] <= cfg.part_points
    # the penetration term: the 10,242 vertices of the fine sphere are read as PEN_POINTS surface samples, each on
    # the sphere (radius 0.11, independent of the code), while the metrics keep every vertex
    from volsmpl.apps.hoi.problem import PEN_POINTS

    assert prob.obj_v.shape[1] == 10242 and prob.pen_v.shape[1] == PEN_POINTS < 10242
    r = prob.pen_v[0].norm(dim=1).numpy()
    assert np.allclose(r, 0.11, atol=2e-3)
