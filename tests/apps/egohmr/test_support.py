"""The guidance's pelvis moves against hand-computed values and finite differences: the support term
(support.py) on flat floors and boxes, the pelvis step along J's gradient and the rule that a body penetrating
the scene is not pulled down (guidance.py), and the flags that set them."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

import volsmpl
from volsmpl.apps.egohmr.guidance import CollisionScore
from volsmpl.apps.egohmr.pose import identity_pose, pose_body
from volsmpl.apps.egohmr.support import SupportGap, support_mask

#: a tilted world up (the camera looks down at a slant): every test's scene and body are turned by TURN
TURN = torch.as_tensor(trimesh.transformations.rotation_matrix(0.5, [1.0, 0.2, 0.0])[:3, :3], dtype=torch.float32)
UP = TURN @ torch.tensor([0.0, 1.0, 0.0])


def _plane(height: float, half: float = 0.6, step: float = 0.01, centre=(0.0, 0.0)) -> torch.Tensor:
    """A horizontal grid of points at `height` (world y), turned by TURN. Shape: (N, 3)."""
    u = torch.arange(-half, half + 1e-9, step)
    x, z = torch.meshgrid(u + centre[0], u + centre[1], indexing="ij")
    p = torch.stack([x.flatten(), torch.full_like(x.flatten(), height), z.flatten()], -1)
    return p @ TURN.T


def _rest_body(body):
    """The default body at rest, pelvis at the origin, turned by TURN: (vertices (V, 3), its lowest height)."""
    with torch.no_grad():
        v = pose_body(body, torch.zeros(1, 10), identity_pose(1), torch.zeros(1, 3)).vertices[0]
    v = v @ TURN.T
    return v, float((v @ UP).min())


def _gap(points, vertices, faces) -> SupportGap:
    pts = points[None]
    mask = torch.as_tensor(support_mask(points.numpy(), UP.numpy()))[None]
    return SupportGap(pts, mask, UP[None], faces)


def test_support_points_are_the_horizontal_ones():
    floor = _plane(0.0, half=0.5)
    wall = torch.stack(torch.meshgrid(torch.full((1,), 0.5), torch.arange(0.0, 1.0, 0.01), torch.arange(-0.5, 0.5, 0.01),
                                      indexing="ij"), -1).reshape(-1, 3) @ TURN.T
    m = support_mask(torch.cat([floor, wall]).numpy(), UP.numpy())
    far = lambda p: ((p @ TURN)[:, 0] < 0.45).numpy()  # noqa: E731  (a plane fitted at the corner mixes both)
    assert m[: len(floor)][far(floor)].all()
    high = ((wall @ TURN)[:, 1] > 0.05).numpy()
    assert not m[len(floor):][high].any()


def test_a_floating_body_is_pulled_down_and_a_sunk_one_pushed_up(body):
    """Hand-computed: the rest body's lowest vertex 5 cm above a flat floor gives g = +0.05 (the step -g*up moves
    it down), 5 cm below it g = -0.05 (up); the gradient of S = g^2/2 with respect to the translation is g*up,
    which central finite differences of S reproduce."""
    v, low = _rest_body(body)
    faces = torch.as_tensor(body.faces)
    for depth in (0.05, -0.05):
        sup = _gap(_plane(low - depth), v, faces)
        g = sup.gap(v[None])
        assert torch.allclose(g, torch.tensor([depth]), atol=1e-4), (depth, g)
        S, dS = sup.score(v[None])
        assert torch.allclose(dS[0], depth * UP, atol=1e-4)
        assert (dS[0] @ UP > 0) == (depth > 0)   # -dS: down when floating, up when sunk
        eps = 1e-3
        fd = torch.stack([(sup.score(v[None] + eps * e)[0] - sup.score(v[None] - eps * e)[0])[0] / (2 * eps)
                          for e in torch.eye(3)])
        assert torch.allclose(fd, dS[0], atol=2e-5), (fd, dS)
        # the step puts the lowest vertex on the floor
        assert abs(float(sup.gap(v[None] - g[0] * UP)[0])) < 1e-4


def test_a_surface_over_the_body_is_no_support_and_one_out_of_reach_none():
    """A flat box (4 cm tall) 5 cm above a floor, under a plate 1 cm above its top: the plate lies 5 cm over the
    box's lowest vertices but outside the box, so g = +0.05 (not -0.05); a floor beyond BELOW gives NaN and S = 0."""
    box = trimesh.creation.box(extents=(0.2, 0.04, 0.2))
    v = torch.as_tensor(box.vertices, dtype=torch.float32) @ TURN.T            # bottom at y = -0.02
    faces = torch.as_tensor(box.faces)
    pts = torch.cat([_plane(-0.07, half=0.3), _plane(0.03, half=0.12)])
    g = _gap(pts, v, faces).gap(v[None])
    assert torch.allclose(g, torch.tensor([0.05]), atol=1e-4)
    # the same plate cutting through a taller box (inside it) is a support the box has sunk into
    tall = trimesh.creation.box(extents=(0.2, 0.1, 0.2))
    vt = torch.as_tensor(tall.vertices, dtype=torch.float32) @ TURN.T          # bottom at y = -0.05
    g = _gap(torch.cat([_plane(-0.3, half=0.3), _plane(0.03, half=0.12)]), vt, faces).gap(vt[None])
    assert torch.allclose(g, torch.tensor([-0.08]), atol=1e-4)
    sup = _gap(_plane(-0.6, half=0.3), v, faces)
    assert torch.isnan(sup.gap(v[None])).all() and sup.score(v[None])[1].abs().sum() == 0


