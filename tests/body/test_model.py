"""volsmpl.Body: matches smplx.SMPL on the same file, batching, gradients, clear errors."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import volsmpl
from volsmpl.body.model import DEFAULT_BODY_FILE, Body
from conftest import random_pose


def test_default_body_shapes(body):
    out = body(**random_pose(3))
    V = body.v_template.shape[0]
    assert out.vertices.shape == (3, V, 3)
    assert out.joints.shape == (3, 24, 3)
    assert out.full_pose.shape == (3, 72)
    assert body.faces.shape[1] == 3 and body.faces.max() < V


def test_matches_smplx_smpl(body):
    smplx = pytest.importorskip("smplx")
    from smplx.utils import Struct
    # smplx.SMPL reads pickles only; its data_struct argument takes the same arrays from our .npz
    ref = smplx.SMPL(model_path=str(DEFAULT_BODY_FILE), num_betas=10, data_struct=Struct(**np.load(DEFAULT_BODY_FILE)))
    p = random_pose(4, scale=0.6, seed=3)
    ours = body(**p)
    theirs = ref(betas=p["betas"], global_orient=p["global_orient"], body_pose=p["body_pose"], transl=p["transl"],
                 return_full_pose=True)
    assert torch.allclose(ours.vertices, theirs.vertices, atol=1e-5)
    assert torch.allclose(ours.joints, theirs.joints[:, :24], atol=1e-5)
    assert torch.allclose(ours.full_pose, theirs.full_pose, atol=0)


def test_batch_equals_items(body):
    p = random_pose(3, seed=1)
    full = body(**p)
    for i in range(3):
        one = body(**{k: v[i:i + 1] for k, v in p.items()})
        assert torch.allclose(full.vertices[i], one.vertices[0], atol=1e-6)
        assert torch.allclose(full.joints[i], one.joints[0], atol=1e-6)


def test_rest_pose_is_template(body):
    out = body()
    assert torch.allclose(out.vertices[0], body.v_template, atol=1e-6)


def test_skinning_transform_consistency(body):
    """joint_transforms map the rest joints onto the posed joints (independent of the vertex path)."""
    p = random_pose(2, seed=2)
    out = body(**p)
    rest = body(betas=p["betas"])
    Jr = rest.joints
    T = out.joint_transforms
    mapped = (T[..., :3, :3] @ Jr[..., None])[..., 0] + T[..., :3, 3]
    assert torch.allclose(mapped, out.joints, atol=1e-5)


def test_gradients_finite_at_zero_pose(body):
    pose = torch.zeros(1, 69, requires_grad=True)
    betas = torch.zeros(1, 10, requires_grad=True)
    out = body(body_pose=pose, betas=betas)
    out.vertices.square().sum().backward()
    assert torch.isfinite(pose.grad).all() and torch.isfinite(betas.grad).all()
    assert betas.grad.abs().sum() > 0


def test_float64(body):
    b64 = volsmpl.create_body().to(torch.float64)
    p = random_pose(1)
    out = b64(**{k: v.double() for k, v in p.items()})
    assert out.vertices.dtype == torch.float64
    assert torch.allclose(out.vertices.float(), body(**p).vertices, atol=1e-5)


@pytest.mark.parametrize("kwargs,msg", [
    (dict(body_pose=torch.zeros(1, 23, 3)), "expected (B, 69)"),
    (dict(body_pose=torch.zeros(2, 69), transl=torch.zeros(3, 3)), "batch size"),
    (dict(betas=torch.full((1, 10), float("nan"))), "NaN"),
    (dict(transl=torch.zeros(1, 3, dtype=torch.float64)), "float64"),
    (dict(betas=np.zeros((1, 10))), "torch.Tensor"),
    (dict(pose2=torch.zeros(1)), "unexpected"),
])
def test_bad_inputs(body, kwargs, msg):
    with pytest.raises((ValueError, TypeError), match=msg.replace("(", r"\(").replace(")", r"\)")):
        body(**kwargs)


def test_unbatched_parameter_is_the_one_named(body):
    """A 1-D betas (10,) beside a (2, 69) body_pose was named wrongly: 'body_pose has batch size 2 but other inputs
    have 1' (the batch was read from the first parameter given, even a 1-D one). The batch is now that of the
    first (B, width) parameter, so the message names betas; a 1-D parameter alone is still a batch of 1."""
    with pytest.raises(ValueError, match=r"^betas has batch size 1 but other inputs have 2"):
        body(betas=torch.zeros(10), body_pose=torch.zeros(2, 69))
    with pytest.raises(ValueError, match=r"^global_orient has batch size 1 but other inputs have 2"):
        body(global_orient=torch.zeros(3), body_pose=torch.zeros(2, 69), transl=torch.zeros(2, 3))
    assert torch.equal(body(betas=torch.zeros(10), body_pose=torch.zeros(1, 69)).vertices, body().vertices)


def test_betas_of_another_width_name_num_betas(body):
    """betas with more or fewer columns than the body's num_betas said only 'expected (B, 10)'; the message now
    names num_betas and the fix (create_body(num_betas=n) when the file has n components)."""
    with pytest.raises(ValueError, match=r"betas has 16 columns but the body was created with num_betas=10; "
                                         r"create the body with volsmpl.create_body\(num_betas=16\)"):
        body(betas=torch.zeros(1, 16))
    with pytest.raises(ValueError, match=r"num_betas=10; create the body with volsmpl.create_body\(num_betas=5\)"):
        body(betas=torch.zeros(1, 5))
    with pytest.raises(ValueError, match=r"has 16 shape components: pass at most 16 columns"):
        body(betas=torch.zeros(1, 300))
    b16 = volsmpl.create_body(num_betas=16)
    assert b16(betas=torch.zeros(1, 16)).vertices.shape == (1, 13348, 3)


@pytest.mark.parametrize("kwargs, exc, msg", [
    (dict(num_betas=10.0), TypeError, "num_betas must be an int, got float 10.0"),
    (dict(batch_size=2.0), TypeError, "batch_size must be an int, got float 2.0"),
    (dict(num_betas="10"), TypeError, "num_betas must be an int, got str"),
    (dict(batch_size=0), ValueError, "batch_size=0"),
])
def test_create_body_options_checked(kwargs, exc, msg):
    """create_body(num_betas=10.0) failed with 'slice indices must be integers', batch_size=2.0 only at forward
    with 'zeros() takes 1 positional argument but 2 were given'; both are refused at creation in one line."""
    with pytest.raises(exc, match=msg) as e:
        volsmpl.create_body(**kwargs)
    assert "\n" not in str(e.value)


def test_num_betas_bounds():
    with pytest.raises(ValueError, match="shape components"):
        Body(DEFAULT_BODY_FILE, num_betas=10_000)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        Body(tmp_path / "nope.npz")
    with pytest.raises(ValueError, match="chumpy"):
        p = tmp_path / "SMPL_NEUTRAL.pkl"
        p.write_bytes(b"x")
        Body(p)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a readable"):
        Body(bad)
    arrays = dict(np.load(DEFAULT_BODY_FILE))
    partial = {k: v for k, v in arrays.items() if k != "J_regressor"}
    np.savez(tmp_path / "partial.npz", **partial)
    with pytest.raises(ValueError, match="missing arrays"):
        Body(tmp_path / "partial.npz")
    mano_like = dict(arrays)
    mano_like["weights"] = np.ones((arrays["v_template"].shape[0], 16), np.float32) / 16
    np.savez(tmp_path / "mano.npz", **mano_like)
    with pytest.raises(ValueError, match="16 skinning joints"):
        Body(tmp_path / "mano.npz")
    nan = dict(arrays)
    nan["v_template"] = nan["v_template"].copy()
    nan["v_template"][0, 0] = np.nan
    np.savez(tmp_path / "nan.npz", **nan)
    with pytest.raises(ValueError, match="NaN"):
        Body(tmp_path / "nan.npz")


def test_kinematic_levels_compose_the_chain_joint_by_joint(body):
    """Forward kinematics by depth equals the chain composed joint by joint in index order (SMPL's parents[j] < j):
    world rotations and posed joints, on a random pose and on a tree given out of order."""
    from volsmpl.body.lbs import chain_rotations, kinematic_levels, rigid_chain, rodrigues

    rot = rodrigues(torch.randn(3, 72, dtype=torch.float64, generator=torch.Generator().manual_seed(2)) * 0.5)
    rest = torch.randn(3, 24, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    par = body.parent_list
    ref_r, ref_j = [rot[:, 0]], [rest[:, 0]]
    for j in range(1, 24):
        p = par[j]
        ref_r.append(ref_r[p] @ rot[:, j])
        ref_j.append(ref_j[p] + (ref_r[p] @ (rest[:, j] - rest[:, p])[..., None])[..., 0])
    glob, posed, skin = rigid_chain(rot, rest, par)
    assert torch.allclose(glob, torch.stack(ref_r, 1), atol=1e-12)
    assert torch.allclose(posed, torch.stack(ref_j, 1), atol=1e-12)
    assert torch.allclose(chain_rotations(rot, kinematic_levels(par)), glob, atol=1e-12)
    order, parent, sizes = kinematic_levels([2, -1, 1, 0])       # 1 -> 2 -> 0 -> 3: depths 0, 1, 2, 3
    assert order.tolist() == [2, 0, 3] and parent.tolist() == [1, 2, 0] and sizes == [1, 1, 1]
    with pytest.raises(ValueError, match="do not form a tree"):
        kinematic_levels([-1, 2, 1])
