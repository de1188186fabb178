"""The agreement statistics against scipy and against SIMPLER's own functions on SIMPLER's tables.

``REAL_PERF``, ``SIMPLER_PERF``, ``pearson_correlation`` and ``mean_maximum_rank_violation`` below
are copied verbatim from simpler-env/SimplerEnv, ``simpler_env/utils/metrics.py`` (the published
real-robot and SIMPLER success rates of RT-1, RT-1-X, RT-2-X and Octo, Li et al. 2024).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from inspector.stats.agreement import (
    COVERAGE_BY_SIZE,
    MEASURED_COVERAGE,
    Point,
    _resampled_means,
    agreement,
    confusion,
    mean_maximum_rank_violation,
    point_statistics,
    simulate_coverage,
)

REAL_PERF = {
    "google_robot_pick_coke_can": {"rt-2-x": 0.907, "rt-1-converged": 0.853, "rt-1-15pct": 0.920, "rt-1-x": 0.760,
                                   "rt-1-begin": 0.133, "octo-base": 0.293},
    "google_robot_move_near": {"rt-2-x": 0.733, "rt-1-converged": 0.633, "rt-1-15pct": 0.583, "rt-1-x": 0.450,
                               "rt-1-begin": 0.017, "octo-base": 0.350},
    "google_robot_open_drawer": {"rt-2-x": 0.333, "rt-1-converged": 0.815, "rt-1-15pct": 0.704, "rt-1-x": 0.519,
                                 "rt-1-begin": 0.000, "octo-base": 0.148},
    "google_robot_close_drawer": {"rt-2-x": 0.630, "rt-1-converged": 0.926, "rt-1-15pct": 0.889, "rt-1-x": 0.741,
                                  "rt-1-begin": 0.000, "octo-base": 0.519},
    "google_robot_place_apple_in_closed_top_drawer": {"rt-2-x": 0.074, "rt-1-converged": 0.185, "rt-1-15pct": 0.185,
                                                      "rt-1-x": 0.407, "rt-1-begin": 0.000, "octo-base": 0.000},
    "widowx_spoon_on_towel": {"rt-1-x": 0.000, "octo-base": 0.333, "octo-small": 0.417},
    "widowx_carrot_on_plate": {"rt-1-x": 0.000, "octo-base": 0.250, "octo-small": 0.083},
    "widowx_stack_cube": {"rt-1-x": 0.000, "octo-base": 0.000, "octo-small": 0.125},
    "widowx_put_eggplant_in_basket": {"rt-1-x": 0.000, "octo-base": 0.250, "octo-small": 0.400},
}

SIMPLER_PERF = {
    "google_robot_pick_coke_can": {"rt-2-x": 0.787, "rt-1-converged": 0.857, "rt-1-15pct": 0.710, "rt-1-x": 0.567,
                                   "rt-1-begin": 0.027, "octo-base": 0.170},
    "google_robot_move_near": {"rt-2-x": 0.779, "rt-1-converged": 0.442, "rt-1-15pct": 0.354, "rt-1-x": 0.317,
                               "rt-1-begin": 0.050, "octo-base": 0.042},
    "google_robot_open_drawer": {"rt-2-x": 0.157, "rt-1-converged": 0.601, "rt-1-15pct": 0.463, "rt-1-x": 0.296,
                                 "rt-1-begin": 0.000, "octo-base": 0.009},
    "google_robot_close_drawer": {"rt-2-x": 0.343, "rt-1-converged": 0.861, "rt-1-15pct": 0.667, "rt-1-x": 0.891,
                                  "rt-1-begin": 0.278, "octo-base": 0.444},
    "google_robot_place_apple_in_closed_top_drawer": {"rt-2-x": 0.037, "rt-1-converged": 0.065, "rt-1-15pct": 0.130,
                                                      "rt-1-x": 0.213, "rt-1-begin": 0.000, "octo-base": 0.000},
    "widowx_spoon_on_towel": {"rt-1-x": 0.000, "octo-base": 0.125, "octo-small": 0.472},
    "widowx_carrot_on_plate": {"rt-1-x": 0.042, "octo-base": 0.083, "octo-small": 0.097},
    "widowx_stack_cube": {"rt-1-x": 0.000, "octo-base": 0.000, "octo-small": 0.042},
    "widowx_put_eggplant_in_basket": {"rt-1-x": 0.000, "octo-base": 0.431, "octo-small": 0.569},
}


def pearson_correlation(perf_sim, perf_real) -> float:
    perf_sim, perf_real = np.array(perf_sim), np.array(perf_real)
    assert perf_sim.shape == perf_real.shape
    perf_sim = perf_sim - np.mean(perf_sim)
    perf_real = perf_real - np.mean(perf_real)
    if np.all(perf_sim == perf_real):
        pearson = 1
    else:
        pearson = np.sum(perf_sim * perf_real) / (
            np.sqrt(np.sum(perf_sim**2) * np.sum(perf_real**2)) + 1e-8
        )
    return pearson


def mean_maximum_rank_violation_simpler(perf_sim, perf_real) -> float:
    perf_sim, perf_real = np.array(perf_sim), np.array(perf_real)
    assert perf_sim.shape == perf_real.shape
    rank_violations = []
    for i in range(len(perf_sim)):
        rank_violation = 0.0
        for j in range(len(perf_sim)):
            if (perf_sim[i] > perf_sim[j]) != (perf_real[i] > perf_real[j]):
                rank_violation = max(
                    rank_violation, np.abs(perf_real[i] - perf_real[j])
                )
        rank_violations.append(rank_violation)
    rank_violation = np.mean(rank_violations)
    return rank_violation


def _sides(task: str) -> tuple[np.ndarray, np.ndarray]:
    policies = sorted(REAL_PERF[task])
    return np.array([SIMPLER_PERF[task][p] for p in policies]), np.array([REAL_PERF[task][p] for p in policies])


@pytest.mark.parametrize("task", sorted(REAL_PERF))
def test_statistics_equal_simpler_and_scipy_on_simpler_tables(task):
    sim, real = _sides(task)
    got = point_statistics(sim, real)
    assert got["mmrv"] == pytest.approx(mean_maximum_rank_violation_simpler(sim, real), abs=1e-12)
    # SIMPLER adds 1e-8 to the denominator D: its r is ours times D / (D + 1e-8)
    denominator = np.sqrt(np.sum((sim - sim.mean()) ** 2) * np.sum((real - real.mean()) ** 2))
    assert got["pearson"] == pytest.approx(pearson_correlation(sim, real), abs=1e-12 + 1e-8 / denominator)
    assert got["spearman"] == pytest.approx(stats.spearmanr(sim, real).statistic, abs=1e-12)
    assert got["kendall"] == pytest.approx(stats.kendalltau(sim, real).statistic, abs=1e-12)
    assert got["mean_abs_difference"] == pytest.approx(np.mean(np.abs(sim - real)), abs=1e-12)


def test_mmrv_is_not_symmetric_and_imagination_is_simpler_sides_first_argument():
    sim, real = _sides("google_robot_close_drawer")
    forward = mean_maximum_rank_violation(sim, real)
    assert forward == pytest.approx(mean_maximum_rank_violation_simpler(sim, real))
    assert forward != pytest.approx(mean_maximum_rank_violation_simpler(real, sim))


def test_batched_bootstrap_statistics_equal_the_pointwise_ones():
    """The vectorised statistics of the bootstrap agree with scipy row by row: checked by giving
    every point one rollout per side (each replicate then equals the data)."""
    rng = np.random.default_rng(3)
    imagined, real = rng.random(12), rng.random(12)
    points = [Point(f"c{i}", "t", np.array([imagined[i]]), np.array([real[i]])) for i in range(12)]
    out = agreement(points, n_bootstrap=50)
    expected = point_statistics(imagined, real)
    for name, value in expected.items():
        assert out[name]["value"] == pytest.approx(value)
        assert out[name]["low"] == pytest.approx(value) and out[name]["high"] == pytest.approx(value)
        assert out[name]["replicates"] == 50


def _simulated_points(rng: np.random.Generator, p: np.ndarray, q: np.ndarray, n: int) -> list[Point]:
    return [Point(f"c{i}", "t", (rng.random(n) < p[i]).astype(float), (rng.random(n) < q[i]).astype(float))
            for i in range(len(p))]


def test_intervals_hold_the_statistic_of_the_true_success_probabilities():
    """Rates of 20 rollouts per side and point, drawn from known probabilities: the intervals hold
    the statistic of the probabilities themselves in most of 40 seeded evaluations (the plain
    percentile interval, shifted by the rates' sampling noise, would hold it in almost none)."""
    rng = np.random.default_rng(0)
    p = rng.uniform(0.05, 0.95, 30)
    q = np.clip(p + rng.normal(0, 0.12, 30), 0.02, 0.98)
    truth = point_statistics(p, q)
    held = dict.fromkeys(truth, 0)
    for seed in range(40):
        out = agreement(_simulated_points(np.random.default_rng(100 + seed), p, q, 20), n_bootstrap=400, seed=seed)
        for name, value in truth.items():
            held[name] += out[name]["low"] <= value <= out[name]["high"]
            assert out[name]["low"] <= out[name]["high"]
        assert out["pearson"]["bias"] < 0 < out["mean_abs_difference"]["bias"]  # noise pulls r down, |d| up
    assert all(n >= 28 for n in held.values()), held  # at least 70% of 40


def test_intervals_narrow_with_more_rollouts():
    rng = np.random.default_rng(0)
    p = np.linspace(0.1, 0.9, 6)
    widths = []
    for n in (10, 200):
        out = agreement(_simulated_points(rng, p, p, n), n_bootstrap=500, seed=1)
        widths.append(out["pearson"]["high"] - out["pearson"]["low"])
    assert widths[1] < widths[0] / 2


def test_fewer_than_three_points_is_refused():
    with pytest.raises(ValueError, match="at least 3"):
        point_statistics([0.1, 0.2], [0.3, 0.4])


def test_a_constant_side_has_no_correlation_but_has_mmrv():
    got = point_statistics([0.5, 0.5, 0.5], [0.1, 0.5, 0.9])
    assert np.isnan(got["pearson"]) and np.isnan(got["kendall"])
    # imagination ties everything: point i is violated by every j below it in reality (strict ">")
    assert got["mmrv"] == pytest.approx(np.mean([0.0, 0.4, 0.8]))
    assert got["mmrv"] == pytest.approx(mean_maximum_rank_violation_simpler([0.5, 0.5, 0.5], [0.1, 0.5, 0.9]))


def test_confusion_counts_each_pairing():
    table = confusion([(True, True), (True, False), (True, False), (False, False)])
    assert table == {"imagined_success_real_success": 1, "imagined_success_real_failure": 2,
                     "imagined_failure_real_success": 0, "imagined_failure_real_failure": 1}


@pytest.mark.parametrize("seed", range(5))
def test_statistics_equal_scipy_on_rates_with_many_ties(seed):
    """Rates of a few rollouts tie often (k/4): the ranks' ties are where Spearman and tau-b differ
    from their plain forms."""
    rng = np.random.default_rng(seed)
    x, y = rng.integers(0, 5, 15) / 4, rng.integers(0, 5, 15) / 4
    got = point_statistics(x, y)
    assert got["pearson"] == pytest.approx(stats.pearsonr(x, y).statistic, abs=1e-12)
    assert got["spearman"] == pytest.approx(stats.spearmanr(x, y).statistic, abs=1e-12)
    assert got["kendall"] == pytest.approx(stats.kendalltau(x, y).statistic, abs=1e-12)
    assert got["mmrv"] == pytest.approx(mean_maximum_rank_violation_simpler(x, y), abs=1e-12)


# ----------------------------------------------------------------------------------------------
# What "95%" is worth: the measured coverage printed beside each interval, and bounded memory


@pytest.mark.slow  # 200 simulated evaluations, each bootstrapped
def test_measured_coverage_is_what_a_simulation_measures():
    """The coverage table the intervals are printed with is reproduced by a fresh simulation at
    6 points x 20 rollouts a side (other seeds, fewer cases: within 0.09, about 2.5 standard errors),
    and the figure printed beside each interval is the least over the sizes simulated."""
    measured = simulate_coverage(6, 20, 200, n_bootstrap=500, seed=12345)
    for name, coverage in measured.items():
        assert coverage == pytest.approx(COVERAGE_BY_SIZE[(6, 20)][name], abs=0.09), (name, coverage)
        assert MEASURED_COVERAGE[name] == min(size[name] for size in COVERAGE_BY_SIZE.values())
    # below the nominal 95% at small n: that is why it is printed
    assert min(MEASURED_COVERAGE.values()) < 0.95
    rng = np.random.default_rng(2)
    out = agreement(_simulated_points(rng, np.linspace(0.1, 0.9, 5), np.linspace(0.2, 0.8, 5), 10), n_bootstrap=200)
    assert {name: s["measured_coverage"] for name, s in out.items()} == MEASURED_COVERAGE


def test_binomial_resampling_is_the_resampled_success_rate():
    """0/1 outcomes resample as Binomial(n, k/n) / n: the same distribution as resampling the
    rollouts (checked on its mean and variance over 200,000 draws)."""
    values = np.array([1.0] * 7 + [0.0] * 13)
    draws = _resampled_means(values, 200_000, np.random.default_rng(0))
    assert draws.mean() == pytest.approx(0.35, abs=0.002)
    assert draws.var() == pytest.approx(0.35 * 0.65 / 20, rel=0.02)
    assert set(np.unique(draws * 20).round(9)) <= set(range(21))


@pytest.mark.slow  # 200,000 replicates
def test_many_replicates_keep_memory_bounded_and_json_strict():
    """--bootstrap 200,000 over 10 points of 1,000 rollouts: peak allocation stays under 200 MB
    (a (replicates, rollouts) index array would be 1.6 GB a point); undefined statistics are null."""
    import json
    import tracemalloc

    rng = np.random.default_rng(1)
    points = _simulated_points(rng, np.linspace(0.1, 0.9, 10), np.linspace(0.15, 0.85, 10), 1000)
    tracemalloc.start()
    try:
        out = agreement(points, n_bootstrap=200_000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 200 * 2**20, peak / 2**20
    assert all(s["replicates"] == 200_000 for s in out.values())
    constant = [Point(f"c{i}", "t", np.ones(4), (rng.random(4) < 0.5).astype(float)) for i in range(4)]
    undefined = agreement(constant, n_bootstrap=100)
    assert undefined["pearson"]["value"] is None and undefined["mmrv"]["value"] is not None
    json.dumps([out, undefined], allow_nan=False)
