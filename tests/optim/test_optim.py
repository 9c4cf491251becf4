"""The optimisation harness (volsmpl.optim) against closed-form optima and hand-computed steps."""
from __future__ import annotations

from types import SimpleNamespace

import pytest
import torch

from volsmpl.optim import MaxIters, Patience, StopWhen, Term, Tolerance, Variable, optimize


def quadratic(target):
    return lambda s: ((s.x - target) ** 2).sum(dim=1)


def test_adam_reaches_the_minimum_of_a_quadratic():
    target = torch.tensor([[1.0, -2.0, 0.5]])
    res = optimize({"x": torch.zeros(1, 3)}, {"q": quadratic(target)}, optimizer="adam", lr=0.05, max_iters=600,
                   progress=False)
    assert torch.allclose(res.variables["x"], target, atol=1e-3)
    assert res.status == ["max_iters"] and res.iterations == [600]
    assert len(res.records) == 601 and not res.records[-1].updated and res.records[-2].updated
    assert res.records[-1].terms["q"][0] < 1e-5 and res.seconds > 0


def test_sgd_step_is_lr_times_gradient_and_weights_scale_terms():
    # one SGD step on w * (x - 3)^2 from x = 0: gradient -6 w, step +6 w lr
    res = optimize({"x": torch.zeros(1, 1)}, {"q": Term(quadratic(torch.tensor([[3.0]])), 0.5)}, optimizer="sgd", lr=0.1,
                   max_iters=1, progress=False)
    assert float(res.variables["x"]) == pytest.approx(0.1 * 6 * 0.5)
    assert res.records[0].total[0] == pytest.approx(0.5 * 9.0) and res.records[0].terms["q"][0] == pytest.approx(9.0)


def test_step_limit_scales_the_whole_update_to_the_longest_group():
    # gradient of sum(g . x) is g; SGD step -lr g; groups of 3: norms 5 (3,4,0) and 1 (0,0,1)
    g = torch.tensor([[3.0, 4.0, 0.0, 0.0, 0.0, 1.0]])
    res = optimize({"x": Variable(torch.zeros(1, 6), max_step=0.5, group=3)}, {"lin": lambda s: (s.x * g).sum(dim=1)},
                   optimizer="sgd", lr=1.0, max_iters=1, progress=False)
    step = res.variables["x"][0]
    assert torch.allclose(step, -g[0] * 0.5 / 5.0)  # direction kept, longest group exactly 0.5
    # under the limit: untouched
    res = optimize({"x": Variable(torch.zeros(1, 6), max_step=10.0, group=3)}, {"lin": lambda s: (s.x * g).sum(dim=1)},
                   optimizer="sgd", lr=1.0, max_iters=1, progress=False)
    assert torch.allclose(res.variables["x"][0], -g[0])


def test_batched_problems_stop_independently_and_equal_single_runs():
    targets = torch.tensor([[1.0], [100.0]])
    # problem 0 stops as soon as its value is below 0.5; problem 1 runs to the cap
    stop = StopWhen(lambda ev: ev.terms["q"] < 0.5, "close")
    both = optimize({"x": torch.zeros(2, 1)}, {"q": quadratic(targets)}, optimizer="sgd", lr=0.1, max_iters=20,
                    stops=[stop], progress=False)
    assert both.status == ["close", "max_iters"]
    assert both.iterations[0] < 20 and both.iterations[1] == 20
    for b in range(2):
        alone = optimize({"x": torch.zeros(1, 1)}, {"q": quadratic(targets[b:b + 1])}, optimizer="sgd", lr=0.1,
                         max_iters=20, stops=[StopWhen(lambda ev: ev.terms["q"] < 0.5, "close")], progress=False)
        assert alone.iterations[0] == both.iterations[b]
        assert torch.allclose(alone.variables["x"][0], both.variables["x"][b])


def test_patience_stops_a_flat_term_and_counts_from_the_best():
    res = optimize({"x": torch.zeros(1, 1)}, {"flat": lambda s: (s.x * 0).sum(dim=1) + 1.0}, optimizer="sgd", lr=0.1,
                   max_iters=100, stops=[Patience("flat", patience=4)], progress=False)
    # evaluation 0 sets the best; evaluations 1..4 bring no new low: the stop comes at evaluation 4 after 4 updates
    assert res.status == ["stalled"] and res.iterations == [4]


