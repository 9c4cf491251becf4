"""Would a CUDA graph take the encoder's launch cost away? A measurement of the encoder's launch cost, not a feature.

    python docs/scripts/cuda_graphs_probe.py [--batch 1 8] [--repeats 20]

The encode of a body output has fixed shapes for a given batch (part frames, boxes, the fixed surface samples,
the PointNet, the decoder-weight generator; no host read), so it can be captured once in a CUDA graph and
replayed: the new output's tensors are copied into the graph's static inputs and one replay launches every kernel.
For each batch size: the median wall time of the eager no-grad encode (`Volume._encode`, as `encode(fresh=True)`
runs it) and of copy + replay, and the largest difference of their codes, boxes and frames (same kernels: expected
0). On a CPU only the eager time is printed (CUDA graphs need a GPU). Prints one line per batch size.
"""
import argparse
from types import SimpleNamespace

import torch

import volsmpl
from cuda_profile import timed          # docs/scripts/cuda_profile.py: median ms after 3 warm-up calls
from volsmpl.bench.jobs import make_frames
from volsmpl.volume.encoding import Encoding


def tensors_of(x) -> list:
    """The tensors an encoding holds (frames, boxes, code and generated weights), flattened in a fixed order."""
    if torch.is_tensor(x):
        return [x]
    if isinstance(x, (list, tuple)):
        return [t for item in x for t in tensors_of(item)]
    if isinstance(x, Encoding):
        return tensors_of([x.G, x.box_min, x.box_max, x.code])
    return []


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 8])
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args()
    device = torch.device(args.device)
    body = volsmpl.create_body().to(device)
    vol = volsmpl.attach_volume(body).to(device).eval()
    for B in args.batch:
        data = make_frames(body, B, 1000, 2, seed=0)
        with torch.no_grad():
            outs = [body(body_pose=data["body_pose"][f].to(device)) for f in range(2)]
            t_eager = timed(lambda: vol._encode(outs[1], None), device, args.repeats)
            if device.type != "cuda":
                print(f"B={B}: eager encode {t_eager:.2f} ms (CUDA graphs need a GPU)")
                continue
            static = SimpleNamespace(**{k: getattr(outs[0], k).clone() for k in ("vertices", "joints", "full_pose")})
            side = torch.cuda.Stream(device)
            side.wait_stream(torch.cuda.current_stream(device))
            with torch.cuda.stream(side):
                for _ in range(3):                      # warm-up on a side stream, as torch.cuda.graph requires
                    vol._encode(static, None)
            torch.cuda.current_stream(device).wait_stream(side)
            graph = torch.cuda.CUDAGraph()
            try:
                with torch.cuda.graph(graph):
                    enc_static = vol._encode(static, None)
            except RuntimeError as e:  # an operation that cannot be captured (a host copy or read inside)
                print(f"B={B}: eager encode {t_eager:.2f} ms; capture failed: {str(e).splitlines()[0]}")
                continue

            def replay(out=outs[1]):
                for k in ("vertices", "joints", "full_pose"):
                    getattr(static, k).copy_(getattr(out, k))
                graph.replay()
                return enc_static

            t_graph = timed(replay, device, args.repeats)
            ref = vol._encode(outs[1], None)
            replay()
            diff = max(float((a - b).abs().max()) for a, b in zip(tensors_of(enc_static), tensors_of(ref)))
            print(f"B={B}: eager encode {t_eager:.2f} ms, CUDA graph copy + replay {t_graph:.2f} ms "
                  f"({t_eager / t_graph:.1f}x), largest difference {diff:.2e}")


if __name__ == "__main__":
    main()
