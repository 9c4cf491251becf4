"""`volsmpl selfpen`: repair self-intersecting bodies with VolumetricSMPL, COAP and/or the exact mesh (Table 6).

    volsmpl selfpen --model volsmpl,coap,mesh --out out/selfpen                 # the 17 shipped cases
    volsmpl selfpen --model volsmpl,coap --checkpoint-coap runs/c/model --resume
    volsmpl selfpen --case-file my_bodies.json --model volsmpl --out out/mine    # your own bodies (cases.py)
    volsmpl selfpen tune --model volsmpl,coap --out docs/selfpen                 # the tuning sweep (tune.py)

Writes OUT/results.json (volsmpl.apps.table's envelope: config, summary.<kind>, the paper's Table 6, per-case
records per kind, figures, meta) and OUT/render_<case>.png (before / after per kind, front and side, colliding
triangles in red; figures.py) for the first --render cases; prints the summary beside the paper's table. Each case
record holds the case's body parameters (`start_params`) and the repaired body (`body`: parameters and joints,
volsmpl's frame: metres, Y up; bodies.py). Mesh files OUT/meshes/<case>/<kind>_before.ply and <kind>_after.ply
(paths in the record's `meshes`) are written for a user's own --case-file always, for the shipped cases with
--save-meshes. Each finished repair is kept in OUT/cases/ with the key of what made it, so a stopped run continues
with --resume (its bodies, meshes and figures are made again from the kept record's pose). A bar over the cases and
the optimiser's per-step bar show on a terminal (not with --quiet).
"""
from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import torch

from volsmpl.apps.checks import applies, claim_out, number, safe_name
from volsmpl.apps.progress import progress, steps_bar
from volsmpl.apps.table import (REFINE_OPTIONS, add_common, check_common, checkpoint_names, code_refinement,
                                CaseRecords, envelope, flag_cases, print_flagged, volumes, write_results)

from .bodies import take_away, writes_meshes
from .cases import CASES_FILE, load_cases
from .figures import render_case
from .optimize import (GOOD, PAPER, PRESETS, RepairResult, SelfPenConfig, format_table, repair_case,
                       summarize)

ACTIONS = ("run", "tune")


def add_parser(sub):
    from .tune import GRID_LR, GRID_W_PRIOR, GRID_W_SELFPEN

    d = SelfPenConfig()
    p = sub.add_parser("selfpen", help="resolve self-intersections by pose optimisation (Sec. 4.2.4, Table 6)",
                       description="Optimise the pose of self-intersecting bodies against the volumetric "
                                   "self-penetration loss; report time, memory, iterations, triangle collisions.")
    p.add_argument("action", nargs="?", default="run", choices=ACTIONS,
                   help="run (default): repair the cases; tune: sweep the step size and weights on them (tune.py)")
    # the encoder's codes: the encoding is most of a step, and one learned pass costs 1.7x (docs/learned_refinement.md)
    add_common(p, out="out/selfpen", seed=None, passes=0)
    p.add_argument("--cases", default="all", help="comma-separated case names from the case file, or 'all'")
    p.add_argument("--case-file", default=str(CASES_FILE), help="JSON case file (default: the shipped 17 cases)")
    p.add_argument("--random-init", action="store_true", help="random network weights (pipeline check only)")
    p.add_argument("--preset", default="tuned", choices=sorted(PRESETS),
                   help="hyper-parameter set: 'tuned' (our tuning run, docs/selfpen/tune.json) or 'paper' "
                        "(lr 1e-5, prior 1e3, self-penetration 0.1); the options below override it")
    p.add_argument("--lr", type=float, default=None, help=f"SGD learning rate (tuned {d.lr:g}, paper 1e-5)")
    p.add_argument("--max-iters", type=int, default=d.max_iters, help=f"iteration cap (paper {d.max_iters})")
    p.add_argument("--w-selfpen", type=float, default=None, help=f"self-penetration weight (tuned {d.w_selfpen:g}, paper 0.1)")
    p.add_argument("--w-prior", type=float, default=None, help=f"pose prior weight (tuned {d.w_prior:g}, paper 1e3)")
    p.add_argument("--limits", default=None, choices=["on", "off"],
                   help="keep every joint within its anatomical limits (volsmpl.body.poses.JOINT_LIMITS; a joint that "
                        "starts outside may not move farther out) as a hard bound (tuned on, paper off)")
    p.add_argument("--hold", default=None, choices=["on", "off"],
                   help="hold the joints the contact does not turn at their start: the spine and legs when an arm meets "
                        "the torso (volsmpl.body.limits.contact_joints; tuned on, paper off)")
    p.add_argument("--n-points", type=int, default=d.n_points, help=f"samples per box of a colliding pair (paper {d.n_points})")
    p.add_argument("--stop-checks", type=int, default=None,
                   help=f"stop when so many point draws in a row find no penetration (tuned {d.stop_checks}, paper 1)")
    p.add_argument("--tau", type=float, default=None,
                   help=f"metres: SDF scale of VolumetricSMPL's soft occupancy in the loss (tuned {d.tau:g}, paper 1)")
    p.add_argument("--patience", type=int, default=None,
                   help=f"stop after so many steps without a new lowest penetration term (tuned {d.patience}, paper 0: off)")
    p.add_argument("--stall-rtol", type=float, default=None,
                   help=f"a new low of the penetration term must beat the best by this fraction (tuned {d.stall_rtol:g})")
    p.add_argument("--max-step", type=float, default=None,
                   help=f"radians: longest rotation step of one joint per iteration (tuned {d.max_step:g}, paper 0: plain SGD)")
    p.add_argument("--code-grad", default=None, choices=["on", "off"],
                   help="back-propagate through the part codes (tuned off: rigid part motion only; paper on)")
    p.add_argument("--sampler-seed", type=int, default=d.seed, help="seed of the penetration point sampler")
    p.add_argument("--grid-lr", type=float, nargs="+", default=list(GRID_LR), help="tune: learning rates tried")
    p.add_argument("--grid-w-selfpen", type=float, nargs="+", default=list(GRID_W_SELFPEN),
                   help="tune: self-penetration weights tried")
    p.add_argument("--grid-w-prior", type=float, nargs="+", default=list(GRID_W_PRIOR), help="tune: prior weights tried")
    p.add_argument("--combine", nargs="+", default=None, metavar="JSON",
                   help="tune: only merge earlier tuning runs (e.g. one kind each) into OUT/tune.json and pick the best")
    return p


