"""How much of a checkpoint's error is its encoder's: the validation IoU with each body's part codes z_k as the
encoder gives them, against codes fitted to that body (the decoders fixed).

    python docs/scripts/code_oracle.py --checkpoint runs/volsmpl_b8q_gpu/ckpt-00051000/model \
        [--bodies 0,8,16,24,32,40,48,56] [--steps 150] [--lr 3e-3] [--draws 4] [--fit exact|surface|parts]
        [--train-step S] [--out code_oracle.json]

For each chosen validation body (standard split, `volsmpl eval`'s bodies) the codes z (K, latent) start from the
encoder's (one fixed sample set) and are fitted by Adam to minimise the training loss (`train.sdf_loss` with the
run's weights) on 60k *other* points of the same kind as the evaluation's (another seed of
`validation.query_points`: uniform in the padded body box and near the surface at 1 cm), exact ground truth.
The NBW decoder weights are generated from z at every step (`decoder.generate`); nothing else changes. The IoU is
then scored on the evaluation's own points (same seed, same ground truth as `volsmpl eval`):

- encoder: the codes `volsmpl eval` uses (D = 1);
- draws: the mean of D sample sets' codes (`--encoder-draws D`);
- fitted: the codes after fitting on the held-out points.

`--fit surface` fits the codes without any ground truth beyond the posed mesh itself: points on the surface offset
along the face normal by t ~ N(0, (3 mm)^2), target SDF t (first order; wrong only where another surface is within
a few mm). `--train-step S` takes the bodies of training step S's batch (`train_batches.make_batch`, the run's
config; a step the run has not reached is a fresh draw of the training distribution) instead of validation bodies,
scored on `validation.query_points` of those bodies. `--fit parts` fits each part's own decoder on its own faces'
points (the form `volsmpl.volume.code_refinement` uses, which other parts overlapping it cannot mislead).

If the fitted codes score far above the encoder's, the decoders can represent the body and the encoder's codes
are what limits the accuracy; if they score near it, the decoders (their width, the NBW rank) are the limit.
"""
import argparse
import dataclasses
import json
import time

import torch

from volsmpl.volume.attach import attach_volume
from volsmpl.body.model import create_body
from volsmpl.evaluation import EvalConfig, evaluation_points
from volsmpl.evaluation.gt_cache import ground_truth
from volsmpl.evaluation.metrics import compute_metrics
from volsmpl.nn.volsmpl_net import PartCode
from volsmpl.train.loop import sdf_loss
from volsmpl.train.config import TrainConfig, read_config_file
from volsmpl.evaluation.validation_set import pose_bodies, query_points, validation_bodies

#: seed of the fitting points (the evaluation's are VAL_SEED's)
FIT_SEED = 424242


def with_code(vol, enc, z):
    """The encoding enc with codes z (1, K, latent) and the decoder weights generated from them."""
    return dataclasses.replace(enc, code=PartCode(z, vol.net.decoder.generate(z)), key=None, grouped=None)


def normal_offsets(vertices, faces, n, sigma, generator):
    """n area-weighted surface samples of one mesh (V, 3), offset along their face normals by t ~ N(0, sigma^2):
    points (n, 3), targets t (n,)."""
    tri = vertices[faces]                                    # (F, 3, 3)
    cross = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=-1)
    area = cross.norm(dim=-1)
    fid = torch.multinomial(area, n, replacement=True, generator=generator)
    u, v = torch.rand(n, generator=generator), torch.rand(n, generator=generator)
    flip = u + v > 1
    u, v = torch.where(flip, 1 - u, u), torch.where(flip, 1 - v, v)
    t0 = tri[fid]
    p = t0[:, 0] + u[:, None] * (t0[:, 1] - t0[:, 0]) + v[:, None] * (t0[:, 2] - t0[:, 0])
    normal = cross[fid] / area[fid, None]
    t = torch.randn(n, generator=generator) * sigma
    return p + t[:, None] * normal, t


def part_offsets(vol, enc, vertices, faces, n, sigma, generator):
    """Per part k, n points on its own (tight) faces offset along the normal by t ~ N(0, sigma^2), as decoder inputs
    of part k: xin (K n, 3) in its normalised frame, part ids (K n,), scales (K n,), targets t (K n,)."""
    xs, ks, ts = [], [], []
    for k, fids in enumerate(vol.partition.tight_face_ids):
        x, t = normal_offsets(vertices, faces[torch.as_tensor(fids)], n, sigma, generator)
        xs.append(x)
        ts.append(t)
        ks.append(torch.full((n,), k))
    x = torch.stack(xs)[None]                                            # (1, K, n, 3)
    local = vol.partition.to_part_frames(x, enc.G)
    scale = enc.scale[:, :, None]                                        # (1, K, 1, 1)
    xin = ((local - enc.center[:, :, None]) / scale)[0].reshape(-1, 3)
    sc = scale.expand(1, len(xs), n, 1)[0].reshape(-1)
    return xin, torch.cat(ks), sc, torch.cat(ts)


