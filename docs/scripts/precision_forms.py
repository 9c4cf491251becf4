"""Time and accuracy of the reduced-precision forms of a VolumetricSMPL query on this machine, alternating in one process.

    python docs/scripts/precision_forms.py [--threads 1] [--points 60000] [--rounds 5] [--eval-bodies 0]
                                           [--eval-forms full 'dec bf16' 'enc bf16' both]

Forms: 'full' (float32, the default), 'dec bf16' (`Volume.set_precision("bf16")`: the decoders' layers in bfloat16
on the grouped engine), 'enc bf16' (the PointNet encoder under bfloat16 autocast, `net.encoder_bf16`, as training
runs it) and 'both'. On the bench's inputs (`bench_jobs.make_frames`, the shipped checkpoint), B = 1 (body 0) and
B = 8; each round times every form once per batch size, `t` (a fresh encoding and the query) and `t query` (the
query on a cached encoding), in an order that alternates between rounds so that the machine's drift falls on all
forms alike. Prints medians per body, the largest value difference from 'full' and the signs that differ from it
(B = 8's points); with --eval-bodies N also `volsmpl eval`'s IoUs on the first N validation bodies per form (exact
ground truth; N = 64 is the whole standard split). Whether bfloat16 is native here (AVX512-BF16 / AMX) or emulated
decides the timings: the script prints the CPU's flags for it.
"""
import argparse
import statistics
import time

import torch

from volsmpl.volume.attach import attach_volume
from volsmpl.bench.jobs import make_frames
from volsmpl.body.model import create_body
from volsmpl.evaluation import EvalConfig, evaluate_volume
from volsmpl.evaluation.validation_set import validation_bodies

FORMS = {"full": ("full", False), "dec bf16": ("bf16", False), "enc bf16": ("full", True), "both": ("bf16", True)}


def set_form(vol, form: str) -> None:
    precision, enc_bf16 = FORMS[form]
    vol.set_precision(precision)
    vol.net.encoder_bf16 = enc_bf16


def bf16_flags() -> str:
    try:
        flags = set(open("/proc/cpuinfo").read().split())
    except OSError:
        return "unknown"
    return ", ".join(f for f in ("avx512_bf16", "amx_bf16") if f in flags) or "none (bfloat16 emulated)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--points", type=int, default=60000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--eval-bodies", type=int, default=0, help="validation bodies for IoU per form (0: none)")
    ap.add_argument("--eval-forms", nargs="+", default=list(FORMS), choices=list(FORMS), help="forms to evaluate")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    print(f"bfloat16 instructions: {bf16_flags()}; torch {torch.__version__}, {a.threads} thread(s)")
    body = create_body()
    vols = {}
    for f in FORMS:   # one volume per form: each caches only encodings made its own way
        vols[f] = attach_volume(body, model="volsmpl")
        set_form(vols[f], f)
    data = make_frames(body, 8, a.points, 1, 0)
    with torch.no_grad():
        pts = {8: data["points"][0], 1: data["points"][0][:1]}
        posed = {B: body(body_pose=data["body_pose"][0][:B]) for B in (1, 8)}
        t = {(f, B, k): [] for f in FORMS for B in (1, 8) for k in ("t", "t query")}
        values = {}
        for r in range(a.rounds):
            for f in (list(FORMS) if r % 2 == 0 else list(FORMS)[::-1]):
                vol = vols[f]
                for B in (1, 8):
                    vol.query_encoded(vol.encode(posed[B], fresh=True), pts[B])     # warm this form and size
                    s = time.perf_counter()
                    enc = vol.encode(posed[B], fresh=True)
                    v = vol.query_encoded(enc, pts[B])
                    t[f, B, "t"].append((time.perf_counter() - s) * 1e3 / B)
                    s = time.perf_counter()
                    vol.query_encoded(enc, pts[B])
                    t[f, B, "t query"].append((time.perf_counter() - s) * 1e3 / B)
                    if B == 8:
                        values[f] = v
        ref = values["full"]
        for f in FORMS:
            d = (values[f] - ref).abs()
            flips = int(((values[f] > 0) != (ref > 0)).sum())
            row = "  ".join(f"B={B} {k} {statistics.median(t[f, B, k]):6.1f} ms" for B in (1, 8) for k in ("t", "t query"))
            print(f"{f:>9}  per body: {row}  |  max |value - full| {float(d.max()):.1e} m, signs differing {flips} of "
                  f"{ref.numel()}")
    if a.eval_bodies > 0:
        bodies = validation_bodies(a.eval_bodies)
        for f in a.eval_forms:
            m = evaluate_volume(vols[f], body, EvalConfig(), bodies=bodies, precision=FORMS[f][0]).metrics
            print(f"{f:>9}  IoU mean / surf. / unif. {100 * m['iou_mean']:.3f} / {100 * m['iou_surf']:.3f} / "
                  f"{100 * m['iou_unif']:.3f} % on {a.eval_bodies} validation bodies")


if __name__ == "__main__":
    main()