def _case_names(text: str) -> list[str] | None:
    """`--cases` -> the case names in order, None for 'all'; an empty list or a name given twice (it would run twice
    and count twice in the summary) is refused."""
    if text.strip() == "all":
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise ValueError(f"--cases {text!r} names no case: give comma-separated case names, or 'all'.")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"--cases names {', '.join(twice)} more than once (it would run and count twice in the "
                         f"summary); give each case once.")
    return names


#: the options each action reads (volsmpl.apps.checks.applies refuses the others)
_COMMON = {"model", "checkpoint_volsmpl", "checkpoint_coap", "threads", "out", "device", "cases", "case_file"}
USES = {"run": _COMMON | {"resume", "render", "save_meshes", "random_init", "preset", "lr", "max_iters", "w_selfpen",
                          "w_prior", "limits", "hold", "n_points", "stop_checks", "tau", "patience", "stall_rtol", "max_step", "code_grad",
                          "sampler_seed"} | REFINE_OPTIONS,
        "tune": _COMMON | {"max_iters", "stop_checks", "tau", "patience", "grid_lr", "grid_w_selfpen", "grid_w_prior",
                           "combine"}}


def check_options(args) -> None:
    """The options of the chosen action, before any work: those it does not read refused, the numbers in range."""
    applies(args, f"selfpen {args.action}", USES[args.action])
    for flag, lo, lo_open in (("lr", 0, True), ("w_selfpen", 0, False), ("w_prior", 0, False), ("tau", 0, True),
                              ("stall_rtol", 0, False), ("max_step", 0, False), ("patience", 0, False),
                              ("stop_checks", 1, False)):
        if getattr(args, flag) is not None:
            number(getattr(args, flag), "--" + flag.replace("_", "-"), lo=lo, lo_open=lo_open)
    number(args.max_iters, "--max-iters", lo=1, what="optimisation steps")
    number(args.n_points, "--n-points", lo=1, what="samples per box")
    number(args.sampler_seed, "--sampler-seed", lo=0, what="a seed: a whole number")
    for flag in ("grid_lr", "grid_w_selfpen", "grid_w_prior"):
        for v in getattr(args, flag):
            number(v, "--" + flag.replace("_", "-"), lo=0, lo_open=flag == "grid_lr")


def _config(args) -> SelfPenConfig:
    given = {k: getattr(args, k) for k in ("lr", "w_selfpen", "w_prior", "stop_checks", "tau", "patience",
                                           "stall_rtol", "max_step") if getattr(args, k) is not None}
    for k in ("code_grad", "limits", "hold"):
        if getattr(args, k) is not None:
            given[k] = getattr(args, k) == "on"
    return SelfPenConfig.preset(args.preset, max_iters=args.max_iters, n_points=args.n_points, seed=args.sampler_seed,
                                device=args.device, **given)


def run(args) -> int:
    import volsmpl

    check_options(args)
    if args.action == "tune" and args.combine:
        from .tune import run_combine
        return run_combine(args)
    models, ckpts = check_common(args)
    if args.random_init and any(ckpts.values()):
        raise ValueError("--random-init and a checkpoint exclude each other: drop one")
    if args.action == "tune":
        if args.random_init:
            raise ValueError("tune chooses settings for trained volumes: drop --random-init")
        if "mesh" in models:
            raise ValueError("tune sweeps the learned kinds' settings: give --model volsmpl,coap (not mesh)")
    cfg = _config(args)
    cases = load_cases(args.case_file, _case_names(args.cases))
    with claim_out(args.out, "selfpen"):
        body = volsmpl.create_body().to(cfg.device)
        vols = volumes(body, models, ckpts, cfg.device, random_init=args.random_init, refine=code_refinement(args))
        if args.action == "tune":
            from .tune import run_tune
            return run_tune(args, body, vols, cases, checkpoint_names(models, ckpts))
        return _repair(args, cfg, body, vols, cases, models, ckpts)


