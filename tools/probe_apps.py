#!/usr/bin/env python3
"""Probe the four apps' user-data paths (hoi, motion, egohmr, selfpen; and `volsmpl report`) the way a new user with
their own data would: ~250 inputs, each run as `PYTHONPATH=<src> <python> -m volsmpl.cli ...` and classified.

    .venv/bin/python tools/probe_apps.py --out /tmp/probe                      # the checkout as the venv installs it
    bash tools/export_snapshot.sh /tmp/before 187d9ff                          # an older commit's package ...
    .venv/bin/python tools/probe_apps.py --src /tmp/before --out /tmp/probe_before    # ... probed
    .venv/bin/python tools/probe_apps.py --src /tmp/before --out /tmp/probe_before --resume   # continue a stopped probe
    .venv/bin/python tools/probe_apps.py --out /tmp/p --only units.motion      # the inputs whose id contains SUBSTR

Every input declares what a user needs (not what some code does):
  refuse:KW1|KW2  exit 2 and one stderr line `volsmpl <app>: error: ...` naming a keyword (case-insensitive)
  warn:KW1|KW2    exit 0 with a line `volsmpl <app>: warning: ...` naming a keyword, or a refusal as above
  flag[:KW|..]    exit 0 and results.json's top-level `flagged` non-empty (or a warning line); or a refusal as above
  ok              exit 0 and OUT/results.json (tune: tune.json) is standard JSON (no NaN / Infinity)
  early:KW|..     ok, or a refusal before any work; a failure after the work (stdout printed, cases stored) is a crash
  partial         an interrupted run (SIGINT after its first stored case): OUT/results.json holds the finished cases
Outcomes: clear (as expected), unclear (exit 2 but the error lacks the keywords, spans more lines, or an `ok` input was
refused), silent (exit 0 where a refusal / warning / flag was expected, or non-standard or missing JSON), crash
(exit 1 internal error, a traceback, a signal, a timeout, memory exhausted).

Writes OUT/probe.json (every input: id, class, app, argv, expectation, rc, stderr tail, outcome; rewritten atomically
after each input) and OUT/probe.md (per class: tried / clear / unclear / silent / crash, and the non-clear inputs).
The input files are generated in OUT/work/ (cases, scenes, frames, case files made from the probed code's own formats);
each input runs in OUT/runs/<id>/ (its --out is OUT/runs/<id>/out) with --threads 1 and OMP_NUM_THREADS=1, under a
timeout and an address-space limit (RLIMIT_AS).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CLASSES = ("units", "flags", "lost", "failed", "messages", "held")
OUTCOMES = ("clear", "unclear", "silent", "crash")


# ============================================================================================ the inputs (data)
@dataclass
class Input:
    id: str
    cls: str
    app: str                 # hoi / motion / egohmr / selfpen / report
    args: str                # after `volsmpl`; {W}: the work folder, {OUT}: this input's --out, {CASES}: selfpen's file
    expect: str
    needs: tuple = ()        # fixture groups (FIXTURES)
    plain: bool = False      # no cheap defaults appended (complete_argv)
    drop: tuple = ()         # defaults not to append
    mode: str = "run"        # run / interrupt (SIGINT after the first stored case) / second (a run into a busy --out)
    out_of: str | None = None    # share another input's --out (runs after it)
    prefill: str | None = None   # copy this work-folder path into --out first (another app's finished run)
    background: str | None = None  # mode second: the args of the run already writing into --out
    note: str = ""


INPUTS: list[Input] = []


def add(cls, app, name, args, expect, needs=(), **kw):
    INPUTS.append(Input(f"{cls}.{app}.{name}", cls, app, f"{app} {args}".strip(), expect, tuple(needs), **kw))


H, M, E, S = "{W}/hoi", "{W}/motion", "{W}/ego", "{W}/selfpen"
FIT = f"fit --case {H}/case.json"
ROOM = f"--scene {M}/room.ply --start 1.8,2.5 --goal 4.2,2.5"
FRAME = f"sample --frame {E}/frame.json --scene {E}/room.ply"
SP1 = f"--case-file {S}/one.json"


def _units():
    c = "units"
    for name, case, exp in [("mesh_m_ok", "case_mesh_m", "ok"), ("mesh_mm_declared_m", "case_mesh_mm_as_m", "warn:units"),
                            ("mesh_mm_units_missing", "case_mesh_mm_nounits", "warn:units"),
                            ("mesh_cm_declared_m", "case_mesh_cm_as_m", "warn:units"),
                            ("mesh_m_declared_mm", "case_mesh_m_as_mm", "warn:units"),
                            ("object_1mm", "case_mesh_1mm", "warn:units|size|small"),
                            ("object_100m", "case_mesh_100m", "warn:units|size|large"),
                            ("mesh_origin_70m", "case_mesh_origin70", "warn:origin|stool_origin70|far"),
                            ("init_object_141m", "case_init_obj_far", "warn:init|translation|far"),
                            ("init_human_141m", "case_init_human_far", "warn:init|translation|far"),
                            ("K_other_image_size", "case_K_other", "refuse:K|image_size|principal"),
                            ("keypoints_outside_image", "case_kp_outside", "refuse:keypoints"),
                            ("keypoints_normalised", "case_kp_normalised", "warn:keypoints|pixel"),
                            ("silhouette_outside_image", "case_sil_outside", "refuse:silhouette")]:
        add(c, "hoi", name, f"fit --case {H}/{case}.json", exp, ["hoi"])
    add(c, "hoi", "db_run_ok", f"--db {H}/db --split all --cases 2", "ok", ["hoi"])
    mr, mm, mc = f"{M}/room.ply", f"{M}/room_mm.ply", f"{M}/room_cm.ply"
    for name, args, exp in [
            ("room_m_ok", ROOM, "ok"),
            ("room_mm_ok", f"--scene {mm} --units mm --start 1800,2500 --goal 4200,2500", "ok"),
            ("room_mm_read_as_m", f"--scene {mm} --start 1800,2500 --goal 4200,2500", "refuse:--units|units"),
            ("room_mm_read_as_m_start_in_m", f"--scene {mm} --start 1.8,2.5 --goal 4.2,2.5", "refuse:--units|units"),
            ("room_cm_read_as_m", f"--scene {mc} --start 180,250 --goal 420,250", "refuse:--units|units"),
            ("room_m_read_as_mm", f"--scene {mr} --units mm --start 1.8,2.5 --goal 4.2,2.5", "refuse:--units|units"),
            ("zup_without_up", f"--scene {M}/room_zup.ply --start 1.8,-2.5 --goal 4.2,-2.5", "refuse:--up"),
            ("zup_ok", f"--scene {M}/room_zup.ply --up z --start 1.8,-2.5 --goal 4.2,-2.5", "ok"),
            ("yup_with_up_z", f"--scene {mr} --up z --start 1.8,-2.5 --goal 4.2,-2.5", "refuse:--up"),
            ("scene_1km_wide", f"--scene {M}/room_km.ply --start 300,420 --goal 302,420", "warn:units|size|--units"),
            ("scene_10cm", f"--scene {M}/room_tiny.ply --start 0.012,0.012 --goal 0.09,0.075", "warn:units|size|--units"),
            ("floor_y_on_walls", f"{ROOM} --floor-y 2.5", "refuse:--floor-y")]:
        add(c, "motion", name, args, exp, ["motion"])
    for name, args, exp in [
            ("room_ok", FRAME, "ok"),
            ("room_mm_read_as_m", f"sample --frame {E}/frame.json --scene {E}/room_mm.ply", "warn:units|--units"),
            ("room_mm_ok", f"sample --frame {E}/frame.json --scene {E}/room_mm.ply --units mm", "ok"),
            ("zup_without_up", f"sample --frame {E}/frame.json --scene {E}/room_zup.ply", "warn:--up|up"),
            ("zup_ok", f"sample --frame {E}/frame.json --scene {E}/room_zup.ply --up z", "ok"),
            ("K_other_image_size", f"sample --frame {E}/frame_K_other.json --scene {E}/room.ply", "refuse:K|principal"),
            ("keypoints_outside_image", f"sample --frame {E}/frame_kp_outside.json --scene {E}/room.ply", "refuse:keypoints"),
            ("image_size_swapped", f"sample --frame {E}/frame_hw_swapped.json --scene {E}/room.ply", "warn:image_size"),
            ("scene_1km_from_camera", f"sample --frame {E}/frame_far.json --scene {E}/room.ply",
             "warn:world_to_camera|scene|far")]:
        add(c, "egohmr", name, args, exp, ["ego"])
    add(c, "selfpen", "pose_in_degrees", f"--case-file {S}/degrees.json", "warn:degrees|radians|body_pose", ["selfpen"])
    add(c, "selfpen", "betas_x100", f"--case-file {S}/betas_x100.json", "warn:betas", ["selfpen"])


def _flags():
    c = "flags"
    actions = {"hoi": [("run", ""), ("fit", FIT), ("make-db", "make-db --n 1"), ("tune", "tune")],
               "motion": [("run", ""), ("tune", "tune"), ("scene", ROOM)],
               "egohmr": [("sample", "sample"), ("frame", FRAME), ("make-data", "make-data"), ("train", "train"),
                          ("tune", "tune")],
               "selfpen": [("run", ""), ("tune", "tune")]}
    needs = {"hoi": ["hoi"], "motion": ["motion"], "egohmr": ["ego"], "selfpen": ["selfpen"]}
    for app, acts in actions.items():
        for act, args in acts:
            for t in ("0", "-1"):
                add(c, app, f"threads{t}.{act}", f"{args} --threads {t}", "refuse:--threads", needs[app])
    for app, args in [("hoi", FIT), ("motion", ROOM), ("egohmr", FRAME), ("selfpen", "")]:
        add(c, app, "render-1", f"{args} --render -1", "refuse:--render", needs[app])
        add(c, app, "model_foo", f"{args} --model foo", "refuse:--model|foo", needs[app])
        add(c, app, "model_empty", f"{args} --model ''", "refuse:--model", needs[app])
        if app in ("hoi", "selfpen"):
            add(c, app, "model_volsmpl_foo", f"{args} --model volsmpl,foo", "refuse:--model|foo", needs[app])
            add(c, app, "checkpoint_missing", f"{args} --model volsmpl --checkpoint-volsmpl {{W}}/nothing.safetensors",
                "refuse:--checkpoint-volsmpl|nothing", needs[app])
    add(c, "hoi", "model_none", f"{FIT} --model none", "refuse:--model|none", ["hoi"])
    # options that do not apply to the mode: a user expects them to act, so at least a warning naming them
    for app, name, args, kw in [
            ("hoi", "fit_split", f"{FIT} --split test", "--split"), ("hoi", "fit_cases", f"{FIT} --cases 3", "--cases"),
            ("hoi", "fit_db", f"{FIT} --db {H}/db", "--db"),
            ("hoi", "run_case", f"--case {H}/case.json", "--case"), ("hoi", "run_grid", "--grid 1e4,1e5", "--grid"),
            ("hoi", "makedb_iters", "make-db --n 1 --iters 50", "--iters"),
            ("motion", "scene_scenes", f"{ROOM} --scenes 3", "--scenes"),
            ("motion", "scene_sequences", f"{ROOM} --sequences 3", "--sequences"),
            ("motion", "scene_seed", f"{ROOM} --seed 5", "--seed"),
            ("motion", "up_without_scene", "--up z", "--up"), ("motion", "units_without_scene", "--units mm", "--units"),
            ("motion", "floor_y_without_scene", "--floor-y 0.1", "--floor-y"),
            ("egohmr", "frame_split", f"{FRAME} --split val", "--split"),
            ("egohmr", "frame_frames", f"{FRAME} --frames 3", "--frames"),
            ("egohmr", "frame_batch", f"{FRAME} --batch 4", "--batch"),
            ("egohmr", "frame_resume", f"{FRAME} --resume", "--resume"),
            ("egohmr", "frame_steps", f"{FRAME} --steps 10", "--steps"),
            ("egohmr", "sample_steps", "sample --steps 10", "--steps"),
            ("egohmr", "sample_factors", "sample --factors 1,2", "--factors"),
            ("egohmr", "sample_units_without_scene", "sample --units mm", "--units"),
            ("selfpen", "run_grid_lr", "--grid-lr 0.1", "--grid-lr")]:
        add(c, app, f"notapply.{name}", args, f"warn:{kw}", needs[app])
    add(c, "motion", "notapply.start_without_scene", "--start 1,2 --goal 3,2", "refuse:--start|--scene", ["motion"])
    add(c, "egohmr", "notapply.scene_without_frame", f"sample --scene {E}/room.ply", "refuse:--frame", ["ego"])
    # numbers: NaN, negative, zero
    for app, base, items in [
            ("hoi", FIT, [("--iters -3", "--iters"), ("--lr nan", "--lr"), ("--lr 0", "--lr"), ("--w-keypoints -1", "--w-keypoints"),
                          ("--w-silhouette nan", "--w-silhouette"), ("--contact-fraction 2", "--contact-fraction"),
                          ("--contact-huber -1", "--contact-huber"),
                          ]),
            ("hoi", "", [("--batch 0", "--batch")]),
            ("hoi", "make-db", [("--n 0", "--n"), ("--n 1 --seed -1", "--seed")]),
            ("motion", "", [("--scenes abc", "--scenes"), ("--scenes 0", "--scenes"), ("--frames 0", "--frames"), 
                            ("--iters 0", "warn:--iters"), ("--lr nan", "--lr"),
                            ("--lr 0", "--lr"), ("--mem-budget-gb nan", "--mem-budget-gb"),
                            ("--mem-budget-gb -1", "--mem-budget-gb"),
                            ("--model coap --w coap=nan", "--w"), ("--w volsmpl=nan", "--w"), ("--w volsmpl=-1", "--w"),
                            ("--coll-frames abc", "--coll-frames"),
                            ("--cost-repeats 0", "--cost-repeats"), ("--batch 0", "--batch"), ("--seed -1", "--seed")]),
            ("motion", ROOM, [("--floor-y nan", "--floor-y")]),
            ("egohmr", FRAME, [("--scale volsmpl=-30", "--scale"), ("--scale volsmpl=nan", "--scale"),
                               ("--scale foo=1", "--scale"), ("--guide-steps 0", "--guide-steps"),
                               ("--plain-steps -1", "--plain-steps"), ("--plain-factor nan", "--plain-factor"),
                               ("--seed -1", "--seed"),
                               (f"--tuned {E}/tuned_nobest.json", "tuned_nobest|best"),
                               (f"--tuned {E}/tuned_notjson.json", "tuned_notjson|--tuned"),
                               (f"--tuned {E}/tuned_latin1.json", "tuned_latin1|--tuned"),
                               (f"--tuned {E}/tuned_missing.json", "tuned_missing|--tuned"),
                               (f"--tuned {E}/tuned_nan.json", "tuned_nan|--tuned|best"),
                               (f"--tuned {E}", "--tuned|ego")]),
            ("egohmr", "sample", [("--batch 0", "--batch"), ("--frames 0", "--frames")]),
            ("egohmr", "tune", [("--factors 0,-1", "--factors"), ("--factors nan", "--factors")]),
            ("egohmr", "train", [("--steps 0", "--steps")]),
            ("selfpen", "", [("--w-prior nan", "--w-prior"), ("--w-selfpen -1", "--w-selfpen"),
                             ("--max-step nan", "--max-step"), ("--lr -1", "--lr"),
                             ("--lr 0", "--lr"), ("--max-iters 0", "--max-iters"), ("--n-points 0", "--n-points"),
                             ("--tau 0", "--tau"),
                             ("--stall-rtol nan", "--stall-rtol"), ("--patience -1", "--patience"),
                             ("--stop-checks 0", "--stop-checks")]),
            ("selfpen", "tune", [("--grid-lr nan", "--grid-lr")])]:
        need = needs[app]
        for opt, kw in items:
            name = re.sub(r"[^A-Za-z0-9=.-]+", "_", opt.replace(E + "/", "").replace(E, "dir")).strip("_")
            act = base.split()[0] if base and not base.startswith("--") else "run"
            if base == FIT:
                act = "fit"
            elif base in (ROOM, FRAME):
                act = "scene" if base == ROOM else "frame"
            # 'warn:' marks a documented value that should be warned about, not refused (motion --iters 0)
            add(c, app, f"{act}.{name}", f"{base} {opt}", kw if kw.startswith("warn:") else f"refuse:{kw}", need)
    for opt in ("--budget-mb -5", "--budget-mb 0", "--budget-mb nan"):
        add(c, "egohmr", f"sample.{opt.replace(' ', '_')}", f"sample {opt}", "refuse:--budget-mb", ["ego"],
            drop=("--no-max-batch",))
    add(c, "hoi", "device_cpu_ok", f"{FIT} --device cpu", "ok", ["hoi"])
    add(c, "egohmr", "frame.scale_1000x_paper", f"{FRAME} --scale volsmpl=30000", "warn:--scale", ["ego"])


def _lost():
    c = "lost"
    long_hoi = f"--db {H}/db --split all --cases 4 --iters 60"
    for app, args, needs in [("hoi", long_hoi, ["hoi"]),
                             ("selfpen", "--cases all --max-iters 30", ["selfpen"]),
                             ("motion", "--sequences 3 --frames 16 --iters 25", ["motion"])]:
        add(c, app, "interrupt", args, "partial", needs, mode="interrupt")
        add(c, app, "resume", f"{args} --resume", "ok", needs, out_of=f"{c}.{app}.interrupt")
        add(c, app, "two_runs_one_out", FIT if app == "hoi" else ("" if app == "selfpen" else ""),
            "refuse:being written|another|--out", needs, mode="second", background=f"{app} {args}")
    for app, args, run in [("hoi", FIT, "runs/selfpen"), ("selfpen", "", "runs/hoi"), ("motion", "", "runs/selfpen"),
                           ("egohmr", FRAME, "runs/hoi")]:
        need = {"hoi": ["hoi"], "selfpen": ["selfpen"], "motion": ["motion"], "egohmr": ["ego"]}[app]
        add(c, app, f"out_is_{run.split('/')[1]}_run", args, "refuse:--out", need + ["runs"], prefill=run)
    add(c, "hoi", "out_is_a_file", f"{FIT} --out {{W}}/runs/hoi/results.json", "refuse:--out", ["hoi", "runs"])
    add(c, "hoi", "resume_changed_iters", f"{FIT} --resume --iters 6", "ok", ["hoi"], prefill="runs/hoi")
    for name, res, kw in [("hoi_given_selfpen", "hoi={W}/runs/selfpen/results.json", "selfpen|hoi"),
                          ("selfpen_given_hoi", "selfpen={W}/runs/hoi/results.json", "selfpen|hoi"),
                          ("motion_given_hoi", "motion={W}/runs/hoi/results.json", "motion|hoi"),
                          ("egohmr_given_selfpen", "egohmr={W}/runs/selfpen/results.json", "egohmr|selfpen"),
                          ("missing_file", "hoi={W}/runs/nothing.json", "nothing.json"),
                          ("not_json", f"hoi={H}/case_notjson.json", "case_notjson"),
                          ("not_utf8", f"hoi={H}/case_latin1.json", "case_latin1"),
                          ("unknown_name", "foo={W}/runs/hoi/results.json", "foo|--results"),
                          ("no_equals", "{W}/runs/hoi/results.json", "--results|NAME=PATH")]:
        add(c, "report", name, f"--results {res}", f"refuse:{kw}", ["runs", "hoi"])
    add(c, "report", "own_results_ok", "--results hoi={W}/runs/hoi/results.json selfpen={W}/runs/selfpen/results.json",
        "ok", ["runs"])
    add(c, "hoi", "iters0", f"{FIT} --iters 0", "early:--iters", ["hoi"])


def _failed():
    c = "failed"
    add(c, "hoi", "lr2_object_lost", f"{FIT} --lr 2 --iters 30", "flag:--lr|diverg", ["hoi"],
        note="object 285 cm off, scale error 100 % at 187d9ff")
    add(c, "hoi", "lr03_collisions_grow", f"{FIT} --lr 0.3 --iters 30", "flag:--lr|diverg", ["hoi"],
        note="collision 1 % -> 14 % at 187d9ff")
    add(c, "hoi", "lr100_exploding", f"{FIT} --lr 100 --iters 30", "flag:--lr|diverg", ["hoi"])
    add(c, "hoi", "init_object_3m_off", f"fit --case {H}/case_init_obj_3m.json --iters 30", "flag:init|far", ["hoi"])
    # every joint free and no limits (--hold off --limits off): with them the same steps repair these bodies
    # (forearm: 2331 -> 1517 pairs, 286 -> 8 collidable); without them they make the bodies worse, to be flagged
    add(c, "selfpen", "betas-5_lr1_forearm", f"--case-file {S}/extreme_neg.json --cases forearm_neg --lr 1 --max-step 0 "
        "--hold off --limits off --max-iters 30", "flag", ["selfpen"],
        note="collisions 2331 -> 2896, status resolved at 187d9ff")
    add(c, "selfpen", "betas-5_lr1_seated", f"--case-file {S}/extreme_neg.json --cases seated_neg --lr 1 --max-step 0 "
        "--hold off --limits off --max-iters 30", "flag", ["selfpen"],
        note="collisions 3451 -> 8263, status stalled at 187d9ff")
    add(c, "selfpen", "betas+5_unrepaired", f"--case-file {S}/extreme_pos.json --cases forearm_pos --max-iters 30",
        "flag", ["selfpen"], note="no_volume_points: 176 collisions left unchanged at 187d9ff")
    add(c, "motion", "goal_behind_wall", f"--scene {M}/room_wall.ply --start 1.8,2.5 --goal 4.2,2.5 --iters 8",
        "flag:wall|goal|blocked", ["motion"], note="at 187d9ff (--iters 20): goal reached through the 10 cm wall, "
        "collision in 50 % of the frames, 10.6 cm deep")
    add(c, "egohmr", "keypoints_one_pixel", f"sample --frame {E}/frame_one_pixel.json --scene {E}/room.ply",
        "flag:keypoints", ["ego"])


def _messages():
    c = "messages"
    for name, path, kw in [("case_not_utf8", "case_latin1.json", "case_latin1"), ("case_not_json", "case_notjson.json",
                           "case_notjson"), ("case_empty", "case_empty.json", "case_empty"),
                           ("case_is_a_list", "case_list.json", "case_list"), ("case_dir", "casedir", "casedir"),
                           ("mesh_txt", "case_mesh_txt.json", "stool.txt"),
                           ("mesh_empty", "case_mesh_empty.json", "stool_empty"),
                           ("mesh_points_only", "case_mesh_points.json", "stool_points"),
                           ("mesh_garbage", "case_mesh_garbage.json", "stool_garbage")]:
        add(c, "hoi", name, f"fit --case {H}/{path}", f"refuse:{kw}", ["hoi"])
    add(c, "hoi", "case_bom", f"fit --case {H}/case_bom.json", "early:case_bom", ["hoi"])
    add(c, "hoi", "name_300_chars", f"fit --case {H}/case_longname.json", "early:name|too long", ["hoi"])
    add(c, "hoi", "mesh_name_space", f"fit --case {H}/case_mesh_space.json", "ok", ["hoi"])
    add(c, "hoi", "mesh_name_umlaut", f"fit --case {H}/case_mesh_umlaut.json", "ok", ["hoi"])
    add(c, "hoi", "case_file_umlaut", f"fit --case '{H}/fall ü.json'", "ok", ["hoi"])
    add(c, "hoi", "figure_render1", f"{FIT} --render 1", "ok", ["hoi"])
    add(c, "hoi", "figure_mesh_render1", f"fit --case {H}/case_mesh_m.json --render 1", "ok", ["hoi"])
    sc = "--start 1.8,2.5 --goal 4.2,2.5"
    for name, path, exp in [("scene_space", "'{W}/motion/my room.ply'", "ok"),
                            ("scene_umlaut", "{W}/motion/tempelü.ply", "ok"),
                            ("scene_npy_points", "{W}/motion/room.npy", "ok"),
                            ("scene_pickled_npy", "{W}/motion/room_pickle.npy", "refuse:room_pickle"),
                            ("scene_empty", "{W}/motion/room_empty.ply", "refuse:room_empty"),
                            ("scene_dir", "{W}/motion/roomdir", "refuse:roomdir"),
                            ("scene_obj_text_as_txt", "{W}/motion/room_mesh.txt", "refuse:room_mesh.txt"),
                            ("scene_not_utf8_txt", "{W}/motion/room_latin1.txt", "refuse:room_latin1"),
                            ("scene_garbage_ply", "{W}/motion/room_garbage.ply", "refuse:room_garbage"),
                            ("scene_points_2d", "{W}/motion/room_2d.npy", "refuse:room_2d"),
                            ("scene_name_250_chars", "{W}/motion/" + "r" * 246 + ".ply", "early:name|too long"),
                            ("scene_figure_render1", "{W}/motion/room.ply", "ok")]:
        extra = " --render 1" if "render1" in name else ""
        add(c, "motion", name, f"--scene {path} {sc}{extra}", exp, ["motion"])
    fr = f"sample --frame {E}/frame.json --scene"
    for name, args, exp in [("scene_space", f"{fr} '{E}/my room.ply'", "ok"),
                            ("scene_umlaut", f"{fr} {E}/tempelü.ply", "ok"),
                            ("scene_pickled_npy", f"{fr} {E}/room_pickle.npy", "refuse:room_pickle"),
                            ("scene_empty", f"{fr} {E}/room_empty.ply", "refuse:room_empty"),
                            ("scene_dir", f"{fr} {E}/roomdir", "refuse:roomdir"),
                            ("frame_not_utf8", f"sample --frame {E}/frame_latin1.json --scene {E}/room.ply",
                             "refuse:frame_latin1"),
                            ("frame_not_json", f"sample --frame {E}/frame_notjson.json --scene {E}/room.ply",
                             "refuse:frame_notjson"),
                            ("frame_empty", f"sample --frame {E}/frame_empty.json --scene {E}/room.ply",
                             "refuse:frame_empty"),
                            ("frame_dir", f"sample --frame {E}/framedir --scene {E}/room.ply", "refuse:framedir"),
                            ("frame_name_250_chars", f"sample --frame {E}/{'f' * 250}.json --scene {E}/room.ply",
                             "early:name|too long"),
                            ("frame_figure_render1", f"{FRAME} --render 1", "ok")]:
        add(c, "egohmr", name, args, exp, ["ego"])
    for name, path, exp in [("casefile_not_utf8", "cases_latin1.json", "refuse:cases_latin1"),
                            ("casefile_not_json", "cases_notjson.json", "refuse:cases_notjson"),
                            ("casefile_empty", "cases_empty.json", "refuse:cases_empty"),
                            ("casefile_empty_list", "cases_emptylist.json", "refuse:cases_emptylist"),
                            ("casefile_dir", "casesdir", "refuse:casesdir"),
                            ("case_name_300_chars", "cases_longname.json", "early:name|too long"),
                            ("case_name_slash", "cases_slash.json", "early:name|/"),
                            ("casefile_space", "'my cases.json'", "ok"), ("casefile_umlaut", "fälle.json", "ok"),
                            ("case_t_pose", "cases_tpose.json", "ok")]:
        add(c, "selfpen", name, f"--case-file {S}/{path}", exp, ["selfpen"])
    add(c, "selfpen", "figure_render1", f"{SP1} --render 1", "ok", ["selfpen"])


def _held():
    c = "held"
    for name, case, kw in [("case_missing", "missing.json", "missing.json"), ("betas_nan", "case_nan_betas.json", "betas"),
                           ("K_inf", "case_inf_K.json", "K"), ("keypoints_17", "case_kp17.json", "keypoints_2d"),
                           ("confidence_negative", "case_conf_neg.json", "keypoints_2d|confidence"),
                           ("rotation_not_rotation", "case_bad_rot.json", "rotation"),
                           ("scale_zero", "case_scale0.json", "scale"),
                           ("category_unknown", "case_category.json", "category"),
                           ("contact_part_unknown", "case_part.json", "part"),
                           ("contact_region_unknown", "case_region.json", "region"),
                           ("fingerprint_other_body", "case_fingerprint.json", "body|fingerprint"),
                           ("mesh_missing", "case_mesh_missing.json", "stool_missing"),
                           ("mesh_nan_vertex", "case_mesh_nan.json", "nan"), ("init_missing", "case_noinit.json", "init")]:
        add(c, "hoi", name, f"fit --case {H}/{case}", f"refuse:{kw}", ["hoi"])
    add(c, "hoi", "db_missing", "--db {W}/nodb", "refuse:make-db|--db", ["hoi"])
    add(c, "hoi", "cases_unknown_name", f"--db {H}/db --split all --cases nosuchcase", "refuse:nosuchcase|case", ["hoi"])
    add(c, "hoi", "fit_without_case", "fit", "refuse:--case")
    for name, args, kw in [
            ("scene_missing", f"--scene {M}/missing.ply --start 1.8,2.5 --goal 4.2,2.5", "missing.ply"),
            ("start_off_floor", f"--scene {M}/room.ply --start 6.6,2.5 --goal 4.2,2.5", "--start"),
            ("goal_off_floor", f"--scene {M}/room.ply --start 1.8,1 --goal 1.8,-0.8", "--goal"),
            ("start_in_table", f"--scene {M}/room.ply --start 3,2.5 --goal 4.6,1", "--start"),
            ("start_equals_goal", f"--scene {M}/room.ply --start 1.8,2.5 --goal 1.8,2.5", "--start|--goal"),
            ("start_one_number", f"--scene {M}/room.ply --start 1.8 --goal 4.2,2.5", "--start"),
            ("start_nan", f"--scene {M}/room.ply --start nan,2.5 --goal 4.2,2.5", "--start"),
            ("scene_nan_points", f"--scene {M}/room_nan.npy --start 1.8,2.5 --goal 4.2,2.5", "nan"),
            ("pair_too_far_for_frames", f"{ROOM} --frames 8", "--frames"),
            ("tune_with_scene", f"tune {ROOM}", "--scene")]:
        add(c, "motion", name, args, f"refuse:{kw}", ["motion"])
    for name, args, kw in [
            ("frame_missing", f"sample --frame {E}/missing.json --scene {E}/room.ply", "missing.json"),
            ("scene_missing", f"sample --frame {E}/frame.json --scene {E}/missing.ply", "missing.ply"),
            ("frame_without_scene", f"sample --frame {E}/frame.json", "--scene"),
            ("keypoints_nan", f"sample --frame {E}/frame_nan.json --scene {E}/room.ply", "keypoints"),
            ("keypoints_17", f"sample --frame {E}/frame_kp17.json --scene {E}/room.ply", "keypoints"),
            ("conf_above_1", f"sample --frame {E}/frame_conf2.json --scene {E}/room.ply", "conf"),
            ("world_to_camera_not_rigid", f"sample --frame {E}/frame_badT.json --scene {E}/room.ply", "world_to_camera"),
            ("three_keypoints_seen", f"sample --frame {E}/frame_conf3.json --scene {E}/room.ply", "keypoints|conf")]:
        add(c, "egohmr", name, args, f"refuse:{kw}", ["ego"])
    for name, args, kw in [("casefile_missing", f"--case-file {S}/missing.json", "missing.json"),
                           ("betas_nan", f"--case-file {S}/nan.json", "betas"),
                           ("body_pose_72", f"--case-file {S}/pose72.json", "body_pose"),
                           ("names_twice_in_file", f"--case-file {S}/dup.json", "twice|name"),
                           ("cases_unknown", "--cases nosuchcase", "nosuchcase|unknown")]:
        add(c, "selfpen", name, args, f"refuse:{kw}", ["selfpen"])
    for app, args, need in [("hoi", FIT, ["hoi"]), ("motion", ROOM, ["motion"]), ("egohmr", FRAME, ["ego"]),
                            ("selfpen", "", ["selfpen"])]:
        add(c, app, "device_cuda", f"{args} --device cuda", "refuse:cuda|--device", need)
        add(c, app, "out_unwritable", f"{args} --out /proc/x", "refuse:--out|/proc/x", need)
    add(c, "report", "out_unwritable", "--out /proc/x/report.md", "refuse:--out|/proc/x")
    add(c, "selfpen", "one_case_ok", SP1, "ok", ["selfpen"])
    add(c, "egohmr", "sample_ok", "sample", "ok", ["ego"])
    add(c, "motion", "rooms_ok", "", "ok")


for _f in (_units, _flags, _lost, _failed, _messages, _held):
    _f()


# ============================================================================================ cheap defaults
def _has(argv, opt):
    return any(a == opt or a.startswith(opt + "=") for a in argv)


def complete_argv(inp: Input, argv: list[str], out: Path, work: Path) -> list[str]:
    """The cheap settings appended unless the input gives them (or is plain): --threads 1, --render 0, one model
    kind, few iterations / frames / cases; and --out OUT."""
    app = argv[0]
    if app == "report":
        return argv + ([] if _has(argv, "--out") else ["--out", str(out / "report.md")])
    acts = {"hoi": ("run", "make-db", "fit", "tune"), "motion": ("run", "tune"),
            "egohmr": ("sample", "make-data", "train", "tune"), "selfpen": ("run", "tune")}[app]
    act = argv[1] if len(argv) > 1 and argv[1] in acts else acts[0]
    d: list[tuple[str, list[str]]] = [("--threads", ["1"])]
    if (app, act) not in (("hoi", "make-db"), ("egohmr", "make-data")):   # they write the database / the cache
        d += [("--out", [str(out)])]
    scene = _has(argv, "--scene") or _has(argv, "--frame")
    if app == "hoi":
        if act == "make-db":
            d += [("--db", [str(out / "db")])]
        else:
            d += [("--render", ["0"])] if act != "tune" else []
            d += [("--model", ["mesh"]), ("--iters", ["5"])]
        if act in ("run", "tune") and not _has(argv, "--case"):
            d += [("--db", [str(work / "hoi/db")]), ("--cases", ["1"])]
        if act == "tune":
            d += [("--grid", ["1e4"])]
    elif app == "motion":
        d += [("--render", ["0"]), ("--model", ["volsmpl"]), ("--frames", ["40" if scene else "16"]), ("--iters", ["2"]),
              ("--cost-repeats", ["1"]), ("--cost-frames", ["1"])]
        if not scene:
            d += [("--scenes", ["2" if act == "tune" else "1"]), ("--sequences", ["1"])]
    elif app == "egohmr":
        if act in ("sample", "tune"):
            d += [("--render", ["0"])] if act == "sample" else []
            d += [("--model", ["volsmpl"])]
        if act == "sample" and not scene:  # the user's frame measures no batch: the option does not apply there
            d += [("--no-max-batch", [])]
        if act in ("sample", "tune") and not scene:
            d += [("--frames", ["2"])]
        if act == "tune":
            d += [("--factors", ["1"])]
        if act == "train":
            d += [("--steps", ["1"])]
    elif app == "selfpen":
        d += [("--render", ["0"])] if act != "tune" else []
        d += [("--model", ["volsmpl"]), ("--max-iters", ["5"])]
        if not _has(argv, "--case-file") and not _has(argv, "--cases"):
            d += [("--cases", ["forearm_through_torso_left"])]
        if act == "tune":
            d += [("--grid-lr", ["1"]), ("--grid-w-selfpen", ["1"]), ("--grid-w-prior", ["1"])]
    for opt, vals in d:
        if opt in inp.drop or _has(argv, opt) or (inp.plain and opt != "--out"):
            continue
        argv = argv + [opt, *vals]
    return argv


def input_argv(inp: Input, out: Path, work: Path, cases_file: str) -> list[str]:
    subst = {"W": str(work), "OUT": str(out), "CASES": cases_file}
    toks = [t.format(**subst) for t in shlex.split(inp.args)]
    return complete_argv(inp, toks, out, work)


# ============================================================================================ the input files
class Env:
    """How every command runs: the python, PYTHONPATH=<src>, one thread, no debug tracebacks."""

    def __init__(self, python: str, src: str | None, mem_gb: float):
        self.python, self.src, self.mem = python, src, int(mem_gb * 2 ** 30)
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VOLSMPL_DEBUG")}
        env.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", PYTHONIOENCODING="utf-8")
        if src:
            env["PYTHONPATH"] = str(Path(src).resolve())
        self.env = env

    def limit(self):
        resource.setrlimit(resource.RLIMIT_AS, (self.mem, self.mem))

    def cli(self, argv):
        return [self.python, "-m", "volsmpl.cli", *argv]

    def run(self, cmd, cwd, timeout=600):
        """A helper command (fixtures): (rc, stdout, stderr)."""
        p = subprocess.run(cmd, cwd=cwd, env=self.env, capture_output=True, text=True, timeout=timeout,
                           preexec_fn=self.limit, errors="replace")
        return p.returncode, p.stdout, p.stderr


def _box(lo, hi):
    import trimesh
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2))


def _mesh(v, f):
    import trimesh
    return trimesh.Trimesh(np.asarray(v, float), np.asarray(f), process=False)


def _write_json(path: Path, obj, text=None, encoding="utf-8"):
    path.write_bytes((text if text is not None else json.dumps(obj, ensure_ascii=False)).encode(encoding))


def build_hoi(w: Path, env: Env):
    """The interaction database (`volsmpl hoi make-db --n 4`), its stool case and variants of it; a stool-like
    cylinder mesh (metres, resting on y = 0) in several units and files."""
    import trimesh
    d = w / "hoi"
    d.mkdir(parents=True, exist_ok=True)
    rc, so, se = env.run(env.cli(["hoi", "make-db", "--n", "4", "--db", str(d / "db"), "--seed", "0", "--threads", "1"]), d)
    if rc != 0:
        raise RuntimeError(f"hoi make-db failed: {se.strip().splitlines()[-1:]}")
    index = json.loads((d / "db/index.json").read_text())
    name = next((c["name"] for c in index["cases"] if c.get("category") == "stool"), index["cases"][0]["name"])
    base = json.loads((d / "db" / f"{name}.json").read_text())
    if base.get("image"):
        shutil.copy(d / "db" / base["image"], d / base["image"])
    _write_json(d / "case.json", base)
    _write_json(d / "fall ü.json", base)
    cyl = trimesh.creation.cylinder(radius=0.18, height=0.45, sections=32)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    cyl.apply_translation([0, 0.225, 0])
    for fname, scale, shift in [("stool_m.obj", 1, 0), ("stool_mm.obj", 1000, 0), ("stool_cm.obj", 100, 0),
                                ("stool_1mm.obj", 0.001 / 0.45, 0), ("stool_100m.obj", 100 / 0.45, 0),
                                ("stool_origin70.obj", 1, 70), ("my stool.obj", 1, 0), ("stool_ü.obj", 1, 0)]:
        m = cyl.copy()
        m.apply_scale(scale)
        m.apply_translation([shift, 0, 0])
        m.export(d / fname)
    (d / "stool.txt").write_text((d / "stool_m.obj").read_text())
    (d / "stool_empty.obj").write_bytes(b"")
    trimesh.PointCloud(cyl.vertices).export(d / "stool_points.ply")
    (d / "stool_garbage.obj").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8)))
    (d / "casedir").mkdir(exist_ok=True)
    lines = (d / "stool_m.obj").read_text().splitlines()
    i = next(k for k, l in enumerate(lines) if l.startswith("v "))
    lines[i] = "v nan 0.0 0.0"
    (d / "stool_nan.obj").write_text("\n".join(lines) + "\n")

    def variant(fname, edit=None, text=None, **mesh):
        c = json.loads(json.dumps(base))
        if mesh:
            c["object"] = {"category": base["object"]["category"], **mesh}
            c["contacts"] = [[p, "any"] for p, _ in base["contacts"]]
        if edit:
            edit(c)
        _write_json(d / fname, c, text)

    def kmul(c, f):
        c["camera"]["K"] = (np.asarray(c["camera"]["K"]) * np.array([[f], [f], [1]])).tolist()

    def shift(key, v):
        def e(c):
            c["init"][key]["translation"] = (np.asarray(c["init"][key]["translation"]) + v).tolist()
        return e

    def kp(fn):
        def e(c):
            a = np.asarray(c["keypoints_2d"], float)
            a[:, :2] = fn(a[:, :2], c)
            c["keypoints_2d"] = a.tolist()
        return e

    H, W = base["camera"]["image_size"]
    variant("case_mesh_m.json", mesh="stool_m.obj", units="m")
    variant("case_mesh_mm_as_m.json", mesh="stool_mm.obj", units="m")
    variant("case_mesh_mm_nounits.json", mesh="stool_mm.obj")
    variant("case_mesh_cm_as_m.json", mesh="stool_cm.obj", units="m")
    variant("case_mesh_m_as_mm.json", mesh="stool_m.obj", units="mm")
    variant("case_mesh_1mm.json", mesh="stool_1mm.obj", units="m")
    variant("case_mesh_100m.json", mesh="stool_100m.obj", units="m")
    variant("case_mesh_origin70.json", mesh="stool_origin70.obj", units="m")
    variant("case_mesh_space.json", mesh="my stool.obj", units="m")
    variant("case_mesh_umlaut.json", mesh="stool_ü.obj", units="m")
    variant("case_mesh_txt.json", mesh="stool.txt", units="m")
    variant("case_mesh_empty.json", mesh="stool_empty.obj", units="m")
    variant("case_mesh_points.json", mesh="stool_points.ply", units="m")
    variant("case_mesh_garbage.json", mesh="stool_garbage.obj", units="m")
    variant("case_mesh_missing.json", mesh="stool_missing.obj", units="m")
    variant("case_mesh_nan.json", mesh="stool_nan.obj", units="m")
    variant("case_init_obj_far.json", shift("object", np.array([100.0, 0, 100.0])))
    variant("case_init_human_far.json", shift("human", np.array([100.0, 0, 100.0])))
    variant("case_init_obj_3m.json", shift("object", np.array([1.5, 0, 2.6])))
    variant("case_K_other.json", lambda c: kmul(c, 4.0))
    variant("case_kp_outside.json", kp(lambda a, c: a + 2000.0))
    variant("case_kp_normalised.json", kp(lambda a, c: a / np.array([W, H])))
    variant("case_sil_outside.json", lambda c: c.update(silhouette=(np.asarray(c["silhouette"]) + 3000).tolist()))
    c = json.loads(json.dumps(base))
    c["name"] = "stuhl_für_tempelü"
    _write_json(d / "case_latin1.json", c, encoding="latin-1")
    (d / "case_notjson.json").write_text("format: volsmpl-hoi-case\nname: mine\n")
    (d / "case_empty.json").write_bytes(b"")
    (d / "case_list.json").write_text("[]")
    (d / "case_bom.json").write_bytes(b"\xef\xbb\xbf" + json.dumps(base).encode())
    variant("case_longname.json", lambda c: c.update(name="sitting_on_my_own_stool_" * 12 + "x" * 12))
    variant("case_nan_betas.json", lambda c: c["body"]["betas"].__setitem__(0, float("nan")))  # json writes NaN
    variant("case_inf_K.json", lambda c: c["camera"]["K"][0].__setitem__(0, float("inf")))
    variant("case_kp17.json", lambda c: c.update(keypoints_2d=c["keypoints_2d"][:17]))
    variant("case_conf_neg.json", lambda c: c["keypoints_2d"][3].__setitem__(2, -1.0))
    variant("case_bad_rot.json", lambda c: c["init"]["object"].update(rotation=[[2, 0, 0], [0, 1, 0], [0, 0, 1]]))
    variant("case_scale0.json", lambda c: c["init"]["human"].update(scale=0.0))
    variant("case_category.json", lambda c: c["object"].update(category="throne"))
    variant("case_part.json", lambda c: c.update(contacts=[["left_tail", "any"]]))
    variant("case_region.json", lambda c: c.update(contacts=[[c["contacts"][0][0], "armrest_of_mars"]]))
    variant("case_fingerprint.json", lambda c: c["body"].update(fingerprint="0123456789abcdef"))
    variant("case_noinit.json", lambda c: c.pop("init"))


def _room(wall=False):
    """A 6 x 5 m room (y up, metres, floor plane at y = 0): four walls, a table between x 2.6 and 3.4, a cupboard;
    wall=True adds a closed wall at x = 3 across the room (start and goal on both sides)."""
    import trimesh
    parts = [_mesh([[0, 0, 0], [6, 0, 0], [6, 0, 5], [0, 0, 5]], [[0, 2, 1], [0, 3, 2]]),
             _box([-0.1, 0, -0.1], [6.1, 2.5, 0]), _box([-0.1, 0, 5], [6.1, 2.5, 5.1]),
             _box([-0.1, 0, 0], [0, 2.5, 5]), _box([6, 0, 0], [6.1, 2.5, 5]),
             _box([2.6, 0, 1.5], [3.4, 0.75, 3.5]), _box([5.2, 0, 0.2], [5.8, 2.0, 1.0])]
    if wall:
        parts.append(_box([2.95, 0, 0], [3.05, 2.5, 5]))
    return trimesh.util.concatenate(parts)


def build_motion(w: Path, env: Env):
    """The room as a user's scene in several units, axes, names and file kinds (meshes, point arrays, broken files)."""
    import trimesh
    d = w / "motion"
    d.mkdir(parents=True, exist_ok=True)
    room = _room()
    room.export(d / "room.ply")
    room.export(d / "my room.ply")
    room.export(d / "tempelü.ply")
    room.export(d / ("r" * 246 + ".ply"))
    _room(wall=True).export(d / "room_wall.ply")
    for fname, s in [("room_mm.ply", 1000.0), ("room_cm.ply", 100.0), ("room_km.ply", 1000.0 / 6), ("room_tiny.ply", 0.1 / 6)]:
        m = room.copy()
        m.apply_scale(s)
        m.export(d / fname)
    z = room.copy()   # y-up (X, Y, Z) -> z-up (X, -Z, Y)
    z.vertices = np.stack([room.vertices[:, 0], -room.vertices[:, 2], room.vertices[:, 1]], 1)
    z.export(d / "room_zup.ply")
    pts = trimesh.sample.sample_surface(room, 40000, seed=0)[0]
    np.save(d / "room.npy", np.asarray(pts, np.float64))
    np.save(d / "room_pickle.npy", np.array([{"points": pts}], dtype=object), allow_pickle=True)
    np.save(d / "room_2d.npy", pts[:, :2])
    bad = pts.copy()
    bad[::100] = np.nan
    np.save(d / "room_nan.npy", bad)
    (d / "room_empty.ply").write_bytes(b"")
    (d / "roomdir").mkdir(exist_ok=True)
    room.export(d / "room_mesh.obj")
    (d / "room_mesh.txt").write_text((d / "room_mesh.obj").read_text())
    (d / "room_latin1.txt").write_bytes("# Raum für Tempelü\n".encode("latin-1")
                                        + b"\n".join(b"%g %g %g" % tuple(p) for p in pts[:2000]))
    (d / "room_garbage.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\n"
                                         + bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8)))


