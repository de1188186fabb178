"""The Bradley-Terry fit: the maximum of its likelihood (checked with scipy's optimiser, on the
dense path and the sparse one), the order it recovers from simulated preferences, its bootstrap
intervals (drawn from pair counts, checked against resampling the votes themselves), and its memory
on a chain of 1,000 sessions."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from scipy import optimize, stats

from inspector.stats import ranking
from inspector.stats.ranking import PRIOR_GAMES, TIE, PairCounts, fit_pairs, fit_strengths, rank_sessions, simulate_votes, win_matrix

TRUE_STRENGTHS = np.array([1.5, 0.75, 0.0, -0.75, -1.5])


def _negative_log_likelihood(theta: np.ndarray, wins: np.ndarray) -> float:
    """The model's likelihood with the prior's virtual games, written out plainly."""
    diff = theta[:, None] - theta[None, :]
    log_beats = -np.logaddexp(0.0, -diff)
    prior = PRIOR_GAMES / 2 * (-np.logaddexp(0.0, -theta) - np.logaddexp(0.0, theta))
    return -float((wins * log_beats).sum() + prior.sum())


def test_fit_is_the_maximum_likelihood_scipy_finds():
    rng = np.random.default_rng(7)
    first, second, score = simulate_votes(TRUE_STRENGTHS, 120, rng, tie_probability=0.2)
    wins = win_matrix(5, first, second, score)
    found = optimize.minimize(_negative_log_likelihood, np.zeros(5), args=(wins,), method="BFGS",
                              options={"gtol": 1e-10}).x
    np.testing.assert_allclose(fit_strengths(wins), found - found.mean(), atol=1e-5)


def test_a_session_that_never_lost_gets_a_finite_strength():
    wins = np.array([[0, 5, 5], [0, 0, 2], [0, 1, 0]], dtype=float)
    strength = fit_strengths(wins)
    assert np.all(np.isfinite(strength)) and strength.argmax() == 0


def test_ties_count_half_a_win_to_each_side():
    wins = win_matrix(2, [0, 0, 1], [1, 1, 0], [1.0, TIE, TIE])
    np.testing.assert_allclose(wins, [[0.0, 2.0], [1.0, 0.0]])


@pytest.mark.parametrize("seed", range(10))
def test_200_simulated_votes_recover_the_order_of_5_sessions(seed):
    rng = np.random.default_rng(seed)
    first, second, score = simulate_votes(TRUE_STRENGTHS, 200, rng, tie_probability=0.1)
    ranking = rank_sessions(5, first, second, score, n_bootstrap=200, seed=seed)
    assert stats.kendalltau(ranking.strength, TRUE_STRENGTHS).statistic >= 0.8 - 1e-9
    assert np.all(ranking.low <= ranking.strength) and np.all(ranking.strength <= ranking.high)
    assert ranking.votes.sum() == 2 * 200 and np.array_equal(ranking.votes, ranking.votes.T)


def test_the_bootstrap_is_reproducible_from_its_seed():
    rng = np.random.default_rng(1)
    votes = simulate_votes(TRUE_STRENGTHS, 60, rng)
    a, b = rank_sessions(5, *votes, n_bootstrap=100, seed=4), rank_sessions(5, *votes, n_bootstrap=100, seed=4)
    np.testing.assert_array_equal(a.low, b.low)
    np.testing.assert_array_equal(a.high, b.high)


def _resampled_votes_bootstrap(n: int, first, second, score, n_bootstrap: int, seed: int) -> np.ndarray:
    """The bootstrap as the definition has it: the votes themselves drawn with replacement, each
    replicate's win matrix fitted."""
    first, second, score = map(np.asarray, (first, second, score))
    rng = np.random.default_rng(seed)
    out = np.empty((n_bootstrap, n))
    for b in range(n_bootstrap):
        pick = rng.integers(0, len(score), len(score))
        out[b] = fit_strengths(win_matrix(n, first[pick], second[pick], score[pick]))
    return out


