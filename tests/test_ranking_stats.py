"""The Bradley-Terry fit: the maximum of its likelihood (checked with scipy's optimiser), the order
it recovers from simulated preferences, and its bootstrap intervals."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize, stats

from inspector.analysis.ranking import PRIOR_GAMES, TIE, fit_strengths, rank_sessions, simulate_votes, win_matrix

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