EGO_SNIPPET = r"""
import json, sys
import numpy as np
from volsmpl.apps.egohmr.data import make_frames
from volsmpl.apps.egohmr.room_checks import load_room
f = make_frames("test", 1)[0]
T = np.eye(4); T[:3, :3] = np.asarray(f.R); T[:3, 3] = np.asarray(f.t)
load_room(int(f.room_seed)).mesh().export(sys.argv[1] + "/room.ply")
json.dump({"K": np.asarray(f.K).tolist(), "image_size": [int(x) for x in f.image_size],
           "keypoints": np.asarray(f.keypoints).tolist(), "conf": np.asarray(f.conf).tolist(),
           "world_to_camera": T.tolist()}, open(sys.argv[1] + "/frame.json", "w"))
"""


def build_ego(w: Path, env: Env):
    """A user's frame (the first generated test frame: K, keypoints, conf, world_to_camera) and its room (world
    frame, y up, metres) as files, with variants."""
    import trimesh
    d = w / "ego"
    d.mkdir(parents=True, exist_ok=True)
    rc, so, se = env.run([env.python, "-c", EGO_SNIPPET, str(d)], d)
    if rc != 0:
        raise RuntimeError(f"egohmr frame export failed: {se.strip().splitlines()[-1:]}")
    room = trimesh.load(d / "room.ply", force="mesh", process=False)
    for fname in ("my room.ply", "tempelü.ply"):
        shutil.copy(d / "room.ply", d / fname)
    mm = room.copy()
    mm.apply_scale(1000.0)
    mm.export(d / "room_mm.ply")
    z = room.copy()
    z.vertices = np.stack([room.vertices[:, 0], -room.vertices[:, 2], room.vertices[:, 1]], 1)
    z.export(d / "room_zup.ply")
    np.save(d / "room_pickle.npy", np.array([{"mesh": "room.ply"}], dtype=object), allow_pickle=True)
    (d / "room_empty.ply").write_bytes(b"")
    for sub in ("roomdir", "framedir"):
        (d / sub).mkdir(exist_ok=True)
    base = json.loads((d / "frame.json").read_text())
    H, W = base["image_size"]

    def variant(fname, edit):
        f = json.loads(json.dumps(base))
        edit(f)
        _write_json(d / fname, f)

    def kpmap(fn):
        return lambda f: f.update(keypoints=fn(np.asarray(f["keypoints"], float)).tolist())

    variant("frame_K_other.json", lambda f: f.update(K=(np.asarray(f["K"]) * np.array([[3], [3], [1]])).tolist()))
    variant("frame_kp_outside.json", kpmap(lambda a: a + np.array([W, H]) * 1.5))
    variant("frame_hw_swapped.json", lambda f: f.update(image_size=[W, H]))
    variant("frame_far.json", lambda f: f["world_to_camera"][0].__setitem__(3, f["world_to_camera"][0][3] + 1000.0))
    variant("frame_one_pixel.json", lambda f: (f.update(keypoints=[[W / 2, H / 2]] * len(f["keypoints"])),
                                               f.update(conf=[1.0] * len(f["conf"]))))
    variant("frame_kp17.json", lambda f: f.update(keypoints=f["keypoints"][:17]))
    variant("frame_conf2.json", lambda f: f["conf"].__setitem__(0, 2.0))
    variant("frame_conf3.json", lambda f: f.update(conf=[0.9 if i < 3 else 0.0 for i in range(len(f["conf"]))]))
    variant("frame_badT.json", lambda f: f.update(world_to_camera=(np.diag([2.0, 1, 1, 1])).tolist()))
    variant("frame_nan.json", lambda f: f["keypoints"][0].__setitem__(0, float("nan")))  # json writes NaN
    _write_json(d / "frame_latin1.json", None, json.dumps(base)[:-1] + ', "note": "Küche"}', encoding="latin-1")
    (d / "frame_notjson.json").write_text("K = [[500, 0, 320], [0, 500, 240], [0, 0, 1]]\n")
    (d / "frame_empty.json").write_bytes(b"")
    shutil.copy(d / "frame.json", d / ("f" * 250 + ".json"))
    (d / "tuned_nobest.json").write_text(json.dumps({"scales": {"volsmpl": 30.0}}))
    (d / "tuned_notjson.json").write_text("best: volsmpl=30\n")
    (d / "tuned_latin1.json").write_bytes('{"best": {"volsmpl": 30.0}, "note": "für"}'.encode("latin-1"))
    (d / "tuned_nan.json").write_text('{"best": {"volsmpl": NaN}}')


