"""The judge of a finished walk, made without ground truth: each sequence record gets `status` and `status_why`.

    reached           the good one: none of the below
    diverged          the walk's optimisation stopped on NaN/Inf (the record holds no walk), a metric or a final
                      loss term is not finite, or the final loss is over EXPLODED_RATIO x the straight start walk's
                      (+ EXPLODED_ABS)
    goal_missed       the final pelvis ends farther than GOAL_MISSED_M from the goal (horizontally)
    colliding         the walk collides (a scene point deeper than 2 mm in the body: synth.PEN_TOL) in more than
                      COLLIDING_FRAMES_PCT of its frames, or its mean penetration depth is over COLLIDING_CM, or it
                      passes through something: deepest penetration over DEEP_CM while colliding in at least
                      DEEP_FRAMES_PCT of its frames (a 10 cm wall across the path: 10.3 cm, 50 %)
    worse_than_start  the optimised walk's collision term (the model's own measure, the one it minimised) is over
                      WORSE_RATIO x the straight start walk's (+ WORSE_ABS)

The first that applies is the status. The limits, from the paper's table run (docs/motion/results.json: 15
generated rooms, 440 sequences of 80 frames, 100 Adam steps, every model and weight): goal distance at most 0.22 m;
colliding frames at most 61%; mean penetration at most 1.6 cm; final loss at most 2.1x the start's; the collision
term over 1.5x the start's in 1 sequence (COAP at w = 0.01, whose weak collision term the goal term outweighs);
deeper than 8 cm in at least 40 % of the frames: 11 sequences (2.5 %; every kind, 8.1-11.3 cm, 45-61 %), which
are flagged.
Floor points count in the collision measures: a walk that collides mostly with the floor (its obstacles-only
depth under half the whole) says so, naming --floor-y.

    rec["status"], rec["status_why"] = judge(rec)    # rec: {'w': weight, 'metrics': synth.evaluate(...) + terms}
"""
from __future__ import annotations

import math

__all__ = ["GOOD", "GOAL_MISSED_M", "COLLIDING_FRAMES_PCT", "COLLIDING_CM", "DEEP_CM", "DEEP_FRAMES_PCT",
           "WORSE_RATIO", "WORSE_ABS",
           "EXPLODED_RATIO", "EXPLODED_ABS", "judge", "failed_metrics"]

GOOD = ("reached",)
GOAL_MISSED_M = 0.5
COLLIDING_FRAMES_PCT = 75.0
COLLIDING_CM = 3.0
DEEP_CM, DEEP_FRAMES_PCT = 8.0, 40.0
WORSE_RATIO, WORSE_ABS = 1.5, 1e-3
EXPLODED_RATIO, EXPLODED_ABS = 10.0, 1.0
#: the metrics whose value must be finite
FINITE = ("goal_dist_m", "collision_cm", "collision_obstacles_cm", "collision_frames_pct", "max_depth_cm")


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)


def _total(terms: dict, w: float) -> float:
    """The weighted loss of a record's terms: the collision term at weight w, the others at 1 (their weights in
    synth.synthesize_batch: goal 1, jerk 1 (its 0.1 inside the term), prior 1)."""
    return float(sum(v * (w if k == "collision" else 1.0) for k, v in terms.items()))


def _problems(rec: dict) -> list[tuple[str, str]]:
    """Every (status, why) that applies to a record, in the order of the module docstring."""
    m = rec.get("metrics") or {}
    if m.get("error"):
        return [("diverged", m["error"])]
    if m.get("stop") == "diverged":   # the harness stopped it: a step made its numbers or loss non-finite
        return [("diverged", "a step made the walk's numbers or loss non-finite (kept: the walk before it); lower "
                             "--lr")]
    out = []
    bad = [k for k in FINITE if not _finite(m.get(k))]
    init, final = m.get("initial_terms") or {}, m.get("final_terms") or {}
    bad += [f"final {k} term" for k, v in final.items() if not _finite(v)]
    if bad:
        out.append(("diverged", "not finite: " + ", ".join(bad)))
    elif init and final:
        t0, t1 = _total(init, float(rec.get("w", 1.0))), _total(final, float(rec.get("w", 1.0)))
        if t1 > EXPLODED_RATIO * t0 + EXPLODED_ABS:
            out.append(("diverged", f"the loss rose from {t0:.3g} (straight start walk) to {t1:.3g}"))
    if bad:
        return out
    goal = m["goal_dist_m"]
    if goal > GOAL_MISSED_M:
        out.append(("goal_missed", f"ends {goal:.2f} m from the goal (over {GOAL_MISSED_M:g} m)"))
    pct, depth = m["collision_frames_pct"], m["collision_cm"]
    deepest = m["max_depth_cm"]
    if deepest > DEEP_CM and pct >= DEEP_FRAMES_PCT and not (pct > COLLIDING_FRAMES_PCT or depth > COLLIDING_CM):
        out.append(("colliding", f"passes {deepest:.1f} cm deep into the scene and collides in {pct:.0f}% of frames "
                                 f"(limits {DEEP_CM:g} cm with {DEEP_FRAMES_PCT:g}%): through an obstacle?"))
    if pct > COLLIDING_FRAMES_PCT or depth > COLLIDING_CM:
        floor = m["collision_obstacles_cm"] < 0.5 * depth
        out.append(("colliding", f"collides in {pct:.0f}% of frames, {depth:.2f} cm deep on average (limits "
                                 f"{COLLIDING_FRAMES_PCT:g}%, {COLLIDING_CM:g} cm)"
                    + ("; mostly with the floor: check --floor-y" if floor else "")))
    c0, c1 = init.get("collision"), final.get("collision")
    if _finite(c0) and _finite(c1) and c1 > WORSE_RATIO * c0 + WORSE_ABS:
        out.append(("worse_than_start", f"its collision term rose from {c0:.3g} (straight start walk) to {c1:.3g}"))
    return out


def judge(rec: dict) -> tuple[str, str]:
    """(status, why) of a sequence record (module docstring); ('reached', '') when nothing applies."""
    problems = _problems(rec)
    return problems[0] if problems else ("reached", "")


def failed_metrics(error: str) -> dict:
    """The metrics of a walk whose optimisation stopped on NaN/Inf: no values (null in results.json), the
    optimiser's message in `error`, an empty pelvis path."""
    keys = ("goal_dist_m", "collision_cm", "collision_obstacles_cm", "collision_frames_pct", "max_depth_cm",
            "points_inside_per_frame", "foot_skate_cm", "jerk_max", "path_m", "iterations", "optim_s", "ms_per_iter",
            "optim_peak_mem_mb", "memory_kind")
    return {**{k: None for k in keys}, "pelvis_xz": [], "error": " ".join(str(error).split())}
