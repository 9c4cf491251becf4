"""`volsmpl hoi`: human–object joint optimisation with VolumetricSMPL, COAP and the exact mesh (paper Table 3).

    volsmpl hoi make-db [--n 100] [--seed 0] [--db FOLDER]       # the interaction database (apps/hoi/database.py)
    volsmpl hoi --model volsmpl,coap,mesh --split test --out out/hoi   # fit the test half, results.json + figures
    volsmpl hoi fit --case my_case.json --model volsmpl --out out/hoi_fit   # a user's own case file (apps/hoi/case.py)
    volsmpl hoi make-case --object mug.obj --units mm --category cup --body pose.json --image-size 480,640 \
        --focal 600 --mask mask.png --contact right_hand:handle --out my_case.json   # that file, without code (make_case.py)
    volsmpl hoi tune --grid w_silhouette=1e3,4e3 --model volsmpl --batch 10 --out docs/hoi   # weights on the tuning half

Writes OUT/results.json (volsmpl.apps.table's envelope: config, summary.<kind>, the paper's Table 3, per-case
records per kind, figures, meta), OUT/case_<name>.png for the first --render cases and OUT/summary.png; each
finished fit is also kept in OUT/cases/<case>_<kind>.json with the key of what made it (configuration, the case's
content, the kind's weights, the source code), so a run stopped at any moment continues with --resume, fitting
only the cases without a matching record.

Each case record holds what a user takes away (apps/hoi/fit.py): the fitted body (`body`: params, joints and
placement) and the fitted object (`object`: similarity, category, first-stage similarity), in the camera frame
(OpenCV axes, metres). Mesh files of the fitted body and the placed object, OUT/meshes/<case>/<kind>_body.ply and
<kind>_object.ply (camera frame, metres), are written for `fit` always and for a table run with --save-meshes;
they are made from the records (a reused record writes them too) and listed in the record's `meshes` (paths
relative to OUT). A progress bar runs over the cases and over each fit's steps, on a terminal only (--quiet: none).
"""
from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

from volsmpl.apps.checks import applies, claim_out, number, safe_name, warn
from volsmpl.apps.table import (REFINE_OPTIONS, CaseRecords, add_common, check_common, check_threads, checkpoint_names,
                                code_refinement, envelope, flag_cases, print_flagged, volumes, write_results)

from .console import case_line, format_table
from .plausibility import GOOD

ACTIONS = ("run", "make-db", "fit", "tune", "make-case")


