"""Pose repair of self-intersecting bodies with a volumetric self-penetration loss (paper Sec. 4.2.4,
supplementary D.4, Table 6), on the shared optimisation harness (volsmpl.optim).

For one body (betas, global_orient, body_pose theta_0) minimise over the body pose theta

    L(theta) = w_selfpen * selfpen_loss(body(theta)) + w_prior * ||theta - theta_0||^2

over the joints the contact turns (`hold`: volsmpl.body.limits.contact_joints of the part pairs whose triangles
collide at the start: an arm against the torso turns the arm's collar, shoulder, elbow, wrist and hand; the spine and
legs are held at their start), every joint kept within its anatomical limits after each step (`limits`: a hard bound,
volsmpl.body.limits.clamp_to_limits of volsmpl.body.poses.JOINT_LIMITS, widened to hold a start that lies outside:
a repair may not move a joint farther out than it began, nor must it pull it in). The paper's objective (preset
'paper') turns every joint and has no limits: hold and limits off.

with SGD, at most `max_iters` steps, stopping as soon as the self-penetration loss samples no
point inside two colliding parts (the list of points returned by `selfpen_loss` is empty)
in `stop_checks` independent draws in a row (the paper stops on the first empty draw: 1; a draw
that finds points again is the one the next step uses, so re-checks never cost a step), or when
the self-penetration term has found no new low (by more than `stall_rtol`, the sampling noise of one
draw) in `patience` steps (an equilibrium with the prior:
the paper has no such rule and runs on to the cap; patience 0 does the same).
Defaults are the values of our tuning run (PRESETS; the paper's are a preset). The repair is measured with the exact
triangle-collision metric (`triangles.body_collisions`) before and after, and by the geodesic
change of each joint's rotation. Any model kind works ('volsmpl', 'coap', 'mesh'): the loop only calls
`volume.selfpen_loss`.

    res = repair_case(body, volume, case, SelfPenConfig())
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from volsmpl.body.limits import (clamp_to_limits, contact_joints, joint_changes_deg, largest_change_deg, limits_around,
                                 violations)
from volsmpl.body.poses import BODY_JOINTS
from volsmpl.optim import MaxIters, Patience, StopWhen, Term, Variable, optimize
from volsmpl.report import paper

from .cases import Case
from .triangles import body_collisions, count_collidable, part_pairs

# Table 6 of the paper (RTX 3090, PROX cases, SMPL-X): per-step time (ms), per-step memory (GB),
# iterations, total time (s), mesh triangle collisions after repair.
PAPER = paper.rows("selfpen")


# The paper's values (Sec. 4.2.4: lr 1e-5, pose-prior weight 1e3, self-penetration weight 0.1, stop on the first
# empty draw, the SDF read in metres: tau 1, plain SGD) and the values of our one tuning run for both models
# (apps/selfpen/tune.py, all 17 cases, docs/selfpen/tune.json): the paper's lr * w_prior (1e-2) kept, the SDF read in
# centimetres (tau 1 cm: the sharpness of COAP's occupancy), every step limited to 0.1 rad per joint (plain SGD flung
# bodies: one step could move the spine by tens of degrees), lr * w_selfpen 0.3 (the best mean of 1e-3 .. 1 for both
# shipped models, 51.85 % of collisions removed; 0.1 .. 1 lie within 0.05 points),
# 3 empty draws to stop, a stall stop after 10 steps without a new low (10 % below the best), and no backward
# pass through the part encoder (code_grad False, Volume.selfpen_loss), all for both models alike.
#: the statuses of a repair that worked or left the body as it was, and of one that failed (RepairResult)
GOOD = ("no_intersection", "resolved", "stalled", "max_iters")
FLAGGED = ("diverged", "worse_than_start", "no_volume_points", "outside_limits")

PRESETS = {
    "paper": {"lr": 1e-5, "w_selfpen": 0.1, "w_prior": 1e3, "stop_checks": 1, "tau": 1.0, "patience": 0, "stall_rtol": 0.0,
              "code_grad": True, "max_step": 0.0, "limits": False, "hold": False},
    "tuned": {"lr": 1e-2, "w_selfpen": 30.0, "w_prior": 1.0, "stop_checks": 3, "tau": 0.01, "patience": 10,
              "stall_rtol": 0.1, "code_grad": False, "max_step": 0.1, "limits": True, "hold": True},
}


@dataclass
class SelfPenConfig:
    """Repair hyper-parameters. Defaults: the tuned preset (PRESETS['tuned']); 200 iterations and 300
    points per box pair as the paper (supp. D.4). `SelfPenConfig.preset('paper')` gives the paper's."""

    lr: float = PRESETS["tuned"]["lr"]
    max_iters: int = 200
    w_selfpen: float = PRESETS["tuned"]["w_selfpen"]
    w_prior: float = PRESETS["tuned"]["w_prior"]
    n_points: int = 300
    stop_checks: int = PRESETS["tuned"]["stop_checks"]  # empty draws in a row that stop the loop (paper: 1)
    tau: float = PRESETS["tuned"]["tau"]  # metres: SDF scale of the loss's soft occupancy (Volume.selfpen_loss; paper 1)
    patience: int = PRESETS["tuned"]["patience"]  # stop after so many steps without a new lowest penetration term (0: off)
    # a new low must beat the best by this fraction: one point draw's penetration term varies by ~14 % (relative std,
    # median over the 17 cases, both models), so smaller "lows" are sampling noise, not progress
    stall_rtol: float = PRESETS["tuned"]["stall_rtol"]
    # radians: longest step of one joint's rotation per iteration (the gradient is scaled to it; 0: plain SGD)
    max_step: float = PRESETS["tuned"]["max_step"]
    code_grad: bool = PRESETS["tuned"]["code_grad"]  # back-propagate through the part codes (Volume.selfpen_loss)
    limits: bool = PRESETS["tuned"]["limits"]  # every joint within its anatomical limits after each step
    hold: bool = PRESETS["tuned"]["hold"]  # only the joints the contact turns move; the others are held
    seed: int = 0  # seeds the point sampler of every case
    device: str = "cpu"

    @classmethod
    def preset(cls, name: str, **overrides) -> SelfPenConfig:
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
        return cls(**{**PRESETS[name], **overrides})

    def __post_init__(self):
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0, got {self.lr}")
        if self.max_iters < 0:
            raise ValueError(f"max_iters must be >= 0, got {self.max_iters}")
        if self.w_selfpen < 0 or self.w_prior < 0:
            raise ValueError(f"loss weights must be >= 0, got w_selfpen={self.w_selfpen}, w_prior={self.w_prior}")
        if self.n_points < 1:
            raise ValueError(f"n_points must be >= 1, got {self.n_points}")
        if not self.tau > 0:
            raise ValueError(f"tau must be > 0 metres, got {self.tau}")
        if self.max_step < 0:
            raise ValueError(f"max_step must be >= 0 radians (0: no limit), got {self.max_step}")
        if not 0.0 <= self.stall_rtol < 1.0:
            raise ValueError(f"stall_rtol must be in [0, 1), got {self.stall_rtol}")
        if self.patience < 0:
            raise ValueError(f"patience must be >= 0 (0 turns the stall stop off), got {self.patience}")
        if self.stop_checks < 1:
            raise ValueError(f"stop_checks must be >= 1 (draws that must all be empty to stop), got {self.stop_checks}")


