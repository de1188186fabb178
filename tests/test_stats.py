"""inspector.stats against scipy: Wilson intervals, McNemar's exact test, Fisher's and Barnard's
tests and the percentile bootstrap, to 1e-9; the power estimate against its definition."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from inspector.stats import (
    barnard_exact,
    fisher_exact,
    mcnemar_exact,
    newcombe_interval,
    paired_bootstrap,
    rollouts_needed,
    verdict_from_interval,
    verdict_from_test,
    wilson_interval,
)

COUNTS = [(0, 1), (1, 1), (0, 20), (20, 20), (2, 20), (18, 20), (4, 20), (7, 13), (500, 1000), (3, 1000)]


@pytest.mark.parametrize(("k", "n"), COUNTS)
@pytest.mark.parametrize("confidence", [0.95, 0.9, 0.99])
def test_wilson_interval_is_scipys(k: int, n: int, confidence: float) -> None:
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
    lo, hi = wilson_interval(k, n, confidence)
    assert lo == pytest.approx(ci.low, abs=1e-9)
    assert hi == pytest.approx(ci.high, abs=1e-9)
    assert 0.0 <= lo <= k / n <= hi <= 1.0


def test_wilson_interval_refuses_impossible_counts() -> None:
    assert wilson_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError):
        wilson_interval(3, 2)


@pytest.mark.parametrize(("a_only", "b_only"), [(0, 0), (0, 1), (2, 9), (9, 2), (5, 5), (0, 14), (30, 41)])
def test_mcnemar_exact_is_a_binomial_test_on_the_discordant_pairs(a_only: int, b_only: int) -> None:
    expected = 1.0 if a_only + b_only == 0 else stats.binomtest(b_only, a_only + b_only, 0.5).pvalue
    assert mcnemar_exact(a_only, b_only).pvalue == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize(("sa", "na", "sb", "nb"), [(18, 20, 20, 20), (18, 20, 4, 20), (3, 10, 7, 12),
                                                    (0, 5, 5, 5)])
def test_fisher_and_barnard_are_scipys(sa: int, na: int, sb: int, nb: int) -> None:
    table = [[sa, na - sa], [sb, nb - sb]]
    assert fisher_exact(sa, na, sb, nb).pvalue == pytest.approx(stats.fisher_exact(table).pvalue, abs=1e-9)
    columns = [[sa, sb], [na - sa, nb - sb]]
    assert barnard_exact(sa, na, sb, nb).pvalue == pytest.approx(stats.barnard_exact(columns).pvalue, abs=1e-9)


def test_paired_bootstrap_is_scipys_percentile_bootstrap_and_deterministic() -> None:
    x = np.random.default_rng(5).normal(0.3, 1.0, 37)
    ours = paired_bootstrap(x, seed=7)
    theirs = stats.bootstrap((x,), np.mean, n_resamples=10_000, batch=1_000, method="percentile",
                             rng=np.random.default_rng(7), vectorized=True).confidence_interval
    assert ours.ci[0] == pytest.approx(theirs.low, abs=1e-9)
    assert ours.ci[1] == pytest.approx(theirs.high, abs=1e-9)
    assert ours.mean == pytest.approx(x.mean(), abs=1e-12)
    assert paired_bootstrap(x, seed=7) == ours  # the same input, the same interval
    assert paired_bootstrap(x, seed=8).ci != ours.ci


def test_newcombe_interval_holds_the_difference_and_narrows_with_n() -> None:
    lo, hi = newcombe_interval(4, 20, 18, 20)
    assert lo < 0.7 < hi and lo > 0  # 18/20 vs 4/20: clearly apart
    lo2, hi2 = newcombe_interval(18, 20, 20, 20)
    assert lo2 < 0 < hi2  # 2 of 20 apart: not
    wide = newcombe_interval(5, 10, 6, 10)
    narrow = newcombe_interval(500, 1000, 600, 1000)
    assert narrow[1] - narrow[0] < wide[1] - wide[0]


def test_rollouts_needed_reaches_the_power_it_promises() -> None:
    """At the returned n the normal-approximation power is >= 80%, at n - 1 it is below."""
    def power(pa: float, pb: float, n: int) -> float:
        z = stats.norm.ppf(0.975)
        p = (pa + pb) / 2
        se0 = np.sqrt(2 * p * (1 - p) / n)
        se1 = np.sqrt((pa * (1 - pa) + pb * (1 - pb)) / n)
        return float(stats.norm.cdf((abs(pa - pb) - z * se0) / se1))

    for pa, pb in [(0.5, 0.6), (0.9, 1.0), (0.2, 0.5), (0.85, 0.75)]:
        n = rollouts_needed(pa, pb)
        assert n is not None and power(pa, pb, n) >= 0.8 > power(pa, pb, n - 1)
    assert rollouts_needed(0.5, 0.5) is None


def test_verdicts() -> None:
    assert verdict_from_interval((0.1, 0.3), higher_is_better=False) == "A better"
    assert verdict_from_interval((0.1, 0.3), higher_is_better=True) == "B better"
    assert verdict_from_interval((-0.1, 0.3), higher_is_better=True) == "no significant difference"
    assert verdict_from_test(0.001, -0.7, higher_is_better=True) == "A better"
    assert verdict_from_test(0.2, -0.7, higher_is_better=True) == "no significant difference"