def _repair(args, cfg, body, vols: dict, cases: list, models: list, ckpts: dict) -> int:
    """`selfpen run` on a claimed --out: each case by each kind; results.json after every case."""
    if args.random_init:
        print("note: --random-init: untrained networks, the numbers only check the pipeline")
    config = {**asdict(cfg), "preset": args.preset, "models": models, "random_init": bool(args.random_init),
              "checkpoints": checkpoint_names(models, ckpts, args.random_init), "case_file": str(args.case_file),
              "code_refinement": code_refinement(args, vols),
              "device_name": torch.cuda.get_device_name(0) if cfg.device == "cuda" else "cpu",
              "threads": torch.get_num_threads()}
    store = CaseRecords(args.out, "selfpen", resume=args.resume)
    per_model = {m: [] for m in models}
    figures = {}
    mesh_out = args.out if writes_meshes(args.case_file, args.save_meshes) else None
    bar = steps_bar(args.quiet)
    steps = {} if bar is None else {"progress": bar}  # None is repair_case's own default: a bar on a terminal
    for i, case in enumerate(progress(cases, f"selfpen {','.join(models)}", quiet=args.quiet)):
        results = {}
        draw = i < args.render
        for m in models:
            spec = {"config": asdict(cfg), "model": m, "random_init": bool(args.random_init),
                    "case": {"name": case.name, "betas": case.betas, "global_orient": case.global_orient,
                             "body_pose": case.body_pose}}
            kept = {}

            def make():
                r = repair_case(body, vols[m], case, cfg, keep_meshes=draw, **steps)
                kept["result"] = r
                return r.to_json()

            rec, reused = store.get_or_make(f"{safe_name(case.name)}_{m}", spec, vols[m], make)
            r = kept.get("result") or RepairResult(**rec)
            made = take_away(body, case, r.body_pose, m, mesh_out)  # from the record's pose, reused or not
            r.start_params, r.body, r.meshes = made["start_params"], made["body"], made["meshes"]
            per_model[m].append(r)
            results[m] = r
            tail = "  (reused)" if reused else ""
            if r.status == "no_intersection":
                print(f"{case.name:28s} {m:8s} no self-intersection: left unchanged{tail}")
            else:
                print(f"{case.name:28s} {m:8s} {r.status:16s} it {r.iterations:3d}  collisions {r.collisions_before:5d} -> "
                      f"{r.collisions_after:5d} (collidable parts {r.collidable_before} -> {r.collidable_after})  "
                      f"pose change {r.pose_change_deg:6.2f} deg  {r.total_s:6.2f} s{tail}")
        if draw:
            render_case(Path(args.out) / f"render_{safe_name(case.name)}.png", body, case, results)
            figures[case.name] = f"render_{safe_name(case.name)}.png"
        path, flagged = _write(args.out, config, per_model, figures, cfg.device)  # a stopped run keeps its cases
    summaries = {m: summarize(rs) for m, rs in per_model.items()}
    print()
    print(format_table(summaries))
    print("collisions: pose-induced intersecting triangle pairs (rest-pose pairs of the same shape left out), "
          "mean over cases; collidable parts: those of them between two parts the self-penetration loss may push "
          "apart (not the same part, not neighbours or ignored pairs); max chg: the mean of each case's largest joint "
          "change (deg); limits: joint angles moved beyond their anatomical limits; memory: " + ", ".join(sorted({s['memory_kind'] for s in summaries.values() if s['memory_kind']})))
    print_flagged(flagged)
    note = store.note()
    if note:
        print(note)
    n_meshes = sum(len(r.meshes) for rs in per_model.values() for r in rs)
    print(f"wrote {path}" + (f", {len(figures)} figure(s)" if figures else "")
          + (f" and {n_meshes} mesh file(s) under {Path(args.out) / 'meshes'}" if n_meshes else ""))
    return 0


def _write(out, config: dict, per_model: dict, figures: dict, device: str):
    """OUT/results.json of the cases done so far: (its path, the flagged repairs)."""
    from volsmpl.io.provenance import machine_info

    recs = {m: [r.to_json() for r in rs] for m, rs in per_model.items()}
    flagged = flag_cases(recs, "name", GOOD)
    result = envelope("selfpen", config, {m: summarize(rs) for m, rs in per_model.items()}, PAPER, recs,
                      machine_info(device), figures, flagged=flagged)
    return write_results(out, result), flagged