@dataclass
class RepairResult:
    """Outcome of one case. status: 'no_intersection' (no triangle collision: left unchanged),
    'no_volume_points' (the volume finds no penetration: left unchanged), 'resolved' (the volume
    finds no penetration after `iterations` steps), 'stalled' (the penetration term found no new low for
    `patience` steps), 'max_iters'. Flagged (`FLAGGED`, why in `status_why`): 'no_volume_points' (triangles
    collide but the volume sees nothing to push apart: not repaired), 'diverged' (a step made the pose or the loss
    non-finite; the pose before it is kept) and 'worse_than_start' (more pose-induced colliding triangle pairs after
    than before)."""

    name: str
    status: str
    iterations: int
    step_ms: list = field(default_factory=list)  # per optimisation step (forward, loss, backward, update)
    total_s: float = 0.0  # the whole loop, final stopping check included
    peak_memory_bytes: int = 0  # above the memory in use before the loop
    memory_kind: str = ""
    collisions_before: int = 0  # pose-induced triangle pairs (rest-pose pairs of the shape left out)
    collisions_after: int = 0
    raw_before: int = 0  # all intersecting triangle pairs
    raw_after: int = 0
    # pose-induced pairs whose triangles lie on two parts that may collide (partition.collision_mask): the
    # collisions a volumetric self-penetration loss can see; the rest are same-part or neighbouring-part
    # pairs (LBS folds at joints), left alone by design.
    collidable_before: int = 0
    collidable_after: int = 0
    pose_change_deg: float = 0.0  # mean over the 23 body joints of the geodesic rotation change
    max_change_deg: float = 0.0  # the largest joint's geodesic rotation change, and that joint
    max_change_joint: str = ""
    # the largest change of a joint that the contact does not need to turn (contact_joints: the spine and legs for
    # an arm against the torso), and that joint
    still_change_deg: float = 0.0
    still_change_joint: str = ""
    moved_joints: list = field(default_factory=list)  # the joints the contact turns (with `hold`, the only ones that move)
    limits_start: list = field(default_factory=list)  # angles of the start beyond JOINT_LIMITS [joint, axis, deg, lo, hi]
    limits_after: list = field(default_factory=list)  # angles the repair moved beyond the limits (or farther out)
    loss: list = field(default_factory=list)  # total loss per step
    points: list = field(default_factory=list)  # penetration samples per evaluation
    body_pose: list = field(default_factory=list)  # final (69,)
    status_why: str = ""  # the reason of a status in FLAGGED
    # what a user takes away, filled by `volsmpl selfpen` from the record's pose (bodies.take_away): the case's body
    # parameters, the repaired body (volsmpl.apps.outputs.body_record) and the mesh files written, relative to OUT
    start_params: dict = field(default_factory=dict)
    body: dict = field(default_factory=dict)
    meshes: dict = field(default_factory=dict)
    pairs_before: np.ndarray | None = field(default=None, repr=False)
    pairs_after: np.ndarray | None = field(default=None, repr=False)
    vertices_before: np.ndarray | None = field(default=None, repr=False)
    vertices_after: np.ndarray | None = field(default=None, repr=False)

    def to_json(self) -> dict:
        d = asdict(self)
        for k in ("pairs_before", "pairs_after", "vertices_before", "vertices_after"):
            d.pop(k)
        return d


