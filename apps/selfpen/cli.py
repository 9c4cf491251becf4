"""`volsmpl selfpen`: repair self-intersecting bodies with VolumetricSMPL, COAP and/or the exact mesh (Table 6).

    volsmpl selfpen --model volsmpl,coap,mesh
    volsmpl selfpen --model volsmpl,coap --checkpoint-volsmpl runs/v.safetensors --checkpoint-coap runs/c.safetensors
    volsmpl selfpen --model volsmpl --cases deep_squat,arm_through_head --random-init --max-iters 20

Writes OUT/results.json (config, per-case results, per-model summary, the paper's numbers) and
OUT/render_<case>.png (before / after per model, intersecting triangles in red) for the first
--render cases; prints the summary beside the paper's table.
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from volsmpl.volume.models import model_kind, parse_models
from volsmpl.io.provenance import machine_info

from .cases import CASES_FILE, load_cases
from .optimize import PAPER, PRESETS, SelfPenConfig, format_table, repair_case, summarize

HIGHLIGHT, GREY = (0.9, 0.1, 0.1), (0.75, 0.75, 0.75)


def add_parser(sub):
    d = SelfPenConfig()
    p = sub.add_parser("selfpen", help="resolve self-intersections by pose optimisation (Sec. 4.2.4, Table 6)",
                       description="Optimise the pose of self-intersecting bodies against the volumetric "
                                   "self-penetration loss; report time, memory, iterations, triangle collisions.")
    p.add_argument("--model", default="volsmpl,coap,mesh",
                   help="comma-separated model kinds: volsmpl, coap, mesh (the exact reference); default all three")
    p.add_argument("--cases", default="all", help="comma-separated case names from the case file, or 'all'")
    p.add_argument("--case-file", default=str(CASES_FILE), help="JSON case file (default: the shipped 17 cases)")
    p.add_argument("--out", default="out/selfpen", help="output folder (results.json, render_*.png)")
    p.add_argument("--checkpoint", default=None, help="trained checkpoint (only with a single --model)")
    p.add_argument("--checkpoint-volsmpl", default=None, help="trained VolumetricSMPL checkpoint")
    p.add_argument("--checkpoint-coap", default=None, help="trained COAP checkpoint")
    p.add_argument("--random-init", action="store_true", help="random network weights (pipeline check only)")
    p.add_argument("--preset", default="tuned", choices=sorted(PRESETS),
                   help="hyper-parameter set: 'tuned' (our tuning run, docs/selfpen/tune.json) or 'paper' "
                        "(lr 1e-5, prior 1e3, self-penetration 0.1); the options below override it")
    p.add_argument("--lr", type=float, default=None, help=f"SGD learning rate (tuned {d.lr:g}, paper 1e-5)")
    p.add_argument("--max-iters", type=int, default=d.max_iters, help=f"iteration cap (paper {d.max_iters})")
    p.add_argument("--w-selfpen", type=float, default=None, help=f"self-penetration weight (tuned {d.w_selfpen:g}, paper 0.1)")
    p.add_argument("--w-prior", type=float, default=None, help=f"pose prior weight (tuned {d.w_prior:g}, paper 1e3)")
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
    p.add_argument("--seed", type=int, default=d.seed, help="seed of the point sampler")
    p.add_argument("--device", default=d.device, choices=["cpu", "cuda"])
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    p.add_argument("--render", type=int, default=3, help="render before/after images of the first N cases (0: none)")
    return p


def _checkpoints(args, models: list[str]) -> dict:
    """model -> checkpoint path or None (shipped); each given checkpoint is checked to exist and to hold its model,
    and one given for a model that does not run is refused (it would be ignored)."""
    from volsmpl.volume.models import expect_checkpoint_model

    ck = {m: None for m in models}
    for m, c in (("volsmpl", args.checkpoint_volsmpl), ("coap", args.checkpoint_coap)):
        if c and m not in ck:
            raise ValueError(f"--checkpoint-{m} is given but --model {','.join(models)} does not run {m}: add it to "
                             f"--model or drop the option.")
        if c:
            ck[m] = c
    if args.checkpoint is not None:
        if len(models) != 1:
            raise ValueError("--checkpoint needs exactly one --model; use --checkpoint-volsmpl / --checkpoint-coap for several")
        ck[models[0]] = args.checkpoint
    for m, c in ck.items():
        if c is not None and not model_kind(m).learned:
            raise ValueError(f"model '{m}' has no weights: drop its checkpoint")
    if args.random_init and any(ck.values()):
        raise ValueError("--random-init and a checkpoint exclude each other")
    for m, c in ck.items():
        if c is not None:
            option = "--checkpoint" if c == args.checkpoint else f"--checkpoint-{m}"
            expect_checkpoint_model(c, m, option, "give it to {held} (--model {held}, --checkpoint-{held}).")
    return ck


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


def render_case(path, faces: np.ndarray, results: dict, size: int = 320) -> None:
    """Before / after (per model: RepairResult kept with keep_meshes) views, front and side,
    intersecting triangles highlighted; the label gives the number of intersecting pairs."""
    from volsmpl.viz.render import grid, render_mesh, save_png

    first = next(iter(results.values()))
    panels = [("before", first.vertices_before, first.pairs_before)]
    panels += [(f"after {m}", r.vertices_after, r.pairs_after) for m, r in results.items()]
    extent = max(float(np.ptp(v[:, :2], axis=0).max()) for _, v, _ in panels) * 1.05
    images, labels = [], []
    for yaw in (0.0, 90.0):
        for label, v, pairs in panels:
            col = np.tile(np.array(GREY), (len(faces), 1))
            col[np.unique(pairs.ravel())] = HIGHLIGHT
            images.append(render_mesh(v, faces, col, size=size, yaw=yaw, extent=extent))
            labels.append(f"{label} ({len(pairs)})")
    save_png(path, grid(images, labels, cols=len(panels)))


def run(args) -> int:
    import volsmpl
    from volsmpl.io.outputs import check_writable, write_atomic

    check_writable(args.out, "dir", "--out")  # before any work: a bad folder fails in seconds
    models = parse_models(args.model)
    ckpts = _checkpoints(args, models)
    given = {k: getattr(args, k) for k in ("lr", "w_selfpen", "w_prior", "stop_checks", "tau", "patience", "stall_rtol", "max_step") if getattr(args, k) is not None}
    if args.code_grad is not None:
        given["code_grad"] = args.code_grad == "on"
    cfg = SelfPenConfig.preset(args.preset, max_iters=args.max_iters, n_points=args.n_points, seed=args.seed,
                               device=args.device, **given)
    if cfg.device == "cuda" and not torch.cuda.is_available():
        raise RuntimeError("--device cuda but torch sees no CUDA GPU; use --device cpu")
    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads {args.threads}: give a positive number of CPU threads.")
        torch.set_num_threads(args.threads)
    cases = load_cases(args.case_file, _case_names(args.cases))
    body = volsmpl.create_body().to(cfg.device)
    volumes = {}
    for m in models:  # fail early (missing checkpoint) before any work
        if args.random_init and model_kind(m).learned:
            volumes[m] = volsmpl.attach_volume(body, model=m, pretrained=False)
        else:
            volumes[m] = volsmpl.attach_volume(body, checkpoint=ckpts[m], model=m)
        volumes[m].to(cfg.device)
    if args.random_init:
        print("note: --random-init: untrained networks, the numbers only check the pipeline")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    per_model = {m: [] for m in models}
    rendered = 0
    for case in cases:
        results = {}
        for m in models:
            r = repair_case(body, volumes[m], case, cfg, keep_meshes=rendered < args.render)
            per_model[m].append(r)
            results[m] = r
            if r.status == "no_intersection":
                print(f"{case.name:28s} {m:8s} no self-intersection: left unchanged")
            else:
                print(f"{case.name:28s} {m:8s} {r.status:16s} it {r.iterations:3d}  collisions {r.collisions_before:5d} -> "
                      f"{r.collisions_after:5d} (collidable parts {r.collidable_before} -> {r.collidable_after})  "
                      f"pose change {r.pose_change_deg:6.2f} deg  {r.total_s:6.2f} s")
        if rendered < args.render and all(r.vertices_before is not None for r in results.values()):
            render_case(out / f"render_{case.name}.png", body.faces, results)
            rendered += 1
    summaries = {m: summarize(rs) for m, rs in per_model.items()}
    print()
    print(format_table(summaries))
    print("collisions: pose-induced intersecting triangle pairs (rest-pose pairs of the same shape left out), "
          "mean over cases; collidable parts: those of them between two parts the self-penetration loss may push "
          "apart (not the same part, not neighbours or ignored pairs); memory: " + ", ".join(sorted({s['memory_kind'] for s in summaries.values() if s['memory_kind']})))
    result = {
        "config": asdict(cfg), "preset": args.preset, "models": models, "random_init": bool(args.random_init),
        "checkpoints": {m: (str(ckpts[m] or "shipped") if model_kind(m).learned and not args.random_init else None)
                        for m in models},
        "case_file": str(args.case_file), "paper": PAPER, "summary": summaries,
        "cases": {m: [r.to_json() for r in rs] for m, rs in per_model.items()},
        "device": torch.cuda.get_device_name(0) if cfg.device == "cuda" else "cpu",
        "threads": torch.get_num_threads(), "meta": machine_info(cfg.device),
    }
    write_atomic(out / "results.json", json.dumps(result, indent=1))
    print(f"wrote {out / 'results.json'}" + (f" and {rendered} render(s)" if rendered else ""))
    return 0
