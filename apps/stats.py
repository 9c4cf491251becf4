"""Confidence intervals the apps report: the BCa bootstrap interval of a mean (scipy.stats.bootstrap) and of the
mean of paired differences.

    lo, hi = mean_ci(x)                             # 95 % interval of the mean of x (N,)
    d, lo, hi = paired_mean_ci(a, b)                # mean of a - b over the same items, and its interval

The motion table pairs its sequences (volsmpl.apps.motion.stats), the egocentric table its frames
(volsmpl.apps.egohmr.evaluate.paired_interval): both read these.
"""
from __future__ import annotations

import inspect

import numpy as np
from scipy import stats

__all__ = ["mean_ci", "paired_mean_ci"]

#: scipy >= 1.15 seeds bootstrap with `rng`, older releases with `random_state`
_SEED_ARG = "rng" if "rng" in inspect.signature(stats.bootstrap).parameters else "random_state"


def mean_ci(x, confidence: float = 0.95, n_resamples: int = 10000, seed: int = 0) -> tuple[float, float]:
    """BCa bootstrap confidence interval of the mean of x (1-D); (v, v) when every value is v (no spread to resample).

    Shape: x (N,), N >= 2."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1 or x.size < 2 or not np.all(np.isfinite(x)):
        raise ValueError(f"a confidence interval needs >= 2 finite values in one dimension, got shape {x.shape}")
    if np.all(x == x[0]):
        return float(x[0]), float(x[0])
    res = stats.bootstrap((x,), np.mean, confidence_level=confidence, n_resamples=n_resamples, method="BCa",
                          **{_SEED_ARG: np.random.default_rng(seed)})
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def paired_mean_ci(a, b, confidence: float = 0.95, n_resamples: int = 10000, seed: int = 0) -> tuple[float, float, float]:
    """Mean of a - b (the same items, in order) and its BCa bootstrap interval (`mean_ci`).

    Shape: a (N,), b (N,), N >= 2, finite; ValueError otherwise.
    Example:
        >>> paired_mean_ci([1.0, 2.0, 3.0], [0.5, 1.5, 2.5])
        (0.5, 0.5, 0.5)
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"paired values need the same items: shapes {a.shape} and {b.shape}")
    d = a - b
    lo, hi = mean_ci(d, confidence, n_resamples, seed)
    return float(d.mean()), lo, hi
