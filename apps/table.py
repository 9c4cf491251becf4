"""What the four apps share: their common options (one spelling, one meaning), the checks of those options before
any work, one volume per model kind, the resumable case records, and the results.json envelope.

Every app's parser calls `add_common`; its `run` calls `check_common` first (models, checkpoints, threads, render,
out; the device is checked once, by `volsmpl.cli`), then `volumes`, loops over its cases with `CaseRecords`, and
writes `envelope(...)` with `write_results`:

    models, ckpts = check_common(args)                          # ValueError (one line) on a bad option
    vols = volumes(body, models, ckpts, args.device)             # {"volsmpl": Volume, "coap": Volume, "mesh": ...}
    store = CaseRecords(args.out, "selfpen", resume=args.resume)
    rec, reused = store.get_or_make(f"{case}_{m}", {"config": cfg, "case": case, "model": m}, vols[m],
                                    lambda: repair(case).to_json())
    write_results(args.out, envelope("selfpen", config, summary, paper, cases, meta))

The options:
  --model KINDS              comma-separated kinds (volsmpl, coap, mesh; and none where an app runs without a volume)
  --checkpoint-volsmpl PATH  trained VolumetricSMPL checkpoint (default: the shipped one); likewise --checkpoint-coap
  --threads N                torch CPU threads (N >= 1; default: torch's)
  --seed S                   the seed of the app's case data (rooms, database, frames)
  --out DIR                  output folder (results.json, figures, cases/)
  --resume                   reuse the finished case records in OUT/cases/ made by the same code, settings, case and
                             weights; compute only the others
  --render N                 figures of the first N cases (0: none)
  --device cpu|cuda          where the work runs
  --save-meshes              write the fitted bodies (and objects) of every case as mesh files under OUT/meshes/
                             (a user's own case writes them always; a table run only with this flag)
  --quiet                    no progress bars (they show only on a terminal anyway: none in a log file)
  --refine-steps R           refine the learned kinds' part codes by R optimiser steps at every encoding (0: none)
  --refine-warm              with R >= 1: carry each body's refinement from one iteration of the fit to the next
  --passes P                 a VolumetricSMPL with learned code-refinement passes runs only its first P of them
                             (0: the encoder's codes; default: all it has)
  --pass-every N             a VolumetricSMPL with learned code-refinement passes runs them at every N-th iteration
                             of a fit and carries their correction between (1: at every encoding)

The envelope: {app, config, summary, paper, cases: {kind: [records]}, figures, meta, flagged, warnings} and, after them, what an app
adds of its own (motion's tuning and paired differences, egohmr's regressor row and batch sizes).
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Callable

__all__ = ["REFINE_OPTIONS", "add_common", "check_common", "check_threads", "check_refinement", "code_refinement",
           "learned_pass_defaults",
           "parse_kinds", "checkpoints", "volumes",
           "checkpoint_names", "CaseRecords", "envelope", "flag_cases", "print_flagged", "case_records",
           "write_results"]

#: the argparse dests of the code-refinement options (every app's modes that encode bodies read all of them)
REFINE_OPTIONS = frozenset({"refine_steps", "refine_warm", "passes", "pass_every"})


def add_common(p, *, out: str | None, model: str = "volsmpl,coap,mesh", none: bool = False, render: int = 3,
               seed: str | None = "the seed of the case data", resume: str | None = None,
               passes: int | None = None, pass_every: int = 1) -> None:
    """Add the shared options to an app's parser (module docstring); `none`: the app accepts the kind 'none';
    seed=None: the app has no seeded case data (no --seed). passes, pass_every: the app's defaults of --passes
    and --pass-every for a VolumetricSMPL with learned passes (`learned_pass_defaults` applies them)."""
    from volsmpl.volume.models import MODELS

    kinds = ("none, " if none else "") + ", ".join(MODELS)
    p.add_argument("--model", default=model, help=f"comma-separated model kinds ({kinds}); default {model}")
    p.add_argument("--checkpoint-volsmpl", default=None, help="trained VolumetricSMPL checkpoint (default: shipped)")
    p.add_argument("--checkpoint-coap", default=None, help="trained COAP checkpoint (default: shipped)")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (>= 1; default: torch's)")
    if seed is not None:
        p.add_argument("--seed", type=int, default=0, help=f"{seed} (default 0)")
    p.add_argument("--out", default=out, help=f"output folder (default {out or 'by action'})")
    p.add_argument("--resume", action="store_true",
                   help=resume or "reuse the finished case records in OUT/cases/ made by the same code, settings, "
                                  "case and weights; compute only the others (a stopped run continues)")
    p.add_argument("--render", type=int, default=render, help=f"figures of the first N cases (0: none; default {render})")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"], help="where the work runs (default cpu)")
    p.add_argument("--save-meshes", action="store_true",
                   help="write every case's fitted bodies (and objects) as .ply files under OUT/meshes/, in the "
                        "input's units and axes (a user's own case writes them always)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bars (shown only on a terminal: never in a log file)")
    p.add_argument("--refine-steps", type=int, default=0,
                   help="refine the learned kinds' part codes by this many optimiser steps on the posed mesh's own "
                        "surface at every encoding (volsmpl.volume.code_refinement; default 0: the encoder's codes)")
    p.add_argument("--refine-warm", action="store_true",
                   help="with --refine-steps R: each encoding continues the same bodies' refinement from the "
                        "previous iteration of the fit (volsmpl.volume.warm_codes), R steps per iteration")
    default_passes = ("all it has" if passes is None else "0" if passes == 0
                      else f"{passes}, or all it has if fewer")
    p.add_argument("--passes", type=int, default=None, metavar="P",
                   help="with a VolumetricSMPL checkpoint that has learned code-refinement passes: run only the first "
                        f"P of them at each encoding (0: the encoder's codes as they are; default: {default_passes})")
    p.add_argument("--pass-every", type=int, default=None, metavar="N",
                   help="with a VolumetricSMPL checkpoint that has learned code-refinement passes: run them at every "
                        "N-th iteration of a fit and add their correction to the encoder's codes of the iterations "
                        "between (volsmpl.volume.carried_passes; "
                        + ("default 1: at every encoding)" if pass_every == 1
                           else f"default {pass_every} where passes run, else 1; 1: at every encoding)"))
    p.set_defaults(app_passes=passes, app_pass_every=pass_every)


def parse_kinds(text: str, none: bool = False) -> list[str]:
    """`--model` -> the kinds in order (a kind given twice counts once; the registry's names, volsmpl.volume.models,
    and 'none' where the app allows it); ValueError naming the known kinds."""
    from volsmpl.volume.models import parse_models

    names = list(dict.fromkeys(k.strip() for k in str(text).split(",") if k.strip()))
    if none and "none" in names:
        rest = [k for k in names if k != "none"]
        kinds = parse_models(",".join(rest)) if rest else []
        return [k if k in kinds else "none" for k in names]
    return parse_models(text)


def check_threads(threads) -> None:
    """`--threads N`: N >= 1 sets torch's CPU threads; None keeps torch's default."""
    if threads is None:
        return
    if not isinstance(threads, int) or threads < 1:
        raise ValueError(f"--threads {threads}: give a positive number of CPU threads (e.g. --threads 1)")
    import torch

    torch.set_num_threads(int(threads))


def checkpoints(args, models: list[str]) -> dict:
    """kind -> the checkpoint given for it (None: the shipped one) for the learned kinds of `models`. A checkpoint
    given for a kind that does not run, or holding another kind, is refused in one line."""
    from volsmpl.volume.models import expect_checkpoint_model

    out = {}
    for kind in ("volsmpl", "coap"):
        path = getattr(args, f"checkpoint_{kind}", None)
        if path and kind not in models:
            raise ValueError(f"--checkpoint-{kind} is given but --model {','.join(models)} does not run {kind}: add it "
                             f"to --model or drop the option")
        if kind in models:
            out[kind] = path or None
        if path:
            expect_checkpoint_model(path, kind, f"--checkpoint-{kind}",
                                    "give it as --checkpoint-{held} (with {held} in --model).")
    return out


def check_common(args, none: bool = False) -> tuple[list[str], dict]:
    """The shared options checked before any work: (kinds, checkpoints). Sets the thread count; creates --out."""
    from volsmpl.io.outputs import check_writable

    models = parse_kinds(args.model, none)
    ckpts = checkpoints(args, models)
    learned_pass_defaults(args, models, ckpts)
    check_refinement(args, models)
    check_threads(args.threads)
    if args.render < 0:
        raise ValueError(f"--render {args.render}: give the number of cases to draw (0: none)")
    check_writable(args.out, "dir", "--out")
    return models, ckpts


def learned_pass_defaults(args, models: list[str], ckpts: dict) -> None:
    """Set `--passes` and `--pass-every` where not given: the app's defaults (`add_common`'s passes, pass_every)
    for the VolumetricSMPL checkpoint that runs (its passes read from its JSON, no weights loaded): passes at most
    the checkpoint's (`args.passes_by_default` then True), the interval only where passes run (else 1). Without
    volsmpl, or a checkpoint without passes: passes None, interval 1."""
    from volsmpl.io.checkpoint import load_checkpoint
    from volsmpl.volume.models import model_kind

    has = 0
    if "volsmpl" in models and not getattr(args, "random_init", False):
        _, cfg, _ = load_checkpoint(ckpts.get("volsmpl") or model_kind("volsmpl").default_checkpoint, weights=False)
        has = int(cfg.get("refiner_iters", 0) or 0)
    default = getattr(args, "app_passes", None)
    if getattr(args, "passes", None) is None and default is not None and has:
        args.passes, args.passes_by_default = min(int(default), has), True
    if getattr(args, "pass_every", 1) is None:
        runs = has if getattr(args, "passes", None) is None else min(args.passes, has)
        args.pass_every = int(getattr(args, "app_pass_every", 1) or 1) if runs and "volsmpl" in models else 1


def check_refinement(args, models: list[str]) -> None:
    """`--refine-steps R` (an integer >= 0), `--refine-warm` (needs R >= 1) for a run with a learned kind,
    `--passes P` (an integer >= 0, with volsmpl) and `--pass-every N` (an integer >= 1; above 1 with volsmpl, without
    --refine-warm and not with --passes 0). How many learned passes the VolumetricSMPL checkpoint has is checked
    where it is loaded (`volumes`)."""
    from volsmpl.volume.carried_passes import check_pass_interval
    from volsmpl.volume.code_refinement import check_refine_steps
    from volsmpl.volume.models import model_kind
    from volsmpl.volume.refinement_setting import check_passes

    steps, warm = getattr(args, "refine_steps", 0), getattr(args, "refine_warm", False)
    every, passes = getattr(args, "pass_every", 1), getattr(args, "passes", None)
    check_refine_steps(steps, "--refine-steps")
    check_passes(passes, "--passes")
    check_pass_interval(every, "--pass-every")
    if warm and steps == 0:
        raise ValueError("--refine-warm carries the code refinement across iterations: give --refine-steps 1 (or more)")
    if steps and not any(m != "none" and model_kind(m).learned for m in models):
        raise ValueError(f"--refine-steps refines the part codes of volsmpl and coap; --model {','.join(models)} has "
                         f"none: add one of them or drop the option")
    if every > 1 and "volsmpl" not in models:
        raise ValueError(f"--pass-every {every} sets VolumetricSMPL's learned passes; --model {','.join(models)} does "
                         f"not run volsmpl: add it or drop the option")
    if every > 1 and warm:
        raise ValueError(f"--pass-every {every} carries the learned passes' correction and --refine-warm its own: "
                         f"use one of them")
    if passes is not None and "volsmpl" not in models:
        raise ValueError(f"--passes {passes} sets VolumetricSMPL's learned passes; --model {','.join(models)} does "
                         f"not run volsmpl: add it or drop the option")
    if passes == 0 and every > 1 and getattr(args, "passes_by_default", False):
        raise ValueError(f"--pass-every {every} runs the learned passes at an interval, and this app runs none by "
                         f"default (--passes 0): give --passes 1 or more with it, or drop --pass-every")
    if passes == 0 and every > 1:
        raise ValueError(f"--pass-every {every} runs the learned passes at an interval, and --passes 0 runs none: "
                         f"drop one of them")


def code_refinement(args, vols: dict | None = None) -> dict:
    """The code-refinement options: {'steps': R, 'warm': bool, 'passes': P, 'pass_every': N}; P is `--passes`
    (None: all the VolumetricSMPL checkpoint has) or, given the run's `vols` with volsmpl among them, the learned
    passes its volume runs (what results.json records)."""
    passes = getattr(args, "passes", None)
    if vols and vols.get("volsmpl") is not None:
        passes = vols["volsmpl"].active_passes
    return {"steps": int(getattr(args, "refine_steps", 0)), "warm": bool(getattr(args, "refine_warm", False)),
            "passes": None if passes is None else int(passes), "pass_every": int(getattr(args, "pass_every", 1))}


def volumes(body, models: list[str], ckpts: dict, device: str = "cpu", random_init: bool = False,
            encoder_bf16: bool = False, refine: dict | None = None) -> dict:
    """One volume per kind, attached to `body` on `device` (kind 'none': None). random_init: untrained networks;
    encoder_bf16: the learned kinds' part encoder under bfloat16 autocast; refine: `code_refinement(args)`, set on
    the learned kinds (`Volume.set_code_refinement`) and its passes and their interval on volsmpl
    (`Volume.set_passes`, `Volume.set_pass_interval`)."""
    import volsmpl
    from volsmpl.volume.models import model_kind

    out = {}
    for m in models:
        if m == "none":
            out[m] = None
            continue
        learned = model_kind(m).learned
        if random_init and learned:
            vol = volsmpl.attach_volume(body, model=m, pretrained=False)
        else:
            vol = volsmpl.attach_volume(body, ckpts.get(m), model=m)
        if learned:
            vol.net.encoder_bf16 = encoder_bf16
            if refine:
                vol.set_code_refinement(refine["steps"], warm=refine["warm"])
        if m == "volsmpl" and refine and refine.get("passes") is not None:
            vol.set_passes(refine["passes"])              # ValueError (one line) for more than the model has
        if m == "volsmpl" and refine and refine.get("pass_every", 1) != 1:
            vol.set_pass_interval(refine["pass_every"])   # ValueError (one line) for a model without passes
        out[m] = vol.to(device)
    return out


def checkpoint_names(models: list[str], ckpts: dict, random_init: bool = False) -> dict:
    """kind -> what results.json records as its weights: the given path, the shipped asset, 'random init', or None
    for a kind without weights."""
    from volsmpl.volume.models import model_kind

    names = {}
    for m in models:
        if m == "none" or not model_kind(m).learned:
            names[m] = None
        elif random_init:
            names[m] = "random init"
        else:
            names[m] = str(ckpts.get(m) or f"core/assets/{model_kind(m).checkpoint}")
    return names


class CaseRecords:
    """The finished cases of an app run in OUT/cases/ (volsmpl.io.case_store), each stored with the key of what
    made it: the settings and inputs given, the volume's weights, the thread count and the source of volsmpl and
    its apps. With resume=False every case is made again (and stored)."""

    def __init__(self, out, app: str, resume: bool = False):
        from volsmpl.io.case_store import CaseStore

        self.app, self.store = app, CaseStore(Path(out) / "cases", resume=resume)

    def key(self, spec: dict, volume=None) -> str:
        import torch

        from volsmpl.io.case_store import job_key

        refine = getattr(volume, "refine_steps", 0)
        if refine:   # the codes depend on it; keys of runs without it stay as they were
            spec = {**spec, "code_refinement": [refine, bool(volume.refine_warm)]}
        passes = getattr(volume, "passes", None)
        if passes is not None:
            spec = {**spec, "passes": passes}
        every = getattr(volume, "pass_every", 1)
        if every != 1:
            spec = {**spec, "pass_every": every}
        return job_key({**spec, "threads": torch.get_num_threads()}, modules=[] if volume is None else [volume],
                       packages=["volsmpl.apps"])

    def get(self, name: str, key: str):
        return self.store.get(name, key)

    def put(self, name: str, key: str, record) -> None:
        self.store.put(name, key, record)

    def get_or_make(self, name: str, spec: dict, volume, make: Callable[[], dict]) -> tuple[dict, bool]:
        """(record, reused): the stored record of `name` when its key matches, else make() stored."""
        key = self.key(spec, volume)
        rec = self.store.get(name, key)
        if rec is not None:
            return rec, True
        rec = make()
        self.store.put(name, key, rec)
        return rec, False

    def note(self) -> str:
        """The line a run prints when it reused records ('' when none)."""
        s = self.store
        if not s.reused:
            return ""
        return f"--resume: {s.reused} case record(s) reused from {s.folder}; {s.stale} stale record(s) made again"


def envelope(app: str, config: dict, summary: dict, paper, cases: dict, meta: dict, figures: dict | None = None,
             flagged: list | None = None, warnings: list | None = None, **extra) -> dict:
    """The results.json of every app: {app, config, summary, paper, cases: {kind: [records]}, figures, meta,
    flagged, warnings, ...}: `flagged` lists the cases whose result is probably wrong (see `flag_cases`),
    `warnings` the warning lines the run printed."""
    if not isinstance(cases, dict):
        raise TypeError(f"cases must map each kind to its records, got {type(cases).__name__}")
    return {"app": app, "config": config, "summary": summary, "paper": paper, "cases": cases,
            "figures": figures or {}, "meta": meta, "flagged": list(flagged or []), "warnings": list(warnings or []),
            **extra}


def flag_cases(cases: dict, name_key: str, good) -> list[dict]:
    """[{case, model, status, why}] of the records (envelope layout {kind: [records]}) whose `status` is not one of
    `good`: each app judges its cases without ground truth (diverged, object lost, worse than start, ...) and
    records the status and its reason (`status_why`) in the record."""
    out = []
    for kind, recs in cases.items():
        for r in recs:
            status = r.get("status") if isinstance(r, dict) else getattr(r, "status", None)
            if status is not None and status not in good:
                get = r.get if isinstance(r, dict) else (lambda k, d=None, r=r: getattr(r, k, d))
                out.append({"case": get(name_key), "model": kind, "status": status, "why": get("status_why", "")})
    return out


def print_flagged(flagged: list) -> None:
    """One line per flagged case ('flagged: <case> <model>: <status> (<why>)'), after the table."""
    for f in flagged:
        print(f"flagged: {f['case']} {f['model']}: {f['status']}" + (f" ({f['why']})" if f.get("why") else ""))


def case_records(cases) -> list:
    """A result's per-case records as one list: the envelope's {kind: [records]} in kind order, or a list as it is
    (the layout of motion tables made before the envelope)."""
    if isinstance(cases, dict):
        return [r for recs in cases.values() for r in recs]
    return list(cases or [])


def write_results(out, result: dict, name: str = "results.json") -> Path:
    """Write OUT/results.json atomically (a crash never leaves half a file), as standard JSON (NaN and inf as null);
    returns its path."""
    from volsmpl.io.outputs import write_atomic

    from .checks import strict_json

    path = Path(out) / name
    os.makedirs(path.parent, exist_ok=True)
    write_atomic(path, json.dumps(strict_json(result), indent=1, allow_nan=False))
    return path