def add_parser(sub):
    from . import make_case
    from .fit import PRESETS, FitConfig

    d = FitConfig()
    p = sub.add_parser("hoi", help="human-object joint optimisation: VolumetricSMPL vs COAP vs exact mesh (Table 3)",
                       description="Refine the human's and the object's scale, rotation and translation of each case "
                                   "so the object touches the body where it should without passing through it "
                                   "(supp. D.1); report time per iteration, collisions and contact per model kind.")
    p.add_argument("action", nargs="?", default="run", choices=ACTIONS,
                   help="run (default): fit database cases; make-db: build the database; fit: one case file; "
                        "tune: weights on the database's tuning half (--grid, tune.py); make-case: a case file "
                        "from your mesh, body, camera, mask and contacts (--out CASE.json, make_case.py)")
    add_common(p, out="out/hoi", seed="the interaction database's seed")
    p.add_argument("--cases", default="all", help="'all', a number N (the first N of the split) or comma-separated names")
    p.add_argument("--split", default=None, choices=["tune", "test", "all"],
                   help="database half (default: test; tune always fits the tuning half): weights are tuned on "
                        "'tune' and reported on 'test'")
    p.add_argument("--case", default=None, help="with 'fit': a case file (format in apps/hoi/case.py)")
    p.add_argument("--db", default=None, help="database folder (default: the user cache, per seed)")
    p.add_argument("--n", type=int, default=100, help="with make-db: number of cases")
    p.add_argument("--preset", default="tuned", choices=sorted(PRESETS),
                   help="weights and schedule: 'tuned' (ours: normal 1e2, penetration 1e5, the object moved along its "
                        "camera ray first, its rotation held for 40 %% of the steps, a contact within 1 cm counted as touching) "
                        "or 'paper' (normal 1e3, penetration 1e4, 1e3 with the exact mesh, every variable from the "
                        "first step)")
    p.add_argument("--iters", type=int, default=d.iters, help=f"optimisation steps (paper {d.iters})")
    p.add_argument("--lr", type=float, default=d.lr, help=f"Adam learning rate (paper {d.lr:g})")
    p.add_argument("--w-keypoints", type=float, default=d.w_keypoints, help="weight of the keypoint term (tuned)")
    p.add_argument("--w-silhouette", type=float, default=d.w_silhouette, help="weight of the silhouette term (tuned)")
    p.add_argument("--contact-fraction", type=float, default=d.contact_fraction,
                   help="share of a contact part's vertices pulled onto the object (its contact patch); 1: the whole "
                        "part, the plain one-way Chamfer")
    p.add_argument("--contact-huber", type=float, default=d.contact_huber,
                   help="metres: contact distances beyond this count linearly (pseudo-Huber); 0: squared throughout")
    p.add_argument("--contact-margin", type=float, default=None,
                   help="metres: a contact vertex this near the object counts as touching it (the contact stops "
                        "pulling there); default: the preset's (tuned %g, paper 0)" % PRESETS["tuned"]["contact_margin"])
    p.add_argument("--batch", type=int, default=1,
                   help="cases optimised together (padded; each as if alone); ms/iter is the batch's divided by it")
    p.add_argument("--grid", action="append", default=None, metavar="NAME=V1,V2",
                   help="tune: a weight and the values tried (repeat for more weights: every combination is fitted); "
                        "default w_silhouette=1e3,4e3,1.6e4")
    make_case.add_arguments(p)
    return p


def select_cases(cases: list, index: dict, split: str, which: str) -> list:
    """The cases of a split ('tune' / 'test' / 'all'), then 'all', the first N, or named ones."""
    if split != "all":
        cases = [c for c in cases if index.get(c.name, {}).get("split") == split]
    which = which.strip()
    if which == "all":
        return cases
    if which.isdigit():
        return cases[: int(which)]
    names = [n.strip() for n in which.split(",") if n.strip()]
    by_name = {c.name: c for c in cases}
    missing = [n for n in names if n not in by_name]
    if missing:
        raise ValueError(f"case(s) {missing} not in the {split} split; known: {', '.join(list(by_name)[:8])} ...")
    return [by_name[n] for n in names]


#: the measures of a fit summarised per back-end and per kind of case (mean and median, before and after)
MEASURES = ("collision_pct", "contact_cm", "obj_trans_err_cm", "obj_rot_err_deg", "scale_err_pct",
            "human_scale_err_pct")


def _values(results: list, key: str, when: str) -> list:
    """The defined values of one measure (None: not defined, a ball's rotation) over the results."""
    xs = [r.__dict__[when].get(key) for r in results]
    return [x for x in xs if x is not None]


def summarize(results: list) -> dict:
    """A model's row: means over its cases (peak memory: the largest), before and after the fit, and the medians
    (`<measure>_median`, `<measure>_median_before`)."""
    def stat(key, when="after", f=np.mean):
        xs = _values(results, key, when)
        return float(f(xs)) if xs else None

    total = float(np.mean([r.total_s for r in results])) if results else None
    out = {"n_cases": len(results), "ms_per_iter": float(np.mean([r.ms_per_iter for r in results])) if results else None,
           "peak_mem_mb": max((r.peak_mem_mb for r in results), default=None), "total_s": total,
           "iter_ms": None, "total_min": None if total is None else total / 60}
    out["iter_ms"] = out["ms_per_iter"]
    for key in MEASURES:
        out[key] = stat(key)
        out[key + "_before"] = stat(key, "before")
    for key in MEASURES:
        out[key + "_median"] = stat(key, f=np.median)
        out[key + "_median_before"] = stat(key, "before", np.median)
    return out


