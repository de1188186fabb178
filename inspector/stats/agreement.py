"""How well success measured in imagination predicts success measured for real.

One point per (checkpoint, task): its success rate (or mean progress) over the rollouts judged in
the world model's imagination, and over those run on the robot or in a simulator. Across the
points:

- ``pearson``: Pearson's r of the rates (as ``scipy.stats.pearsonr``);
- ``spearman``: Spearman's rho (as ``scipy.stats.spearmanr``: Pearson's r of the ranks, ties at
  their mean rank);
- ``kendall``: Kendall's tau-b (as ``scipy.stats.kendalltau``);
- ``mmrv``: the Mean Maximum Rank Violation of SIMPLER (Li et al. 2024, "Evaluating Real-World
  Robot Manipulation Policies in Simulation", simpler-env/SimplerEnv
  ``simpler_env/utils/metrics.py``): for each point i, the largest real-rate gap
  ``|real_i - real_j|`` over the points j that imagination orders the other way round from
  reality, averaged over i. 0 is perfect; it is in units of success rate. It is not symmetric:
  imagination takes the place of SIMPLER's simulated side (its first argument);
- ``mean_abs_difference``: the mean of ``|imagined - real|`` over the points.

Each comes with a bootstrap interval over rollouts: each point's rollouts are resampled with
replacement on each side (their number kept) and the statistic recomputed over the replicates
where it is defined (a correlation is not where a side's rates are all equal). The interval is the
basic bootstrap interval ``[2 t - q97.5, 2 t - q2.5]`` (Davison & Hinkley 1997, "Bootstrap Methods
and their Application", eq. 5.6), cut to the statistic's range, not the plain percentiles: a rate
carries its sampling noise, which pulls a correlation of rates towards 0 and pushes MMRV and the
differences up, and a resampled rate carries it twice, so the replicates sit further off than the
estimate does. The basic interval turns that shift back, but not all the way: the statistic of
rates is biased, and a rank statistic's bias is not what resampling doubles. Measured by
simulation (:func:`simulate_coverage`, 500 evaluations at each of 5 points x 10 rollouts a side,
6 x 20, 10 x 20 and 30 x 20, the truth known), the 95% intervals held it 71-95% of the time
(:data:`COVERAGE_BY_SIZE`); the least per statistic (:data:`MEASURED_COVERAGE`) is reported beside
each interval, so "95%" is never taken at its word. ``bias`` is the replicates' mean less the
estimate: how far sampling noise alone moves the statistic.

Memory follows a block of replicates, not their number: successes resample as binomial counts,
and the statistics run over blocks of at most two million numbers.

Everything is computed in numpy, batched over the replicates (scipy's import alone takes a
second); the tests hold each statistic to scipy's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

DEFAULT_BOOTSTRAP = 2000
MIN_POINTS = 3  # fewer points make no correlation
# How often the 95% intervals held the statistic of the true probabilities: simulate_coverage,
# 500 simulated evaluations per (points, rollouts a side), seed points * 100 + rollouts.
COVERAGE_BY_SIZE = {
    (5, 10): {"pearson": 0.876, "spearman": 0.780, "kendall": 0.736, "mmrv": 0.842, "mean_abs_difference": 0.856},
    (6, 20): {"pearson": 0.898, "spearman": 0.756, "kendall": 0.714, "mmrv": 0.820, "mean_abs_difference": 0.876},
    (10, 20): {"pearson": 0.940, "spearman": 0.858, "kendall": 0.804, "mmrv": 0.852, "mean_abs_difference": 0.868},
    (30, 20): {"pearson": 0.952, "spearman": 0.932, "kendall": 0.828, "mmrv": 0.796, "mean_abs_difference": 0.816},
}
STATISTICS = ("pearson", "spearman", "kendall", "mmrv", "mean_abs_difference")
# where each statistic can lie (rates and progress fractions are in [0, 1])
RANGES = {"pearson": (-1.0, 1.0), "spearman": (-1.0, 1.0), "kendall": (-1.0, 1.0), "mmrv": (0.0, 1.0),
          "mean_abs_difference": (0.0, 1.0)}
# The least of those, per statistic: printed beside each interval, what its "95%" is worth.
MEASURED_COVERAGE = {name: min(size[name] for size in COVERAGE_BY_SIZE.values()) for name in STATISTICS}


@dataclass(frozen=True)
class Point:
    """One (checkpoint, task): the per-rollout values on each side (1/0 success, or progress 0..1)."""

    checkpoint: str
    task: str
    imagined: npt.NDArray[np.float64]
    real: npt.NDArray[np.float64]


def mean_maximum_rank_violation(imagined: npt.ArrayLike, real: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """SIMPLER's MMRV with imagination as its simulated side, over the last axis.

    Args:
        imagined, real: (..., n) rates of the same n points.

    Returns:
        (...) the mean over i of ``max |real_i - real_j|`` over the j ordered differently.
    """
    sim, rl = np.asarray(imagined, dtype=np.float64), np.asarray(real, dtype=np.float64)
    disagree = (sim[..., :, None] > sim[..., None, :]) != (rl[..., :, None] > rl[..., None, :])
    violation = np.where(disagree, np.abs(rl[..., :, None] - rl[..., None, :]), 0.0)
    return violation.max(axis=-1).mean(axis=-1)


def point_statistics(imagined: npt.ArrayLike, real: npt.ArrayLike) -> dict[str, float]:
    """Every statistic of :data:`STATISTICS` for one pair of rate vectors (NaN where undefined).

    Raises:
        ValueError: fewer than :data:`MIN_POINTS` points, or the vectors differ in length.
    """
    x, y = np.asarray(imagined, dtype=np.float64), np.asarray(real, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"imagined and real rates differ in shape ({x.shape} and {y.shape})")
    if len(x) < MIN_POINTS:
        raise ValueError(f"{len(x)} checkpoint-task points; a correlation needs at least {MIN_POINTS}")
    return {name: float(values[0]) for name, values in _batched_statistics(x[None], y[None]).items()}


def _batched_statistics(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> dict[str, npt.NDArray[np.float64]]:
    """The statistics of (B, n) replicate rates, row by row (the same definitions as
    :func:`point_statistics`, vectorised; NaN where a row of a side is constant)."""
    def pearson(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        a = a - a.mean(axis=1, keepdims=True)
        b = b - b.mean(axis=1, keepdims=True)
        denominator = np.sqrt((a * a).sum(axis=1) * (b * b).sum(axis=1))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(denominator > 0, (a * b).sum(axis=1) / denominator, np.nan)

    sx = np.sign(x[:, :, None] - x[:, None, :])
    sy = np.sign(y[:, :, None] - y[:, None, :])
    # tau-b = sum sx*sy / sqrt(sum sx^2 * sum sy^2) over the pairs (both triangles: the factor 2 cancels)
    return {
        "pearson": pearson(x, y),
        "spearman": pearson(mean_ranks(x), mean_ranks(y)),
        "kendall": _ratio((sx * sy).sum(axis=(1, 2)), np.sqrt((sx * sx).sum(axis=(1, 2)) * (sy * sy).sum(axis=(1, 2)))),
        "mmrv": mean_maximum_rank_violation(x, y),
        "mean_abs_difference": np.abs(x - y).mean(axis=1),
    }


def mean_ranks(values: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(B, n) -> the rank of each value within its row, 1-based, ties at their mean rank
    (``scipy.stats.rankdata(method="average", axis=1)``)."""
    # rank of v = 1 + (values below v) + (values equal to v, less one) / 2
    below = (values[:, None, :] < values[:, :, None]).sum(axis=2)
    equal = (values[:, None, :] == values[:, :, None]).sum(axis=2)
    return 1.0 + below + (equal - 1) / 2.0