def pose_change_deg(pose0, pose1) -> float:
    """Mean geodesic angle (degrees) between the joint rotations of two (69,) axis-angle body poses."""
    return float(joint_changes_deg(pose0, pose1).mean())


def check_case(case: Case) -> None:
    """Clear errors for cases built by hand (load_cases validates file input the same way)."""
    for key, n in (("betas", 10), ("global_orient", 3), ("body_pose", 69)):
        t = getattr(case, key)
        if not torch.is_tensor(t) or t.numel() != n:
            raise ValueError(f"case {case.name!r}: '{key}' must hold {n} numbers, got "
                             f"{tuple(t.shape) if torch.is_tensor(t) else type(t).__name__}")
        if not torch.isfinite(t).all():
            raise ValueError(f"case {case.name!r}: '{key}' contains NaN or Inf")


def repair_case(body, volume, case: Case, cfg: SelfPenConfig = SelfPenConfig(), keep_meshes: bool = False,
                progress: bool | None = None) -> RepairResult:
    """Optimise one case's body pose against `volume`'s self-penetration loss (module docstring).

    Args:
        body: the body model (volsmpl.Body) the volume is attached to; volume: its Volume
        (VolumetricSMPL or COAP); case: the body to repair; cfg: hyper-parameters;
        keep_meshes: keep vertices and intersecting pairs before/after (for rendering);
        progress: the optimisation harness's per-step bar (None: on a terminal, for a cap of 50 steps or more;
            False: never).
    Returns: RepairResult (a case without triangle collisions is returned unchanged, 0 iterations).
    """
    check_case(case)
    dev = torch.device(cfg.device)
    if dev.type == "cuda" and dev.index is None and torch.cuda.is_available():
        dev = torch.device("cuda", torch.cuda.current_device())  # 'cuda' names the current GPU: compare as cuda:N
    before = body_collisions(body, case.betas, case.global_orient, case.body_pose)
    res = RepairResult(name=case.name, status="no_intersection", iterations=0,
                       collisions_before=len(before["pairs"]), raw_before=len(before["raw"]))
    res.body_pose = case.body_pose.tolist()
    final_pose = case.body_pose
    if res.collisions_before > 0:
        fl, cm = volume.partition.face_labels.cpu().numpy(), volume.partition.collision_mask.cpu().numpy()
        moving = contact_joints(part_pairs(before["pairs"], fl, cm), volume.partition.table, body.parents.cpu().numpy())
        final_pose = _optimise(body, volume, case, cfg, dev, res, progress, moving)
    after = before if final_pose is case.body_pose else body_collisions(body, case.betas, case.global_orient, final_pose)
    res.collisions_after, res.raw_after = len(after["pairs"]), len(after["raw"])
    fl, cm = volume.partition.face_labels.cpu().numpy(), volume.partition.collision_mask.cpu().numpy()
    res.collidable_before = count_collidable(before["pairs"], fl, cm)
    res.collidable_after = count_collidable(after["pairs"], fl, cm)
    res.pose_change_deg = pose_change_deg(case.body_pose, final_pose)
    res.max_change_deg, res.max_change_joint = largest_change_deg(case.body_pose, final_pose)
    moving = contact_joints(part_pairs(before["pairs"], fl, cm), volume.partition.table, body.parents.cpu().numpy())
    res.moved_joints = [BODY_JOINTS[j] for j in np.flatnonzero(moving)]
    still = ~moving
    if still.any():
        d = joint_changes_deg(case.body_pose, final_pose)
        j = int(np.flatnonzero(still)[d[still].argmax()])
        res.still_change_deg, res.still_change_joint = float(d[j]), BODY_JOINTS[j]
    lo, hi = limits_around(case.body_pose)
    res.limits_start = [list(v) for v in violations(case.body_pose)]
    res.limits_after = [list(v) for v in violations(final_pose, lo, hi)]
    res.body_pose = final_pose.tolist()
    if res.status == "diverged":
        res.status_why = "a step made the pose or the loss non-finite (kept: the pose before it); lower --lr"
    elif res.status == "no_volume_points":
        res.status_why = (f"{res.collisions_before} colliding triangle pairs, but the volume finds no penetration "
                          f"to push apart: left as it was")
    elif res.limits_after:
        j, a, deg, lo_d, hi_d = res.limits_after[0]
        res.status_why = (f"{len(res.limits_after)} joint angle(s) beyond the anatomical limits, e.g. {j} {a} "
                          f"{deg:.0f} deg (limit {lo_d:.0f}..{hi_d:.0f}): not repairable within the limits with "
                          f"these settings (the optimiser stopped as {res.status!r})")
        res.status = "outside_limits"
    elif res.collisions_after > res.collisions_before:
        res.status_why = (f"colliding triangle pairs {res.collisions_before} -> {res.collisions_after} (the "
                          f"optimiser stopped as {res.status!r})")
        res.status = "worse_than_start"
    if keep_meshes:
        res.pairs_before, res.vertices_before = before["pairs"], before["vertices"]
        res.pairs_after, res.vertices_after = after["pairs"], after["vertices"]
    return res


