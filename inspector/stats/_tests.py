"""Tests on success counts, the rollouts that would settle a comparison, and verdicts
(references in :mod:`inspector.stats`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ._intervals import normal_quantile, z_quantile

Verdict = Literal["A better", "B better", "no significant difference"]
NO_DIFFERENCE: Verdict = "no significant difference"

@dataclass(frozen=True)
class TestResult:
    """A test's p-value, its name as reports print it, and the counts it was computed from."""

    __test__ = False  # not a pytest class

    pvalue: float
    test: str


def mcnemar_exact(a_only: int, b_only: int) -> TestResult:
    """McNemar's exact test on paired successes.

    Args:
        a_only: pairs where A succeeded and B failed.
        b_only: pairs where B succeeded and A failed (the concordant pairs carry no information).

    Returns:
        The two-sided p-value of ``b_only`` of ``a_only + b_only`` discordant pairs under
        Binomial(n, 1/2): ``min(1, 2 * P(X <= min(a_only, b_only)))``; 1 with no discordant pair.
    """
    n = a_only + b_only
    if n == 0:
        return TestResult(1.0, "mcnemar_exact")
    from scipy import stats  # imported when a test runs: scipy.stats costs seconds to import

    tail = float(stats.binom.cdf(min(a_only, b_only), n, 0.5))
    return TestResult(min(1.0, 2.0 * tail), "mcnemar_exact")


def fisher_exact(successes_a: int, n_a: int, successes_b: int, n_b: int) -> TestResult:
    """Fisher's exact test (two-sided) on two independent success counts."""
    table = [[successes_a, n_a - successes_a], [successes_b, n_b - successes_b]]
    from scipy import stats

    return TestResult(float(stats.fisher_exact(table).pvalue), "fisher_exact")


def barnard_exact(successes_a: int, n_a: int, successes_b: int, n_b: int) -> TestResult:
    """Barnard's unconditional exact test (two-sided): more power than Fisher's on small samples,
    at the price of a numerical search over the nuisance parameter."""
    table = [[successes_a, successes_b], [n_a - successes_a, n_b - successes_b]]
    from scipy import stats

    return TestResult(float(stats.barnard_exact(table).pvalue), "barnard_exact")


def rollouts_needed(rate_a: float, rate_b: float, *, confidence: float = 0.95,
                    power: float = 0.8) -> int | None:
    """Rollouts per side at which a true difference ``rate_b - rate_a`` is found significant
    (two-sided, at ``confidence``) with probability ``power``; None when the rates are equal
    (no number of rollouts tells apart two equal rates).

    ``n = (z_a * sqrt(2 p (1 - p)) + z_b * sqrt(pa (1 - pa) + pb (1 - pb)))^2 / (pa - pb)^2`` with
    ``p = (pa + pb) / 2``, ``z_a`` the two-sided normal quantile of ``confidence`` and ``z_b`` the
    one-sided quantile of ``power``; rounded up.
    """
    if rate_a == rate_b:
        return None
    z_alpha = z_quantile(confidence)
    z_beta = normal_quantile(power)
    p = (rate_a + rate_b) / 2.0
    n = ((z_alpha * math.sqrt(2.0 * p * (1.0 - p))
          + z_beta * math.sqrt(rate_a * (1.0 - rate_a) + rate_b * (1.0 - rate_b))) ** 2
         / (rate_a - rate_b) ** 2)
    return max(1, math.ceil(n - 1e-9))


def verdict_from_interval(ci: tuple[float, float], higher_is_better: bool) -> Verdict:
    """The verdict of an interval of ``b - a``: a side is better only when the whole interval says so."""
    lo, hi = ci
    if lo > 0:
        return "B better" if higher_is_better else "A better"
    if hi < 0:
        return "A better" if higher_is_better else "B better"
    return NO_DIFFERENCE


def verdict_from_test(p: float, diff: float, higher_is_better: bool, confidence: float = 0.95) -> Verdict:
    """The verdict of a test: significant at ``1 - confidence`` and in the direction of ``diff`` (b - a)."""
    if p >= 1.0 - confidence or diff == 0:
        return NO_DIFFERENCE
    return "B better" if (diff > 0) == higher_is_better else "A better"