def test_patience_on_a_negative_term_needs_a_real_new_low():
    # a term that only gets worse (+1 per evaluation) from +100 or from -100, rtol 0.1: no new low, so both stall
    # after 3 evaluations. For -100 the bar was best * (1 - rtol) = -90, above the best, so every worse value
    # counted as a new low (the run went on to the cap of 100 updates); now the bar is best - rtol * |best|
    for start in (100.0, -100.0):
        calls = []

        def rising(s, start=start, calls=calls):
            calls.append(1)
            return (s.x * 0).sum(dim=1) + start + len(calls) - 1

        res = optimize({"x": torch.zeros(1, 1)}, {"t": rising}, optimizer="sgd", lr=0.01, max_iters=100,
                       stops=[Patience("t", patience=3, rtol=0.1)], progress=False)
        assert res.status == ["stalled"] and res.iterations == [3], (start, res.status, res.iterations)
    rule = Patience("t", patience=2, rtol=0.5)
    rule.reset(1, torch.device("cpu"))
    ev = lambda v: SimpleNamespace(value=lambda name: torch.tensor([v]), device=torch.device("cpu"))  # noqa: E731
    assert not rule.check(ev(-10.0)) and float(rule.best) == -10.0
    assert not rule.check(ev(-14.0)) and float(rule.best) == -10.0  # not below -15: no new low
    assert not rule.check(ev(-16.0)) and float(rule.best) == -16.0  # a new low
    assert not rule.check(ev(-20.0)) and rule.check(ev(-23.0))      # -20, -23 not below -24: stalled


def test_tolerance_stops_on_converged_total():
    res = optimize({"x": torch.zeros(1, 1)}, {"q": quadratic(torch.tensor([[1.0]]))}, optimizer="sgd", lr=0.5,
                   max_iters=50, stops=[Tolerance(rtol=0.0, atol=1e-12)], progress=False)
    # lr 0.5 on (x-1)^2 lands on the minimum in one step; the next evaluation equals it
    assert res.status == ["converged"] and res.iterations == [2]


def test_rules_fire_in_order_and_max_iters_is_not_appended_twice():
    res = optimize({"x": torch.zeros(1, 1)}, {"q": quadratic(torch.tensor([[1.0]]))}, optimizer="sgd", lr=0.1,
                   max_iters=100, stops=[MaxIters(3), Patience("q", 1)], progress=False)
    assert res.status == ["max_iters"] and res.iterations == [3]


def test_frozen_modules_get_no_gradient_and_are_restored():
    net = torch.nn.Linear(2, 1)
    res = optimize({"x": torch.ones(1, 2)}, {"q": lambda s: net(s.x)[:, 0] ** 2}, optimizer="sgd", lr=0.01, max_iters=3,
                   frozen=[net], progress=False)
    assert all(p.requires_grad and p.grad is None for p in net.parameters())
    assert res.iterations == [3]


def test_prepare_output_reaches_the_terms_and_info_is_recorded():
    res = optimize({"x": torch.zeros(1, 2)}, {"q": lambda s: (s.y.sum(dim=1), {"seen": float(s.y.detach().sum())})},
                   prepare=lambda s: {"y": (s.x - 1) ** 2}, optimizer="sgd", lr=0.1, max_iters=2, progress=False)
    assert res.records[0].info["q"]["seen"] == pytest.approx(2.0)


def test_caller_tensors_are_not_modified():
    x0 = torch.zeros(1, 2)
    optimize({"x": x0}, {"q": quadratic(torch.ones(1, 2))}, optimizer="sgd", lr=0.1, max_iters=2, progress=False)
    assert torch.equal(x0, torch.zeros(1, 2))


def test_bad_input_gives_clear_errors():
    with pytest.raises(ValueError, match="one value per problem"):
        optimize({"x": torch.zeros(2, 1)}, {"q": lambda s: s.x.sum()}, max_iters=1, progress=False)
    with pytest.raises(ValueError, match="unknown optimizer"):
        optimize({"x": torch.zeros(1, 1)}, {"q": lambda s: s.x.sum(dim=1)}, optimizer="nope", progress=False)
    with pytest.raises(ValueError, match="problems on its first dimension"):
        optimize({"x": torch.zeros(1, 1), "y": torch.zeros(2, 1)}, {"q": lambda s: s.x.sum(dim=1)}, progress=False)
    with pytest.raises(ValueError, match="group"):
        optimize({"x": Variable(torch.zeros(1, 4), max_step=0.1, group=3)}, {"q": lambda s: s.x.sum(dim=1)}, progress=False)
    with pytest.raises(ValueError, match="NaN"):
        optimize({"x": torch.full((1, 1), float("nan"))}, {"q": lambda s: s.x.sum(dim=1)}, progress=False)
    with pytest.raises(ValueError, match="max_iters"):
        MaxIters(-1)


