"""Probe: code refinement warm-started along an optimisation's trajectory, scored at its end.

    python docs/scripts/warm_refinement.py --checkpoint CK [--bodies 16] [--iters 100] [--steps 1] [--lr 1e-2]
        [--jitter 0.3] [--schedule constant|cosine] [--carry delta|code] [--threads 1] [--out F.json]
    python docs/scripts/warm_refinement.py --checkpoint CK --pass-every 1 2 4 [--path cubic|linear] ...

An app re-encodes its bodies at every optimisation step. Warm-started refinement keeps each (body, part)'s code
correction delta from the previous step and adds it to the new encoding, then takes `steps` Adam steps on the
part's refinement loss (volsmpl.volume.code_refinement: the same points, loss and optimiser as
`--refine-steps`), Adam's moments carried too. So after T steps a body that moved little has had T * steps steps
of refinement at the cost of `steps` per step.

The trajectory imitates an optimisation that converges: for each of the first `bodies` validation bodies, the body
pose starts at the validation pose plus N(0, jitter^2) per axis-angle coordinate (seeded) and moves to the
validation pose along 1 - (1 - u)^3, u = i / iters; shape, orientation and translation fixed. At the end the body is
the validation body, so `volsmpl eval`'s points and exact ground truth score the final codes (mean / surface /
uniform IoU). Rows: the encoder's codes at the end (what the apps use), and the warm-started codes, with how far the
encoder's codes move from one step to the next, against how far each is from the nearest other body's (a warm
state must not hand one body's correction to another).

`--carry code` keeps the refined code itself instead of the correction (z_t = z_{t-1}, the encoder read once).
With the defaults (`--schedule constant --carry delta`) the warm codes are the volume's own
(`Volume.set_code_refinement(steps, warm=True)` inside `warm_start()`, volsmpl.volume.warm_codes), which drops a
(body, part)'s correction where its encoder code moved by more than `--max-change` of its norm in one step.

`--pass-every N` (a checkpoint with learned passes, `refiner_iters` >= 1): the volume's own carried passes
(`Volume.set_pass_interval(N)` inside `warm_start()`, volsmpl.volume.carried_passes): the learned passes run at
encodings 0, N, 2N, ... and where an encoder code jumped by more than 5 % of its norm, and the correction they made is
added to the encoder's codes of the encodings between (`--max-change` sets the 5 %). With `--iters` = kN - 1 the scored last encoding is N - 1
encodings after the last scheduled pass: the stalest correction of the schedule.
"""
import argparse
import dataclasses
import json
import math
import time

import torch
from volsmpl.body.model import create_body
from volsmpl.evaluation.config import EvalConfig
from volsmpl.evaluation.run import evaluate
from volsmpl.evaluation.validation_set import validation_bodies
from volsmpl.nn.code_refiner import decode_targets, refinement_losses
from volsmpl.volume.attach import attach_volume
from volsmpl.volume.code_refinement import refinement_points
from volsmpl.volume.warm_codes import WARM_MAX_CHANGE, WARM_WARMUP


def encoder_codes(vol, out):
    """A fresh encoding of `out` (the encoder and any learned passes, no fitting), and its refinement points."""
    steps, warm = vol.refine_steps, vol.refine_warm
    vol.set_code_refinement(0)
    enc = vol.encode(out, fresh=True)
    vol.set_code_refinement(steps, warm=warm)
    xin, target, sc = refinement_points(vol.partition, out.vertices, enc.G, enc.center, enc.scale, None)
    return enc, enc.code.z, xin, target, sc