def _ratio(num: npt.NDArray[np.float64], den: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


# Resampled rates drawn at once, and statistics computed at once, bound memory: at most this many
# numbers in a (draws, points) block or a (batch, points, points) sign array, whatever --bootstrap is.
_BLOCK_ELEMENTS = 2_000_000


def _resampled_means(values: npt.NDArray[np.float64], size: int, rng: np.random.Generator) -> npt.NDArray[np.float64]:
    """(size,) means of ``values`` resampled with replacement, ``len(values)`` each. Successes
    (0/1) resample as a binomial count, the same distribution without the (size, n) index array."""
    n = len(values)
    if np.all((values == 0.0) | (values == 1.0)):
        return rng.binomial(n, float(values.mean()), size) / n
    out = np.empty(size)
    block = max(1, _BLOCK_ELEMENTS // n)
    for start in range(0, size, block):
        stop = min(size, start + block)
        out[start:stop] = values[rng.integers(0, n, size=(stop - start, n))].mean(axis=1)
    return out


def _replicates(points: Sequence[Point], n_bootstrap: int, rng: np.random.Generator) -> dict[str, npt.NDArray[np.float64]]:
    """Each statistic over ``n_bootstrap`` replicates (rollouts resampled per point and side), in
    blocks: memory follows the block, not ``n_bootstrap``."""
    n = len(points)
    batch = max(1, _BLOCK_ELEMENTS // max(1, n * n))  # rows of the (batch, n, n) sign arrays
    draw = max(batch, _BLOCK_ELEMENTS // max(1, n))  # rows of resampled rates drawn at once
    parts: dict[str, list[npt.NDArray[np.float64]]] = {name: [] for name in STATISTICS}
    for start in range(0, n_bootstrap, draw):
        size = min(draw, n_bootstrap - start)
        x = np.stack([_resampled_means(p.imagined, size, rng) for p in points], axis=1)
        y = np.stack([_resampled_means(p.real, size, rng) for p in points], axis=1)
        for i in range(0, size, batch):
            for name, values in _batched_statistics(x[i:i + batch], y[i:i + batch]).items():
                parts[name].append(values)
    return {name: np.concatenate(chunks) if chunks else np.empty(0) for name, chunks in parts.items()}


def agreement(points: Sequence[Point], *, n_bootstrap: int = DEFAULT_BOOTSTRAP, confidence: float = 0.95,
              seed: int = 0) -> dict[str, dict[str, float | int | None]]:
    """Each statistic with its bootstrap interval over rollouts.

    Returns:
        ``{name: {"value", "low", "high", "bias", "replicates", "measured_coverage"}}``;
        ``replicates`` counts the bootstrap replicates where the statistic was defined;
        ``value``/``low``/``high``/``bias`` are None where it is not defined (a side whose rates
        are all equal); ``measured_coverage`` is how often such an interval held the truth in
        simulated small evaluations (:data:`MEASURED_COVERAGE`), not the nominal ``confidence``.

    Raises:
        ValueError: fewer than :data:`MIN_POINTS` points, or a point with no rollout on a side.
    """
    if any(len(p.imagined) == 0 or len(p.real) == 0 for p in points):
        raise ValueError("a checkpoint-task point with no rollout on one side")
    imagined = np.array([p.imagined.mean() for p in points])
    real = np.array([p.real.mean() for p in points])
    values = point_statistics(imagined, real)
    replicates = _replicates(points, n_bootstrap, np.random.default_rng(seed))
    tail = (1.0 - confidence) / 2 * 100
    out: dict[str, dict[str, float | int | None]] = {}
    for name in STATISTICS:
        defined = replicates[name][np.isfinite(replicates[name])]
        value = values[name]
        coverage = MEASURED_COVERAGE[name] if confidence == 0.95 else None
        if np.isfinite(value) and len(defined) > 0:
            q_low, q_high = np.percentile(defined, [tail, 100 - tail])
            low, high = RANGES[name]
            out[name] = {"value": float(value), "low": float(np.clip(2 * value - q_high, low, high)),
                         "high": float(np.clip(2 * value - q_low, low, high)),
                         "bias": float(defined.mean() - value), "replicates": int(len(defined)),
                         "measured_coverage": coverage}
        else:
            out[name] = {"value": None, "low": None, "high": None, "bias": None, "replicates": int(len(defined)),
                         "measured_coverage": coverage}
    return out


def simulate_coverage(n_points: int, n_rollouts: int, cases: int, *, n_bootstrap: int = 1000,
                      seed: int = 0) -> dict[str, float]:
    """How often the 95% intervals of :func:`agreement` hold the statistic of the true success
    probabilities, over ``cases`` simulated evaluations of ``n_points`` checkpoint-tasks with
    ``n_rollouts`` rollouts a side. Each case draws its own truth: imagined probabilities
    uniform in [0.05, 0.95], real ones those plus N(0, 0.12) noise (kept in [0.02, 0.98]).

    Returns:
        ``{statistic: coverage}`` over the cases where the true statistic is defined.
    """
    rng = np.random.default_rng(seed)
    held = dict.fromkeys(STATISTICS, 0)
    defined = dict.fromkeys(STATISTICS, 0)
    for case in range(cases):
        p = rng.uniform(0.05, 0.95, n_points)
        q = np.clip(p + rng.normal(0.0, 0.12, n_points), 0.02, 0.98)
        truth = point_statistics(p, q)
        points = [Point(str(i), "t", (rng.random(n_rollouts) < p[i]).astype(float),
                        (rng.random(n_rollouts) < q[i]).astype(float)) for i in range(n_points)]
        out = agreement(points, n_bootstrap=n_bootstrap, seed=case)
        for name, value in truth.items():
            low, high = out[name]["low"], out[name]["high"]
            if np.isfinite(value):
                defined[name] += 1
                held[name] += low is not None and high is not None and low <= value <= high
    return {name: held[name] / defined[name] if defined[name] else float("nan") for name in STATISTICS}


def confusion(pairs: Sequence[tuple[bool, bool]]) -> dict[str, int]:
    """Counts of (imagined success, real success) over rollouts paired by their start."""
    table = {"imagined_success_real_success": 0, "imagined_success_real_failure": 0,
             "imagined_failure_real_success": 0, "imagined_failure_real_failure": 0}
    for dreamt, real in pairs:
        table[f"imagined_{'success' if dreamt else 'failure'}_real_{'success' if real else 'failure'}"] += 1
    return table