def _optimise(body, volume, case: Case, cfg: SelfPenConfig, dev: torch.device, res: RepairResult,
              progress: bool | None = None, moving=None) -> torch.Tensor:
    """The SGD loop on the harness; fills res (status, iterations, timings, memory, losses) and returns the final
    (69,) pose. moving: (23,) bool, the joints the contact turns (with cfg.hold the only ones optimised)."""
    if body.v_template.device != dev or volume.device != dev:
        raise ValueError(f"body and volume must be on {dev} (got body on {body.v_template.device}, volume on "
                         f"{volume.device}); move them with .to('{dev}') first")
    betas = case.betas.reshape(1, -1).to(dev)
    orient = case.global_orient.reshape(1, 3).to(dev)
    theta0 = case.body_pose.reshape(1, -1).to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)  # CPU generator: identical samples on every device

    def selfpen(state):
        for _ in range(cfg.stop_checks):  # re-draw while empty, up to stop_checks draws
            sp, pts = volume.selfpen_loss(state.out, n_points=cfg.n_points, generator=gen, return_points=True,
                                          tau=cfg.tau, code_grad=cfg.code_grad)
            res.points.append(int(pts[0].shape[0]))
            if pts[0].shape[0] > 0:
                break
        return sp, {"points": int(pts[0].shape[0])}

    stops = [StopWhen(lambda ev: ev.info["selfpen"]["points"] == 0, "resolved"), MaxIters(cfg.max_iters)]
    if cfg.patience:
        stops.append(Patience("selfpen", cfg.patience, cfg.stall_rtol))
    free = np.ones(23, bool) if not cfg.hold or moving is None or not np.any(moving) else np.asarray(moving, bool)
    idx = torch.as_tensor(np.flatnonzero(np.repeat(free, 3)), device=dev)
    lo, hi = limits_around(case.body_pose)

    def full(values):   # the whole (B, 69) pose: the free joints' values, the held ones at their start
        return theta0.expand(values.shape[0], -1).index_copy(1, idx, values)

    def project(values):
        return clamp_to_limits(full(values), lo, hi).index_select(1, idx)

    run = optimize(
        {"body_pose": Variable(theta0[:, idx].clone(), max_step=cfg.max_step or None, group=3,
                               project=project if cfg.limits else None)},
        {"selfpen": Term(selfpen, cfg.w_selfpen),
         "prior": Term(lambda s: ((s.body_pose - theta0[:, idx]) ** 2).sum(dim=1), cfg.w_prior)},
        prepare=lambda s: {"out": body(betas=betas, global_orient=orient, body_pose=full(s.body_pose))},
        optimizer="sgd", lr=cfg.lr, stops=stops, frozen=[volume], device=dev, progress=progress)
    res.iterations = run.iterations[0]
    res.status = run.status[0]
    if res.status == "resolved" and res.iterations == 0:
        res.status = "no_volume_points"
    res.step_ms = run.step_ms()
    res.loss = [r.total[0] for r in run.records if r.updated]
    res.total_s = run.seconds
    res.peak_memory_bytes, res.memory_kind = int(run.peak_bytes), run.memory_kind
    return full(run.variables["body_pose"])[0].cpu()