@pytest.fixture(scope="module")
def mesh_volume():
    return volsmpl.attach_volume(volsmpl.create_body(), model="mesh")


def _score(body, vol, points, pelvis_step=0.0, support=False, along="free", pelvis=None):
    pts = points[None]
    sup = None
    if support:
        sup = SupportGap(pts, torch.as_tensor(support_mask(points.numpy(), UP.numpy()))[None], UP[None], body.faces)
    pelvis = torch.zeros(1, 3) if pelvis is None else pelvis
    return CollisionScore(body, vol, torch.zeros(1, 10), pelvis, pts, pelvis_step=pelvis_step, support=sup,
                          along=along)


def _turned_pose() -> torch.Tensor:
    """The rest pose with its root turned by TURN (pose vector, (1, 144))."""
    from volsmpl.geometry.rotations import matrix_to_axis_angle
    from volsmpl.apps.egohmr.pose import pose_vector

    return pose_vector(matrix_to_axis_angle(TURN[None]), torch.zeros(1, 69))


def test_the_pelvis_step_goes_down_the_collision_gradient(body, mesh_volume):
    """Feet 1 cm into a floor ('mesh' kind, exact): J's gradient with respect to the pelvis matches central finite
    differences of J, and one guided step moves the pelvis by pelvis_step along its negative, i.e. up. (At 3 cm the
    floor points lie nearer the toes' top than their sole and J's gradient points down: the support term, not J,
    lifts deeply sunk feet.)"""
    x = _turned_pose()
    with torch.no_grad():
        low = float((pose_body(body, torch.zeros(1, 10), x, torch.zeros(1, 3)).vertices[0] @ UP).min())
    sc = _score(body, mesh_volume, _plane(low + 0.01, half=0.4, step=0.02), pelvis_step=0.01)
    eps = 5e-4
    fd = []
    for e in torch.eye(3):
        sc.offset = eps * e[None]
        hi = float(sc.score(x)[0])
        sc.offset = -eps * e[None]
        fd.append((hi - float(sc.score(x)[0])) / (2 * eps))
    fd = torch.tensor(fd)
    sc.offset = torch.zeros(1, 3)
    sc.gradient(x, x, 0)
    moved = sc.offset[0]
    assert abs(float(moved.norm()) - 0.01) < 1e-6
    cos = float(-(fd / fd.norm()) @ (moved / moved.norm()))
    assert cos > 0.999, (fd, moved)
    assert float(moved @ UP) > 0.0099                        # out of the floor: up


def test_the_support_step_holds_a_penetrating_body_up(body, mesh_volume):
    """Feet 5 cm above a floor: a guided step pulls the body down 5 cm; with a block of scene points inside its
    chest (J > 0) it is not pulled down (the support step only lifts a body that penetrates the scene)."""
    x = _turned_pose()
    with torch.no_grad():
        v = pose_body(body, torch.zeros(1, 10), x, torch.zeros(1, 3)).vertices[0]
    low = float((v @ UP).min())
    floor = _plane(low - 0.05, half=0.4, step=0.015)
    sc = _score(body, mesh_volume, floor, support=True)
    sc.gradient(x, x, 0)
    assert torch.allclose(sc.offset[0], -0.05 * UP, atol=1e-4)
    with torch.no_grad():
        chest = pose_body(body, torch.zeros(1, 10), x, torch.zeros(1, 3)).joints[0, 9]
    block = chest + 0.02 * torch.randn(50, 3, generator=torch.Generator().manual_seed(0))
    sc = _score(body, mesh_volume, torch.cat([floor, block]), support=True)
    sc.gradient(x, x, 0)
    assert float(sc.last[0]) > 0 and torch.allclose(sc.offset, torch.zeros(1, 3))


