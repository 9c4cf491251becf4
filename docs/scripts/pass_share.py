"""Probe: how often an app's run with `--pass-every N` ran the learned passes, a volsmpl command run in this process.

    python docs/scripts/pass_share.py selfpen --model volsmpl \\
        --checkpoint-volsmpl checkpoints/volsmpl_r3/ckpt-00057000/model --pass-every 4 --threads 1 --render 0 \\
        --out /tmp/sp_every4

Inside an optimisation's `warm_start()` a volume set to `set_pass_interval(N)` runs the passes for a body at every
N-th encoding, and also where one of its part codes moved by more than 5 % since its last pass
(volsmpl.volume.carried_passes). This probe counts, over all the run's scopes, the (body, part) codes encoded, those
made by running the passes, and the bodies passed anew because a code jumped, and prints them as one JSON line
after the command's own output (`"share"`: passed / encoded; 1 / N where no code jumps).
"""
from __future__ import annotations

import json
import sys


def main(argv: list[str]) -> int:
    if not argv:
        print("usage: pass_share.py VOLSMPL-ARGS... (a volsmpl command with --pass-every N)", file=sys.stderr)
        return 2
    import volsmpl.volume.carried_passes as carried_passes
    from volsmpl.cli import main as volsmpl_main

    totals = {"encoded": 0, "passed": 0, "restarted": 0}
    apply = carried_passes.CarriedPasses.apply

    def counted(self, *args, **kwargs):
        before = {k: getattr(self, k) for k in totals}
        z = apply(self, *args, **kwargs)
        for k in totals:
            totals[k] += getattr(self, k) - before[k]
        return z

    carried_passes.CarriedPasses.apply = counted
    rc = volsmpl_main(argv)
    share = totals["passed"] / totals["encoded"] if totals["encoded"] else None
    print(json.dumps({"pass_share": {**totals, "share": None if share is None else round(share, 4)}}), flush=True)
    return rc


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
