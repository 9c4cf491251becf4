"""The egocentric app's pose, diffusion, guidance and metrics against closed forms and exact references."""
from __future__ import annotations

import pytest
import torch
import trimesh

import volsmpl
from volsmpl.apps.egohmr.diffusion import Guidance, Schedule, sample
from volsmpl.apps.egohmr.guidance import CollisionScore
from volsmpl.apps.egohmr.metrics import collision_ratio, contact, mpjpe, pa_mpjpe, procrustes
from volsmpl.apps.egohmr.network import EgoConfig, EgoNet
from volsmpl.apps.egohmr.pose import axis_angle, pose_body, pose_joints, pose_vector, rest_joints


def _poses(B=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.randn(B, 10, generator=g), torch.randn(B, 3, generator=g) * 0.5,
            torch.randn(B, 69, generator=g) * 0.3, torch.randn(B, 3, generator=g))


def test_pose_vector_round_trip_and_forward_kinematics(body):
    betas, go, bp, pelvis = _poses()
    x = pose_vector(go, bp)
    go2, bp2 = axis_angle(x)
    assert torch.allclose(volsmpl.geometry.rotations.axis_angle_to_matrix(torch.cat([go2, bp2], 1).reshape(-1, 3)),
                          volsmpl.geometry.rotations.axis_angle_to_matrix(torch.cat([go, bp], 1).reshape(-1, 3)), atol=1e-5)
    # joints by forward kinematics alone equal the full body forward's joints, pelvis where asked
    out = pose_body(body, betas, x, pelvis)
    ref = body(betas=betas, global_orient=go, body_pose=bp, transl=pelvis - rest_joints(body, betas)[:, 0])
    assert torch.allclose(out.vertices, ref.vertices, atol=1e-5)
    assert torch.allclose(pose_joints(body, betas, x, pelvis), ref.joints[:, :24], atol=1e-5)
    assert torch.allclose(ref.joints[:, 0], pelvis, atol=1e-5)


def test_sampler_reproduces_a_gaussian_with_the_exact_denoiser():
    """Data ~ N(m, s^2) per dimension: E[x0 | x_t] is closed-form; ancestral sampling with it must give N(m, s^2)
    as the steps grow (DDPM's posterior variance drops Var(x0 | x_t): at 50 steps the spread is 5-10 % low)."""
    sched = Schedule(1000)
    m, s = torch.tensor([1.5, -0.7]), torch.tensor([0.3, 2.0])

    def denoise(xt, t):
        ab = sched.alphas_cumprod[t].float()[:, None]
        return m + s ** 2 * ab.sqrt() / (ab * s ** 2 + 1 - ab) * (xt - ab.sqrt() * m)

    x = sample(denoise, (20000, 2), sched, torch.Generator().manual_seed(0))
    assert torch.allclose(x.mean(0), m, atol=0.04)
    assert torch.allclose(x.std(0), s, rtol=0.02)
    # a wrong posterior (e.g. the x_t coefficient dropped) does not: the test can fail
    sched.coef_xt = sched.coef_xt * 0
    x = sample(denoise, (4000, 2), sched, torch.Generator().manual_seed(0))
    assert not torch.allclose(x.std(0), s, rtol=0.1)


def test_guidance_shift_follows_the_schedule():
    g = Guidance(lambda xt, x0, t: torch.ones_like(xt), scale=2.0, steps=10, plain_steps=5)
    x = torch.zeros(1, 3)
    var = torch.full((1, 1), 0.25)
    assert g.step(x, x, 10, var) is None                        # unguided early steps
    assert torch.allclose(g.step(x, x, 7, var), torch.full((1, 3), -0.5))   # -a Sigma grad
    assert torch.allclose(g.step(x, x, 2, var), torch.full((1, 3), -2.0))   # -a grad in the last 5


def _wall_through_leg(body, betas, x, pelvis):
    """Scene points on a plane 3 cm inside the outer side of the right leg (x = const), 0.5 x 0.5 m around the knee."""
    out = pose_body(body, betas, x, pelvis)
    knee, v = out.joints[0, 5], out.vertices[0]
    leg = v[((v[:, 1] - knee[1]).abs() < 0.1) & (v[:, 0] < 0)]
    u = torch.linspace(-0.25, 0.25, 40)
    yy, zz = torch.meshgrid(u, u, indexing="ij")
    return torch.stack([torch.full_like(yy, float(leg[:, 0].min() + 0.03)), yy + knee[1], zz + knee[2]], -1)[None].reshape(1, -1, 3)