SELFPEN_SNIPPET = "import volsmpl.apps.selfpen.cases as c; print(c.CASES_FILE)"


def build_selfpen(w: Path, env: Env):
    """Case files from the shipped one (found through the probed code): one case, extreme shapes, variants."""
    d = w / "selfpen"
    d.mkdir(parents=True, exist_ok=True)
    rc, so, se = env.run([env.python, "-c", SELFPEN_SNIPPET], d)
    if rc != 0:
        raise RuntimeError(f"selfpen case file not found: {se.strip().splitlines()[-1:]}")
    shipped = json.loads(Path(so.strip().splitlines()[-1]).read_text())
    cases = shipped["cases"] if isinstance(shipped, dict) else shipped
    by = {c["name"]: {k: c[k] for k in ("name", "description", "betas", "global_orient", "body_pose") if k in c}
          for c in cases}
    one = by["forearm_through_torso_left"]

    def write(fname, items, encoding="utf-8"):
        _write_json(d / fname, {"version": 1, "cases": items}, encoding=encoding)

    def alt(sign):
        return [float(sign * (1 if i % 2 == 0 else -1)) for i in range(10)]

    write("one.json", [one])
    write("my cases.json", [one])
    write("fälle.json", [one])
    tag = {1: "pos", -1: "neg"}
    for s in (1, -1):
        write(f"extreme_{tag[s]}.json", [dict(by["forearm_through_torso_left"], name=f"forearm_{tag[s]}", betas=alt(5 * s)),
                                         dict(by["seated_hands_in_thighs"], name=f"seated_{tag[s]}", betas=alt(5 * s))])
    write("degrees.json", [dict(one, name="degrees", body_pose=[float(np.degrees(v)) for v in one["body_pose"]])])
    write("betas_x100.json", [dict(one, name="betas_x100", betas=[100.0 * b for b in one["betas"]])])
    write("cases_latin1.json", [dict(one, name="unterarm", description="Unterarm durch den Bauch, für Tempelü")],
          encoding="latin-1")
    (d / "cases_notjson.json").write_text("cases:\n  - name: mine\n")
    (d / "cases_empty.json").write_bytes(b"")
    (d / "cases_emptylist.json").write_text("[]")
    (d / "casesdir").mkdir(exist_ok=True)
    write("cases_longname.json", [dict(one, name="forearm_through_torso_" * 13 + "x" * 14)])
    write("cases_slash.json", [dict(one, name="mine/forearm")])
    write("cases_tpose.json", [dict(one, name="t_pose", body_pose=[0.0] * 69)])
    write("nan.json", [dict(one, name="nan_betas", betas=[float("nan")] + one["betas"][1:])])  # json writes NaN
    write("pose72.json", [dict(one, name="pose72", body_pose=one["body_pose"] + [0.0, 0.0, 0.0])])
    write("dup.json", [one, one])