def by_kind(results: list, kind_of) -> dict:
    """{kind: {'n', '<measure>_median_before', '<measure>_median', 'worse_rotation'}} of a model's results grouped
    by `kind_of(name)` (the case's kind: 'sit_chair', 'hold_cup', ...; a user's case: its category). worse_rotation:
    the cases whose rotation error grew."""
    groups = {}
    for r in results:
        groups.setdefault(kind_of(r.name), []).append(r)
    out = {}
    for k, rs in sorted(groups.items()):
        row = {"n": len(rs)}
        for key in MEASURES:
            for when, suffix in (("before", "_median_before"), ("after", "_median")):
                xs = _values(rs, key, when)
                row[key + suffix] = float(np.median(xs)) if xs else None
        row["worse_rotation"] = sum(1 for r in rs if r.after.get("obj_rot_err_deg") is not None
                                    and r.after["obj_rot_err_deg"] > r.before.get("obj_rot_err_deg", np.inf))
        out[k] = row
    return out


def _cases(args, split: str, database) -> list:
    """The database cases of `split` that --cases selects; one line naming the fix when there is no database."""
    folder = Path(args.db) if args.db else database.database_folder(args.seed)
    if not (folder / "index.json").is_file():
        raise FileNotFoundError(f"no interaction database in {folder}; build it with `volsmpl hoi make-db"
                                f"{' --db ' + str(folder) if args.db else ''} --seed {args.seed}`")
    loaded = database.load_database(folder)  # reads and checks the index; each case carries its split
    cases = select_cases(loaded, {c.name: {"split": c.split} for c in loaded}, split, args.cases)
    if not cases:
        raise ValueError(f"no cases selected (split {split!r}, cases {args.cases!r})")
    return cases


#: the options each action reads (volsmpl.apps.checks.applies refuses the others)
_COMMON = {"model", "checkpoint_volsmpl", "checkpoint_coap", "threads", "out", "device"}
_REFINE = REFINE_OPTIONS
_FIT = {"preset", "iters", "lr", "w_keypoints", "w_silhouette", "contact_fraction", "contact_huber", "contact_margin"}
USES = {"make-db": {"n", "seed", "db", "threads"},
        "run": _COMMON | _FIT | _REFINE | {"resume", "render", "cases", "split", "db", "seed", "batch", "save_meshes"},
        "fit": _COMMON | _FIT | _REFINE | {"resume", "render", "case", "save_meshes"},  # fit writes its meshes always
        "tune": _COMMON | {"preset", "iters", "lr", "contact_fraction", "contact_huber", "contact_margin", "cases",
                           "split", "db", "seed", "grid", "batch"},
        "make-case": {"object", "units", "category", "size_m", "body", "keypoints", "image_size", "focal",
                      "principal", "K", "object_pose", "mask", "contact", "out"}}


def check_options(args) -> None:
    """The options of the chosen action, before any work: those it does not read refused, the numbers in range."""
    applies(args, f"hoi {args.action}", USES[args.action])
    check_threads(args.threads)
    if "seed" in USES[args.action]:
        number(args.seed, "--seed", lo=0, what="a seed: a whole number")
    if args.action == "make-db":
        number(args.n, "--n", lo=1, what="cases to make")
        return
    number(args.iters, "--iters", lo=1, what="optimisation steps")
    number(args.lr, "--lr", lo=0, lo_open=True, what="Adam's step size")
    for flag in ("w_keypoints", "w_silhouette"):
        number(getattr(args, flag), "--" + flag.replace("_", "-"), lo=0, what="a term's weight")
    number(args.contact_fraction, "--contact-fraction", lo=0, hi=1, lo_open=True, what="a share of a part's vertices")
    number(args.contact_huber, "--contact-huber", lo=0, what="metres; 0: squared throughout")
    if args.contact_margin is not None:
        number(args.contact_margin, "--contact-margin", lo=0, what="metres; 0: the contact pulls onto the surface")
    number(args.batch, "--batch", lo=1, what="cases optimised together")