class WarmCodes:
    """Per-(body, part) code corrections and Adam moments carried across the steps of one trajectory."""

    def __init__(self, steps, lr, schedule, iters, carry):
        self.steps, self.lr, self.schedule, self.iters, self.carry = steps, lr, schedule, iters, carry
        self.delta = self.prev = self.m1 = self.m2 = None
        self.t = 0

    def __call__(self, net, z, xin, target, sc, i):
        if self.carry == "code" and self.prev is not None:
            var = self.prev.clone()
        else:
            var = z.detach() + (0 if self.delta is None else self.delta)
        var.requires_grad_(True)
        if self.m1 is None:
            self.m1, self.m2 = torch.zeros_like(var), torch.zeros_like(var)
        lr = self.lr if self.schedule == "constant" else self.lr * 0.5 * (1 + math.cos(math.pi * i / self.iters))
        for _ in range(self.steps):
            self.t += 1
            pred = decode_targets(net, var, xin, sc, None)
            (g,) = torch.autograd.grad(refinement_losses(net.output, pred, target).sum(), var)
            self.m1.mul_(0.9).add_(g, alpha=0.1)
            self.m2.mul_(0.999).addcmul_(g, g, value=0.001)
            denom = (self.m2 / (1 - 0.999 ** self.t)).sqrt_().add_(1e-8)
            with torch.no_grad():
                var.addcdiv_(self.m1, denom, value=-lr / (1 - 0.9 ** self.t))
        var = var.detach()
        self.delta, self.prev = var - z.detach(), var
        return var


def iou_row(res) -> list:
    """mean / surface / uniform IoU (%) of an EvalResult."""
    return [round(100 * res.metrics[k], 2) for k in ("iou_mean", "iou_surf", "iou_unif")]


