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
estimate does. The basic interval turns that shift back; on simulated evaluations (30 points, 20
rollouts a side) it held the statistic of the true success probabilities 79-93% of the time where
the percentiles held it 0-29% (``agreement_interval_coverage`` in the benchmarks). ``bias`` is the
replicates' mean less the estimate: how far sampling noise alone moves the statistic.

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
STATISTICS = ("pearson", "spearman", "kendall", "mmrv", "mean_abs_difference")
# where each statistic can lie (rates and progress fractions are in [0, 1])
RANGES = {"pearson": (-1.0, 1.0), "spearman": (-1.0, 1.0), "kendall": (-1.0, 1.0), "mmrv": (0.0, 1.0),
          "mean_abs_difference": (0.0, 1.0)}


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


def _resampled_means(values: npt.NDArray[np.float64], n_bootstrap: int, rng: np.random.Generator) -> npt.NDArray[np.float64]:
    """(B,) means of ``values`` resampled with replacement, ``len(values)`` each."""
    return values[rng.integers(0, len(values), size=(n_bootstrap, len(values)))].mean(axis=1)


def agreement(points: Sequence[Point], *, n_bootstrap: int = DEFAULT_BOOTSTRAP, confidence: float = 0.95,
              seed: int = 0) -> dict[str, dict[str, float | int | None]]:
    """Each statistic with its bootstrap interval over rollouts.

    Returns:
        ``{name: {"value", "low", "high", "bias", "replicates"}}``; ``replicates`` counts the
        bootstrap replicates where the statistic was defined; ``value``/``low``/``high``/``bias``
        are None where it is not defined (a side whose rates are all equal).

    Raises:
        ValueError: fewer than :data:`MIN_POINTS` points, or a point with no rollout on a side.
    """
    if any(len(p.imagined) == 0 or len(p.real) == 0 for p in points):
        raise ValueError("a checkpoint-task point with no rollout on one side")
    imagined = np.array([p.imagined.mean() for p in points])
    real = np.array([p.real.mean() for p in points])
    values = point_statistics(imagined, real)
    rng = np.random.default_rng(seed)
    x = np.stack([_resampled_means(p.imagined, n_bootstrap, rng) for p in points], axis=1)
    y = np.stack([_resampled_means(p.real, n_bootstrap, rng) for p in points], axis=1)
    batch = max(1, 2_000_000 // max(1, len(points) ** 2))  # keeps the (batch, n, n) sign arrays small
    parts = [_batched_statistics(x[i:i + batch], y[i:i + batch]) for i in range(0, n_bootstrap, batch)]
    tail = (1.0 - confidence) / 2 * 100
    out: dict[str, dict[str, float | int | None]] = {}
    for name in STATISTICS:
        replicates = np.concatenate([part[name] for part in parts])
        defined = replicates[np.isfinite(replicates)]
        value = values[name]
        ok = np.isfinite(value) and len(defined) > 0
        if ok:
            q_low, q_high = np.percentile(defined, [tail, 100 - tail])
            low, high = RANGES[name]
            out[name] = {"value": float(value), "low": float(np.clip(2 * value - q_high, low, high)),
                         "high": float(np.clip(2 * value - q_low, low, high)),
                         "bias": float(defined.mean() - value), "replicates": int(len(defined))}
        else:
            out[name] = {"value": None, "low": None, "high": None, "bias": None, "replicates": int(len(defined))}
    return out


def confusion(pairs: Sequence[tuple[bool, bool]]) -> dict[str, int]:
    """Counts of (imagined success, real success) over rollouts paired by their start."""
    table = {"imagined_success_real_success": 0, "imagined_success_real_failure": 0,
             "imagined_failure_real_success": 0, "imagined_failure_real_failure": 0}
    for dreamt, real in pairs:
        table[f"imagined_{'success' if dreamt else 'failure'}_real_{'success' if real else 'failure'}"] += 1
    return table
