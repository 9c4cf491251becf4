"""The paper's own numbers (VolumetricSMPL, Mihajlovic et al., ICCV 2025), one place, as plain data.

Every table is a dict:

    id        the paper's number ("1" .. "6" in the main text, "C.4", "D.1" in the supplement)
    label     its \\label in the paper's source
    title     the caption's bold title; caption: the rest of the caption, shortened
    hardware  the GPU the paper names for it, or "not stated"; hardware_note: where that comes from
    columns   column key -> {"label": header as printed, "unit": unit}; ordered as the printed table
    rows      row key -> {column key: value as printed, None where the paper prints "-"}; ordered as printed
    row_labels  row key -> the row's label as printed
    notes     optional: row key -> {column key: note} (e.g. COAP's 71 GB of Table 5 is for 16 frames only)

Row keys name the back-end where there is one ('volsmpl', 'coap', 'mesh', 'leap', 'winding'), so the apps can put
their `summary.<back-end>` beside the paper's row of the same key, column by column. Values are copied from
the paper's tables exactly as printed (units in `columns`; Table 1's IoU in %, Table 2's MSE in units of 1e-5);
tests/report/test_paper.py re-reads them from the paper's LaTeX source.

    from volsmpl.report import paper
    paper.value("6", "volsmpl", "step_ms")     # 14
    paper.rows("selfpen")                      # {'coap': {...}, 'volsmpl': {...}}: apps/selfpen's PAPER dict
    paper.bench_paper()                        # core/bench/run.py's PAPER dict
"""
from __future__ import annotations

import copy

_COLS = lambda *cols: {k: {"label": label, "unit": unit} for k, label, unit in cols}  # noqa: E731

TABLE_1 = {
    "id": "1", "label": "tab:bodies", "title": "Comparisons with Volumetric Bodies.",
    "caption": "Compared to COAP on unseen subjects from the challenging PosePrior dataset; resources measured on "
               "a total of 60k query points uniformly sampled around the body and sampled around the surface; surf. "
               "and unif. IoU refer to points sampled around the surface and uniformly at random.",
    "hardware": "not stated (GPU memory; the paper trains on one 24 GB RTX 3090)",
    "hardware_note": "the table does not name its GPU; the paper trains on a single 24GB RTX 3090",
    "columns": _COLS(("t_ms", "t", "ms"), ("gpu_gb", "GPU", "GB"), ("iou_mean", "IoU mean", "%"),
                     ("iou_surf", "IoU surf.", "%"), ("iou_unif", "IoU unif.", "%"), ("mse_sdf", "MSE SDF", "m^2"),
                     ("mse_abs_sdf", "MSE |SDF|", "m^2")),
    "rows": {
        "leap": {"t_ms": 79, "gpu_gb": 7.7, "iou_mean": 75.98, "iou_surf": 69.98, "iou_unif": 81.97,
                 "mse_sdf": None, "mse_abs_sdf": None},
        "coap": {"t_ms": 140, "gpu_gb": 18.7, "iou_mean": 94.31, "iou_surf": 93.98, "iou_unif": 94.63,
                 "mse_sdf": None, "mse_abs_sdf": None},
        "volsmpl": {"t_ms": 15, "gpu_gb": 3.1, "iou_mean": 94.67, "iou_surf": 94.25, "iou_unif": 95.10,
                    "mse_sdf": 3.7e-5, "mse_abs_sdf": 3.5e-5},
    },
    "row_labels": {"leap": "LEAP", "coap": "COAP", "volsmpl": "VolumetricSMPL"},
}

