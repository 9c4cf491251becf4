"""The optimisation harness shared by the apps: `optimize` (harness.py), stop rules (stops.py).

    from volsmpl.optim import optimize, Variable, Term, Patience, StopWhen
"""
from .harness import Evaluation, OptimResult, State, StepRecord, Term, Variable, optimize
from .stops import MaxIters, Patience, StopRule, StopWhen, Tolerance

__all__ = ["optimize", "Variable", "Term", "State", "Evaluation", "StepRecord", "OptimResult",
           "StopRule", "MaxIters", "Patience", "Tolerance", "StopWhen"]
