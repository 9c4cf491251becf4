"""Stop rules of the optimisation harness (volsmpl.optim.optimize).

A rule looks at the evaluation of the current variables (before any update of that iteration) and says,
per problem of the batch, whether that problem stops, and with which status. Rules are checked in the
order given; a problem stops at the first rule that fires for it. Rules keep state across iterations
(`reset` is called at the start of a run).

    rules = [StopWhen(lambda ev: ev.info["selfpen"]["points"] == 0, "resolved"),
             MaxIters(200), Patience("selfpen", patience=10, rtol=0.1)]
"""
from __future__ import annotations

import torch

__all__ = ["StopRule", "MaxIters", "Patience", "Tolerance", "StopWhen"]


class StopRule:
    """Base class. `check(ev)` -> (B,) bool: problems that stop now; `status` names the reason."""

    status = "stopped"

    def reset(self, batch: int, device) -> None:
        pass

    def check(self, ev) -> torch.Tensor:  # pragma: no cover - interface
        raise NotImplementedError


class MaxIters(StopRule):
    """Stop once `max_iters` updates were made (the evaluation after the last update is still recorded)."""

    status = "max_iters"

    def __init__(self, max_iters: int):
        if not isinstance(max_iters, int) or isinstance(max_iters, bool) or max_iters < 0:
            raise ValueError(f"max_iters must be an integer >= 0, got {max_iters!r}")
        self.max_iters = max_iters

    def check(self, ev) -> torch.Tensor:
        return ev.iteration >= self.max_iters


class Patience(StopRule):
    """Stop a problem whose value of `term` ('total' for the weighted sum) has found no new low for `patience`
    evaluations; a new low must beat the best so far by the fraction `rtol` of its magnitude (noise of a sampled
    term; negative values too: below best - rtol * |best|)."""

    status = "stalled"

    def __init__(self, term: str, patience: int, rtol: float = 0.0):
        if not isinstance(patience, int) or patience < 1:
            raise ValueError(f"patience must be an integer >= 1, got {patience!r}")
        if not 0.0 <= rtol < 1.0:
            raise ValueError(f"rtol must be in [0, 1), got {rtol}")
        self.term, self.patience, self.rtol = term, patience, rtol

    def reset(self, batch: int, device) -> None:
        self.best = torch.full((batch,), float("inf"), dtype=torch.float64)
        self.since = torch.zeros(batch, dtype=torch.long)

    def check(self, ev) -> torch.Tensor:
        value = ev.value(self.term).double().cpu()
        # the fraction rtol of |best| below it (best * (1 - rtol) would lie above a negative best)
        bar = torch.where(self.best >= 0, self.best * (1.0 - self.rtol), self.best * (1.0 + self.rtol))
        better = value < bar
        self.best = torch.where(better, value, self.best)
        self.since = torch.where(better, torch.zeros_like(self.since), self.since + 1)
        return (self.since >= self.patience).to(ev.device)


class Tolerance(StopRule):
    """Stop a problem whose `term` ('total' by default) changed by at most `atol + rtol * |previous|` since the
    previous evaluation (converged)."""

    status = "converged"

    def __init__(self, term: str = "total", rtol: float = 1e-6, atol: float = 0.0):
        if rtol < 0 or atol < 0:
            raise ValueError(f"rtol and atol must be >= 0, got rtol={rtol}, atol={atol}")
        self.term, self.rtol, self.atol = term, rtol, atol

    def reset(self, batch: int, device) -> None:
        self.previous = None

    def check(self, ev) -> torch.Tensor:
        value = ev.value(self.term).double().cpu()
        prev, self.previous = self.previous, value
        if prev is None:
            return torch.zeros(value.shape, dtype=torch.bool, device=ev.device)
        return ((value - prev).abs() <= self.atol + self.rtol * prev.abs()).to(ev.device)


class StopWhen(StopRule):
    """Stop where `predicate(ev)` holds: a (B,) bool tensor, a list of bools, or one bool for every problem."""

    def __init__(self, predicate, status: str = "done"):
        self.predicate, self.status = predicate, status

    def check(self, ev) -> torch.Tensor:
        hit = self.predicate(ev)
        return torch.as_tensor(hit, dtype=torch.bool, device=ev.device).expand(ev.batch).clone()
