"""Per-part evaluation points (`volsmpl.evaluation.points`, `volsmpl eval --sampling parts`): where each block of points
lies, checked against brute-force references (part boxes recomputed from the part's vertices, exact distances to
the part's own faces), the offsets' scale, reproducibility, and the CLI's checks."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from volsmpl.evaluation import resources as eval_resources
import volsmpl.evaluation as ev
from volsmpl.evaluation import validation_set as val
from volsmpl.evaluation.points import part_query_points
from volsmpl.body.partition import Partition


@pytest.fixture(scope="module")
def setup(body):
    bodies = val.validation_bodies(3)
    part = Partition(body, n_samples=2)
    with torch.no_grad():
        out = body(**bodies)
    G = part.part_transforms(out.full_pose, out.joints).double()
    return bodies, part, out.vertices.double(), G


def test_uniform_blocks_fill_their_part_box(body, setup):
    bodies, part, verts, G = setup
    K, per = part.num_parts, 64
    pts, is_surface = part_query_points(body, bodies, n_points=K * per, surface_fraction=0.5)
    assert pts.shape == (3, K * per, 3) and int(is_surface.sum()) == K * per // 2
    assert not is_surface[:K * per // 2].any() and is_surface[K * per // 2:].all()
    labels = part.vertex_labels.numpy()
    for b in range(3):
        for k in range(K):
            R, t = G[b, k, :3, :3].numpy(), G[b, k, :3, 3].numpy()
            local_v = (verts[b].numpy()[labels == k] - t) @ R               # the part's vertices in its frame
            lo, hi = local_v.min(0), local_v.max(0)
            c, h = 0.5 * (lo + hi), 0.5 * (hi - lo) * 1.125                 # padded by 12.5 %, as the models' boxes
            block = pts[b, k * per // 2:(k + 1) * per // 2].double().numpy()
            local = (block - t) @ R
            assert np.all(np.abs(local - c) <= h + 1e-5), (b, k)
            # spread over the box, not bunched: each half of each axis holds some points
            assert np.all((local > c).any(0)) and np.all((local < c).any(0)), (b, k)


def test_surface_blocks_lie_on_their_parts_own_faces(body, setup):
    bodies, part, verts, _ = setup
    K, per = part.num_parts, 32
    pts, _ = part_query_points(body, bodies, n_points=K * per, surface_sigma=0.0)
    faces = part.faces.numpy()
    for b in range(2):
        for k in range(K):
            block = pts[b, K * per // 2 + k * per // 2:K * per // 2 + (k + 1) * per // 2].double().numpy()
            own = trimesh.Trimesh(verts[b].numpy(), faces[part.tight_face_ids[k]], process=False)
            _, dist, _ = trimesh.proximity.closest_point(own, block)
            assert dist.max() < 1e-5, (b, k, dist.max())


def test_offsets_are_gaussian_with_the_given_sigma(body, setup):
    bodies = {k: v[:2] for k, v in setup[0].items()}
    K = setup[1].num_parts
    base, surf = part_query_points(body, bodies, n_points=K * 400, surface_sigma=0.0)
    moved, _ = part_query_points(body, bodies, n_points=K * 400, surface_sigma=0.02)
    assert torch.equal(base[:, ~surf], moved[:, ~surf])                      # the uniform points do not move
    z = ((moved[:, surf] - base[:, surf]).double() / 0.02).reshape(-1)
    assert abs(z.mean()) < 0.05 and abs(z.std() - 1.0) < 0.05


def test_reproducible_and_a_prefix_for_fewer_bodies(body, setup):
    bodies = setup[0]
    K = setup[1].num_parts
    a, _ = part_query_points(body, bodies, n_points=K * 20)
    again, _ = part_query_points(body, bodies, n_points=K * 20)
    first, _ = part_query_points(body, {k: v[:2] for k, v in bodies.items()}, n_points=K * 20)
    other, _ = part_query_points(body, bodies, n_points=K * 20, seed=val.VAL_SEED + 1)
    assert torch.equal(a, again) and torch.equal(a[:2], first)   # body i's points do not depend on later bodies
    assert not (a - other).abs().lt(1e-6).all(-1).any()           # another seed: no point in common


def test_points_must_split_evenly_over_the_parts(body, setup):
    with pytest.raises(ValueError, match="multiple of the 16 parts"):
        part_query_points(body, setup[0], n_points=1000)
    with pytest.raises(ValueError, match="near-surface set empty; give --points of at least 32"):
        part_query_points(body, setup[0], n_points=16)   # one point per part: one of the two sets would be empty
    with pytest.raises(ValueError, match="sampling"):
        ev.EvalConfig(sampling="grid")


def test_eval_cli_parts_sampling_of_an_exact_predictor(body, tmp_path):
    """A predictor that is the ground truth scores IoU 1 on both sets under per-part sampling (the split by
    `is_surface` matches the layout), and the JSON records the sampling."""
    from volsmpl.geometry.groundtruth import batch_mesh_sdf

    def exact(out, pts):
        return batch_mesh_sdf(out.vertices.detach(), body.faces, pts, sign="ray_winding", nsamples=3)

    res = ev.evaluate(exact, body=body, config=ev.EvalConfig(n_bodies=2, n_points=16 * 50, sampling="parts",
                                                             use_cache=False))
    assert res.metrics["iou_surf"] == 1.0 and res.metrics["iou_unif"] == 1.0
    assert res.config["sampling"] == "parts"


def test_timing_measures_the_points_of_the_evaluation(body, monkeypatch):
    """`measure_resources` times body 0 on the points the accuracy columns were measured on, in either sampling."""
    seen = {}

    def fake_isolated(target, job, timeout_s):
        seen["points"] = torch.load(job["inputs"])["points"]
        return {}

    monkeypatch.setattr(eval_resources, "run_isolated", fake_isolated)
    bodies = val.validation_bodies(1)
    for sampling in ("parts", "body"):
        cfg = ev.EvalConfig(n_points=16 * 40, sampling=sampling)
        eval_resources.measure_resources({"checkpoint": None}, cfg)
        expected, _ = ev.evaluation_points(body, bodies, val.pose_bodies(body, bodies), cfg)
        assert torch.equal(seen["points"], expected), sampling