TABLE_2 = {
    "id": "2", "label": "tab:bodies_ablation", "title": "Ablation Study of design choices in our body model.",
    "caption": "Regular MLP instead of neural blend weights (NBW), the positional encoding gamma (two levels) of the "
               "local query point, and NBW ranks from R=1 to R=80; evaluation as Table 1.",
    "hardware": "not stated (GPU memory; as Table 1)",
    "hardware_note": "the table does not name its GPU",
    "columns": _COLS(("t_ms", "t", "ms"), ("gpu_gb", "GPU", "GB"), ("params_m", "#param", "M"),
                     ("iou_mean", "IoU mean", "%"), ("iou_surf", "IoU surf.", "%"), ("iou_unif", "IoU unif.", "%"),
                     ("mse_sdf", "MSE SDF", "1e-5"), ("mse_abs_sdf", "MSE |SDF|", "1e-5")),
    "rows": {
        "base_mlp": {"t_ms": 15, "gpu_gb": 2.9, "params_m": 0.4, "iou_mean": 92.75, "iou_surf": 92.23,
                     "iou_unif": 93.27, "mse_sdf": 5.2, "mse_abs_sdf": 6.9},
        "posenc": {"t_ms": 15, "gpu_gb": 3.1, "params_m": 0.4, "iou_mean": 93.00, "iou_surf": 92.42,
                   "iou_unif": 93.59, "mse_sdf": 8.3, "mse_abs_sdf": 11},
        "nbw_r1": {"t_ms": 15, "gpu_gb": 3.1, "params_m": 0.8, "iou_mean": 94.06, "iou_surf": 93.55,
                   "iou_unif": 94.58, "mse_sdf": 4.8, "mse_abs_sdf": 5.2},
        "nbw_r5": {"t_ms": 15, "gpu_gb": 3.1, "params_m": 1.0, "iou_mean": 94.12, "iou_surf": 93.82,
                   "iou_unif": 94.42, "mse_sdf": 4.4, "mse_abs_sdf": 4.6},
        "nbw_r10": {"t_ms": 15, "gpu_gb": 3.1, "params_m": 1.2, "iou_mean": 94.07, "iou_surf": 93.67,
                    "iou_unif": 94.46, "mse_sdf": 4.1, "mse_abs_sdf": 3.9},
        "nbw_r20": {"t_ms": 15, "gpu_gb": 3.1, "params_m": 1.6, "iou_mean": 94.60, "iou_surf": 94.10,
                    "iou_unif": 95.10, "mse_sdf": 3.7, "mse_abs_sdf": 3.5},
        "nbw_r40": {"t_ms": 15, "gpu_gb": 3.1, "params_m": 2.4, "iou_mean": 94.79, "iou_surf": 94.43,
                    "iou_unif": 95.14, "mse_sdf": 3.8, "mse_abs_sdf": 3.7},
        "nbw_r80": {"t_ms": 15, "gpu_gb": 3.1, "params_m": 4.0, "iou_mean": 94.67, "iou_surf": 94.25,
                    "iou_unif": 95.10, "mse_sdf": 3.7, "mse_abs_sdf": 3.5},
    },
    "row_labels": {"base_mlp": "Base MLP", "posenc": "+ gamma", "nbw_r1": "+ NBW (R=1)", "nbw_r5": "+ NBW (R=5)",
                   "nbw_r10": "+ NBW (R=10)", "nbw_r20": "+ NBW (R=20)", "nbw_r40": "+ NBW (R=40)",
                   "nbw_r80": "+ NBW (R=80)"},
}

TABLE_3 = {
    "id": "3", "label": "tab:hoi", "title": "In-the-Wild Human-Object Reconstruction.",
    "caption": "Optimization efficiency and reconstruction quality under identical settings (same optimization "
               "iterations and hardware) on the interaction database of Wang et al.; metrics averaged over 100 "
               "images. Collision: object penetration ratio; contact: Chamfer distance.",
    "hardware": "NVIDIA RTX 3090", "hardware_note": "Table 3's caption",
    "columns": _COLS(("iter_ms", "per iteration", "ms"), ("total_min", "total", "min"),
                     ("collision_pct", "collision", "%"), ("contact_cm", "contact", "cm")),
    "rows": {
        "mesh": {"iter_ms": 2128.2, "total_min": 35.9, "collision_pct": 6.33, "contact_cm": 3.20},
        "volsmpl": {"iter_ms": 4.28, "total_min": 0.57, "collision_pct": 5.73, "contact_cm": 3.96},
    },
    "row_labels": {"mesh": "w. SDF [Wang et al.]", "volsmpl": "w. Ours"},
}

