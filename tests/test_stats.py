"""inspector.stats against scipy: Wilson intervals, the signed-rank test with its Hodges-Lehmann
interval, McNemar's exact test and its interval, Fisher's and Barnard's tests and the percentile
bootstrap, to 1e-9; each verdict's interval against its own test (it leaves 0 out exactly when
the test rejects); the power estimate against its definition."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from inspector.stats import (
    barnard_exact,
    fisher_can_reject,
    fisher_central,
    fisher_exact,
    fisher_min_per_side,
    fisher_odds_ratio,
    mcnemar_exact,
    mcnemar_interval,
    min_pairs_to_reject,
    newcombe_interval,
    paired_bootstrap,
    rollouts_needed,
    signed_rank_test,
    verdict_from_test,
    wilson_interval,
)
from inspector.stats._signed_rank import _walsh_order_statistics, walsh_order_statistic

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
    assert verdict_from_test(0.001, -0.7, higher_is_better=True) == "A better"
    assert verdict_from_test(0.001, -0.7, higher_is_better=False) == "B better"
    assert verdict_from_test(0.2, -0.7, higher_is_better=True) == "no difference shown"
    assert verdict_from_test(0.05, 0.7, higher_is_better=True) == "no difference shown"  # p < 0.05 only


# ----------------------------------------------------------------------------------------------
# The signed-rank test, its Hodges-Lehmann estimate and interval


def _walsh(d: np.ndarray) -> np.ndarray:
    d = np.sort(d)
    return np.sort(np.concatenate([(d[i] + d[i:]) / 2 for i in range(len(d))]))


def _differences(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    if kind == "continuous":
        return rng.normal(0.4, 1.0, n)
    if kind == "steps":  # progress in 10% steps: tied magnitudes, opposite pairs (0 a Walsh average)
        return rng.integers(-4, 6, n) * 10.0
    return np.round(rng.normal(0.5, 1.0, n), 1)  # rounded: some ties


@pytest.mark.slow  # scipy's permutation test at n <= 13 with ties enumerates 2**n signs
@pytest.mark.parametrize("kind", ["continuous", "steps", "rounded"])
def test_signed_rank_test_is_scipys_wilcoxon_and_its_interval_inverts_it(kind: str) -> None:
    """p as ``scipy.stats.wilcoxon`` (exact, permutation with ties at n <= 13, else normal), the
    estimate as the median of the Walsh averages, the interval's ends Walsh averages, and 0 outside
    the interval exactly when p < 0.05, over 150 samples of 1 to 70 pairs."""
    rng = np.random.default_rng({"continuous": 0, "steps": 1, "rounded": 2}[kind])
    methods = set()
    for _ in range(150):
        d = _differences(rng, kind, int(rng.integers(1, 71)))
        r = signed_rank_test(d)
        informative = d[d != 0]
        assert r.n_pairs == len(d) and r.n_informative == len(informative)
        if not len(informative):
            assert r.pvalue is None and r.ci is None
            continue
        methods.add(r.method)
        assert r.pvalue == pytest.approx(stats.wilcoxon(informative).pvalue, abs=1e-9)
        walsh = _walsh(informative)
        assert r.estimate == pytest.approx(np.median(walsh), abs=1e-12)
        if r.n_informative < 6:
            assert r.ci is None  # no outcome of fewer than 6 pairs reaches 0.05: unbounded
            assert r.pvalue >= 0.05
            continue
        assert r.ci is not None and r.ci[0] in walsh and r.ci[1] in walsh
        assert r.ci[0] <= r.estimate <= r.ci[1]
        lo_in = r.ci[0] < 0 or (r.ci[0] == 0 and not r.ci_open[0])
        hi_in = 0 < r.ci[1] or (r.ci[1] == 0 and not r.ci_open[1])
        assert (lo_in and hi_in) == (r.pvalue >= 0.05), (d.tolist(), r)
    assert methods >= ({"exact", "normal"} if kind == "continuous" else {"permutation", "normal"}), methods


def test_signed_rank_interval_is_the_classical_one_without_ties() -> None:
    """Exact case: ``[W_(k+1), W_(N-k)]`` with k the largest count whose two tails stay under 0.05
    (Hollander, Wolfe & Chicken, section 3.3), k from scipy's exact distribution."""
    rng = np.random.default_rng(4)
    for n in (6, 9, 20, 50):
        d = rng.normal(0.2, 1.0, n)
        total = n * (n + 1) // 2
        # the exact null: the lower tail of T at k, from scipy on a sample with T = k
        k = max(t for t in range(total) if 2 * _exact_cdf(n, t) < 0.05)
        walsh = _walsh(d)
        r = signed_rank_test(d)
        assert r.method == "exact" and r.ci == (walsh[k], walsh[total - k - 1])