def fit_config(args):
    """The FitConfig of the options: --preset's weights with the fit flags on top (--contact-margin only when
    given: else the preset's margin)."""
    from .fit import FitConfig

    margin = {} if args.contact_margin is None else {"contact_margin": args.contact_margin}
    return FitConfig.preset(args.preset, iters=args.iters, lr=args.lr, w_keypoints=args.w_keypoints,
                            w_silhouette=args.w_silhouette, contact_fraction=args.contact_fraction,
                            contact_huber=args.contact_huber, device=args.device, **margin)


def check_data(cases: list, body, device: str, warnings: list) -> None:
    """Each case's data against the body and its image (plausibility.check_case_data), before the networks load:
    what cannot be right is refused, what is unusual warned about."""
    from .case import object_mesh, object_template
    from .plausibility import check_case_data

    for c in cases:
        with torch.no_grad():
            v = body(**{k: torch.as_tensor(x)[None].to(device) for k, x in c.body.items()}).vertices[0].cpu().numpy()
        mesh, _ = object_mesh(c, object_template(c))
        check_case_data(c, mesh, v, lambda text: warn("hoi", text, warnings))


def run(args) -> int:
    from volsmpl.io.outputs import check_writable

    from volsmpl.apps.hoi import database

    check_options(args)
    if args.action == "make-case":
        from .make_case import run as make_case
        return make_case(args)
    if args.action == "make-db":
        from volsmpl.io.outputs import exclusive_folder

        folder = check_writable(args.db or database.database_folder(args.seed), "dir", "--db")
        with exclusive_folder(folder, "volsmpl hoi make-db"):
            paths = database.make_database(args.n, args.seed, folder)
        print(f"{len(paths)} cases in {folder}")
        return 0
    if args.action == "tune":
        if args.split not in (None, "tune"):
            raise ValueError(f"tune fits the database's tuning half: drop --split {args.split}")
        from .tune import parse_grid, run_tune
        args.grid = args.grid or ["w_silhouette=1e3,4e3,1.6e4"]
        parse_grid(args.grid)  # a wrong --grid stops here, before the database is read
        cases = _cases(args, "tune", database)
        with claim_out(args.out, "hoi"):
            return run_tune(args, cases, fit_config(args))
    models, ckpts = check_common(args)
    with claim_out(args.out, "hoi"):
        return _run(args, models, ckpts)


def case_meshes(out, case, kind: str, record: dict, body, save: bool) -> dict:
    """The mesh files of one case's fit by `kind`, made from its record (fit.placed_meshes; a reused record writes
    them too): OUT/meshes/<case>/<kind>_body.ply and <kind>_object.ply (camera frame, metres). Returns {'body',
    'object'}: their paths relative to OUT. save=False writes none and removes those of an earlier run in OUT at
    these paths (they would not match this run's records); returns {}."""
    from volsmpl.apps.outputs import mesh_path, write_mesh

    from .fit import placed_meshes

    paths = {what: mesh_path(out, case.name, kind, what) for what in ("body", "object")}
    if not save:
        for p in paths.values():
            p.unlink(missing_ok=True)
        return {}
    for what, (v, f) in placed_meshes(case, record, body).items():
        write_mesh(paths[what], v, f, units="m", up="y")  # the camera frame's metres and axes, as they are
    return {what: p.relative_to(out).as_posix() for what, p in paths.items()}