TABLE_4 = {
    "id": "4", "label": "tab:egohmr-results", "title": "Human Mesh Reconstruction in 3D Scenes using EgoHMR "
                                                      "with VolumetricSMPL vs. COAP.",
    "caption": "EgoBody test set (62,140 frames). coll.: human-scene collision, printed as a fraction (the caption "
               "reads 0.184 / 0.191 as 18.4 % / 19.1 %); cont.: contact in %; MPJPE over all, visible and invisible "
               "joints.",
    "hardware": "NVIDIA TITAN RTX (24 GB)", "hardware_note": "Table 4's caption",
    "columns": _COLS(("batch", "batch", "samples"), ("s_per_frame", "t", "s/frame"),
                     ("collision", "coll.", "fraction"), ("contact_pct", "cont.", "%"),
                     ("mpjpe_mm", "MPJPE mean", "mm"), ("mpjpe_vis_mm", "MPJPE vis.", "mm"),
                     ("mpjpe_invis_mm", "MPJPE invis.", "mm")),
    "rows": {
        "coap": {"batch": 3, "s_per_frame": 2.08, "collision": 0.191, "contact_pct": 99, "mpjpe_mm": 86.74,
                 "mpjpe_vis_mm": 65.7, "mpjpe_invis_mm": 107.8},
        "volsmpl": {"batch": 30, "s_per_frame": 0.61, "collision": 0.184, "contact_pct": 99, "mpjpe_mm": 86.63,
                    "mpjpe_vis_mm": 65.8, "mpjpe_invis_mm": 107.5},
    },
    "row_labels": {"coap": "w. COAP", "volsmpl": "w. Ours"},
    # the app's summary keys for the columns it names otherwise
    "our_keys": {"batch": "max_batch", "collision": "collision_ratio", "mpjpe_vis_mm": "mpjpe_visible_mm",
                 "mpjpe_invis_mm": "mpjpe_invisible_mm"},
}

TABLE_5 = {
    "id": "5", "label": "tab:dart", "title": "Scene-Constrained Human Motion Synthesis.",
    "caption": "Indoor navigation with DartControl and different collision evaluation methods; 15 reconstructed "
               "scenes, 8 sequences each, 80-120 frames; totals for an 80-frame sequence.",
    "hardware": "NVIDIA A100 (80 GB)", "hardware_note": "Table 5's caption",
    "columns": _COLS(("frame_mem_gb", "per-frame memory", "GB"), ("frame_ms", "per-frame time", "ms"),
                     ("total_mem_gb", "total memory", "GB"), ("collision_cm", "collision", "cm"),
                     ("goal_dist_m", "goal dist.", "m")),
    "rows": {
        "coap": {"frame_mem_gb": 4.44, "frame_ms": 26.53, "total_mem_gb": 71.0, "collision_cm": 2.78,
                 "goal_dist_m": 0.16},
        "volsmpl": {"frame_mem_gb": 0.19, "frame_ms": 3.78, "total_mem_gb": 15.9, "collision_cm": 0.24,
                    "goal_dist_m": 0.01},
    },
    "row_labels": {"coap": "w. COAP", "volsmpl": "w. Ours"},
    "notes": {"coap": {"total_mem_gb": "* for 16 frames only: COAP's collision checks for the 80-frame sequence "
                                      "exceed an 80 GB GPU"}},
}

TABLE_6 = {
    "id": "6", "label": "tab_app:abl_selfint", "title": "Volumetric Constraints for Self-Intersections.",
    "caption": "VolumetricSMPL and COAP: per-step cost (runtime and memory), total optimization iterations and "
               "time, and final mesh triangle collisions, on self-intersected PROX meshes (COAP's setup).",
    "hardware": "NVIDIA RTX 3090", "hardware_note": "supplement, Sec. D (self-intersection handling)",
    "columns": _COLS(("step_ms", "per-step time", "ms"), ("memory_gb", "per-step memory", "GB"),
                     ("iterations", "iterations", ""), ("total_s", "total time", "s"),
                     ("collisions", "triangle collisions", "")),
    "rows": {
        "coap": {"step_ms": 30, "memory_gb": 6.2, "iterations": 9.75, "total_s": 0.29, "collisions": 74},
        "volsmpl": {"step_ms": 14, "memory_gb": 1.8, "iterations": 7.37, "total_s": 0.10, "collisions": 68},
    },
    "row_labels": {"coap": "w. COAP", "volsmpl": "w. Ours"},
}

TABLE_C4 = {
    "id": "C.4", "label": "tab:winding", "title": "Comparison of occupancy checks using winding numbers and "
                                                  "VolumetricSMPL.",
    "caption": "Inference time and GPU memory to check whether SMPL-X vertices are inside another SMPL-X body.",
    "hardware": "not stated (GPU memory)", "hardware_note": "the table does not name its GPU",
    "columns": _COLS(("t_ms", "inference time", "ms"), ("mem_gb", "GPU memory", "GB")),
    "rows": {"winding": {"t_ms": 464.41, "mem_gb": 15.58}, "volsmpl": {"t_ms": 11.06, "mem_gb": 0.27}},
    "row_labels": {"winding": "Winding Numbers", "volsmpl": "VolumetricSMPL"},
}