def _exact_cdf(n: int, t: int) -> float:
    """P(T <= t) of the signed-rank statistic of n pairs, from scipy's exact one-sided test."""
    ranks = np.arange(1, n + 1, dtype=float)
    # signs giving T+ = t exactly: the greedy subset of ranks summing to t
    positive, left = [], t
    for rank in ranks[::-1]:
        if rank <= left:
            positive.append(rank)
            left -= rank
    d = np.array([r if r in positive else -r for r in ranks])
    return float(stats.wilcoxon(d, alternative="less", method="exact").pvalue)


@pytest.mark.slow  # a bisection per order statistic, every one of them
def test_walsh_order_statistics_by_counting_equal_the_listed_ones() -> None:
    rng = np.random.default_rng(7)
    for d in (np.sort(rng.normal(0, 1, 40)), np.sort(np.round(rng.normal(0, 1, 40), 1)), np.array([2.5]),
              np.sort(rng.integers(-3, 4, 30) * 10.0)):
        walsh = _walsh(d)
        assert [walsh_order_statistic(d, k) for k in range(1, len(walsh) + 1)] == walsh.tolist()
        assert _walsh_order_statistics(d, list(range(1, len(walsh) + 1))) == walsh.tolist()


def test_too_few_pairs_is_said_and_the_limit_is_where_the_test_can_first_reject() -> None:
    assert min_pairs_to_reject(0.05) == 6 and min_pairs_to_reject(0.01) == 8
    assert stats.wilcoxon(np.arange(1.0, 6.0)).pvalue >= 0.05 > stats.wilcoxon(np.arange(1.0, 7.0)).pvalue
    r = signed_rank_test([0.0] * 13 + [0.3, 0.5, 0.2, 0.9])  # 4 pairs differ of 17, all one way
    assert (r.n_pairs, r.n_informative, r.min_informative) == (17, 4, 6)
    assert r.pvalue == pytest.approx(stats.wilcoxon([0.3, 0.5, 0.2, 0.9]).pvalue) and r.ci is None
    big = signed_rank_test(np.random.default_rng(0).normal(0.1, 1.0, 20_000))  # O(n) memory, normal
    assert big.method == "normal" and big.ci is not None and big.ci[0] < big.estimate < big.ci[1]


# ----------------------------------------------------------------------------------------------
# Success: McNemar's interval, Fisher's central test and its odds-ratio interval


def test_mcnemar_interval_is_clopper_pearson_and_inverts_the_test() -> None:
    for a_only in range(0, 26):
        for b_only in range(0, 26):
            m, n = a_only + b_only, a_only + b_only + 7
            if m == 0:
                assert mcnemar_interval(0, 0, n) is None
                continue
            lo, hi = mcnemar_interval(a_only, b_only, n)
            cp = stats.binomtest(b_only, m).proportion_ci(method="exact")
            assert lo == pytest.approx((2 * cp.low - 1) * m / n, abs=1e-12)
            assert hi == pytest.approx((2 * cp.high - 1) * m / n, abs=1e-12)
            assert lo <= (b_only - a_only) / n <= hi
            assert (lo <= 0 <= hi) == (mcnemar_exact(a_only, b_only).pvalue >= 0.05), (a_only, b_only)


@pytest.mark.slow  # scipy's conditional interval is a root search per table: 1,300 tables
def test_fisher_central_and_its_odds_ratio_interval_agree() -> None:
    for na in range(1, 9):
        for nb in range(1, 9):
            for sa in range(na + 1):
                for sb in range(nb + 1):
                    table = [[sb, nb - sb], [sa, na - sa]]
                    p = fisher_central(sa, na, sb, nb).pvalue
                    one_sided = min(stats.fisher_exact(table, alternative=alt).pvalue for alt in ("less", "greater"))
                    assert p == pytest.approx(min(1.0, 2 * one_sided), abs=1e-12)
                    _, lo, hi = fisher_odds_ratio(sa, na, sb, nb)
                    holds_one = (lo is None or lo <= 1) and (hi is None or 1 <= hi)
                    assert holds_one == (p >= 0.05), (sa, na, sb, nb)
                    if not fisher_can_reject(na, nb):
                        assert p >= 0.05
    assert fisher_min_per_side() == 4 and fisher_can_reject(4, 4) and not fisher_can_reject(3, 3)
