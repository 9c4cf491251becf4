"""`volsmpl motion`: scene-constrained walking with VolumetricSMPL, COAP and/or the exact mesh (Table 5, D.1).

    volsmpl motion --model volsmpl,coap,mesh --scenes 2 --sequences 2 --out out/motion
    volsmpl motion --model volsmpl --scenes all              # 15 rooms x 8 pairs, as the paper
    volsmpl motion tune --model volsmpl,coap,mesh --scenes all --out out/motion   # weights tuned, then tested
    volsmpl motion --scene room.ply --up z --units mm --start=1200,400 --goal=3100,2000 --model volsmpl
    volsmpl motion --model volsmpl --scene examples/motion/scene.ply --up z --units mm --start=-1000,0 --goal=1000,200 \
        --frames 50 --coll-frames 16 --out out/motion_example     # the example (examples/motion/README.md)

Per model (and per collision weight: COAP's sweep w in {0.01, 0.1, 1}, Table D.1) every start/goal pair is walked
by optimising the walking model (apps/motion/walk.py) against the objective of supp. D.3 (objective.py). The
collision term's per-frame time and memory are measured once per model on the full cloud (a room's 16,384 points,
a user's corridor; forward, and forward + backward); the longest sequence whose forward + backward fits
--mem-budget-gb follows from the per-frame memory, and a model for which --frames do not fit is evaluated on 16
evenly spaced frames (the authors' COAP setting; --coll-frames forces 'all' or a number).

With two rooms or more, every third room tunes the weights and the others test (tuning.py): summary.<model>_test
is each model over the test rooms at the weight that scored best on the tuning rooms (results.json's `tuning`).
`volsmpl motion tune` sweeps the weights on the tuning rooms only and runs each model's best weight on the test
rooms (a third of the sweep's cost; its rows <model> are the test rooms').

Writes OUT/results.json (volsmpl.apps.table's envelope: config, summary.<model>, <model>_w<w> and <model>_test, the
paper's rows, per-sequence records per kind, figures, meta; then `tuning`, `cost` and `paired`: the compared rows' per-sequence differences with bootstrap intervals, stats.py),
OUT/topdown_<scene>.png (figures.py: axes in metres, cropped to the walks) and OUT/strip_<scene>_<k>_<model>.png
(the obstacles near the body, the points inside it in red) for the first --render sequences. results.json is
written after every finished sequence (its `progress` says how many of the planned ones it holds), and each
sequence's record is kept in OUT/cases/ for --resume. A user's scene (and the generated rooms with --save-meshes)
also gets each walk's bodies, every frame, in its record (`body`) and a mesh of every 10th frame's body in
OUT/meshes/<scene>_<k>/<model>_walk.ply, in the input's --units and --up (outputs.py; a reused record's mesh is
made from the record). On a terminal, bars show the walks of each model and the steps of each walk (--quiet: none).

A user's scene (user_scene.py) is read whole at any size and checked on an overview; its points are taken only in
the walk's corridor (the box the walk can reach in --frames at the walking model's top speed, widened by the body),
one per --spacing metres, and its floor level is found there (the densest low slab, printed in one line).

Each sequence record gets a status judged without ground truth (status.py: reached, diverged, goal_missed,
colliding, worse_than_start) and its reason; results.json's `flagged` lists those not reached (printed after the
table), its `warnings` what looked unusual in a user's scene (scene_checks.py: size against --units, up axis).
Every option is checked before any work (options.py: the options a mode does not read are refused), a user's scene
right after reading it, before the networks load.
"""
from __future__ import annotations

import hashlib
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from volsmpl.apps.checks import claim_out, warn
from volsmpl.apps.table import add_common

from .options import ALL_SCENES, PAPER_W, check_options, parse_weights, parse_xy, scene_count  # noqa: F401
from .stats import compared_runs, format_pairs, paired_differences
from .summary import cost_columns, fit_budget, format_table, paper_summary, tuned_rows, tuned_summary, wkey
from .tuning import choose_weights, split_scenes
from .user_scene import DEFAULT_SPACING_M

