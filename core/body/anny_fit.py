"""Fitting of the SMPL-format body from T-posed Anny samples (`volsmpl.body.anny_export`): skinning weights
merged per joint, joint targets, the non-negative sparse J_regressor, the PCA shape space (betas) and the
watertightness report of the mesh.
"""
from __future__ import annotations

import numpy as np

from .anny_skeleton import (J_REGRESSOR_CONE_COS, J_REGRESSOR_DIRECTIONS, J_REGRESSOR_PER_DIRECTION, N_BETAS,
                            SUM_TO_ONE_WEIGHT)


# ----------------------------------------------------------------------------------------------------------------
# Skinning weights, joints, J_regressor
# ----------------------------------------------------------------------------------------------------------------
def dense_bone_weights(model) -> np.ndarray:
    """(V, J_anny) float64 Anny skinning weights (rows sum to 1)."""
    import anny.skinning.skinning as sk

    w = sk.dense_bone_weights(model.vertex_bone_weights, model.vertex_bone_indices, len(model.bone_labels))
    return w.double().cpu().numpy()


def merge_weights(bone_weights: np.ndarray, bone_labels, table: dict, joint_names) -> np.ndarray:
    """Sum Anny bone weights into joints.

    Args:
        bone_weights: (V, J_anny); bone_labels: J_anny labels; table: bone -> joint; joint_names: (J,) names.
    Returns:
        (V, J) float64 weights, rows renormalised to sum to 1.
    """
    M = np.zeros((len(bone_labels), len(joint_names)))
    col = {n: j for j, n in enumerate(joint_names)}
    for b, label in enumerate(bone_labels):
        M[b, col[table[label]]] = 1.0
    w = bone_weights @ M
    w[w < 0] = 0.0
    return w / w.sum(1, keepdims=True)


def joint_targets(heads: np.ndarray, bone_labels, anchors: dict, joint_names) -> np.ndarray:
    """Joint positions per shape = mean of the anchor bones' heads.

    Args:
        heads: (N, J_anny, 3) posed bone heads; anchors: joint -> list of bone labels.
    Returns:
        (N, J, 3) joint positions.
    """
    idx = {n: i for i, n in enumerate(bone_labels)}
    return np.stack([heads[:, [idx[b] for b in anchors[j]]].mean(1) for j in joint_names], axis=1)


def fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) near-uniform unit directions on the sphere (deterministic)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z ** 2)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def regressor_candidates(mean_verts: np.ndarray, joint: np.ndarray, n_dirs: int | None = None,
                         per_dir: int | None = None, cos_cone: float = J_REGRESSOR_CONE_COS) -> np.ndarray:
    """Candidate vertices surrounding a joint: the nearest `per_dir` vertices inside each of `n_dirs` cones.

    A nearest-neighbour set would lie on one side of joints close to the surface (spine, hips); sampling the
    surrounding surface in all directions keeps the joint inside the candidates' convex hull.
    Args:
        mean_verts: (V, 3) mean body; joint: (3,) joint position.
    Returns:
        sorted unique vertex indices (K,).
    """
    n_dirs = n_dirs or J_REGRESSOR_DIRECTIONS
    per_dir = per_dir or J_REGRESSOR_PER_DIRECTION
    off = mean_verts - joint
    dist = np.linalg.norm(off, axis=1)
    cosang = (off / np.maximum(dist, 1e-12)[:, None]) @ fibonacci_directions(n_dirs).T  # (V, n_dirs)
    cand = []
    for k in range(n_dirs):
        inside = np.flatnonzero(cosang[:, k] > cos_cone)
        cand.extend(inside[np.argsort(dist[inside], kind="stable")[:per_dir]].tolist())
    return np.unique(np.asarray(cand, dtype=np.int64))


def fit_j_regressor(verts: np.ndarray, targets: np.ndarray):
    """Sparse non-negative joint regressor fitted over shapes.

    Args:
        verts: (N, V, 3) T-posed vertices of N shapes; targets: (N, J, 3) joint positions.
    Returns:
        J_regressor (J, V) float64 (rows >= 0, sum 1), errors (N, J) regression error in metres.
    """
    from scipy.optimize import nnls

    N, V, _ = verts.shape
    J = targets.shape[1]
    mean_v, mean_t = verts.mean(0), targets.mean(0)
    reg = np.zeros((J, V))
    for j in range(J):
        cand = regressor_candidates(mean_v, mean_t[j])
        A = (verts[:, cand, :] - mean_t[j]).transpose(0, 2, 1).reshape(3 * N, len(cand))
        y = (targets[:, j] - mean_t[j]).reshape(-1)
        A = np.vstack([A, SUM_TO_ONE_WEIGHT * np.ones((1, len(cand)))])
        y = np.concatenate([y, [SUM_TO_ONE_WEIGHT]])
        w, _ = nnls(A, y, maxiter=50 * len(cand))
        reg[j, cand] = w / w.sum()
    err = np.linalg.norm(np.einsum("jv,nvc->njc", reg, verts) - targets, axis=-1)
    return reg, err


# ----------------------------------------------------------------------------------------------------------------
# Shape space
# ----------------------------------------------------------------------------------------------------------------
def pca_shape_space(verts: np.ndarray, n_betas: int = N_BETAS):
    """PCA of T-posed meshes.

    Args:
        verts: (N, V, 3) T-posed vertices.
        n_betas: components kept.
    Returns:
        v_template (V, 3) population mean, shapedirs (V, 3, n_betas) = eigvec * sqrt(eigval),
        explained (n_betas,) cumulative fraction of the vertex variance.
    """
    N, V, _ = verts.shape
    mean = verts.mean(0)
    X = (verts - mean).reshape(N, -1)
    _, s, vt = np.linalg.svd(X, full_matrices=False)
    eig = s ** 2 / (N - 1)
    comps = vt[:n_betas]
    flip = np.sign(comps[np.arange(n_betas), np.abs(comps).argmax(1)])
    comps = comps * flip[:, None]
    shapedirs = (comps * np.sqrt(eig[:n_betas])[:, None]).T.reshape(V, 3, n_betas)
    explained = np.cumsum(eig[:n_betas]) / eig.sum()
    return mean, shapedirs, explained


def project_betas(verts: np.ndarray, v_template: np.ndarray, shapedirs: np.ndarray) -> np.ndarray:
    """Least-squares betas of meshes: (N, V, 3) -> (N, NB)."""
    A = shapedirs.reshape(-1, shapedirs.shape[-1]).astype(np.float64)
    X = (verts - v_template).reshape(len(verts), -1).T
    return np.linalg.lstsq(A, X, rcond=None)[0].T


# ----------------------------------------------------------------------------------------------------------------
# Mesh checks
# ----------------------------------------------------------------------------------------------------------------
def mesh_report(vertices: np.ndarray, faces: np.ndarray) -> dict:
    """Watertightness / manifoldness figures of a triangle mesh ((V,3), (F,3))."""
    import trimesh

    m = trimesh.Trimesh(vertices, faces, process=False)
    return {
        "watertight": bool(m.is_watertight), "winding_consistent": bool(m.is_winding_consistent),
        "components": int(len(m.split(only_watertight=False))), "volume_m3": float(m.volume),
        "unused_vertices": int(len(vertices) - len(np.unique(faces))),
    }