def score(vol, enc, z, points, gt, is_surface):
    with torch.no_grad():
        pred = vol.query_encoded(with_code(vol, enc, z), points).double()
    return {k: float(v.mean()) for k, v in compute_metrics(pred, gt, is_surface).items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--config", default="checkpoints/volsmpl_b8r.json", help="training config (loss weights)")
    ap.add_argument("--bodies", default="0,8,16,24,32,40,48,56")
    ap.add_argument("--steps", type=int, default=150)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--draws", type=int, default=4)
    ap.add_argument("--fit", choices=("exact", "surface", "parts"), default="exact")
    ap.add_argument("--fit-points", type=int, default=30000, help="points of --fit surface / parts")
    ap.add_argument("--fit-sigma", type=float, default=0.003, help="offsets of --fit surface / parts, metres")
    ap.add_argument("--train-step", type=int, default=None)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    tcfg = TrainConfig.from_dict(read_config_file(args.config))
    body = create_body()
    vol = attach_volume(body, checkpoint=args.checkpoint).eval()
    for p in vol.parameters():
        p.requires_grad_(False)
    cfg = EvalConfig()
    ids = [int(s) for s in args.bodies.split(",")]
    if args.train_step is None:   # the evaluation's points and (cached) ground truth of all bodies, then the chosen
        allb = validation_bodies(cfg.n_bodies, cfg.seed)
        verts = pose_bodies(body, allb)
        points, is_surface = evaluation_points(body, allb, verts, cfg)
        gt = ground_truth(verts, body.faces, points, cfg.gt_sign, cfg.gt_nsamples)
        verts, points, gt = verts[ids], points[ids], gt[ids]
        bodies = {k: v[ids] for k, v in allb.items()}
    else:
        from volsmpl.train.batches import make_batch
        allb = {k: v.float() for k, v in make_batch(tcfg, body, vol.partition, args.train_step)["params"].items()}
        allb["betas"] = allb["betas"][:, :body.num_betas]
        bodies = {k: v[ids] for k, v in allb.items()}
        verts = pose_bodies(body, bodies)
        points, is_surface = query_points(verts, body.faces, cfg.n_points, cfg.seed)
        gt = ground_truth(verts, body.faces, points, cfg.gt_sign, cfg.gt_nsamples)
    fit_points, _ = query_points(verts, body.faces, cfg.n_points, FIT_SEED)
    fit_gt = (ground_truth(verts, body.faces, fit_points, cfg.gt_sign, cfg.gt_nsamples) if args.fit == "exact"
              else None)
    rows = []
    for j, i in enumerate(ids):
        t0 = time.time()
        out = body(**{k: v[j:j + 1] for k, v in bodies.items()})
        pts, g = points[j:j + 1], gt[j:j + 1]
        with torch.no_grad():
            enc = vol.encode(out, fresh=True)
            z0 = enc.code.z.detach().clone()
            draws_before = vol.partition.draws
            vol.set_encoder_draws(args.draws)
            zd = vol.encode(out, fresh=True).code.z.detach().clone()
            vol.set_encoder_draws(draws_before)
        row = {"body": i, "encoder": score(vol, enc, z0, pts, g, is_surface),
               "draws": score(vol, enc, zd, pts, g, is_surface)}
        z = z0.clone().requires_grad_(True)
        opt = torch.optim.Adam([z], lr=args.lr)
        if args.fit == "exact":
            fp, fg = fit_points[j:j + 1], fit_gt[j:j + 1]
        else:
            gen = torch.Generator().manual_seed(FIT_SEED + i)
            fp, fg = normal_offsets(out.vertices[0].detach().float(), body.faces_tensor, args.fit_points,
                                    args.fit_sigma, gen)
            fp, fg = fp[None], fg[None]
        if args.fit == "parts":
            gen = torch.Generator().manual_seed(FIT_SEED + i)
            xin, kk, sc, fg = part_offsets(vol, enc, out.vertices[0].detach().float(), body.faces_tensor,
                                           args.fit_points // vol.num_parts, args.fit_sigma, gen)
        losses = []
        for step in range(args.steps):
            opt.zero_grad(set_to_none=True)
            if args.fit == "parts":
                pred = vol.net.decode_pairs(xin, torch.zeros_like(kk), kk, with_code(vol, enc, z).code) * sc
                loss, _ = sdf_loss(pred[None], fg[None], tcfg)
            else:
                loss, _ = sdf_loss(vol.query_encoded(with_code(vol, enc, z), fp), fg, tcfg)
            loss.backward()
            opt.step()
            losses.append(float(loss.detach()))
        row["fitted"] = score(vol, enc, z.detach(), pts, g, is_surface)
        row["fit_loss"] = [losses[0], losses[-1]]
        row["code_change"] = float((z.detach() - z0).norm() / z0.norm())
        row["draws_change"] = float((zd - z0).norm() / z0.norm())
        row["seconds"] = time.time() - t0
        rows.append(row)
        pct = {c: {k: 100 * v for k, v in row[c].items()} for c in ("encoder", "draws", "fitted")}
        print(f"body {i}: IoU mean encoder {pct['encoder']['iou_mean']:.2f}  draws {pct['draws']['iou_mean']:.2f}  "
              f"fitted {pct['fitted']['iou_mean']:.2f}  (surf. {pct['encoder']['iou_surf']:.2f} / "
              f"{pct['draws']['iou_surf']:.2f} / {pct['fitted']['iou_surf']:.2f}); loss {losses[0]:.4f} -> "
              f"{losses[-1]:.4f}; |dz|/|z| {row['code_change']:.3f} (draws {row['draws_change']:.3f}); "
              f"{row['seconds']:.0f} s", flush=True)
    mean = {c: {k: sum(r[c][k] for r in rows) / len(rows) for k in ("iou_mean", "iou_surf", "iou_unif")}
            for c in ("encoder", "draws", "fitted")}
    print("mean over bodies:", json.dumps(mean, indent=1))
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"checkpoint": args.checkpoint, "args": vars(args), "rows": rows, "mean": mean}, f, indent=1)


if __name__ == "__main__":
    main()
