"""The optimisation harness every app runs on: named tensors of a batch of problems, weighted loss terms,
any torch optimiser, stop rules, per-variable step limits, a learning-rate schedule, the body network frozen,
per-step records (each term, time) and the run's peak memory (volsmpl.runtime.meter).

    res = optimize(
        {"body_pose": Variable(theta0.clone(), max_step=0.1, group=3)},
        {"selfpen": Term(selfpen, 10.0), "prior": Term(lambda s: ((s.body_pose - theta0) ** 2).sum(-1), 1.0)},
        prepare=lambda s: {"out": body(body_pose=s.body_pose)},
        optimizer="sgd", lr=1e-2, max_iters=200, stops=[Patience("selfpen", 10, 0.1)], frozen=[volume])
    res.variables["body_pose"], res.status, res.iterations, res.summary()

Each iteration: `prepare(state)` (shared work: pose the body once), every term on the state, the stop rules
on that evaluation (a problem that stops keeps its variables from now on), then, for the problems still
running, one backward pass of the sum over problems of sum_t weight_t * term_t and one optimiser update.
After `max_iters` updates (rule MaxIters, appended when the caller gives none) the final evaluation is still
made and recorded, so every result's last record describes the returned variables.

Problems: every variable has the batch of problems on its first dimension; terms return one value per
problem (B,), or a scalar for B = 1. Problems are independent (their losses are summed), so the batch
optimises each as if alone, except for the optimiser's shared learning-rate schedule.
"""
from __future__ import annotations

import contextlib
import sys
import time
from dataclasses import dataclass, field
from typing import Callable

import torch

from volsmpl.runtime.meter import Meter, sync
from .stops import MaxIters

__all__ = ["Variable", "Term", "State", "Evaluation", "StepRecord", "OptimResult", "optimize"]

OPTIMIZERS = {"adam": torch.optim.Adam, "adamw": torch.optim.AdamW, "sgd": torch.optim.SGD}


@dataclass
class Variable:
    """A tensor to optimise, (B, ...) with the batch of problems first.

    lr: its own learning rate (default: optimize's lr). max_step: the longest update of one group of `group`
    consecutive values per iteration (e.g. 0.1 rad per axis-angle joint with group=3); a longer update is
    scaled down as a whole (its direction kept: a trust region). None: no limit. project: values (B, ...) -> values
    inside a feasible set, applied without gradient after every update (a hard bound, e.g. joint limits).
    start: the first update that changes it (a coarse-to-fine schedule: 0, every update); before it the variable
    is held at its value and the optimiser keeps no state for it (Adam's moments begin at its first update).
    """

    value: torch.Tensor
    lr: float | None = None
    max_step: float | None = None
    group: int = 1
    project: Callable | None = None
    start: int = 0


@dataclass
class Term:
    """A weighted loss term: fn(state) -> (B,) tensor, a scalar (B = 1), or (value, info dict)."""

    fn: Callable
    weight: float = 1.0


class State(dict):
    """The variables and prepare()'s outputs by name, readable as attributes (state.body_pose)."""

    __getattr__ = dict.__getitem__


@dataclass
class Evaluation:
    """One evaluation of the terms at the current variables (what stop rules see).
    iteration: updates made so far; terms: name -> (B,) detached values (unweighted); total (B,) weighted
    sum; info: name -> the info dict a term returned."""

    iteration: int
    terms: dict
    total: torch.Tensor
    info: dict
    batch: int
    device: torch.device

    def value(self, name: str) -> torch.Tensor:
        return self.total if name == "total" else self.terms[name]


@dataclass
class StepRecord:
    """A recorded evaluation: per-problem term values and total, the terms' info, whether an update followed,
    and the wall time of the iteration in ms (evaluation and update, synchronised)."""

    iteration: int
    terms: dict
    total: list
    info: dict
    updated: bool
    ms: float


@dataclass
class OptimResult:
    """What optimize returns: final variables (detached), per-problem status and number of updates, the
    records, the loop's wall time and peak memory above its start (volsmpl.runtime.meter)."""

    variables: dict
    status: list
    iterations: list
    records: list = field(default_factory=list)
    seconds: float = 0.0
    peak_bytes: int = 0
    memory_kind: str = ""

    def step_ms(self) -> list:
        """Time of every iteration that made an update."""
        return [r.ms for r in self.records if r.updated]

    def summary(self) -> dict:
        steps = self.step_ms()
        return {"problems": len(self.status), "status": list(self.status), "iterations": list(self.iterations),
                "ms_per_iter": sum(steps) / len(steps) if steps else float("nan"), "total_s": self.seconds,
                "peak_mem_mb": self.peak_bytes / 2 ** 20, "memory_kind": self.memory_kind,
                "final": dict(self.records[-1].terms, total=self.records[-1].total) if self.records else {}}


