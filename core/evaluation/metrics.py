"""Accuracy metrics of a predicted SDF against the ground truth (paper Table 1 columns).

Per body, then the plain mean over bodies (all bodies have the same number of points, so the MSE means
equal the means over all points):
  - IoU(S) = |{pred < 0} & {gt < 0}| / |{pred < 0} | {gt < 0}| over the point set S (1 when both are
    empty); iou_surf on the near-surface set, iou_unif on the uniform set, iou_mean = their average.
  - mse_sdf = mean (pred - gt)^2, mse_abs_sdf = mean (|pred| - |gt|)^2 (metres^2), over all points;
    `_surf` / `_unif` suffixes: over the near-surface / uniform set only. Note ||a| - |b|| <= |a - b|, so
    mse_abs_sdf <= mse_sdf on any point set; the paper's Table 2 has rows with |SDF| > SDF, so its
    exact definition must differ (not stated); these are the well-defined ones.
"""
from __future__ import annotations

import math
from typing import Dict

import torch

__all__ = ["iou", "compute_metrics"]


def iou(pred_occ: torch.Tensor, gt_occ: torch.Tensor) -> torch.Tensor:
    """Intersection over union of boolean occupancies (B, N) -> (B,) float64; 1.0 where both are empty."""
    pred_occ, gt_occ = torch.as_tensor(pred_occ).bool(), torch.as_tensor(gt_occ).bool()
    if pred_occ.shape != gt_occ.shape:
        raise ValueError(f"occupancies must have equal shapes, got {tuple(pred_occ.shape)} and {tuple(gt_occ.shape)}.")
    inter = (pred_occ & gt_occ).sum(-1).double()
    union = (pred_occ | gt_occ).sum(-1).double()
    return torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(union))


def compute_metrics(pred: torch.Tensor, gt: torch.Tensor, is_surface: torch.Tensor) -> Dict[str, torch.Tensor]:
    """Per-body metrics (module docstring). pred, gt (B, N) SDF, negative inside; is_surface (N,) bool.

    Returns: dict name -> (B,) float64: iou_mean, iou_surf, iou_unif, mse_sdf, mse_abs_sdf and the
    `_surf` / `_unif` variants of the two MSEs.
    """
    pred, gt = torch.as_tensor(pred).double(), torch.as_tensor(gt).double()
    if pred.shape != gt.shape or pred.ndim != 2:
        raise ValueError(f"pred and gt must both be (B, N), got {tuple(pred.shape)} and {tuple(gt.shape)}.")
    if not torch.isfinite(pred).all():
        bad = int((~torch.isfinite(pred)).sum())
        raise ValueError(f"the predictor returned {bad} non-finite SDF values; fix the model (NaN weights?) before evaluating.")
    surf = torch.as_tensor(is_surface).bool()
    sets = {"": slice(None), "_surf": surf, "_unif": ~surf}
    m = {}
    for tag in ("_surf", "_unif"):
        m["iou" + tag] = iou(pred[:, sets[tag]] < 0, gt[:, sets[tag]] < 0)
    m["iou_mean"] = 0.5 * (m["iou_surf"] + m["iou_unif"])
    for tag, sel in sets.items():
        p, g = pred[:, sel], gt[:, sel]
        empty = p.shape[1] == 0
        m["mse_sdf" + tag] = torch.full((len(p),), math.nan, dtype=torch.float64) if empty else ((p - g) ** 2).mean(1)
        m["mse_abs_sdf" + tag] = torch.full((len(p),), math.nan, dtype=torch.float64) if empty else \
            ((p.abs() - g.abs()) ** 2).mean(1)
    return m