def quantiles(x: torch.Tensor) -> dict:
    """min / median / 99th percentile / max of a 1-D tensor, rounded."""
    q = torch.quantile(x.double(), torch.tensor([0.0, 0.5, 0.99, 1.0], dtype=torch.float64))
    return dict(zip(("min", "median", "p99", "max"), (round(float(v), 4) for v in q)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--bodies", type=int, default=16)
    ap.add_argument("--iters", type=int, default=100)
    ap.add_argument("--steps", type=int, nargs="+", default=None,
                    help="warm Adam steps per encoding, one row each (default 1; none with --pass-every)")
    ap.add_argument("--lr", type=float, default=1e-2)
    ap.add_argument("--jitter", type=float, default=0.3)
    ap.add_argument("--schedule", default="constant", choices=["constant", "cosine"])
    ap.add_argument("--carry", default="delta", choices=["delta", "code"])
    ap.add_argument("--max-change", type=float, default=WARM_MAX_CHANGE,
                    help="the volume's restart threshold, also of --pass-every (inf: never restart)")
    ap.add_argument("--warmup", type=int, default=WARM_WARMUP, help="the volume's step-size warm-up (0: none)")
    ap.add_argument("--path", default="cubic", choices=["cubic", "linear"])
    ap.add_argument("--pass-every", type=int, nargs="+", default=[],
                    help="rows with the learned passes at every N-th encoding, their correction carried between")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    if a.steps is None:
        a.steps = [] if a.pass_every else [1]
    torch.set_num_threads(a.threads)
    body = create_body()
    vol = attach_volume(body, checkpoint=a.checkpoint)
    net = vol.net
    bodies = validation_bodies(a.bodies)
    cfg = EvalConfig(n_bodies=a.bodies, batch_size=a.bodies)
    g = torch.Generator().manual_seed(7)
    start = bodies["body_pose"] + torch.randn(bodies["body_pose"].shape, generator=g, dtype=torch.float64).to(
        bodies["body_pose"].dtype) * a.jitter
    rows = []

    def path(i):
        return i / a.iters if a.path == "linear" else 1 - (1 - i / a.iters) ** 3

    def encoder_only(out, pts):
        return vol.query(out, pts)

    res = evaluate(encoder_only, bodies=bodies, body=body, config=cfg, name="encoder")
    rows.append({"codes": "encoder", "iou": iou_row(res)})
    print(json.dumps(rows[-1]), flush=True)
    for steps in a.steps:
        warm = WarmCodes(steps, a.lr, a.schedule, a.iters, a.carry)
        t0 = time.perf_counter()

        drift = {"per_step": [], "between": None}

        core = a.schedule == "constant" and a.carry == "delta"

        def warm_encode(out):
            return vol.encode(out, fresh=True).code.z.detach()

        def warm_predict(out_end, pts, warm=warm, drift=drift):
            z = prev = None
            scope = None
            if core:
                vol.set_code_refinement(steps, warm=True)
                scope = vol.warm_start()
                state = scope.__enter__()
                state.lr, state.max_change, state.warmup = a.lr, a.max_change, a.warmup
            for i in range(a.iters + 1):
                u = path(i)
                pose = start + (bodies["body_pose"] - start) * u
                with torch.no_grad():
                    out = body(**{**bodies, "body_pose": pose})
                enc, z0, xin, target, sc = encoder_codes(vol, out)
                if prev is not None:
                    drift["per_step"].append(((z0 - prev).norm(dim=-1) / prev.norm(dim=-1)).flatten())
                prev = z0
                if scope is not None:      # the volume's own warm state
                    z = warm_encode(out)
                    continue
                with torch.enable_grad():
                    z = warm(net, z0, xin, target, sc, i)
            if scope is not None:
                drift["restarted"] = state.restarted / max(state.encoded, 1)
                scope.__exit__(None, None, None)
                vol.set_code_refinement(0)
            other = torch.cdist(prev.transpose(0, 1), prev.transpose(0, 1))           # (K, B, B)
            other = other.masked_fill(torch.eye(len(prev), dtype=torch.bool), float("inf"))   # another body
            drift["between"] = (other.min(dim=-1).values.T / prev.norm(dim=-1)).flatten()   # (B * K,)
            return vol.query_encoded(dataclasses.replace(enc, code=net.code_from_z(z, None)), pts)

        with torch.no_grad():
            res = evaluate(warm_predict, bodies=bodies, body=body, config=cfg, name=f"warm{steps}")
        rows.append({"codes": f"warm, {steps} step(s) per iteration", "steps": steps,
                     "seconds": round(time.perf_counter() - t0, 1), "iou": iou_row(res),
                     # |z_t - z_(t-1)| / |z_(t-1)| of the encoder's codes from one step to the next, over all
                     # (step, body, part); and at the end, each (body, part)'s nearest other body's code likewise
                     "code_change_per_step": quantiles(torch.cat(drift["per_step"])),
                     "code_distance_to_other_bodies": quantiles(drift["between"]),
                     "restarted_share": drift.get("restarted")})
        print(json.dumps(rows[-1]), flush=True)
    if a.pass_every and net.refiner is None:
        raise SystemExit(f"--pass-every needs a checkpoint with learned passes; {a.checkpoint} has none")
    for every in a.pass_every:
        t0 = time.perf_counter()
        counts = {}

        def carried_predict(out_end, pts, every=every, counts=counts):
            vol.set_pass_interval(every)
            try:
                with vol.warm_start() as carried:
                    carried.max_change = a.max_change
                    for i in range(a.iters + 1):
                        pose = start + (bodies["body_pose"] - start) * path(i)
                        with torch.no_grad():
                            enc = vol.encode(body(**{**bodies, "body_pose": pose}), fresh=True)
            finally:
                vol.set_pass_interval(1)
            counts.update(passed=carried.passed // carried.num_parts, restarted=carried.restarted,
                          encoded=carried.encoded // carried.num_parts)
            return vol.query_encoded(enc, pts)

        with torch.no_grad():
            res = evaluate(carried_predict, bodies=bodies, body=body, config=cfg, name=f"every{every}")
        rows.append({"codes": f"learned passes at every {every}. encoding, correction carried", "pass_every": every,
                     "seconds": round(time.perf_counter() - t0, 1), "iou": iou_row(res),
                     "encodings": counts["encoded"], "encodings_with_passes": counts["passed"],
                     "restarts": counts["restarted"]})
        print(json.dumps(rows[-1]), flush=True)
    if a.out:
        with open(a.out, "w") as fh:
            json.dump({"args": vars(a), "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
