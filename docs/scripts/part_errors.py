"""Where a checkpoint's errors are, part by part, under COAP's per-part sampling (`volsmpl eval --sampling parts`).

    python docs/scripts/part_errors.py [--checkpoint core/assets/volsmpl_anny] [--sigma 0.01] [--n-bodies 64]
                                       [--out part_errors.json]

Per-part sampling gives every body part the same number of points (uniform in its padded box, near its own
faces), laid out part by part, so each part's block of points can be scored on its own: IoU of the near-surface
and uniform points of part k's block (pooled over the bodies: intersection and union summed, then divided, so
that a body where part k holds few inside points weighs little), and the share of all wrong signs that fall in part
k's near-surface block. For an SDF model also the error of the predicted distance at part k's near-surface points
within 1 cm of the surface: its mean (a bias: the level set moved out or in), its median absolute value and its
root mean square, in millimetres. Same bodies, points (`evaluate.evaluation_points`) and exact ground truth
(cached) as `volsmpl eval --sampling parts`.
"""
import argparse
import json

import torch

from volsmpl.volume.attach import attach_volume
from volsmpl.body.model import create_body
from volsmpl.evaluation import EvalConfig, evaluation_points
from volsmpl.evaluation.gt_cache import ground_truth
from volsmpl.evaluation.validation_set import pose_bodies, validation_bodies

#: near-surface points closer than this to the surface (metres) enter the distance-error columns
NEAR = 0.01


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", default=None, help="checkpoint path (default: the shipped VolumetricSMPL)")
    ap.add_argument("--sigma", type=float, default=0.01)
    ap.add_argument("--n-bodies", type=int, default=64)
    ap.add_argument("--points", type=int, default=60000)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    body = create_body()
    vol = attach_volume(body, checkpoint=args.checkpoint)
    names = vol.partition.table.part_names
    K = len(names)
    cfg = EvalConfig(n_bodies=args.n_bodies, n_points=args.points, surface_sigma=args.sigma, sampling="parts")
    bodies = validation_bodies(args.n_bodies, cfg.seed)
    verts = pose_bodies(body, bodies)
    points, is_surface = evaluation_points(body, bodies, verts, cfg)
    gt = ground_truth(verts, body.faces, points, cfg.gt_sign, cfg.gt_nsamples)
    preds = []
    with torch.no_grad():
        for s in range(0, args.n_bodies, 8):
            out = body(**{k: v[s:s + 8] for k, v in bodies.items()})
            p = vol.query(out, points[s:s + 8])
            preds.append((p if vol.is_sdf else vol.level - p).float())
    pred = torch.cat(preds)
    pred_in, gt_in = pred < 0, gt < 0
    wrong = pred_in != gt_in
    n_unif = int((~is_surface).sum()) // K
    n_surf = int(is_surface.sum()) // K
    rows = []
    for k, name in enumerate(names):
        row = {"part": name}
        for label, start, n in (("unif", k * n_unif, n_unif), ("surf", K * n_unif + k * n_surf, n_surf)):
            sl = slice(start, start + n)
            inter = (pred_in[:, sl] & gt_in[:, sl]).sum().item()
            union = (pred_in[:, sl] | gt_in[:, sl]).sum().item()
            row[f"iou_{label}"] = inter / union if union else 1.0
            row[f"wrong_{label}"] = wrong[:, sl].float().mean().item()
            if label == "surf" and vol.is_sdf:   # distances within NEAR of the surface: bias, median |e|, rms
                g = gt[:, sl].float()
                err = (pred[:, sl] - g)[g.abs() < NEAR]
                row["sdf_bias_mm"] = 1e3 * err.mean().item()
                row["sdf_median_abs_mm"] = 1e3 * err.abs().median().item()
                row["sdf_rms_mm"] = 1e3 * err.pow(2).mean().sqrt().item()
            if label == "surf":
                row["share_of_surface_errors"] = wrong[:, sl].sum().item()
        rows.append(row)
    total = sum(r["share_of_surface_errors"] for r in rows) or 1
    for r in rows:
        r["share_of_surface_errors"] /= total
    sdf = vol.is_sdf
    print("| part | IoU surf. | IoU unif. | wrong signs surf. | wrong signs unif. | share of surf. errors |"
          + (" SDF error bias / median abs / rms [mm] |" if sdf else ""))
    print("|---|---:|---:|---:|---:|---:|" + ("---:|" if sdf else ""))
    for r in sorted(rows, key=lambda r: r["iou_surf"]):
        print(f"| {r['part']} | {100 * r['iou_surf']:.2f} | {100 * r['iou_unif']:.2f} | {100 * r['wrong_surf']:.2f} % | "
              f"{100 * r['wrong_unif']:.2f} % | {100 * r['share_of_surface_errors']:.1f} % |"
              + (f" {r['sdf_bias_mm']:+.2f} / {r['sdf_median_abs_mm']:.2f} / {r['sdf_rms_mm']:.2f} |" if sdf else ""))
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"args": vars(args), "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
