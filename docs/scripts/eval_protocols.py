"""IoU of checkpoints under the two sampling protocols of `volsmpl eval` and several surface offsets, one table.

    python docs/scripts/eval_protocols.py [--checkpoints NAME=PATH ...] [--sigmas 0.01 0.02 0.03]
                                          [--samplings body parts] [--out docs/eval_protocols.json]

For each checkpoint (default: the shipped VolumetricSMPL and COAP), each sampling ('body': uniform in the body's
padded bounding box and near the whole surface, the default; 'parts': COAP's per-part sampling) and each surface
offset sigma, `evaluate_checkpoint` on the 64-body standard split (60k points per body, exact ground truth,
cached). The uniform points do not depend on sigma, so their IoU is the same along a row's sigmas: that is the
check that only the near-surface set moved. Writes the metrics per (checkpoint, sampling, sigma) as JSON and
prints a markdown table.
"""
import argparse
import json
import time

import torch

from volsmpl.evaluation import EvalConfig, evaluate_checkpoint
from volsmpl.io.provenance import machine_info

SHIPPED = {"VolumetricSMPL": "core/assets/volsmpl_anny", "COAP": "core/assets/coap_anny"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoints", nargs="+", default=[f"{k}={v}" for k, v in SHIPPED.items()],
                    help="NAME=PATH pairs (PATH without .safetensors)")
    ap.add_argument("--samplings", nargs="+", default=["body", "parts"], choices=["body", "parts"])
    ap.add_argument("--sigmas", nargs="+", type=float, default=[0.01, 0.02, 0.03])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None, help="write the rows as JSON here")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    rows = []
    for spec in args.checkpoints:
        name, _, path = spec.partition("=")
        for sampling in args.samplings:
            for sigma in args.sigmas:
                t0 = time.perf_counter()
                res = evaluate_checkpoint(path, config=EvalConfig(sampling=sampling, surface_sigma=sigma))
                m = res.metrics
                rows.append({"model": name, "checkpoint": path, "sampling": sampling, "sigma": sigma,
                             "iou_mean": m["iou_mean"], "iou_surf": m["iou_surf"], "iou_unif": m["iou_unif"],
                             "mse_sdf": m["mse_sdf"], "points_digest": res.points_digest,
                             "seconds": round(time.perf_counter() - t0, 1)})
                print(f"{name} {sampling} sigma {sigma:g}: {100 * m['iou_mean']:.2f} / {100 * m['iou_surf']:.2f} / "
                      f"{100 * m['iou_unif']:.2f}", flush=True)
    print("\n| model | sampling | sigma [m] | IoU mean | surf. | unif. | MSE SDF |\n|---|---|---:|---:|---:|---:|---:|")
    for r in rows:
        mse = "-" if r["mse_sdf"] is None else f"{r['mse_sdf']:.2e}"
        print(f"| {r['model']} | {r['sampling']} | {r['sigma']:g} | {100 * r['iou_mean']:.2f} | "
              f"{100 * r['iou_surf']:.2f} | {100 * r['iou_unif']:.2f} | {mse} |")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"command": "python docs/scripts/eval_protocols.py " + " ".join(
                           f"--{k} {' '.join(map(str, v)) if isinstance(v, list) else v}" for k, v in vars(args).items()
                           if v is not None),
                       "rows": rows, "meta": machine_info("cpu", torch.get_num_threads())}, f, indent=1)


if __name__ == "__main__":
    main()