def build_runs(w: Path, env: Env):
    """Finished runs of two apps (hoi fit, selfpen one case): folders for --out and results for `volsmpl report`."""
    d = w / "runs"
    d.mkdir(parents=True, exist_ok=True)
    for app, argv in [("hoi", ["hoi", "fit", "--case", str(w / "hoi/case.json"), "--model", "mesh", "--iters", "5"]),
                      ("selfpen", ["selfpen", "--case-file", str(w / "selfpen/one.json"), "--model", "volsmpl",
                                   "--max-iters", "5"])]:
        rc, so, se = env.run(env.cli(argv + ["--render", "0", "--threads", "1", "--out", str(d / app)]), d)
        if rc != 0 or not (d / app / "results.json").is_file():
            raise RuntimeError(f"{app} run for the run folders failed: {se.strip().splitlines()[-1:]}")


FIXTURES = {"hoi": (build_hoi, ()), "motion": (build_motion, ()), "ego": (build_ego, ()),
            "selfpen": (build_selfpen, ()), "runs": (build_runs, ("hoi", "selfpen"))}


def build_fixtures(names, work: Path, env: Env, log) -> dict:
    """Build each fixture group once (a stamp file marks it done); {group: error message} of the failed ones."""
    failed, done = {}, set()

    def one(n):
        if n in done:
            return
        for dep in FIXTURES[n][1]:
            one(dep)
        done.add(n)
        stamp = work / f".built_{n}"
        if stamp.exists():
            return
        bad = [dep for dep in FIXTURES[n][1] if dep in failed]
        if bad:
            failed[n] = f"needs {bad[0]}: {failed[bad[0]]}"
            return
        t0 = time.time()
        try:
            FIXTURES[n][0](work, env)
            stamp.write_text("ok\n")
            log(f"fixtures {n}: built in {time.time() - t0:.0f} s")
        except Exception as e:  # noqa: BLE001 - recorded against the inputs that need it
            failed[n] = f"{type(e).__name__}: {e}"
            log(f"fixtures {n}: FAILED {failed[n]}")

    work.mkdir(parents=True, exist_ok=True)
    for n in names:
        one(n)
    return failed