PUBLISHED = "coap_published"   # summary/cost key of COAP as published (--published-cost)


def add_parser(sub):
    p = sub.add_parser("motion", help="scene-constrained walking: VolumetricSMPL vs COAP vs exact mesh (Table 5)",
                       description="Walk from start to goal through furnished rooms (or your own scan) by "
                                   "optimising a differentiable walking model against a goal, a scene collision and "
                                   "a jerk term; report per-frame cost, total memory, collisions and goal distance.")
    p.add_argument("action", nargs="?", default="run", choices=("run", "tune"),
                   help="run (default): every weight on every room (Tables 5 and D.1; rows <model>_test add the "
                        "tuning split's view); tune: the weights swept on every third room only, each model's best "
                        "weight run on the other rooms (the compared rows), a third of the sweep's cost")
    # one learned pass: 1.17x the encoder's collision term per frame, two 1.38x (docs/learned_refinement.md)
    add_common(p, out="out/motion", render=1, seed="the first generated room's seed", passes=1,
               resume="reuse the sequences OUT/cases/ already holds from an identical run (same code, weights, "
                      "settings and inputs); the others are computed")
    p.add_argument("--scenes", default="2", help="without --scene: 'all' (15 generated rooms) or a number of rooms")
    p.add_argument("--sequences", type=int, default=8, help="without --scene: start/goal pairs per room (default 8)")
    p.add_argument("--scene", default=None,
                   help="your own scene instead of rooms: a mesh or point cloud file of any size (see --spacing); "
                        "its walk's bodies go to results.json and OUT/meshes/ always")
    p.add_argument("--start", default=None, help="with --scene: start floor position A,B (negative: --start=-1,2; the file's horizontal "
                                                 "axes in order, its units)")
    p.add_argument("--goal", default=None, help="with --scene: goal floor position A,B")
    p.add_argument("--up", default="y", choices=["y", "z"], help="with --scene: the file's up axis (checked against "
                   "the floor found in the points)")
    p.add_argument("--units", default="m", choices=["m", "cm", "mm"], help="with --scene: the file's units")
    p.add_argument("--floor-y", type=float, default=None,
                   help="with --scene: floor height in metres after --units, along --up (default: the densest low "
                        "slab of the points around the walk, printed); given, a floor that seems to lie across "
                        "another axis than --up is a warning, not a refusal")
    p.add_argument("--spacing", type=float, default=DEFAULT_SPACING_M,
                   help=f"with --scene: metres between the scene points taken around the walk (default "
                        f"{DEFAULT_SPACING_M:g}: a 20 cm object gets ~100 points). The file is read whole at any size, "
                        f"checked on an overview (size, up axis), and its points taken only in the walk's corridor: "
                        f"the box the walk can reach in --frames at the walking model's top speed (2.2 m/s) ending "
                        f"within 0.5 m of the goal, widened by the body's reach (0.6 m) and the collision term's "
                        f"margin (0.4 m), from 0.1 m under the floor to 2.2 m above it (apps/motion/user_scene.py). "
                        f"Results: each walk's bodies per frame in results.json and a .ply of every 10th frame's "
                        f"body under OUT/meshes/, in the file's --units and --up")
    p.add_argument("--frames", type=int, default=80, help="frames per sequence (paper 80-120)")
    p.add_argument("--iters", type=int, default=100,
                   help="Adam steps (paper 100; 0: the straight start walk, not optimised: the cost columns only)")
    p.add_argument("--lr", type=float, default=0.05, help="Adam learning rate, linearly decayed (paper 0.05)")
    p.add_argument("--w", action="append", default=[], metavar="MODEL=W[,W...]",
                   help="collision weights of a model, e.g. --w coap=0.1 (default volsmpl=1, mesh=1, "
                        "coap=0.01,0.1,1 as Table D.1); repeatable")
    p.add_argument("--coll-frames", default="auto",
                   help="frames the collision term evaluates: 'auto' (all if they fit --mem-budget-gb, else 16), "
                        "'all', or a number")
    p.add_argument("--mem-budget-gb", type=float, default=24.0,
                   help="memory budget for max_frames_in_budget and --coll-frames auto (default 24, the paper's GPU)")
    p.add_argument("--residuals", action="store_true", help="optimise per-frame pose residuals too (pose prior)")
    p.add_argument("--floor-in-loss", action="store_true",
                   help="keep the floor points in the optimised collision term (slow on a CPU; metrics always count them)")
    p.add_argument("--cost-frames", type=int, default=8, help="frames batched in the per-frame cost measurement")
    p.add_argument("--cost-repeats", type=int, default=3, help="repeats of the cost measurement (median)")
    p.add_argument("--published-cost", action="store_true",
                   help="with coap: also the per-frame cost of COAP as published (every part at every scene point, "
                        "no culling), on one frame (GBs of memory): summary row 'coap_published', cost only")
    p.add_argument("--encoder-bf16", action="store_true",
                   help="run the learned kinds' part encoder (the PointNet, most of the collision term's cost) under "
                        "bfloat16 autocast, both kinds alike: ~1.7x faster per frame on a CPU with AVX512-BF16 or AMX "
                        "(emulated, not timed, on one without), codes rounded (docs/history/readme.md); default float32")
    p.add_argument("--batch", type=int, default=1,
                   help="without --scene: optimise up to N start/goal pairs of a room together (one harness run; "
                        "each walk its own objective): fills a GPU; 1 (default) keeps the per-sequence time and "
                        "memory columns")
    return p