def summarize(results: list[RepairResult]) -> dict:
    """Table row of one model over its cases: means over the cases that had collisions (per-step
    time over all steps; memory: the largest peak). removed_per_s: triangle collisions removed per second
    of repair, sum over those cases of (before - after) over the sum of their loop times. max_change_deg: the mean
    over the cases of each case's largest joint change; largest_change_deg its largest; largest_still_change_deg: the
    largest change of a joint the contact does not turn; limit_violations: joint angles the repairs moved beyond
    their limits (all cases); collidable_left_cases: the cases the exact counter still finds pairs of collidable parts
    in after the repair."""
    active = [r for r in results if r.status != "no_intersection"]
    steps = [t for r in active for t in r.step_ms]
    mean = lambda xs: float(np.mean(xs)) if len(xs) else float("nan")
    return {
        "cases": len(results),
        "cases_with_collisions": len(active),
        "resolved_by_volume": sum(r.status == "resolved" for r in active),
        "collision_free_after": sum(r.collisions_after == 0 for r in active),
        "step_ms": mean(steps),
        "memory_gb": max([r.peak_memory_bytes for r in active], default=0) / 1e9,
        "memory_kind": active[0].memory_kind if active else "",
        "iterations": mean([r.iterations for r in active]),
        "total_s": mean([r.total_s for r in active]),
        "collisions_before": mean([r.collisions_before for r in active]),
        "collisions_after": mean([r.collisions_after for r in active]),
        "raw_collisions_after": mean([r.raw_after for r in active]),
        "collidable_before": mean([r.collidable_before for r in active if r.collidable_before is not None]),
        "collidable_after": mean([r.collidable_after for r in active if r.collidable_after is not None]),
        "pose_change_deg": mean([r.pose_change_deg for r in active]),
        "max_change_deg": mean([r.max_change_deg for r in active]),
        "largest_change_deg": max([r.max_change_deg for r in active], default=0.0),
        "largest_still_change_deg": max([r.still_change_deg for r in active], default=0.0),
        "limit_violations": sum(len(r.limits_after) for r in active),
        "collidable_left_cases": sum(bool(r.collidable_after) for r in active),
        "removed_per_s": (sum(r.collisions_before - r.collisions_after for r in active) / total
                          if (total := sum(r.total_s for r in active)) > 0 else float("nan")),
    }


def format_table(summaries: dict) -> str:
    """Our rows (model -> summarize(...)) beside the paper's Table 6."""
    head = (f"{'':24s} {'step ms':>8s} {'mem GB':>8s} {'iters':>7s} {'total s':>8s} {'coll. before':>12s} {'coll. after':>11s} "
            f"{'pose chg deg':>12s} {'max chg':>7s} {'limits':>6s} {'collidable parts':>16s} {'removed/s':>9s}")
    lines = [head, "-" * len(head)]
    names = {"volsmpl": "VolumetricSMPL", "coap": "COAP", "mesh": "exact mesh"}
    for m, s in summaries.items():
        lines.append(f"{'ours ' + names.get(m, m):24s} {s['step_ms']:8.1f} {s['memory_gb']:8.3f} {s['iterations']:7.2f} "
                     f"{s['total_s']:8.3f} {s['collisions_before']:12.1f} {s['collisions_after']:11.1f} {s['pose_change_deg']:12.3f} "
                     f"{s.get('max_change_deg', float('nan')):7.1f} {s.get('limit_violations', 0):6d} {s['collidable_before']:7.1f} -> {s['collidable_after']:5.1f} {s['removed_per_s']:9.1f}")
    for m in ("coap", "volsmpl"):
        p = PAPER[m]
        lines.append(f"{'paper ' + names[m]:24s} {p['step_ms']:8.1f} {p['memory_gb']:8.3f} {p['iterations']:7.2f} "
                     f"{p['total_s']:8.3f} {'-':>12s} {p['collisions']:11d} {'-':>12s}")
    return "\n".join(lines)