# ============================================================================================ running and judging
ERR = re.compile(r"^volsmpl [\w?-]+: error: ")
WARN = re.compile(r"^volsmpl [\w?-]+: warning: ")
BAR = re.compile(r"\d+%\|.*\||\bit/s\]|\bs/it\]")
MEMORY = re.compile(r"MemoryError|can't allocate memory|Cannot allocate memory|std::bad_alloc|out of memory", re.I)


def message_lines(stderr: str) -> list[str]:
    """stderr's lines without argparse's usage block and progress bars."""
    out, usage = [], False
    for line in stderr.replace("\r", "\n").splitlines():
        if not line.strip():
            usage = False
            continue
        if line.startswith("usage: "):
            usage = True
            continue
        if usage and line.startswith(" "):
            continue
        usage = False
        if not BAR.search(line):
            out.append(line.rstrip())
    return out


def _reject(c):
    raise ValueError(f"non-standard JSON constant {c}")


def read_result(out: Path):
    """(status, data): 'missing' / 'nonstandard' / 'ok' of OUT/results.json (else OUT/tune.json)."""
    for name in ("results.json", "tune.json"):
        p = out / name
        if p.is_file():
            try:
                return "ok", json.loads(p.read_text(encoding="utf-8"), parse_constant=_reject)
            except ValueError:
                return "nonstandard", None
    return "missing", None


