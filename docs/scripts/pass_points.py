"""Probe: the learned passes (and code refinement) reading only K of each part's tight-face samples, then a volsmpl
command (or a Python script: its path and arguments) run in the same process.

    python docs/scripts/pass_points.py 64 eval --checkpoint checkpoints/volsmpl_r3/ckpt-00057000/model \\
        --n-bodies 16 --split standard --threads 1 --out /tmp/k64.json
    python docs/scripts/pass_points.py 64 selfpen --model volsmpl \\
        --checkpoint-volsmpl checkpoints/volsmpl_r3/ckpt-00057000/model --threads 1 --render 0 --out /tmp/sp64
    python docs/scripts/pass_points.py 64 docs/scripts/warm_refinement.py --checkpoint \\
        checkpoints/volsmpl_b8q/ckpt-00050000/model --bodies 16

`volsmpl.volume.code_refinement.refinement_points` gives each part 2n points (n tight-face samples at +t and -t;
n = 256 for the shipped configs). This probe keeps K of the n samples (a fixed random choice, seed 7), each still
at +t and -t, by replacing the function the volume calls; K >= n keeps all. docs/learned_refinement.md, "Cost",
gives what it measured.
"""
from __future__ import annotations

import runpy
import sys

import torch


def main(argv: list[str]) -> int:
    if len(argv) < 2 or not argv[0].isdigit() or int(argv[0]) < 1:
        print("usage: pass_points.py K VOLSMPL-ARGS... (K >= 1 tight samples per part)", file=sys.stderr)
        return 2
    keep = int(argv[0])
    import volsmpl.volume.learned as learned
    from volsmpl.cli import main as volsmpl_main
    from volsmpl.volume.code_refinement import refinement_points

    def fewer(*args, **kwargs):
        x, t, scale = refinement_points(*args, **kwargs)
        n = x.shape[2] // 2
        if keep >= n:
            return x, t, scale
        chosen = torch.randperm(n, generator=torch.Generator().manual_seed(7))[:keep].sort().values.to(x.device)
        idx = torch.cat([chosen, chosen + n])   # each kept sample at +t and at -t
        return x[:, :, idx], t[:, :, idx], scale

    learned.refinement_points = fewer
    if argv[1].endswith(".py"):
        sys.argv = argv[1:]
        runpy.run_path(argv[1], run_name="__main__")
        return 0
    return volsmpl_main(argv[1:])


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
