"""Each app's time per iteration with each candidate VolumetricSMPL setting, beside a base setting's (by default
the model shipped before the current one, `s33000`).

    python tools/app_cost.py --rounds 3 --threads 1 --out docs/app_cost.json
    python tools/app_cost.py --apps hoi,selfpen --settings s33000,shipped --rounds 1 --out /tmp/cost.json
    python tools/app_cost.py --settings shipped,r3 --base shipped --out /tmp/cost.json    # ratios to the shipped model's

The cost that matters for a model or a refinement setting is an app's whole iteration, not the volume's share of it
(docs/learned_refinement.md, "Cost"): hoi encodes the body once per fit, selfpen and motion re-encode at every step,
egohmr at every guided denoising step. Each run is the app's own command (`python -m volsmpl.cli ...`) on a small
fixed workload, VolumetricSMPL only, with the app's own timer:
- hoi: 10 test cases fitted together (`--batch 10`), `--iters 100`: `ms_per_iter` (per case);
- selfpen: the 17 cases of Table 6: `step_ms` (the mean over their steps);
- motion: 1 room, 1 walk of 80 frames, `--iters 20`: `ms_per_frame_fwdbwd`, the collision term's forward and
  backward per frame on 8 fixed frames of a probe walk (Table 5's figure); the whole optimisation step's
  `ms_per_iter` is kept beside it, but it depends on where each model's walk went (how many frames pass near
  obstacles), not only on the model. The 8 frames are timed outside the fit, so a setting that carries code
  corrections across the fit's iterations (`--pass-every`, `--refine-warm`) shows what it saves only in `ms_per_iter`;
- egohmr: 4 test frames with the tuned guidance: `s_per_frame`.
Round after round, every setting runs each app in turn, so that a change of machine load falls on all settings
alike; per (app, setting) the median over rounds, and its ratio to the base setting's (`--base`, one of the settings
run; default 's33000').
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: setting name -> the flags it adds to every app's command; 'shipped' (no flags) runs the shipped model (volsmpl_r3's
#: model) with each app's own --passes and --pass-every defaults, the other settings with learned passes pin them
R1, R3 = "checkpoints/volsmpl_r1/ckpt-00053000/model", "checkpoints/volsmpl_r3/ckpt-00057000/model"
SETTINGS = {
    "s33000": ["--checkpoint-volsmpl", "checkpoints/volsmpl_s33000/model"],
    "shipped": [],
    "step50k": ["--checkpoint-volsmpl", "checkpoints/volsmpl_b8q/ckpt-00050000/model"],
    "r1": ["--checkpoint-volsmpl", R1, "--passes", "1", "--pass-every", "1"],
    "r3": ["--checkpoint-volsmpl", R3, "--passes", "2", "--pass-every", "1"],
    "step50k_warm1": ["--checkpoint-volsmpl", "checkpoints/volsmpl_b8q/ckpt-00050000/model",
                      "--refine-steps", "1", "--refine-warm"],
    "r3_every4": ["--checkpoint-volsmpl", R3, "--passes", "2", "--pass-every", "4"],
    "r3_passes1": ["--checkpoint-volsmpl", R3, "--passes", "1", "--pass-every", "1"],
}

HOI_CASES = ("lean_table_0050,push_cart_0051,sit_chair_0052,sit_stool_0053,sit_sofa_0054,lie_bed_0055,hold_box_0056,"
             "carry_ball_0057,hold_bat_0058,hold_bottle_0059")

#: app -> (its command after `volsmpl`, what to read from results.json's summary (the first is tabulated), its unit)
APPS = {
    "hoi": (["hoi", "run", "--cases", HOI_CASES, "--batch", "10", "--iters", "100"], ("ms_per_iter",), "ms per step"),
    "selfpen": (["selfpen"], ("step_ms",), "ms per step"),
    "motion": (["motion", "--w", "volsmpl=1", "--scenes", "1", "--seed", "1", "--sequences", "1", "--frames", "80",
                "--iters", "20", "--lr", "0.05", "--coll-frames", "all", "--mem-budget-gb", "24", "--batch", "1"],
               ("ms_per_frame_fwdbwd", "ms_per_iter"), "ms per frame"),
    "egohmr": (["egohmr", "sample", "--split", "test", "--frames", "4", "--no-max-batch", "--tuned",
                "docs/egohmr/tune.json"], ("s_per_frame",), "s per frame"),
}


def read_times(app: str, results: dict) -> dict:
    """The app's times of VolumetricSMPL from its results.json: read key -> value."""
    return {k: float(results["summary"]["volsmpl"][k]) for k in APPS[app][1]}