def _records(data) -> int:
    cases = data.get("cases") if isinstance(data, dict) else None
    if isinstance(cases, dict):
        return sum(len(v) for v in cases.values() if isinstance(v, list))
    return len(cases) if isinstance(cases, list) else 0


def _stored(out: Path) -> int:
    d = out / "cases"
    return len([p for p in d.glob("*.json")]) if d.is_dir() else 0


def worked(stdout: str, stderr: str, out: Path) -> bool:
    """Whether a run did work before it failed: it printed results or progress, or began to store cases / figures."""
    return bool(stdout.strip() or BAR.search(stderr) or (out / "cases").is_dir() or any(out.glob("*.png")))


def names(line: str, keys) -> bool:
    """Whether `line` names one of the keywords (case-insensitive; a plain word only as a whole word: 'K', 'up')."""
    low = line.lower()
    return any(re.search(rf"(?<![\w]){re.escape(k)}(?![\w])", low) if re.fullmatch(r"\w+", k) else k in low
               for k in keys)


def classify(inp: Input, argv, rc, stdout, stderr, out: Path, info: dict) -> tuple[str, str]:
    kind, _, kws = inp.expect.partition(":")
    keys = [k.strip().lower() for k in kws.split("|") if k.strip()]
    msg = message_lines(stderr)
    if rc is None:
        return "crash", f"timeout after {info.get('timeout')} s"
    if rc < 0:
        return "crash", f"killed by signal {-rc}" + (" (memory limit?)" if -rc == signal.SIGKILL else "")
    if "Traceback (most recent call last)" in stderr:
        return "crash", "Python traceback"
    if MEMORY.search(stderr):
        return "crash", "memory exhausted"
    if rc == 1:
        return "crash", "internal error" if "internal error" in stderr else "exit 1"
    if kind == "partial":
        if rc not in (0, 2, 130):
            return "crash", f"exit {rc}"
        n = info.get("stored_at_interrupt", 0)
        if not info.get("interrupted"):
            if rc == 2 and any(ERR.match(m) for m in msg):
                return "unclear", "refused before storing a case"
            return "unclear", "probe: the run ended before the interrupt"
        status, data = read_result(out)
        if status == "missing":
            return "silent", f"no results.json after the interrupt ({n} finished case(s) stored in OUT/cases/)"
        if status == "nonstandard":
            return "silent", "results.json is not standard JSON"
        k = _records(data)
        return ("clear", f"results.json holds {k} record(s)") if k >= max(n, 1) else \
            ("silent", f"results.json holds {k} record(s) of the {n} finished")
    if rc not in (0, 2):
        return "crash", f"exit {rc}"
    errs = [m for m in msg if ERR.match(m)]
    warns = [m for m in msg if WARN.match(m)]
    if rc == 2:
        if not errs:
            return "unclear", "exit 2 without a `volsmpl <app>: error:` line"
        if kind == "ok":
            return "unclear", "a valid input was refused"
        if kind == "early" and worked(stdout, stderr, out):
            return "crash", "failed after the work (it printed results / stored cases first)"
        if keys and not names(errs[-1], keys):
            return "unclear", f"the error names none of {'|'.join(keys)}"
        extra = [m for m in msg if not ERR.match(m) and not WARN.match(m)]
        if extra or len(errs) > 1:
            return "unclear", f"{len(extra) + len(errs) - 1} stderr line(s) besides the error"
        return "clear", "refused"
    status, data = read_result(out)
    if status == "nonstandard":
        return "silent", "exit 0 but results.json is not standard JSON (NaN / Infinity)"
    if kind in ("ok", "early"):
        if status == "missing" and argv[0] != "report" and "make-db" not in argv:
            return "silent", "exit 0 but no results.json"
        return "clear", "ran"
    if kind == "warn":
        if any(names(w, keys) for w in warns):
            return "clear", "warned"
        return "silent", "exit 0 without a warning naming " + "|".join(keys) + (f" ({len(warns)} other warning(s))"
                                                                               if warns else "")
    if kind == "flag":
        flagged = data.get("flagged") if isinstance(data, dict) else None
        if flagged or warns:
            return "clear", "flagged" if flagged else "warned"
        return "silent", "exit 0, nothing flagged" + ("" if status == "ok" else " (no results.json)")
    return "silent", "exit 0: accepted"