def test_along_the_ray_the_support_step_keeps_the_pelvis_on_its_ray(body, mesh_volume):
    """along='ray', the camera at the origin, the pelvis 2.5 m ahead of it and 1 m below its eye level: a body
    floating 5 cm above a floor moves along the ray through its pelvis (the image position stays) by the run that
    lowers it 5 cm; J's gradient projected on the ray moves it by pelvis_step along the ray."""
    x = _turned_pose()
    pelvis = (TURN @ torch.tensor([0.3, -1.0, 2.5]))[None]
    with torch.no_grad():
        v = pose_body(body, torch.zeros(1, 10), x, pelvis).vertices[0]
    low = float((v @ UP).min())
    floor = _plane(low - 0.05, half=0.4, step=0.015, centre=(0.3, 2.5))
    sc = _score(body, mesh_volume, floor, support=True, along="ray", pelvis=pelvis)
    sc.gradient(x, x, 0)
    moved, ray = sc.offset[0], pelvis[0] / pelvis[0].norm()
    assert abs(float(moved @ UP) + 0.05) < 1e-4                        # 5 cm lower
    assert float(torch.linalg.cross(moved, ray).norm()) < 1e-5         # along the ray: the pelvis's image stays
    sunk = _plane(low + 0.01, half=0.4, step=0.02, centre=(0.3, 2.5))
    sc = _score(body, mesh_volume, sunk, pelvis_step=0.01, along="ray", pelvis=pelvis)
    sc.gradient(x, x, 0)
    moved = sc.offset[0]
    assert abs(float(moved.norm()) - 0.01) < 1e-6 and float(torch.linalg.cross(moved, ray).norm()) < 1e-6
    assert float(moved @ UP) > 0                                         # out of the floor


def _wall_case(body, gap: float = 0.003):
    """The body of the ray test floating 5 cm above a floor, with a wall `gap` beyond its farthest point along
    the view (un-turned z): the ray through the pelvis runs into it. Returns (pose, pelvis, floor + wall points,
    the un-turned vertices)."""
    x = _turned_pose()
    pelvis = (TURN @ torch.tensor([0.3, -1.0, 2.5]))[None]
    with torch.no_grad():
        v = pose_body(body, torch.zeros(1, 10), x, pelvis).vertices[0] @ TURN  # un-turned
    low = float(v[:, 1].min())
    floor = _plane(low - 0.05, half=0.5, step=0.015, centre=(0.3, 2.5))
    u = torch.arange(-0.6, 0.6 + 1e-9, 0.015)
    a, b = torch.meshgrid(u + 0.3, torch.arange(0.0, 1.8, 0.015) + low - 0.04, indexing="ij")
    wall = torch.stack([a.flatten(), b.flatten(), torch.full_like(a.flatten(), float(v[:, 2].max()) + gap)], -1)
    return x, pelvis, torch.cat([floor, wall @ TURN.T]), v


def test_a_support_step_that_would_push_the_body_into_a_wall_goes_straight_down(body, mesh_volume):
    """A body floating 5 cm above a floor with a wall 3 mm beyond it along the view (a person leaning on the wall
    behind them, seen from the front): the move along the ray that lowers it 5 cm goes 12 cm into the wall, so it
    is replaced by the vertical move, which lowers it 5 cm and leaves it touching nothing; with a block of points
    under its feet the vertical move penetrates too, and the body stays."""
    x, pelvis, pts, v = _wall_case(body)
    sc = _score(body, mesh_volume, pts, support=True, along="ray", pelvis=pelvis)
    sc.gradient(x, x, 0)
    assert float(sc.last[0]) == 0.0
    assert torch.allclose(sc.offset[0], -0.05 * UP, atol=1e-4)
    assert float(sc.score(x)[0]) == 0.0
    lowest = v[int(v[:, 1].argmin())]
    g = torch.Generator().manual_seed(0)
    block = lowest + torch.tensor([0.0, -0.03, 0.0]) + 0.02 * (torch.rand(200, 3, generator=g) - 0.5)
    sc = _score(body, mesh_volume, torch.cat([pts, block @ TURN.T]), support=True, along="ray", pelvis=pelvis)
    sc.gradient(x, x, 0)
    assert float(sc.last[0]) == 0.0 and torch.allclose(sc.offset, torch.zeros(1, 3))
    far = _score(body, mesh_volume, _wall_case(body, gap=0.5)[2], support=True, along="ray", pelvis=pelvis)
    far.gradient(x, x, 0)    # the wall 50 cm away: the ray move stays out of it and is kept
    ray = pelvis[0] / pelvis[0].norm()
    assert float(torch.linalg.cross(far.offset[0], ray).norm()) < 1e-5 and float(far.offset[0] @ UP) < -0.049


def test_pelvis_flags_are_checked(tmp_path, capsys):
    from volsmpl.cli import main

    assert main(["egohmr", "sample", "--pelvis-step", "0.5", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--pelvis-step 0.5" in err and "<= 0.1" in err and "\n" not in err
    assert main(["egohmr", "tune", "--factors", "0", "--pelvis-step", "0", "--support", "off",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "unguided sampler's" in err and "\n" not in err
    assert main(["egohmr", "sample", "--model", "none", "--support", "off", "--out", str(tmp_path / "o")]) == 2
    assert "--support" in capsys.readouterr().err
