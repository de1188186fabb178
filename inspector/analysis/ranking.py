"""Bradley-Terry strengths of checkpoints from pairwise preferences, with bootstrap intervals.

The model (Bradley & Terry 1952): session i beats session j with probability
``p_i / (p_i + p_j)``; a strength is ``log p_i`` (natural log), reported centred so that the
sessions' mean strength is 0. A strength difference of d means odds ``exp(d)`` of winning.

Ties count as half a win for each side (the convention of RoboArena's and Chatbot Arena's
rankings); the Davidson extension's extra tie parameter is not fitted.

The fit is the maximum of the likelihood (Newton's method on the win matrix), batched over
bootstrap replicates. Every session also plays
``PRIOR_GAMES`` virtual games against a fixed reference of strength 0, winning half: a weak prior
that keeps a session which never lost (or never won) at a finite strength, as choix's ``alpha``
does; with tens of votes per session its pull is small (the coverage benchmark measures it).

Intervals: the votes are resampled with replacement (a nonparametric bootstrap), the model refitted
on each replicate, and the 2.5 and 97.5 percentiles of each centred strength reported.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

# Virtual games per session against the reference (half won): see the module docstring.
PRIOR_GAMES = 1.0
DEFAULT_BOOTSTRAP = 2000
MAX_ITERATIONS = 100
MAX_STEP = 2.0  # largest change of a strength in one Newton step
TOLERANCE = 1e-10

# Outcome of one vote for its first session: 1 a win, 0 a loss, 0.5 a tie.
WIN, LOSS, TIE = 1.0, 0.0, 0.5


def win_matrix(n_sessions: int, first: npt.ArrayLike, second: npt.ArrayLike,
               score: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """(n, n) ``W[i, j]``: wins of session i over session j, a tie counting half to each.

    Args:
        first, second: (n_votes,) session indexes of each vote's two sides.
        score: (n_votes,) the first side's result: 1 won, 0 lost, 0.5 tie.
    """
    first, second = np.asarray(first, dtype=np.intp), np.asarray(second, dtype=np.intp)
    score = np.asarray(score, dtype=np.float64)
    wins = np.zeros((n_sessions, n_sessions))
    np.add.at(wins, (first, second), score)
    np.add.at(wins, (second, first), 1.0 - score)
    return wins


def fit_strengths(wins: npt.ArrayLike, prior_games: float = PRIOR_GAMES) -> npt.NDArray[np.float64]:
    """Bradley-Terry log-strengths, centred to mean 0, for one or a batch of win matrices.

    Maximises the log-likelihood (with the prior's virtual games) by Newton's method, each step
    limited to ``MAX_STEP`` per strength: the prior makes the likelihood strictly concave, so
    this converges from 0 in a few tens of steps, for a whole batch at once.

    Args:
        wins: (n, n) or (B, n, n) win matrices (:func:`win_matrix`).
        prior_games: virtual games of each session against a reference of strength 0.

    Returns:
        (n,) or (B, n) centred log-strengths [natural log of the odds scale].
    """
    w = np.asarray(wins, dtype=np.float64)
    single = w.ndim == 2
    w = w[None] if single else w
    games = w + np.swapaxes(w, 1, 2)  # N[i, j]: games between i and j
    won = w.sum(axis=2) + prior_games / 2
    theta = np.zeros(w.shape[:2])
    eye = np.eye(w.shape[1], dtype=bool)
    for _ in range(MAX_ITERATIONS):
        beats = _sigmoid(theta[:, :, None] - theta[:, None, :])  # P(i beats j)
        beats_reference = _sigmoid(theta)
        gradient = won - (games * beats).sum(axis=2) - prior_games * beats_reference
        curvature = games * beats * (1.0 - beats)
        hessian = curvature.copy()
        hessian[:, eye] = -curvature.sum(axis=2) - prior_games * beats_reference * (1.0 - beats_reference)
        step = np.linalg.solve(hessian, gradient[..., None])[..., 0]
        theta -= np.clip(step, -MAX_STEP, MAX_STEP)
        if np.max(np.abs(step)) < TOLERANCE:
            break
    theta -= theta.mean(axis=1, keepdims=True)
    return theta[0] if single else theta


def _sigmoid(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


@dataclass(frozen=True)
class Ranking:
    """A fitted ranking. Arrays are indexed by session (the order the votes' indexes use).

    Attributes:
        strength: (n,) centred log-strengths.
        low, high: (n,) bootstrap percentile interval of each strength.
        wins: (n, n) win matrix, ties as halves.
        votes: (n, n) votes between each pair (symmetric).
        confidence: the intervals' level.
        n_bootstrap: bootstrap replicates.
    """

    strength: npt.NDArray[np.float64]
    low: npt.NDArray[np.float64]
    high: npt.NDArray[np.float64]
    wins: npt.NDArray[np.float64]
    votes: npt.NDArray[np.int64]
    confidence: float
    n_bootstrap: int

    def order(self) -> list[int]:
        """Session indexes, strongest first."""
        return [int(i) for i in np.argsort(-self.strength, kind="stable")]


def rank_sessions(n_sessions: int, first: Sequence[int], second: Sequence[int], score: Sequence[float], *,
                  n_bootstrap: int = DEFAULT_BOOTSTRAP, confidence: float = 0.95,
                  seed: int = 0) -> Ranking:
    """Fit Bradley-Terry strengths to votes and bootstrap their intervals.

    Args:
        n_sessions: how many sessions the indexes refer to.
        first, second: (n_votes,) session index of each vote's two sides.
        score: (n_votes,) the first side's result: 1 won, 0 lost, 0.5 tie.
        n_bootstrap: replicates (votes resampled with replacement).
        confidence: the intervals' level.
        seed: the bootstrap's random seed (the result is reproducible from the inputs).
    """
    first_a, second_a = np.asarray(first, dtype=np.intp), np.asarray(second, dtype=np.intp)
    score_a = np.asarray(score, dtype=np.float64)
    wins = win_matrix(n_sessions, first_a, second_a, score_a)
    strength = fit_strengths(wins)
    rng = np.random.default_rng(seed)
    n_votes = len(score_a)
    replicates = np.empty((n_bootstrap, n_sessions))
    batch = 250  # replicates fitted at once: (batch, n, n) matrices stay small
    for start in range(0, n_bootstrap, batch):
        size = min(batch, n_bootstrap - start)
        picks = rng.integers(0, n_votes, size=(size, n_votes)) if n_votes else np.zeros((size, 0), np.intp)
        boot = np.zeros((size, n_sessions, n_sessions))
        rows = np.repeat(np.arange(size), n_votes)
        f, s, sc = first_a[picks].ravel(), second_a[picks].ravel(), score_a[picks].ravel()
        np.add.at(boot, (rows, f, s), sc)
        np.add.at(boot, (rows, s, f), 1.0 - sc)
        replicates[start:start + size] = fit_strengths(boot)
    tail = (1.0 - confidence) / 2 * 100
    low, high = np.percentile(replicates, [tail, 100 - tail], axis=0)
    votes = np.zeros((n_sessions, n_sessions), dtype=np.int64)
    np.add.at(votes, (first_a, second_a), 1)
    votes = votes + votes.T
    return Ranking(strength=strength, low=low, high=high, wins=wins, votes=votes,
                   confidence=confidence, n_bootstrap=n_bootstrap)


def simulate_votes(strengths: npt.ArrayLike, n_votes: int, rng: np.random.Generator,
                   tie_probability: float = 0.0) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp],
                                                          npt.NDArray[np.float64]]:
    """Votes drawn from the Bradley-Terry model itself: uniform random pairs of distinct sessions,
    the first winning with ``sigmoid(s_first - s_second)``; a fraction ``tie_probability`` of votes
    are ties instead. For checking the fit (tests, the coverage benchmark).

    Returns:
        ``(first, second, score)`` as :func:`rank_sessions` takes them.
    """
    s = np.asarray(strengths, dtype=np.float64)
    first = rng.integers(0, len(s), size=n_votes)
    second = (first + rng.integers(1, len(s), size=n_votes)) % len(s)
    p_first = 1.0 / (1.0 + np.exp(s[second] - s[first]))
    score = (rng.random(n_votes) < p_first).astype(np.float64)
    score[rng.random(n_votes) < tie_probability] = TIE
    return first, second, score