def _start(env: Env, argv, cwd: Path):
    return subprocess.Popen(env.cli(argv), cwd=cwd, env=env.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, errors="replace", preexec_fn=env.limit, start_new_session=True)


def _finish(p, timeout):
    try:
        so, se = p.communicate(timeout=timeout)
        return p.returncode, so, se
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        so, se = p.communicate()
        return None, so, se


def _stop(p, wait=60):
    """SIGINT, then SIGKILL of the process group after `wait` s; its (rc, stdout, stderr)."""
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
    return _finish(p, wait)


def run_input(inp: Input, argv, env: Env, out: Path, cwd: Path, timeout: float) -> dict:
    info = {"timeout": timeout}
    t0 = time.time()
    if inp.mode == "interrupt":
        p = _start(env, argv, cwd)
        while p.poll() is None and _stored(out) == 0 and time.time() - t0 < timeout:
            time.sleep(0.3)
        if p.poll() is None and _stored(out):
            time.sleep(0.3)
            info["stored_at_interrupt"] = _stored(out)
            info["interrupted"] = True
            rc, so, se = _stop(p)
        else:   # it ended (or timed out) before storing a case: judged as it is
            info["interrupted"] = False
            rc, so, se = _finish(p, max(1.0, timeout - (time.time() - t0)))
    elif inp.mode == "second":
        bargv = complete_argv(inp, shlex.split(inp.background.format(W=str(cwd.parents[1] / "work"))), out,
                              cwd.parents[1] / "work")
        info["background_argv"] = bargv
        bg = _start(env, bargv, cwd)
        while bg.poll() is None and not (out / "cases").is_dir() and time.time() - t0 < 60:
            time.sleep(0.3)
        time.sleep(1.0)
        p = _start(env, argv, cwd)
        rc, so, se = _finish(p, timeout)
        brc, bso, bse = _stop(bg)
        info["background_rc"] = brc
        info["background_stderr_tail"] = message_lines(bse)[-3:]
    else:
        p = _start(env, argv, cwd)
        rc, so, se = _finish(p, timeout)
    info["seconds"] = round(time.time() - t0, 1)
    return {"rc": rc, "stdout": so, "stderr": se, **info}


