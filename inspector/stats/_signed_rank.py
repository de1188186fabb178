"""The Wilcoxon signed-rank test of paired differences with the Hodges-Lehmann estimate and the
interval that inverts the same test (references in :mod:`inspector.stats`).

One test decides: the verdict, the p-value and the interval all come from the signed-rank
statistic of the pairs that differ. Its interval is the set of shifts ``theta`` the test does not
reject on ``d - theta``: between two consecutive Walsh averages ``(d_i + d_j) / 2`` (i <= j) the
statistic of ``d - theta`` is the number of Walsh averages above ``theta`` (Tukey's identity), so
the interval runs between two order statistics of the Walsh averages, and it leaves 0 out exactly
when the test rejects (Hollander, Wolfe & Chicken 2014, "Nonparametric Statistical Methods",
3rd ed., sections 3.1-3.3). The null distribution is scipy's ``wilcoxon(method="auto")``'s: exact
for at most 50 pairs without tied magnitudes, the exact permutation distribution of the midranks
for at most 13 pairs with ties, else the normal approximation with the tie correction (no
continuity correction). With tied magnitudes the interval keeps the test's own null distribution
(the one at 0): the midranks of ``d - theta`` move with ``theta``, the verdict's test does not.
An end exactly at 0 (0 is a Walsh average: steps such as +10 and -10) is open where the test at 0
rejects (``ci_open``).

Memory stays bounded: beyond 1,000 pairs the Walsh averages' order statistics are found by
counting (O(n) memory), never by listing the n (n + 1) / 2 of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from ._intervals import z_quantile

Method = Literal["exact", "permutation", "normal"]
# |d| at most this is a tie: identical inputs give identical numbers, but not bit for bit across a
# cache round trip [data units]
TIE_TOLERANCE = 1e-9
_EXACT_MAX_PAIRS = 50  # scipy's limit for its exact distribution
_PERMUTATION_MAX_PAIRS = 13  # with ties: 2**13 sign patterns, as scipy enumerates them


@dataclass(frozen=True)
class SignedRankResult:
    """What one signed-rank test says about paired differences ``b - a``.

    Attributes:
        n_pairs: differences given.
        n_informative: differences further than :data:`TIE_TOLERANCE` from 0 (the test's n).
        statistic: the sum of the ranks of the positive informative differences (midranks).
        pvalue: two-sided; None without an informative pair.
        method: the null distribution used.
        estimate: the Hodges-Lehmann shift: the median of the informative differences' Walsh averages.
        ci: the interval inverting the test at ``confidence``; None when no outcome of this many
            pairs could be rejected (the interval is unbounded).
        ci_open: whether each end is left out: only an end exactly at 0 where the test rejects.
        min_informative: the informative pairs needed before any outcome can reach ``alpha``.
    """

    n_pairs: int
    n_informative: int
    statistic: float | None
    pvalue: float | None
    method: Method | None
    estimate: float | None
    ci: tuple[float, float] | None
    ci_open: tuple[bool, bool]
    min_informative: int


def min_pairs_to_reject(alpha: float) -> int:
    """The fewest pairs at which an exact sign or signed-rank test can reach ``p < alpha``:
    the most extreme outcome (every pair one way) has ``p = 2 / 2**n`` (6 at alpha 0.05)."""
    n = 1
    while 2.0 * 0.5 ** n >= alpha:
        n += 1
    return n


def _midranks(magnitudes: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Ranks 1..n of ``magnitudes``, ties at their mean rank."""
    order = np.argsort(magnitudes, kind="mergesort")
    sorted_values = magnitudes[order]
    starts = np.flatnonzero(np.r_[True, sorted_values[1:] != sorted_values[:-1]])
    ends = np.r_[starts[1:], len(sorted_values)]
    ranks = np.empty(len(magnitudes))
    ranks[order] = np.repeat((starts + ends + 1) / 2.0, ends - starts)
    return ranks


def _null_pmf(doubled_ranks: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
    """P(2 T = k), k = 0..sum, of twice the signed-rank statistic when each rank's sign is a fair
    coin: the exact distribution (ranks 1..n) or the permutation one (midranks)."""
    pmf = np.zeros(int(doubled_ranks.sum()) + 1)
    pmf[0] = 1.0
    top = 0  # the largest sum reached so far
    for r in doubled_ranks.tolist():
        shifted = np.zeros_like(pmf)
        shifted[r:top + r + 1] = pmf[:top + 1]  # this rank's sign positive
        pmf = 0.5 * (pmf + shifted)
        top += r
    return pmf


class _Null:
    """The test's null distribution of T (the positive ranks' sum) for one set of ranks."""

    def __init__(self, ranks: npt.NDArray[np.float64], method: Method) -> None:
        self.method = method
        n = len(ranks)
        self.total = n * (n + 1) / 2.0
        if method == "normal":
            _, counts = np.unique(ranks, return_counts=True)
            variance = n * (n + 1) * (2 * n + 1) / 24.0 - float(np.sum(counts ** 3 - counts)) / 48.0
            self.sd = math.sqrt(max(variance, 0.0))
        else:
            self.pmf = _null_pmf(np.rint(2 * ranks).astype(np.int64))
            self.cdf = np.cumsum(self.pmf)
            self.sf = np.cumsum(self.pmf[::-1])[::-1]

    def pvalue(self, t: float | npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Two-sided p of statistic(s) ``t``: ``2 min(P(T <= t), P(T >= t))``, at most 1."""
        t = np.asarray(t, dtype=np.float64)
        if self.method == "normal":
            from scipy.special import ndtr

            if self.sd == 0:
                return np.ones_like(t)
            z = np.abs(t - self.total / 2.0) / self.sd
            return np.minimum(1.0, 2.0 * ndtr(-z))
        k = 2 * t
        # scipy's rounding of a half-integer statistic: up for the lower tail, down for the upper
        low = self.cdf[np.clip(np.ceil(k - 1e-9).astype(np.int64), 0, len(self.cdf) - 1)]
        high = self.sf[np.clip(np.floor(k + 1e-9).astype(np.int64), 0, len(self.sf) - 1)]
        return np.minimum(1.0, 2.0 * np.minimum(low, high))


def _walsh_count_at_most(d: npt.NDArray[np.float64], total: float) -> int:
    """How many pairs i <= j of sorted ``d`` have ``d_i + d_j <= total``, the sums as floats add
    them (``d_j <= total - d_i`` rounds differently: one step each way puts it right)."""
    n = len(d)
    j = np.searchsorted(d, total - d, side="right")
    up = j < n
    up[up] = d[up] + d[j[up]] <= total
    j[up] = np.searchsorted(d, d[j[up]], side="right")  # past the whole run of that value
    down = j > 0
    down[down] = d[down] + d[j[down] - 1] > total
    j[down] = np.searchsorted(d, d[j[down] - 1], side="left")
    return int(np.maximum(j - np.arange(n), 0).sum())


_LISTED_MAX_PAIRS = 1000  # up to here the Walsh averages are listed (at most 500,500 floats): faster


def _walsh_order_statistics(d: npt.NDArray[np.float64], ks: list[int]) -> list[float]:
    """The ``ks``-th smallest (1-based) Walsh averages of sorted ``d``."""
    if len(d) > _LISTED_MAX_PAIRS:
        return [walsh_order_statistic(d, k) for k in ks]
    i, j = np.triu_indices(len(d))
    walsh = np.partition((d[i] + d[j]) / 2.0, [k - 1 for k in ks])
    return [float(walsh[k - 1]) for k in ks]


def walsh_order_statistic(d: npt.NDArray[np.float64], k: int) -> float:
    """The ``k``-th smallest (1-based) Walsh average of sorted ``d``, by bisection on the count of
    sums below a value (O(n log n) a step, no list of the n (n + 1) / 2 averages), then snapped to
    the smallest actual sum above the last value counted short."""
    lo, hi = 2.0 * d[0], 2.0 * d[-1]  # every sum lies in [lo, hi]
    if _walsh_count_at_most(d, lo) >= k:
        return float(lo / 2.0)
    while lo < (mid := lo + (hi - lo) / 2.0) < hi:
        if _walsh_count_at_most(d, mid) >= k:
            hi = mid
        else:
            lo = mid
    # the k-th sum is the least actual sum above lo: per i, the first j >= i past lo - d_i (and
    # its neighbours, for the rounding of that difference)
    i = np.arange(len(d))
    first = np.maximum(np.searchsorted(d, lo - d, side="right"), i)
    sums = [d[i[ok]] + d[j[ok]] for j in (first - 1, first, first + 1) if (ok := (j >= i) & (j < len(d))).any()]
    above = np.concatenate(sums)
    above = above[above > lo]
    return float((above.min() if above.size else hi) / 2.0)


def hodges_lehmann(d: npt.NDArray[np.float64]) -> float:
    """The median of the Walsh averages of sorted ``d``."""
    total = len(d) * (len(d) + 1) // 2
    if total % 2:
        return _walsh_order_statistics(d, [total // 2 + 1])[0]
    return float(np.mean(_walsh_order_statistics(d, [total // 2, total // 2 + 1])))


def signed_rank_test(differences: npt.ArrayLike, confidence: float = 0.95) -> SignedRankResult:
    """The signed-rank test of paired differences (``b - a``) against no shift, its interval and
    the Hodges-Lehmann shift, over the pairs that differ (ties at 0 left out, scipy's
    ``zero_method="wilcox"``).

    Args:
        differences: (n_pairs,) finite differences.
        confidence: of the interval; the test rejects at ``alpha = 1 - confidence`` exactly when
            the interval leaves 0 out.
    """
    alpha = round(1.0 - confidence, 12)
    d_all = np.asarray(differences, dtype=np.float64).ravel()
    if not np.isfinite(d_all).all():
        raise ValueError("signed_rank_test needs finite differences")
    d = np.sort(d_all[np.abs(d_all) > TIE_TOLERANCE])
    n = len(d)
    need = min_pairs_to_reject(alpha)
    if n == 0:
        return SignedRankResult(len(d_all), 0, None, None, None, None, None, (False, False), need)
    ranks = _midranks(np.abs(d))
    tied = len(np.unique(ranks)) < n
    method: Method = ("exact" if not tied and n <= _EXACT_MAX_PAIRS
                      else "permutation" if tied and n <= _PERMUTATION_MAX_PAIRS else "normal")
    null = _Null(ranks, method)
    statistic = float(ranks[d > 0].sum())
    p = float(null.pvalue(statistic))
    estimate = hodges_lehmann(d)
    total = n * (n + 1) // 2
    # a shift theta between Walsh averages leaves count(W < theta) = c and statistic total - c:
    # the accepted c form one run (the test rejects both tails), the interval its closure
    if method == "normal":
        accepted = _accepted_normal(null, total, alpha)
    else:
        accepted = np.flatnonzero(null.pvalue(total - np.arange(total + 1, dtype=np.float64)) >= alpha)
    ci: tuple[float, float] | None = None
    if n >= need and len(accepted):
        c_min, c_max = int(accepted[0]), int(accepted[-1])
        if c_min > 0 and c_max < total:
            low, high = _walsh_order_statistics(d, [c_min, c_max + 1])
            ci = (low, high)
    # an end exactly at 0 (0 is then a Walsh average: steps such as +10 and -10) belongs to the
    # interval as the test at 0 says: open where it rejects
    rejects = p < alpha
    open_ends = (False, False) if ci is None else (ci[0] == 0.0 and rejects, ci[1] == 0.0 and rejects)
    return SignedRankResult(len(d_all), n, statistic, p, method, estimate, ci, open_ends, need)


def _accepted_normal(null: _Null, total: int, alpha: float) -> npt.NDArray[np.int64]:
    """The accepted counts of the normal approximation in closed form (too many to list one by one)."""
    half_width = z_quantile(1.0 - alpha) * null.sd
    return np.array([max(0, math.ceil(total / 2.0 - half_width)), min(total, math.floor(total / 2.0 + half_width))])