def _print_case(scene: str, k: int, label: str, rec: dict, reused: bool = False) -> None:
    met, status = rec["metrics"], rec.get("status", "reached")
    if met.get("error"):
        line = f"no walk: {met['error']}"
    else:
        line = (f"goal {met['goal_dist_m']:.3f} m  collision {met['collision_cm']:.3f} cm "
                f"({met['collision_frames_pct']:.0f}% frames)  skate {met['foot_skate_cm']:.3f} cm  "
                f"{met['optim_s']:.0f} s")
    print(f"{scene:8s} seq {k} {label:12s} {line}" + ("" if status == "reached" else f"  [{status}]")
          + ("  (reused)" if reused else ""), flush=True)


def _scenes(args, frames: int, warnings: list) -> list:
    """The user's scene: its walk's corridor with its start and goal (checked: size, up axis, reach, floor,
    obstacles; user_scene.load_user_scene), or the generated rooms."""
    from .scenes import room_scenes

    if args.scene is not None:
        from .user_scene import load_user_scene

        return [load_user_scene(args.scene, parse_xy(args.start, "--start"), parse_xy(args.goal, "--goal"), frames,
                                up=args.up, units=args.units, spacing=args.spacing, floor_y=args.floor_y,
                                warn=lambda text: warn("motion", text, warnings))]
    return room_scenes(scene_count(args.scenes), args.sequences, frames, first_seed=args.seed)


def _walks(model, volume, sc, ks: list, w: float, cfg, progress=False) -> list:
    """synthesize_batch on the pairs `ks` of scene `sc`. A walk the harness stops as diverged keeps its last finite
    values (status.judge flags it); an error raised inside a step on NaN/Inf values makes a result without a walk
    (status.failed_metrics) instead of ending the run; in a batch, its pairs are walked again one by one so that
    only the one that failed is lost."""
    from .status import failed_metrics
    from .synth import synthesize_batch

    try:
        return synthesize_batch(model, volume, sc, [sc.pairs[k] for k in ks], w, cfg, progress=progress)
    except RuntimeError as e:
        if "NaN or Inf" not in str(e):
            raise
        if len(ks) > 1:
            return [r for k in ks for r in _walks(model, volume, sc, [k], w, cfg, progress)]
        return [{"walk": None, "metrics": failed_metrics(f"the optimisation stopped: {e}")}]