def _run(args, models: list, ckpts: dict) -> int:
    """`hoi run` / `hoi fit` on a claimed --out."""
    import volsmpl
    from volsmpl.apps.progress import progress, steps_bar
    from volsmpl.report import paper
    from volsmpl.io.provenance import machine_info

    from volsmpl.apps.hoi import database
    from .case import case_to_dict, load_case, mesh_digest
    from .figures import case_panel, summary_plot
    from .fit import Problem, fit_cases

    split = args.split or "test"
    out = Path(args.out)
    cfg = fit_config(args)
    if args.action == "fit":
        if not args.case:
            raise ValueError("'volsmpl hoi fit' needs --case FILE (a case file, format in apps/hoi/case.py)")
        cases = [load_case(args.case)]
    else:
        cases = _cases(args, split, database)
    body = volsmpl.create_body().to(args.device)
    warnings = []
    check_data(cases, body, args.device, warnings)
    vols = volumes(body, models, ckpts, args.device, refine=code_refinement(args))
    config = {**asdict(cfg), "preset": args.preset, "models": models, "checkpoints": checkpoint_names(models, ckpts),
              "code_refinement": code_refinement(args, vols), "split": split,
              "seed": args.seed, "batch": args.batch, "cases_requested": len(cases),
              "threads": torch.get_num_threads()}
    store = CaseRecords(out, "hoi", resume=args.resume)
    # each case's kind for the per-kind medians: the database's (sit_chair, hold_cup, ...), else its category
    kind_of = {c.name: getattr(c, "kind", None) or c.category for c in cases}
    per_model = {m: [] for m in models}
    save = args.action == "fit" or args.save_meshes  # a user's own case: its meshes always
    for i0 in progress(range(0, len(cases), args.batch), f"hoi {','.join(models)}", quiet=args.quiet,
                       unit="case" if args.batch == 1 else "batch"):
        group = cases[i0:i0 + args.batch]
        results = {c.name: {} for c in group}
        digests = {c.name: mesh_digest(c) for c in group}  # a user's mesh file: its content, not only its name
        problem = None  # the group's Problem, built once: it reads only what every kind shares (prepare sets the kind)
        for m in models:
            # the batch size and the thread count are part of a fit's key: its time per case depends on both
            # (and the thread count may change the summation order of its values)
            keys = {c.name: store.key({"config": asdict(cfg), "model": m, "case": case_to_dict(c),
                                       **({"mesh_sha256": digests[c.name]} if digests[c.name] else {}),
                                       **({"batch": args.batch} if args.batch > 1 else {})}, vols[m]) for c in group}
            recs = {c.name: store.get(f"{safe_name(c.name)}_{m}", keys[c.name]) for c in group}
            todo = [c for c in group if recs[c.name] is None]
            if todo:
                whole = len(todo) == len(group)
                if whole:
                    problem = problem or Problem(group, body, vols[m], cfg)
                for c, r in zip(todo, fit_cases(todo, body, vols[m], cfg, problem if whole else None,
                                                progress=steps_bar(args.quiet))):
                    recs[c.name] = asdict(r)
                    store.put(f"{safe_name(c.name)}_{m}", keys[c.name], recs[c.name])
            for c in group:
                r = SimpleNamespace(**recs[c.name], meshes=case_meshes(out, c, m, recs[c.name], body, save))
                per_model[m].append(r)
                results[c.name][m] = r
                print(case_line(c.name, m, r) + ("" if c in todo else "  (reused)"))
        for j, c in enumerate(group):
            if i0 + j < args.render:
                problem = problem or Problem(group, body, vols[models[0]], cfg)
                case_panel(out / f"case_{safe_name(c.name)}.png", problem, results[c.name], j)
        # results so far, after every batch: a long run stopped early still leaves its finished cases
        done = i0 + len(group)
        summary = {m: summarize(rs) for m, rs in per_model.items()}
        kinds = {m: by_kind(rs, lambda n: kind_of.get(n, "case")) for m, rs in per_model.items()}
        figures = {"summary": "summary.png",
                   **{f"case_{c.name}": f"case_{safe_name(c.name)}.png" for c in cases[: min(done, args.render)]}}
        recs_out = {m: [dict(vars(r)) for r in rs] for m, rs in per_model.items()}
        flagged = flag_cases(recs_out, "name", GOOD)
        result = envelope("hoi", config, summary, paper.rows("hoi"), recs_out, machine_info(args.device), figures,
                          flagged=flagged, warnings=warnings, by_kind=kinds)
        summary_plot(out / "summary.png", summary)
        write_results(out, result)
    note = store.note()
    if note:
        print(note)
    print(format_table(summary))
    print_flagged(flagged)
    print(f"wrote {out / 'results.json'}")
    if save:
        print(f"wrote the fitted bodies and objects under {out / 'meshes'} (.ply, camera frame, metres)")
    return 0