def test_the_bootstrap_from_pair_counts_matches_resampling_the_votes():
    rng = np.random.default_rng(11)
    votes = simulate_votes(TRUE_STRENGTHS, 150, rng, tie_probability=0.15)
    ranking = rank_sessions(5, *votes, n_bootstrap=4000, seed=2)
    reference = _resampled_votes_bootstrap(5, *votes, n_bootstrap=4000, seed=3)
    low, high = np.percentile(reference, [2.5, 97.5], axis=0)
    # two Monte Carlo estimates of the same percentiles: the intervals' ends are ~0.3 wide apart
    # from the strength, their sampling error with 4,000 replicates ~0.015
    np.testing.assert_allclose(ranking.low, low, atol=0.06)
    np.testing.assert_allclose(ranking.high, high, atol=0.06)


def _likelihood_and_gradient(theta: np.ndarray, pairs: PairCounts) -> tuple[float, np.ndarray]:
    """Minus the log-likelihood over the pairs (with the prior's games) and its gradient."""
    d = theta[pairs.low] - theta[pairs.high]
    p = 1.0 / (1.0 + np.exp(-d))
    value = -(pairs.wins * np.log(p) + (pairs.games - pairs.wins) * np.log1p(-p)).sum()
    q = 1.0 / (1.0 + np.exp(-theta))
    value -= (PRIOR_GAMES / 2 * (np.log(q) + np.log1p(-q))).sum()
    surplus = pairs.wins - pairs.games * p
    grad = -(np.bincount(pairs.low, surplus, len(theta)) - np.bincount(pairs.high, surplus, len(theta)))
    grad -= PRIOR_GAMES / 2 - PRIOR_GAMES * q
    return float(value), grad


def test_the_sparse_fit_of_many_sessions_is_the_maximum_likelihood_scipy_finds():
    n = ranking.DENSE_SESSIONS + 36
    rng = np.random.default_rng(5)
    votes = simulate_votes(rng.normal(0, 1, n), 1500, rng, tie_probability=0.1)
    pairs = PairCounts.from_votes(n, *votes)
    found = optimize.minimize(_likelihood_and_gradient, np.zeros(n), args=(pairs,), jac=True, method="L-BFGS-B",
                              options={"gtol": 1e-12, "ftol": 1e-15, "maxiter": 10_000}).x
    sparse_fit = fit_pairs(pairs)
    np.testing.assert_allclose(sparse_fit, found - found.mean(), atol=1e-5)
    np.testing.assert_allclose(sparse_fit, fit_strengths(pairs.win_matrix()), atol=1e-9)  # the dense path


def test_pair_counts_hold_each_pair_once_whatever_the_order_of_its_sides():
    pairs = PairCounts.from_votes(3, [0, 1, 2, 0, 1], [1, 0, 0, 2, 0], [1.0, 1.0, TIE, 0.0, 0.0])
    assert list(zip(pairs.low, pairs.high)) == [(0, 1), (0, 2)]
    np.testing.assert_array_equal(pairs.games, [3, 2])
    np.testing.assert_array_equal(pairs.wins, [2.0, 0.5])  # 0 beat 1 twice; 0-2: a tie and a loss


@pytest.mark.slow
def test_a_chain_of_1000_sessions_ranks_without_an_n_by_n_array_per_replicate():
    n = 1000
    rng = np.random.default_rng(0)
    first = np.arange(n - 1)
    score = (rng.random(n - 1) < 0.5).astype(float)
    tracemalloc.start()
    try:
        ranking = rank_sessions(n, first, first + 1, score, n_bootstrap=300, seed=0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # before: (250, 1000, 1000) replicate matrices, 2 GB; now the (n, n) win and vote matrices
    # the result carries (8 MB each) and per-replicate vectors
    assert peak < 100 * 2**20, peak
    assert ranking.n_bootstrap == 300 and ranking.votes.sum() == 2 * (n - 1)
    assert np.all(ranking.low <= ranking.strength + 1e-12) and np.all(ranking.strength <= ranking.high + 1e-12)


def test_densely_compared_sessions_get_the_replicates_the_budget_allows_and_no_fewer_than_the_floor():
    n = 400
    low, high = np.triu_indices(n, 1)
    every_pair = PairCounts(n, low, high, np.ones(len(low)), np.full(len(low), 0.5))
    chain = PairCounts(n, np.arange(n - 1), np.arange(1, n), np.ones(n - 1), np.ones(n - 1))
    assert ranking.affordable_replicates(chain, 2000) == 2000
    allowed = ranking.affordable_replicates(every_pair, 20_000)
    assert ranking.MIN_BOOTSTRAP <= allowed < 2000
    assert ranking.affordable_replicates(every_pair, 50) == 50  # never more than asked