def _per_problem(value, name: str, batch: int) -> torch.Tensor:
    if value.ndim == 0:
        if batch != 1:
            raise ValueError(f"term '{name}' returned a scalar for a batch of {batch} problems; return one value per problem (B,)")
        return value.reshape(1)
    if value.shape != (batch,):
        raise ValueError(f"term '{name}' returned shape {tuple(value.shape)}; expected ({batch},): one value per problem")
    return value


def _progress(enabled, total: int, desc: str | None):
    if enabled is None:
        enabled = sys.stderr.isatty() and total >= 50
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, leave=False)


def optimize(variables: dict, terms: dict, *, prepare: Callable | None = None, optimizer="adam", lr: float = 1e-2,
             schedule: Callable[[int], float] | None = None, max_iters: int = 100, stops=(), frozen=(),
             device=None, progress: bool | None = None, desc: str | None = None,
             usable: Callable[[dict], torch.Tensor] | None = None) -> OptimResult:
    """Minimise sum_t weight_t * term_t over the variables (module docstring).

    A problem whose total loss is not finite, or whose variables after an update are not usable (default: not
    finite), stops with status 'diverged' and keeps its values from before the update that broke it; the others
    go on.

    Args:
        variables: name -> Variable or tensor (B, ...); the tensors are copied, the caller's stay untouched.
        terms: name -> Term or (fn, weight) or fn (weight 1).
        prepare: state -> dict of shared values added to the state before the terms run.
        optimizer: 'adam', 'adamw', 'sgd' or a factory(param_groups, lr) -> torch.optim.Optimizer.
        lr: learning rate; schedule: iteration -> multiplier of every group's lr (torch LambdaLR).
        max_iters: update cap (a MaxIters rule appended unless `stops` holds one); stops: StopRule list.
        frozen: modules whose parameters get no gradient during the run (restored after); a volume among them opens
            one `warm_start` for the run, in which it carries its bodies' code corrections from one iteration to
            the next where it is set to (`Volume.set_code_refinement(steps, warm=True)`, `set_pass_interval(N)`).
        device: where time and memory are measured (default: the first variable's device).
        progress: tqdm bar (None: only on a terminal and for runs of 50 iterations or more).
        usable: variables {name: (B, ...)} -> (B,) bool, the problems whose values the next evaluation can take
            (e.g. a log-scale whose exp is finite); default: every value finite.
    Returns: OptimResult.
    """
    if not variables:
        raise ValueError("optimize needs at least one variable")
    if not terms:
        raise ValueError("optimize needs at least one loss term")
    vars_ = {n: v if isinstance(v, Variable) else Variable(v) for n, v in variables.items()}
    terms_ = {n: t if isinstance(t, Term) else Term(*t) if isinstance(t, tuple) else Term(t) for n, t in terms.items()}
    batch = next(iter(vars_.values())).value.shape[0]
    for n, v in vars_.items():
        if not torch.is_tensor(v.value) or not v.value.is_floating_point() or v.value.ndim < 1:
            raise ValueError(f"variable '{n}' must be a floating-point tensor with the batch of problems first")
        if v.value.shape[0] != batch:
            raise ValueError(f"variable '{n}' has {v.value.shape[0]} problems on its first dimension, others {batch}")
        if v.max_step is not None and (v.max_step <= 0 or v.value[0].numel() % v.group):
            raise ValueError(f"variable '{n}': max_step must be > 0 and group ({v.group}) must divide its "
                             f"{v.value[0].numel()} values per problem")
        if not torch.isfinite(v.value).all():
            raise ValueError(f"variable '{n}' starts with NaN or Inf values")
        if not isinstance(v.start, int) or v.start < 0:
            raise ValueError(f"variable '{n}': start must be an update number >= 0, got {v.start!r}")
    params = {n: v.value.detach().clone().requires_grad_(True) for n, v in vars_.items()}
    groups = [{"params": [params[n]], "lr": v.lr if v.lr is not None else lr} for n, v in vars_.items()]
    if callable(optimizer):
        opt = optimizer(groups, lr)
    elif optimizer in OPTIMIZERS:
        opt = OPTIMIZERS[optimizer](groups, lr=lr)
    else:
        raise ValueError(f"unknown optimizer {optimizer!r}; use one of {', '.join(OPTIMIZERS)} or a factory")
    sched = torch.optim.lr_scheduler.LambdaLR(opt, schedule) if schedule is not None else None
    rules = list(stops)
    if not any(isinstance(r, MaxIters) for r in rules):
        rules.append(MaxIters(max_iters))
    cap = max([r.max_iters for r in rules if isinstance(r, MaxIters)])
    dev = torch.device(device) if device is not None else next(iter(params.values())).device
    for r in rules:
        r.reset(batch, dev)
    status, iterations = [None] * batch, [0] * batch
    active = torch.ones(batch, dtype=torch.bool, device=dev)
    records = []
    prev = None  # the variables before the last update: what a problem that diverges keeps
    usable = usable or _finite_rows
    flags = [(p, p.requires_grad) for m in frozen for p in m.parameters()]
    bar = _progress(progress, cap, desc)
    try:
        for p, _ in flags:
            p.requires_grad_(False)
        with contextlib.ExitStack() as warm, Meter(dev) as meter:
            for m in frozen:   # volumes set to carry code corrections (warm refinement, passes at an interval)
                if hasattr(m, "warm_start"):
                    warm.enter_context(m.warm_start())
            for it in range(cap + 1):
                t0 = time.perf_counter()
                state = State(params)
                if prepare is not None:
                    state.update(prepare(state))
                values, info = {}, {}
                for n, t in terms_.items():
                    r = t.fn(state)
                    if isinstance(r, tuple):
                        r, info[n] = r
                    values[n] = _per_problem(r, n, batch)
                total = sum(terms_[n].weight * v for n, v in values.items())
                ev = Evaluation(it, {n: v.detach() for n, v in values.items()}, total.detach(), info, batch, dev)
                # a loss that is not finite: the problem stops, set back (after the backward, which still holds its
                # values) to the values before the update that did it
                lost = active & ~torch.isfinite(ev.total)
                active &= ~lost
                for rule in rules:
                    hit = torch.as_tensor(rule.check(ev), dtype=torch.bool, device=dev).expand(batch) & active
                    for b in hit.nonzero()[:, 0].tolist():
                        status[b] = rule.status
                    active &= ~hit
                updated = bool(active.any())
                if updated:
                    opt.zero_grad(set_to_none=True)
                    (total * active.to(total.dtype)).sum().backward()
                    for n, v in vars_.items():
                        if it < v.start:  # held: no gradient, so the optimiser neither moves it nor keeps state
                            params[n].grad = None
                    old = {n: p.detach().clone() for n, p in params.items()}
                    opt.step()
                    if sched is not None:
                        sched.step()
                    _limit_and_keep(params, old, vars_, active)
                    with torch.no_grad():
                        broken = active & ~torch.as_tensor(usable({n: p.detach() for n, p in params.items()}),
                                                           dtype=torch.bool, device=dev).expand(batch)
                    if broken.any():
                        _diverge(params, old, broken, status)
                        active &= ~broken
                    for b in active.nonzero()[:, 0].tolist():
                        iterations[b] += 1
                if lost.any():
                    _diverge(params, prev, lost, status)
                    for b in lost.nonzero()[:, 0].tolist():  # the update it is set back from does not count
                        iterations[b] -= 1 if prev is not None else 0
                if updated:
                    prev = old
                sync(dev)
                records.append(StepRecord(it, {n: v.tolist() for n, v in ev.terms.items()}, ev.total.tolist(), info,
                                          updated, (time.perf_counter() - t0) * 1e3))
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix(loss=f"{float(ev.total.sum()):.4g}")
                if not updated:
                    break
    finally:
        for p, flag in flags:
            p.requires_grad_(flag)
        if bar is not None:
            bar.close()
    return OptimResult({n: p.detach() for n, p in params.items()}, status, iterations, records, meter.seconds,
                       meter.peak_bytes, meter.kind)