TABLE_D1 = {
    "id": "D.1", "label": "tab:coll_weights", "title": "Motion synthesis with COAP at several collision weights "
                                                       "vs. VolumetricSMPL.",
    "caption": "Indoor navigation motion synthesis using a COAP-based collision term with different weights w and "
               "the VolumetricSMPL-based collision term (w = 1).",
    "hardware": "not stated (Table 5's experiments: NVIDIA A100 80 GB)",
    "hardware_note": "the table does not name its GPU; its w=0.1 row is Table 5's COAP row",
    "columns": _COLS(("frame_mem_gb", "per-frame memory", "GB"), ("frame_ms", "per-frame time", "ms"),
                     ("collision_cm", "collision", "cm"), ("goal_dist_m", "goal dist.", "m")),
    "rows": {
        "coap_w0.01": {"frame_mem_gb": 4.44, "frame_ms": 26.48, "collision_cm": 4.92, "goal_dist_m": 0.02},
        "coap_w0.1": {"frame_mem_gb": 4.44, "frame_ms": 26.53, "collision_cm": 2.78, "goal_dist_m": 0.16},
        "coap_w1.0": {"frame_mem_gb": 4.44, "frame_ms": 26.77, "collision_cm": 4.92, "goal_dist_m": 0.57},
        "volsmpl_w1.0": {"frame_mem_gb": 0.19, "frame_ms": 3.78, "collision_cm": 0.24, "goal_dist_m": 0.01},
    },
    "row_labels": {"coap_w0.01": "w. COAP (w=0.01)", "coap_w0.1": "w. COAP (w=0.1)", "coap_w1.0": "w. COAP (w=1.0)",
                   "volsmpl_w1.0": "w. Ours (w=1.0)"},
    "collision_weight": {"coap_w0.01": 0.01, "coap_w0.1": 0.1, "coap_w1.0": 1.0, "volsmpl_w1.0": 1.0},
}

#: every table by the paper's number
TABLES = {t["id"]: t for t in (TABLE_1, TABLE_2, TABLE_3, TABLE_4, TABLE_5, TABLE_6, TABLE_C4, TABLE_D1)}

#: names by topic -> the paper's number
ALIASES = {"bodies": "1", "ablation": "2", "hoi": "3", "egohmr": "4", "motion": "5", "selfpen": "6",
           "winding": "C.4", "coll_weights": "D.1"}


def table(key: str) -> dict:
    """The table by its number ('1' .. '6', 'C.4', 'D.1'; 'Table 6' also works) or topic (ALIASES); a copy."""
    k = str(key).strip()
    k = k[len("table"):].strip() if k.lower().startswith("table") else k
    k = ALIASES.get(k.lower(), k.upper())
    if k not in TABLES:
        raise KeyError(f"no paper table {key!r}: one of {', '.join(TABLES)} or {', '.join(ALIASES)}")
    return copy.deepcopy(TABLES[k])


def rows(key: str) -> dict:
    """row key -> {column: value} of a table (a copy). rows('selfpen') is apps/selfpen's PAPER dict."""
    return table(key)["rows"]


def value(key: str, row: str, column: str):
    """One number as printed (None where the paper prints '-')."""
    t = table(key)
    if row not in t["rows"]:
        raise KeyError(f"Table {t['id']} has no row {row!r}: {', '.join(t['rows'])}")
    if column not in t["columns"]:
        raise KeyError(f"Table {t['id']} has no column {column!r}: {', '.join(t['columns'])}")
    return t["rows"][row][column]


def bench_paper() -> dict:
    """core/bench/run.py's PAPER dict (Table 1 time/memory, Table C.4), built from the tables above."""
    t1, c4 = TABLES["1"]["rows"], TABLES["C.4"]["rows"]
    out = {m: {"t_ms": float(t1[m]["t_ms"]), "mem_gb": float(t1[m]["gpu_gb"])} for m in ("volsmpl", "coap")}
    out["winding_bodybody"] = dict(c4["winding"])
    out["volsmpl_bodybody"] = dict(c4["volsmpl"])
    out["ratios"] = {
        "coap/volsmpl": {"time": out["coap"]["t_ms"] / out["volsmpl"]["t_ms"],
                         "mem": out["coap"]["mem_gb"] / out["volsmpl"]["mem_gb"]},
        # the paper's model has no learned passes: our variant of the same form
        "coap/volsmpl-encoder": {"time": out["coap"]["t_ms"] / out["volsmpl"]["t_ms"],
                                 "mem": out["coap"]["mem_gb"] / out["volsmpl"]["mem_gb"]},
        "winding/volsmpl": {"time": c4["winding"]["t_ms"] / c4["volsmpl"]["t_ms"],
                            "mem": c4["winding"]["mem_gb"] / c4["volsmpl"]["mem_gb"]},
    }
    return out
