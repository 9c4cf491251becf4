"""Where a query's time goes on a GPU: encode and cached query of the lean path, profiled op by op.

    python docs/scripts/cuda_profile.py [--device cuda] [--batch 1 8] [--points 60000] [--out DIR]

For each batch size and each setting (default chunks; one chunk with untiled decoders, as bench model
'volsmpl-onechunk'), on the benchmark's inputs (`bench_jobs.make_frames`, the shipped checkpoint): the wall time of
the encode and of the cached query (median of 10 after 3 warm-ups), then one profiled encode + query with the CPU
and CUDA activities: top operators by self device time and by self CPU time, kernel launches, host-device copies and
synchronisations. Writes the tables to DIR/cuda_profile.txt and the B = 1 default trace to DIR/trace_b1.json.gz.
Values of the two settings are checked equal.
"""
import argparse
import gzip
import os
import shutil
import statistics

import torch

import volsmpl
from volsmpl.bench.jobs import make_frames
from volsmpl.runtime.meter import timed_ms


def timed(fn, device, n=10, warm=3):
    """Median milliseconds of n calls after `warm` untimed ones (volsmpl.runtime.meter.timed_ms: synchronised on the device)."""
    for _ in range(warm):
        fn()
    return statistics.median(timed_ms([fn] * n, device))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 8])
    ap.add_argument("--points", type=int, default=60000)
    ap.add_argument("--out", default="out/cuda_profile")
    args = ap.parse_args()
    from torch.profiler import ProfilerActivity, profile

    device = torch.device(args.device)
    cuda = device.type == "cuda"
    os.makedirs(args.out, exist_ok=True)
    report = open(os.path.join(args.out, "cuda_profile.txt"), "w")

    def say(s=""):
        print(s, flush=True)
        report.write(s + "\n")

    body = volsmpl.create_body().to(device)
    vol = volsmpl.attach_volume(body).to(device)
    default = (vol.chunk_elems, vol.cpu_chunk_elems, vol.gpu_chunk_elems, vol.net.decoder.TILE_ROWS)
    say(f"device {torch.cuda.get_device_name(device) if cuda else 'cpu'}, torch {torch.__version__}, "
        f"chunk_elems {vol.chunk_elems}, gpu_chunk_elems {vol.gpu_chunk_elems}, tile rows {vol.net.decoder.TILE_ROWS}")
    sort_dev = "self_cuda_time_total" if cuda else "self_cpu_time_total"
    for B in args.batch:
        data = make_frames(body, B, args.points, 1, seed=0)
        with torch.no_grad():
            out = body(body_pose=data["body_pose"][0].to(device))
            pts = data["points"][0].to(device)
            ref = None
            for setting in ("default", "onechunk"):
                if setting == "default":
                    vol.chunk_elems, vol.cpu_chunk_elems, vol.gpu_chunk_elems, tiles = default
                else:
                    vol.chunk_elems = vol.cpu_chunk_elems = vol.gpu_chunk_elems = 1 << 62
                    tiles = 1 << 62
                vol.net.set_tile_rows(tiles)
                enc = vol.encode(out, fresh=True)
                t_enc = timed(lambda: vol.encode(out, fresh=True), device)
                t_q = timed(lambda: vol.query_encoded(enc, pts), device)
                v = vol.query_encoded(enc, pts)
                ref = v if ref is None else ref
                same = torch.allclose(v, ref, atol=1e-5)
                say(f"\n=== B={B} {setting}: encode {t_enc:.2f} ms, cached query {t_q:.2f} ms "
                    f"({t_q / B:.2f} ms per body); values equal to default: {same}")
                with profile(activities=[ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])) as prof:
                    e = vol.encode(out, fresh=True)
                    vol.query_encoded(e, pts)
                    torch.cuda.synchronize(device) if cuda else None
                ka = prof.key_averages()
                rt = {k.key: k.count for k in ka if k.key.startswith("cuda") or k.key.startswith("cudaMemcpy")}
                say("runtime calls: " + ", ".join(f"{k} {c}" for k, c in sorted(rt.items(), key=lambda kv: -kv[1])))
                say(ka.table(sort_by=sort_dev, row_limit=25, max_name_column_width=60))
                if cuda:
                    say(ka.table(sort_by="self_cpu_time_total", row_limit=15, max_name_column_width=60))
                if B == args.batch[0] and setting == "default":
                    path = os.path.join(args.out, "trace_b1.json")
                    prof.export_chrome_trace(path)
                    with open(path, "rb") as f, gzip.open(path + ".gz", "wb") as g:
                        shutil.copyfileobj(f, g)
                    os.remove(path)
    report.close()


if __name__ == "__main__":
    main()