def _finite_rows(variables: dict) -> torch.Tensor:
    """(B,) bool: the problems whose every variable value is finite."""
    return torch.stack([torch.isfinite(v.reshape(v.shape[0], -1)).all(dim=1) for v in variables.values()]).all(dim=0)


@torch.no_grad()
def _diverge(params: dict, before: dict | None, rows: torch.Tensor, status: list) -> None:
    """Problems `rows` (B,) stop as 'diverged', their variables set back to `before` (when there is one)."""
    for b in rows.nonzero()[:, 0].tolist():
        status[b] = "diverged"
    if before is not None:
        for n, p in params.items():
            p[rows] = before[n][rows]


@torch.no_grad()
def _limit_and_keep(params: dict, old: dict, vars_: dict, active: torch.Tensor) -> None:
    """Scale each problem's update of a variable with max_step so no group moves farther than max_step, project
    it into its feasible set (Variable.project), and put back the values of problems that stopped."""
    for n, p in params.items():
        v = vars_[n]
        if v.max_step is None and bool(active.all()) and v.project is None:
            continue
        delta = p - old[n]
        if v.max_step is not None:
            longest = delta.reshape(delta.shape[0], -1, v.group).norm(dim=-1).amax(dim=1)  # (B,)
            factor = (v.max_step / longest.clamp_min(torch.finfo(longest.dtype).tiny)).clamp(max=1.0)
            delta = delta * factor.reshape(-1, *[1] * (delta.ndim - 1))
        keep = active.reshape(-1, *[1] * (delta.ndim - 1)).to(delta.dtype)
        p.copy_(old[n] + delta * keep)
        if v.project is not None:
            moved = v.project(p.detach().clone())
            p.copy_(torch.where(active.reshape(-1, *[1] * (p.ndim - 1)), moved, p))
