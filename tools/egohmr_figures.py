"""Figures of chosen frames of an egohmr table (`volsmpl egohmr sample` on a split), drawn from its results.json.

    python tools/egohmr_figures.py docs/egohmr/results.json test_0006,test_0106 --out docs/egohmr/failures

A table run draws its first --render frames only; this draws any of its frames (the flagged ones, say) the same way
(apps/egohmr/figures.frame_figure): the ground truth with the keypoints' joints, then each guide's recovered body
from its record (`body.params`, camera frame), the scene points of the guidance's crop inside it in red (the
collision metric's winding-number test). Writes OUT/frame_<name>.png per frame.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("results", type=Path, help="results.json of `volsmpl egohmr sample --split ...`")
    p.add_argument("frames", help="comma-separated frame names, e.g. test_0006,test_0106")
    p.add_argument("--out", type=Path, required=True, help="folder of the figures")
    args = p.parse_args(argv)

    import volsmpl
    from volsmpl.apps.egohmr.data import make_frames, scene_mesh
    from volsmpl.apps.egohmr.evaluate import prepare
    from volsmpl.apps.egohmr.figures import frame_figure
    from volsmpl.apps.egohmr.train import load_model
    from volsmpl.geometry.point_mesh_distance import winding_numbers

    res = json.loads(args.results.read_text())
    cfg, cases = res["config"], res["cases"]
    names = [n.strip() for n in args.frames.split(",") if n.strip()]
    split = cfg["split"]
    known = {r["frame"] for recs in cases.values() for r in recs}
    missing = [n for n in names if n not in known]
    if missing:
        print(f"error: frame(s) {', '.join(missing)} are not in {args.results}; it holds {split} frames "
              f"{min(known)}..{max(known)}", file=sys.stderr)
        return 2
    want = max(int(n.rsplit("_", 1)[1]) for n in names) + 1
    frames = {f.name: f for f in make_frames(split, want, seed=cfg["seed"])}
    body = volsmpl.create_body()
    net, _ = load_model(None if cfg.get("network", "").endswith("egohmr_anny") else cfg["network"], body)
    faces = torch.as_tensor(body.faces)
    args.out.mkdir(parents=True, exist_ok=True)
    for n in names:
        f = frames[n]
        with torch.no_grad():
            pts = prepare(net, body, [f], seed=cfg["seed"])["guide_points"][0]
            gt = body(betas=torch.as_tensor(f.betas)[None], global_orient=torch.as_tensor(f.global_orient)[None],
                      body_pose=torch.as_tensor(f.body_pose)[None], transl=torch.as_tensor(f.transl)[None]).vertices[0]
            samples, inside = {}, {}
            for g, recs in cases.items():
                rec = next(r for r in recs if r["frame"] == n)
                if not rec.get("body"):
                    continue  # a diverged sample: no body, its status says so
                params = {k: torch.as_tensor(v, dtype=torch.float32)[None] for k, v in rec["body"]["params"].items()}
                v = body(**params).vertices[0]
                samples[f"{g} ({rec['status']})"] = v.numpy()
                inside[f"{g} ({rec['status']})"] = pts[winding_numbers(v, faces, pts) > 0.5].numpy()
        path = args.out / f"frame_{n}.png"
        frame_figure(path, f, scene_mesh(f), gt.numpy(), samples, body.faces, inside)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
