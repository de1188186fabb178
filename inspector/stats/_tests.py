"""Tests on success counts, the rollouts that would settle a comparison, and verdicts
(references in :mod:`inspector.stats`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ._intervals import normal_quantile, z_quantile

Verdict = Literal["A better", "B better", "no difference shown"]
NO_DIFFERENCE: Verdict = "no difference shown"
ALPHA = 0.05  # every verdict's level: a side is better only where its test gives p < ALPHA


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


def too_few(n: int, need: int, what: str = "pairs") -> str:
    """The verdict where no outcome of ``n`` could reach significance: says how many it takes."""
    return f"too few {what} to tell (n = {n}; needs >= {need})"


def verdict_from_test(p: float, diff: float, higher_is_better: bool, alpha: float = ALPHA) -> Verdict:
    """The verdict of a test: significant (``p < alpha``) and in the direction of ``diff`` (b - a)."""
    if p >= alpha or diff == 0:
        return NO_DIFFERENCE
    return "B better" if (diff > 0) == higher_is_better else "A better"


def mcnemar_interval(a_only: int, b_only: int, n_pairs: int,
                     confidence: float = 0.95) -> tuple[float, float] | None:
    """The exact conditional interval of the paired difference of success rates ``B - A``.

    Given the ``m = a_only + b_only`` discordant pairs, ``b_only ~ Binomial(m, pi)``; the
    Clopper-Pearson interval of ``pi`` (scipy's ``binomtest(b_only, m).proportion_ci("exact")``)
    maps to the rate difference ``(2 pi - 1) m / n_pairs``. It leaves 0 out exactly when
    :func:`mcnemar_exact` rejects at ``1 - confidence``: both invert the same binomial tails
    (Breslow & Day 1980, "Statistical Methods in Cancer Research" I, section 5.2). None without a
    discordant pair.
    """
    m = a_only + b_only
    if m == 0:
        return None
    from scipy import stats

    ci = stats.binomtest(b_only, m).proportion_ci(confidence_level=confidence, method="exact")
    return (2.0 * ci.low - 1.0) * m / n_pairs, (2.0 * ci.high - 1.0) * m / n_pairs


def fisher_central(successes_a: int, n_a: int, successes_b: int, n_b: int) -> TestResult:
    """Fisher's exact test, two-sided as twice the smaller one-sided p (at most 1): the form whose
    inversion is the exact conditional interval of the odds ratio (:func:`fisher_odds_ratio`)."""
    from scipy import stats

    table = [[successes_b, n_b - successes_b], [successes_a, n_a - successes_a]]
    less = stats.fisher_exact(table, alternative="less").pvalue
    greater = stats.fisher_exact(table, alternative="greater").pvalue
    return TestResult(float(min(1.0, 2.0 * min(less, greater))), "fisher_exact_central")


def fisher_odds_ratio(successes_a: int, n_a: int, successes_b: int, n_b: int,
                      confidence: float = 0.95) -> tuple[float | None, float | None, float | None]:
    """B's odds of success over A's: the conditional maximum-likelihood estimate and its exact
    conditional interval (scipy's ``contingency.odds_ratio(kind="conditional")``; Cornfield 1956),
    which leaves 1 out exactly when :func:`fisher_central` rejects at ``1 - confidence``. What is
    infinite (a side with no failure) is None."""
    from scipy.stats.contingency import odds_ratio

    result = odds_ratio([[successes_b, n_b - successes_b], [successes_a, n_a - successes_a]], kind="conditional")
    ci = result.confidence_interval(confidence_level=confidence)

    def finite(v: float) -> float | None:
        return float(v) if math.isfinite(v) else None

    return finite(result.statistic), finite(ci.low), finite(ci.high)


def fisher_min_per_side(alpha: float = ALPHA) -> int:
    """The fewest rollouts a side at which Fisher's test can reject (all of one side succeeding,
    none of the other: ``p = 2 / C(2n, n)``): 4 at 0.05."""
    n = 1
    while 2.0 / math.comb(2 * n, n) >= alpha:
        n += 1
    return n


def fisher_can_reject(n_a: int, n_b: int, alpha: float = ALPHA) -> bool:
    """Whether any outcome of ``n_a`` and ``n_b`` rollouts could reach ``p < alpha`` in
    :func:`fisher_central` (its most extreme table has ``p = 2 / C(n_a + n_b, n_a)``)."""
    return 2.0 / math.comb(n_a + n_b, n_a) < alpha
