"""The apps' confidence intervals (volsmpl.apps.stats): a point interval without spread, the BCa interval against
the normal-theory interval on a large sample, the paired difference by hand, refusals."""
from __future__ import annotations

import numpy as np
import pytest

from volsmpl.apps import stats as S


def test_constant_values_give_a_point_interval():
    assert S.mean_ci([0.25, 0.25, 0.25]) == (0.25, 0.25)


def test_interval_matches_normal_theory_on_a_large_sample():
    x = np.random.default_rng(3).normal(1.0, 2.0, 4000)
    lo, hi = S.mean_ci(x, n_resamples=4000)
    half = 1.959964 * x.std(ddof=1) / np.sqrt(x.size)
    assert lo == pytest.approx(x.mean() - half, abs=0.1 * half)
    assert hi == pytest.approx(x.mean() + half, abs=0.1 * half)


def test_interval_refuses_too_few_or_non_finite_values():
    with pytest.raises(ValueError, match=">= 2 finite"):
        S.mean_ci([1.0])
    with pytest.raises(ValueError, match=">= 2 finite"):
        S.mean_ci([1.0, float("nan")])


def test_paired_difference_is_the_interval_of_the_differences():
    """The mean of a - b by hand, and its interval that of the differences (not of a and b apart: the shared
    spread of the items cancels)."""
    rng = np.random.default_rng(5)
    items = rng.normal(0.0, 50.0, 400)                # a large spread common to both
    a, b = items + 1.0 + rng.normal(0.0, 0.5, 400), items
    d, lo, hi = S.paired_mean_ci(a, b, n_resamples=2000)
    assert d == pytest.approx(float(np.mean(a - b)), abs=1e-12)
    half = 1.959964 * np.std(a - b, ddof=1) / np.sqrt(400)
    assert lo == pytest.approx(d - half, abs=0.15 * half) and hi == pytest.approx(d + half, abs=0.15 * half)
    assert hi - lo < 0.2                                 # the items' spread of 50 would give about 10
    with pytest.raises(ValueError, match="same items"):
        S.paired_mean_ci([1.0, 2.0], [1.0, 2.0, 3.0])