def checkpoint_of(setting: str) -> str:
    """The VolumetricSMPL checkpoint a setting runs (the shipped one where it names none)."""
    flags = SETTINGS[setting]
    if "--checkpoint-volsmpl" not in flags:
        return "core/assets/volsmpl_anny"
    return flags[flags.index("--checkpoint-volsmpl") + 1]


def run_one(app: str, setting: str, threads: int, workdir: Path) -> tuple[dict, float]:
    """Run one app with one setting; returns (its times, read_times; wall seconds of the command)."""
    out = workdir / f"{app}_{setting}"
    cmd = [sys.executable, "-m", "volsmpl.cli", *APPS[app][0], "--model", "volsmpl", *SETTINGS[setting],
           "--threads", str(threads), "--render", "0", "--quiet", "--out", str(out)]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["(no output)"]
        raise SystemExit(f"app_cost: {app} with {setting} failed (exit {done.returncode}): {tail[0]}")
    return read_times(app, json.loads((out / "results.json").read_text())), wall


def main() -> int:
    from volsmpl.io.outputs import write_atomic
    from volsmpl.io.provenance import machine_info

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--apps", default=",".join(APPS))
    p.add_argument("--settings", default=",".join(SETTINGS))
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--base", default="s33000", help="the setting whose times the ratios divide by (one of --settings)")
    p.add_argument("--out", default="docs/app_cost.json")
    args = p.parse_args()
    apps, settings = args.apps.split(","), args.settings.split(",")
    for name, given, known in (("app", apps, APPS), ("setting", settings, SETTINGS)):
        bad = [x for x in given if x not in known]
        if bad:
            raise SystemExit(f"app_cost: unknown {name} {bad[0]!r}; choose from {', '.join(known)}")
    if args.base not in settings:
        raise SystemExit(f"app_cost: --base {args.base!r} is not among --settings ({args.settings}); add it there "
                         f"or choose one of them")
    for flag, value in (("--rounds", args.rounds), ("--threads", args.threads)):
        if value < 1:
            raise SystemExit(f"app_cost: {flag} {value}: give a number >= 1")
    rounds = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            row = {a: {} for a in apps}
            for a in apps:
                for s in settings:
                    times, wall = run_one(a, s, args.threads, Path(tmp))
                    row[a][s] = {k: round(v, 4) for k, v in times.items()}
                    t = times[APPS[a][1][0]]
                    print(f"round {r} {a:8s} {s:14s} {t:9.3f} {APPS[a][2]} ({wall:.0f} s)", flush=True)
            rounds.append(row)
    median = {a: {s: float(np.median([row[a][s][APPS[a][1][0]] for row in rounds])) for s in settings} for a in apps}
    ratio = {a: {s: median[a][s] / median[a][args.base] for s in settings} for a in apps}
    result = {"command": "python tools/app_cost.py " + " ".join(
                  f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items()),
              "settings": {s: SETTINGS[s] for s in settings},
              "checkpoints": {s: checkpoint_of(s) for s in settings},
              "workloads": {a: {"command": APPS[a][0], "reads": APPS[a][1], "unit": APPS[a][2]} for a in apps},
              "median": median, "base": args.base, "ratio_to_base": ratio, "rounds": rounds,
              "meta": machine_info("cpu", args.threads)}
    write_atomic(Path(args.out), json.dumps(result, indent=1))
    for a in apps:
        print(f"{a:8s} " + "  ".join(f"{s} {median[a][s]:.3f} ({ratio[a][s]:.2f}x)" for s in settings))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