def _costs(args, body, model, vols: dict, scenes: list, opt: dict) -> tuple[dict, dict]:
    """The collision term's per-frame cost per kind on the first room's full cloud and straight walk, and the frames
    each kind's term evaluates (--coll-frames, or what fits --mem-budget-gb)."""
    import volsmpl

    from .synth import initial_controls, measure_cost, published_penetration, speed_of_control

    frames, cf, budget = opt["frames"], opt["cf"], args.mem_budget_gb * 2 ** 30
    sc0 = scenes[0]
    s0, g0 = sc0.pairs[0]
    init = initial_controls(s0, g0, frames, body.v_template.dtype, body.v_template.device)
    with torch.no_grad():
        probe = model(init["heading_delta"], speed_of_control(init["speed_u"]), frames=frames, start=init["start"],
                      heading0=init["heading0"])
    costs, coll_frames = {}, {}
    for m in opt["models"]:   # the per-frame cost on the full cloud, on the straight walk of the first pair
        print(f"{m:8s} measuring the collision term's per-frame cost on {len(sc0.points):,} points ...", flush=True)
        costs[m] = measure_cost(vols[m], probe, sc0.points, frames=args.cost_frames, repeats=args.cost_repeats,
                                device=args.device)
        line = fit_budget(costs[m], budget)
        fits = costs[m]["max_frames_in_budget"] is None or costs[m]["max_frames_in_budget"] >= frames
        coll_frames[m] = ("all" if fits else 16) if cf == "auto" else ("all" if cf == "all" else int(cf))
        print(f"{m:8s} {line} -> collision on {coll_frames[m]} frames")
    if args.published_cost:  # COAP's own code: every part at every point, the same values (cost only)
        pub = volsmpl.attach_volume(body, opt["ckpts"].get("coap"), model="coap", dense=True).to(args.device)
        pub.net.encoder_bf16 = args.encoder_bf16
        costs[PUBLISHED] = measure_cost(pub, probe, sc0.points, frames=1, repeats=args.cost_repeats,
                                        device=args.device, loss=published_penetration)
        print(f"coap as published {fit_budget(costs[PUBLISHED], budget)}")
        del pub
    return costs, coll_frames


def run(args) -> int:
    opt = check_options(args)   # every option, before any work
    with claim_out(args.out, "motion"):   # one writer of OUT; another app's results.json is refused
        return _run(args, opt)