@pytest.mark.parametrize("kind", ["volsmpl", "mesh"])
def test_collision_gradient_moves_a_penetrating_body_out(body, kind):
    vol = volsmpl.attach_volume(volsmpl.create_body(), model=kind)
    betas = torch.zeros(1, 10)
    x = pose_vector(torch.zeros(1, 3), torch.zeros(1, 69))
    pelvis = torch.zeros(1, 3)
    pts = _wall_through_leg(body, betas, x, pelvis)
    score = CollisionScore(body, vol, betas, pelvis, pts)
    j0 = score.score(x)
    assert j0.item() > 0
    # against an exact reference: the mean over the points of the exact penetration depth (mesh kind)
    if kind == "mesh":
        out = pose_body(body, betas, x, pelvis)
        d = volsmpl.geometry.point_mesh_distance.mesh_signed_distance(out.vertices[0], torch.as_tensor(body.faces), pts[0])
        assert torch.allclose(j0, torch.relu(-d).mean()[None], rtol=1e-4)
    g0 = score.gradient(x, x, 0)
    xx = x.clone()
    for _ in range(6):  # steps of 0.02 down the gradient
        g = score.gradient(xx, xx, 0)
        xx = xx - 0.02 * g / (g.norm() + 1e-12)
    assert score.score(xx).item() < 0.5 * j0.item()
    assert score.score(x + 0.02 * g0 / g0.norm()).item() > j0.item()  # and up the gradient it gets worse


def test_collision_score_is_zero_in_free_space(body):
    vol = volsmpl.attach_volume(volsmpl.create_body(), model="volsmpl")
    x = pose_vector(torch.zeros(2, 3), torch.zeros(2, 69))
    pts = torch.rand(2, 500, 3) + torch.tensor([3.0, 0.0, 0.0])
    score = CollisionScore(body, vol, torch.zeros(2, 10), torch.zeros(2, 3), pts)
    assert torch.equal(score.score(x), torch.zeros(2))
    assert torch.equal(score.gradient(x, x, 0), torch.zeros_like(x))


def test_procrustes_recovers_a_similarity_and_mpjpe_is_pelvis_aligned():
    g = torch.Generator().manual_seed(1)
    gt = torch.randn(4, 24, 3, generator=g)
    R = volsmpl.geometry.rotations.axis_angle_to_matrix(torch.randn(4, 3, generator=g))
    pred = 1.7 * gt @ R.transpose(1, 2) + torch.randn(4, 1, 3, generator=g)
    assert torch.allclose(procrustes(pred, gt), gt, atol=1e-5)
    assert pa_mpjpe(pred, gt).max() < 1e-2
    assert torch.allclose(mpjpe(gt + torch.tensor([1.0, 2.0, 3.0]), gt), torch.zeros(4, 24), atol=2e-3)
    moved = gt.clone()
    moved[:, 5] += torch.tensor([0.0, 0.03, 0.04])
    assert torch.allclose(mpjpe(moved, gt)[:, 5], torch.full((4,), 50.0), atol=1e-3)


def test_collision_ratio_and_contact_are_exact_on_a_box():
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    v, f = torch.tensor(box.vertices, dtype=torch.float32)[None], torch.tensor(box.faces)
    # 3 of 8 points inside the unit box
    pts = torch.tensor([[0.1, 0, 0], [0.4, 0.4, 0.4], [-0.2, 0.3, 0.1], [0.6, 0, 0], [0, 0, 0.51], [2, 2, 2],
                        [0.5001, 0, 0], [-1, 0, 0]])[None]
    assert collision_ratio(v, f, pts).item() == pytest.approx(3 / 8)
    far = trimesh.creation.box((1.0, 1.0, 1.0))
    far.apply_translation([0.0, 0.0, 1.015])   # 1.5 cm away from the box's top face
    farther = far.copy()
    farther.apply_translation([0.0, 0.0, 0.01])  # 2.5 cm
    assert contact(v.numpy(), [far]).tolist() == [True]
    assert contact(v.numpy(), [farther]).tolist() == [False]


def test_network_shapes_and_bad_keypoints():
    net = EgoNet(EgoConfig(width=32, blocks=1, cond_width=16))
    kp = torch.randn(5, 24, 3)
    c = net.keypoints(kp)
    pelvis, betas, pose = net.regress(c)
    assert pelvis.shape == (5, 3) and (pelvis[:, 2] > 0).all() and betas.shape == (5, 10) and pose.shape == (5, 144)
    cond = net.condition(c, torch.randn(5, 64, 3), pelvis)
    assert net.denoise(pose, torch.zeros(5, dtype=torch.long), cond).shape == (5, 144)
    with pytest.raises(ValueError, match="keypoints must be"):
        net.keypoints(torch.randn(5, 17, 3))