def source_digest(src: str | None) -> str:
    """sha256 of the probed package's .py files (names and bytes): a --src changed during the probe stops it."""
    import hashlib
    if not src:
        return ""
    root = Path(src) / "volsmpl"
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


# ============================================================================================ the report
def write_atomic(path: Path, text: str):
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def short(s: str, n: int = 150) -> str:
    s = " ".join(s.split())
    return s if len(s) <= n else s[: n - 3] + "..."


def markdown(doc: dict) -> str:
    recs = doc["inputs"]
    lines = [f"# App probe: {doc['src']}" + (f" (commit {doc['source_commit']})" if doc.get("source_commit") else ""),
             "", f"python {doc['python']}; {len(recs)} inputs; "
             f"started {doc['started']}", "", "| class | tried | clear | unclear | silent | crash |",
             "|---|---:|---:|---:|---:|---:|"]
    total = {o: 0 for o in OUTCOMES}
    for cls in CLASSES:
        rs = [r for r in recs if r["class"] == cls]
        if not rs:
            continue
        n = {o: sum(r["outcome"] == o for r in rs) for o in OUTCOMES}
        for o in OUTCOMES:
            total[o] += n[o]
        lines.append(f"| {cls} | {len(rs)} | " + " | ".join(str(n[o]) for o in OUTCOMES) + " |")
    lines.append(f"| **all** | {len(recs)} | " + " | ".join(str(total[o]) for o in OUTCOMES) + " |")
    lines += ["", "## Non-clear inputs", ""]
    for r in recs:
        if r["outcome"] != "clear":
            tail = r["stderr_tail"][-1] if r["stderr_tail"] else ""
            lines.append(f"- `{r['id']}` ({r['expect']}): **{r['outcome']}**: {r['why']}"
                         + (f" — `{short(tail, 140)}`" if tail else ""))
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--src", default=None, help="folder holding the package (tools/export_snapshot.sh DIR COMMIT); "
                                                "default: the venv's install of this checkout (no PYTHONPATH)")
    ap.add_argument("--out", required=True, help="folder for probe.json, probe.md, work/ and runs/")
    ap.add_argument("--python", default=str(ROOT / ".venv/bin/python") if (ROOT / ".venv/bin/python").exists()
                    else sys.executable)
    ap.add_argument("--only", default=None, help="only the inputs whose id contains SUBSTR (comma-separated: any of them)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=180.0, help="seconds per input (then: crash 'timeout')")
    ap.add_argument("--mem-gb", type=float, default=8.0, help="address-space limit of each command (RLIMIT_AS)")
    ap.add_argument("--resume", action="store_true", help="skip the inputs probe.json holds with the same argv "
                    "(without it the selected inputs run again; the other records of the same --src are kept)")
    ap.add_argument("--list", action="store_true", help="list the selected inputs and exit")
    a = ap.parse_args(argv)
    if a.jobs < 1 or a.timeout <= 0 or a.mem_gb <= 0:
        ap.error("--jobs, --timeout and --mem-gb must be positive")
    if a.src and not (Path(a.src) / "volsmpl" / "cli.py").is_file():
        ap.error(f"--src {a.src}: no volsmpl/cli.py inside (make one with tools/export_snapshot.sh DIR COMMIT)")
    only = [t for t in (a.only or "").split(",") if t]
    sel = [i for i in INPUTS if not only or any(t in i.id for t in only)]
    ids = [i.id for i in INPUTS]
    assert len(ids) == len(set(ids)), "input ids must be unique"
    if a.list:
        for i in sel:
            print(f"{i.id:60s} {i.expect:40s} volsmpl {i.args}")
        print(f"{len(sel)} of {len(INPUTS)} inputs")
        return 0
    out = Path(a.out).resolve()
    work, runs = out / "work", out / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    env = Env(a.python, a.src, a.mem_gb)
    probe_json = out / "probe.json"
    src = str(Path(a.src).resolve()) if a.src else f"{ROOT} (installed)"
    old = {}   # the records of an earlier probe of the same source: kept; with --resume also not run again
    if probe_json.is_file():
        prev_doc = json.loads(probe_json.read_text())
        if prev_doc.get("src") == src and prev_doc.get("source_sha256", "") == source_digest(a.src):
            old = {r["id"]: r for r in prev_doc["inputs"] if r["id"] in set(ids)}
    digest = source_digest(a.src)
    commit = Path(a.src) / "volsmpl/SOURCE_COMMIT" if a.src else None
    doc = {"src": src, "source_commit": commit.read_text().strip() if commit and commit.is_file() else None,
           "source_sha256": digest, "python": a.python,
           "started": time.strftime("%Y-%m-%d %H:%M:%S"), "timeout_s": a.timeout, "mem_gb": a.mem_gb, "inputs": []}
    lock = threading.Lock()

    def log(s):
        with lock:
            print(s, flush=True)

    failed = build_fixtures(sorted({n for i in sel for n in i.needs}), work, env, log)
    cases_file = str(work / "selfpen/one.json")
    order = {i.id: k for k, i in enumerate(INPUTS)}
    results = {rid: r for rid, r in old.items()}

    def save():
        recs = sorted(results.values(), key=lambda r: order.get(r["id"], 1e9))
        doc["inputs"] = recs
        write_atomic(probe_json, json.dumps(doc, indent=1, ensure_ascii=False))
        write_atomic(out / "probe.md", markdown(doc))

    # inputs sharing an --out run in order in one task
    groups: dict[str, list[Input]] = {}
    for i in sel:
        groups.setdefault(i.out_of or i.id, []).append(i)
    try:
        from tqdm import tqdm
        bar = tqdm(total=len(sel), desc="probe", file=sys.stderr, dynamic_ncols=True)
    except ImportError:  # pragma: no cover
        bar = None

    def do(group):
        for inp in group:
            if digest and source_digest(a.src) != digest:
                raise SystemExit(f"probe_apps: the source under --src {a.src} changed during the probe; stopped "
                                 f"(export a private copy with tools/export_snapshot.sh)")
            cwd = runs / (inp.out_of or inp.id)
            o = cwd / "out"
            argv = input_argv(inp, o, work, cases_file)
            prev = old.get(inp.id)
            if a.resume and prev is not None and prev.get("argv") == argv:
                if bar:
                    bar.update(1)
                continue
            if inp.out_of is None and cwd.exists():
                shutil.rmtree(cwd, ignore_errors=True)
            cwd.mkdir(parents=True, exist_ok=True)
            rec = {"id": inp.id, "class": inp.cls, "app": inp.app, "argv": argv, "expect": inp.expect,
                   "mode": inp.mode, "note": inp.note}
            bad = [n for n in inp.needs if n in failed]
            if bad:
                rec.update(rc=None, stderr_tail=[f"fixture {bad[0]}: {failed[bad[0]]}"], outcome="crash",
                           why=f"input files not made: fixture {bad[0]} failed")
            else:
                if inp.prefill:
                    shutil.rmtree(o, ignore_errors=True)
                    shutil.copytree(work / inp.prefill, o)
                r = run_input(inp, argv, env, o, cwd, a.timeout)
                outcome, why = classify(inp, argv, r["rc"], r["stdout"], r["stderr"], o, r)
                tail = [ln for ln in r["stderr"].replace("\r", "\n").splitlines() if ln.strip() and not BAR.search(ln)]
                rec.update({k: v for k, v in r.items() if k not in ("stdout", "stderr", "timeout")})
                rec.update(stderr_tail=tail[-6:], stdout_tail=[ln for ln in r["stdout"].splitlines() if ln.strip()][-3:],
                           outcome=outcome, why=why)
            with lock:
                results[inp.id] = rec
                save()
                if bar:
                    bar.update(1)
            log(f"{rec['outcome']:8s} {inp.id}  ({rec['why']}; {rec.get('seconds', '-')} s)")

    if a.jobs == 1:
        for g in groups.values():
            do(g)
    else:
        with ThreadPoolExecutor(a.jobs) as ex:
            for f in [ex.submit(do, g) for g in groups.values()]:
                f.result()
    if bar:
        bar.close()
    with lock:
        save()
    print(markdown(doc).split("## Non-clear")[0])
    print(f"wrote {probe_json} and {out / 'probe.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
