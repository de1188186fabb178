"""Intervals: a success rate's, a difference of two rates', and the paired bootstrap's of a mean
difference (references in :mod:`inspector.stats`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

# The bootstrap's defaults: enough resamples that the 2.5% and 97.5% percentiles move by well
# under a hundredth of the interval's width between seeds; a fixed seed so the same input always
# gives the same interval.
BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0
# Resamples drawn per block: bounds the index array at this many x n_pairs integers.
_BOOTSTRAP_BLOCK = 1_000




def z_quantile(confidence: float) -> float:
    """The standard normal quantile of a two-sided ``confidence`` interval (1.96 for 0.95)."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    return normal_quantile(0.5 + confidence / 2.0)


def normal_quantile(p: float) -> float:
    """The standard normal distribution's ``p`` quantile (Wichura's AS241 in the standard
    library: within 1e-15 of ``scipy.special.ndtri``, without scipy's half-second import in every
    process that writes a report row)."""
    return NormalDist().inv_cdf(p)


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval ``(lo, hi)`` of the success rate ``successes / n``.

    Unlike the normal (Wald) interval it stays inside [0, 1] and keeps its coverage near 0 and 1,
    where evaluations of a few dozen rollouts often land. ``n == 0`` gives ``(0.0, 1.0)``: nothing
    is known.
    """
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return 0.0, 1.0
    z = z_quantile(confidence)
    p = successes / n
    denominator = 2.0 * (n + z * z)
    center = (2.0 * n * p + z * z) / denominator
    half = z * math.sqrt(z * z + 4.0 * n * p * (1.0 - p)) / denominator
    # the bounds at 0 and n are exactly 0 and 1 (rounding would leave 1 - 1e-16)
    lo = 0.0 if successes == 0 else max(0.0, center - half)
    hi = 1.0 if successes == n else min(1.0, center + half)
    return lo, hi


def newcombe_interval(successes_a: int, n_a: int, successes_b: int, n_b: int,
                      confidence: float = 0.95) -> tuple[float, float]:
    """The interval of the difference of rates ``b - a`` of two independent samples (Newcombe's
    hybrid score interval, from each side's Wilson interval)."""
    pa, pb = successes_a / n_a, successes_b / n_b
    la, ua = wilson_interval(successes_a, n_a, confidence)
    lb, ub = wilson_interval(successes_b, n_b, confidence)
    d = pb - pa
    lo = d - math.sqrt((pb - lb) ** 2 + (ua - pa) ** 2)
    hi = d + math.sqrt((ub - pb) ** 2 + (pa - la) ** 2)
    return max(-1.0, lo), min(1.0, hi)


@dataclass(frozen=True)
class BootstrapResult:
    """The mean of the differences and its percentile interval."""

    mean: float
    ci: tuple[float, float]
    resamples: int
    seed: int


def paired_bootstrap(differences: Sequence[float] | np.ndarray, *, resamples: int = BOOTSTRAP_RESAMPLES,
                     seed: int = BOOTSTRAP_SEED, confidence: float = 0.95) -> BootstrapResult:
    """Efron's percentile bootstrap interval of the mean of paired differences (``b - a`` per pair).

    Resamples the pairs with replacement ``resamples`` times (numpy's PCG64 seeded with ``seed``:
    the same input gives the same interval), takes each resample's mean, and reports the
    ``(1 - confidence) / 2`` and ``(1 + confidence) / 2`` percentiles of those means (linear
    interpolation). Pairs are resampled, not the two sides apart: what both sides share (a hard
    episode) cancels in each difference.

    Args:
        differences: (n_pairs,) finite numbers; at least one.
    """
    x = np.asarray(differences, dtype=np.float64)
    if x.ndim != 1 or x.size == 0 or not np.isfinite(x).all():
        raise ValueError("paired_bootstrap needs a non-empty 1-D array of finite differences")
    rng = np.random.default_rng(seed)
    means = np.empty(resamples)
    for start in range(0, resamples, _BOOTSTRAP_BLOCK):
        stop = min(resamples, start + _BOOTSTRAP_BLOCK)
        # one draw per block, in the order scipy.stats.bootstrap draws them (batch = block)
        idx = rng.integers(0, x.size, (stop - start, x.size))
        means[start:stop] = x[idx].mean(axis=-1)
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.percentile(means, [100 * alpha, 100 * (1 - alpha)])
    return BootstrapResult(float(x.mean()), (float(lo), float(hi)), resamples, seed)