def _run(args, opt: dict) -> int:
    """`volsmpl motion` on a claimed --out, its options checked."""
    import volsmpl
    from volsmpl.apps.table import (CaseRecords, checkpoint_names, code_refinement, envelope, flag_cases,
                                    print_flagged, volumes, write_results)
    from volsmpl.io.provenance import machine_info
    from volsmpl.report import paper

    from volsmpl.apps.motion import walk as W
    from volsmpl.apps.progress import progress, shown

    from .figures import topdown
    from .outputs import publish, walk_body
    from .status import GOOD, judge
    from .synth import SynthConfig

    models, ckpts, protocol, weights, frames = (opt[k] for k in ("models", "ckpts", "protocol", "weights", "frames"))
    out = Path(args.out)
    warnings = list(opt.get("warnings", []))
    scenes = _scenes(args, frames, warnings)   # a user's scene checked here, before the networks load
    body = volsmpl.create_body().to(args.device)
    model = W.WalkModel(body)
    vols = volumes(body, models, ckpts, args.device, encoder_bf16=args.encoder_bf16,  # bf16: in every key
                   refine=code_refinement(args))
    costs, coll_frames = _costs(args, body, model, vols, scenes, opt)
    records = {(m, w): [] for m in models for w in weights[m]}
    cases, figures = {}, {}
    store = CaseRecords(out, "motion", resume=args.resume)
    every = [(m, w) for m in models for w in weights[m]]
    if protocol == "tuned":
        tune, test = split_scenes([sc.name for sc in scenes])
        planned = sum(len(sc.pairs) * (len(every) if sc.name in tune else len(models)) for sc in scenes)
    else:
        planned = sum(len(sc.pairs) for sc in scenes) * len(every)
    config = {"models": models, "weights": weights, "frames": frames, "iters": args.iters, "lr": args.lr,
              "scenes": [sc.name for sc in scenes], "sequences": args.sequences if args.scene is None else 1,
              "coll_frames": coll_frames, "mem_budget_gb": args.mem_budget_gb, "residuals": args.residuals,
              "floor_in_loss": args.floor_in_loss, "user_scene": args.scene, "device": args.device,
              "checkpoints": checkpoint_names(models, ckpts), "batch": args.batch, "protocol": protocol,
              "encoder_bf16": args.encoder_bf16, "code_refinement": code_refinement(args, vols),
              "seed": args.seed, "threads": torch.get_num_threads(),
              "objective": "Huber(delta=1)(last pelvis xz, goal) + w * mean_frames sum_points penetration + "
                           "0.1 * max jerk; Adam lr 0.05 linear decay, unit-norm gradients"}
    units, up = (args.units, args.up) if args.scene is not None else ("m", "y")
    save = args.scene is not None or args.save_meshes   # a user's scene: its bodies and meshes always
    config.update(save_meshes=save)
    if args.scene is not None:
        config.update(up=args.up, units=args.units, floor_y=args.floor_y, spacing=args.spacing,
                      floor_found_m=round(scenes[0].lift + scenes[0].floor_found, 4),
                      corridor_points=len(scenes[0].points))

    def result(summary: dict, **extra) -> dict:
        """results.json as it stands: the records so far, their flags, the warnings, the progress."""
        done = sum(len(v) for v in records.values())
        return envelope("motion", config, summary, {**paper.rows("motion"), **paper.rows("coll_weights")}, cases,
                        machine_info(args.device), figures, flagged=flag_cases(cases, "case", GOOD),
                        warnings=warnings, progress={"sequences": done, "planned": planned}, **extra)

    def save_partial() -> None:
        """results.json after a finished sequence: a run stopped at any moment leaves what it finished."""
        done = {k: v for k, v in records.items() if v}
        write_results(out, result(paper_summary(done, costs, coll_frames, weights), cost=costs))

    def run_scene(sc, plan) -> None:
        """Walk every pair of room `sc` for each (model, weight) of `plan`, reusing stored sequences; its figure."""
        paths = {}
        cloud = hashlib.sha256(np.ascontiguousarray(sc.points, dtype=np.float64).tobytes()
                               + np.asarray(sc.floor, dtype=bool).tobytes()).hexdigest()
        for m, w in plan:
            cfg = SynthConfig(frames=frames, iters=args.iters, lr=args.lr, residuals=args.residuals,
                              floor_in_loss=args.floor_in_loss, coll_frames=coll_frames[m], device=args.device)
            label = m if len(weights[m]) == 1 else wkey(m, w)
            names, keys, recs, pubs = [], [], {}, {}
            for k, (s, g) in enumerate(sc.pairs):
                names.append(f"{sc.name}_{k}_{label}")
                keys.append(store.key({"config": asdict(cfg), "w": w, "model": m, "scene": sc.name, "cloud": cloud,
                                       "start": np.asarray(s).tolist(), "goal": np.asarray(g).tolist(),
                                       "batch": args.batch, "body": body.fingerprint, "lift": sc.lift,
                                       "frame": [units, up], "encoder_bf16": args.encoder_bf16}, vols[m]))
                rec = store.get(names[k], keys[k])
                if rec is not None:
                    rec.setdefault("case", names[k])
                    rec["status"], rec["status_why"] = judge(rec)
                    recs[k] = rec
            for k in sorted(recs):
                _print_case(sc.name, k, label, recs[k], reused=True)
                pubs[k] = publish(recs[k], out, f"{sc.name}_{k}", label, body, save)   # meshes from the record
                records[(m, w)].append(pubs[k])
                cases.setdefault(m, []).append(pubs[k])
            todo = [k for k in range(len(sc.pairs)) if k not in recs]
            batches = [todo[i:i + args.batch] for i in range(0, len(todo), args.batch)]
            unit = "walk" if args.batch == 1 else "batch"
            for ks in progress(batches, f"{sc.name} {label}", quiet=args.quiet, unit=unit):   # the pairs not stored
                for k, r in zip(ks, _walks(model, vols[m], sc, ks, w, cfg, shown(args.quiet))):
                    s, g = sc.pairs[k]
                    recs[k] = {"case": names[k], "scene": sc.name, "sequence": k, "model": m, "w": w,
                               "start": np.asarray(s).tolist(), "goal": np.asarray(g).tolist(), "frames": frames,
                               "collision_frames": coll_frames[m], "metrics": r["metrics"]}
                    recs[k]["status"], recs[k]["status_why"] = judge(recs[k])
                    if r["walk"] is not None:
                        recs[k]["body"] = walk_body(r["walk"], sc.lift, units, up)
                    if k < args.render and r["walk"] is not None:
                        W.render_strip(r["walk"], body.faces, out / f"strip_{names[k]}.png", every=10,
                                       scene_points=sc.points, scene_floor=sc.floor)
                        figures[f"strip_{names[k]}"] = f"strip_{names[k]}.png"
                    store.put(names[k], keys[k], recs[k])
                    _print_case(sc.name, k, label, recs[k])
                    pubs[k] = publish(recs[k], out, f"{sc.name}_{k}", label, body, save)
                    records[(m, w)].append(pubs[k])
                    cases.setdefault(m, []).append(pubs[k])
                    save_partial()
            n = len(sc.pairs)   # this block's records, in sequence order (the last n of their lists)
            records[(m, w)][-n:] = cases[m][-n:] = [pubs[k] for k in range(n)]
            for k in range(n):
                if recs[k]["metrics"].get("pelvis_xz"):
                    paths.setdefault(label, []).append(np.asarray(recs[k]["metrics"]["pelvis_xz"]))
        topdown(sc, paths, sc.pairs, path=out / f"topdown_{sc.name}.png", up=up)
        figures[f"topdown_{sc.name}"] = f"topdown_{sc.name}.png"

    if protocol == "tuned":   # the sweep on the tuning rooms, then each model's chosen weight on the others
        for sc in scenes:
            if sc.name in tune:
                run_scene(sc, every)
        choice = choose_weights(records, tune)
        print("chosen on rooms " + ", ".join(tune) + ": " + ", ".join(f"{m} w={c['w']:g}" for m, c in choice.items()))
        for sc in scenes:
            if sc.name in test:
                run_scene(sc, [(m, choice[m]["w"]) for m in models])
        summary, tuning = tuned_summary(records, choice, tune, test, costs, coll_frames, weights)
    else:
        for sc in scenes:
            run_scene(sc, every)
        summary = paper_summary(records, costs, coll_frames, weights)
        tuning = tuned_rows(summary, records, [sc.name for sc in scenes], costs, coll_frames)
    if PUBLISHED in costs:   # cost columns only: its optimisation would be the 'coap' rows' (same values)
        summary[PUBLISHED] = dict(cost_columns(costs[PUBLISHED]), n_sequences=0)
    print()
    print(format_table(summary))
    if tuning:
        rows = "rows <model>" if protocol == "tuned" else "rows *_test"
        print(f"{rows}: rooms {', '.join(tuning['test_scenes'])} only, each model at the weight best on rooms "
              f"{', '.join(tuning['tune_scenes'])} ({', '.join(f'{m} w={w:g}' for m, w in tuning['choice'].items())}); "
              f"criterion: {tuning['criterion']}")
    print("per-frame cost: the collision term on the full cloud (" + ", ".join(sorted({c["memory_kind"] for c in costs.values()}))
          + "); total: peak of one whole-sequence optimisation; collision: exact mesh test, every scene point")
    final = result(summary, tuning=tuning, cost=costs)
    print_flagged(final["flagged"])
    runs = compared_runs(final)
    if len(runs) >= 2 and min(len(r) for r in runs.values()) >= 2:   # paired differences need 2+ shared sequences
        final["paired"] = paired_differences(runs)
        print(format_pairs(final["paired"]))
    write_results(out, final)
    note = store.note()
    if note:
        print(note)
    print(f"wrote {out / 'results.json'}")
    return 0