def test_a_problem_that_diverges_stops_and_keeps_its_last_finite_values():
    """Two problems q_b(x) = c_b x^2 by SGD (lr 1) from x = 1: the step is x <- x - 2 c_b x = (1 - 2 c_b) x, so
    c = 0.25 halves x each step, and c = 1e38 jumps to -2e38, whose loss 4e114 is inf in float32: that problem stops
    as 'diverged' with the values before that update (x = 1, no update counted), the other runs on alone."""
    c = torch.tensor([0.25, 1e38])
    res = optimize({"x": torch.ones(2, 1)}, {"q": lambda s: c * (s.x ** 2).sum(dim=1)}, optimizer="sgd", lr=1.0,
                   max_iters=4, progress=False)
    assert res.status == ["max_iters", "diverged"]
    assert res.iterations == [4, 0]
    assert res.variables["x"][0, 0] == pytest.approx(0.5 ** 4) and res.variables["x"][1, 0] == 1.0
    # values that overflow: c = 1e30 from x = 1e20 steps to -2e50 = -inf in float32: set back to 1e20
    c = torch.tensor([0.25, 1e30])
    res = optimize({"x": torch.tensor([[1.0], [1e-20]])}, {"q": lambda s: c * (s.x ** 2).sum(dim=1)},
                   optimizer="sgd", lr=1e30, max_iters=2, progress=False)
    assert res.status[1] == "diverged" and res.variables["x"][1, 0] == pytest.approx(1e-20)
    # a loss that is not finite though the values are: x = 1e20 squared overflows float32
    res = optimize({"x": torch.tensor([[1.0], [1e20]])}, {"q": lambda s: (s.x ** 2).sum(dim=1)}, optimizer="sgd",
                   lr=0.25, max_iters=3, progress=False)
    assert res.status == ["max_iters", "diverged"] and res.iterations == [3, 0]
    assert res.variables["x"][1, 0] == pytest.approx(1e20) and res.variables["x"][0, 0] == pytest.approx(0.125)


def test_project_is_a_hard_bound_after_every_update():
    """min (x - 2)^2 with x projected into [0, 1] after each step ends at x = 1 (the bound), never beyond it, while
    the unprojected problem in the same batch goes on to 2."""
    seen = []

    def clamp(v):
        out = v.clone()
        out[0] = out[0].clamp(0.0, 1.0)
        return out

    def term(s):
        seen.append(float(s.x[0, 0]))
        return ((s.x - 2.0) ** 2).sum(1)

    res = optimize({"x": Variable(torch.zeros(2, 1), project=clamp)}, {"f": term}, optimizer="sgd", lr=0.1,
                   max_iters=200)
    assert res.variables["x"][0, 0].item() == pytest.approx(1.0)
    assert res.variables["x"][1, 0].item() == pytest.approx(2.0, abs=1e-4)
    assert max(seen) <= 1.0


def test_a_variable_with_a_start_is_held_until_then_and_adam_begins_afresh():
    """x starts at update 3: its values stay 0 through updates 0-2 while y moves; at update 3 Adam's first
    (bias-corrected) step moves it by exactly lr against the gradient's sign, as a fresh Adam would. Had the
    optimiser kept state for it (zero gradients counted as steps), that step would be (1 - 0.9) / (1 - 0.9^4) lr."""
    seen = []

    def term(s):
        seen.append((float(s.x[0, 0]), float(s.y[0, 0])))
        return ((s.x - 5.0) ** 2).sum(1) + ((s.y - 5.0) ** 2).sum(1)

    optimize({"x": Variable(torch.zeros(1, 1), start=3), "y": torch.zeros(1, 1)}, {"f": term}, optimizer="adam",
             lr=0.1, max_iters=4, progress=False)
    assert [x for x, _ in seen[:4]] == [0.0, 0.0, 0.0, 0.0]
    assert seen[3][1] == pytest.approx(0.3, abs=1e-3)  # y took its three steps of about lr
    assert seen[4][0] == pytest.approx(0.1, abs=1e-6)
    with pytest.raises(ValueError, match="start must be"):
        optimize({"x": Variable(torch.zeros(1, 1), start=-1)}, {"f": term}, max_iters=1, progress=False)
