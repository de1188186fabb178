"""Bradley-Terry strengths of checkpoints from pairwise preferences, with bootstrap intervals.

The model (Bradley & Terry 1952): session i beats session j with probability
``p_i / (p_i + p_j)``; a strength is ``log p_i`` (natural log), reported centred so that the
sessions' mean strength is 0. A strength difference of d means odds ``exp(d)`` of winning.

Ties count as half a win for each side (the convention of RoboArena's and Chatbot Arena's
rankings); the Davidson extension's extra tie parameter is not fitted.

The votes are first counted per pair of sessions (:class:`PairCounts`): everything after works on
the comparison graph's edges, so memory and time grow with the pairs compared, not with the votes
nor with the square of the sessions. The fit is the maximum of the likelihood by Newton's method:
with few sessions on dense (n, n) Hessians, batched over bootstrap replicates; with more, one
replicate at a time on a sparse Hessian (a graph Laplacian plus the prior's diagonal), which a
chain of 1,000 sessions factorises in linear time. Every session also plays ``PRIOR_GAMES``
virtual games against a fixed reference of strength 0, winning half: a weak prior that keeps a
session which never lost (or never won) at a finite strength, as choix's ``alpha`` does; with tens
of votes per session its pull is small (the coverage benchmark measures it).

Intervals: the votes are resampled with replacement (a nonparametric bootstrap), the model refitted
on each replicate, and the 2.5 and 97.5 percentiles of each centred strength reported. Resampling
n votes with replacement draws each (pair, outcome)'s count from one multinomial over those
categories, so a replicate is drawn as that multinomial: the same distribution without an
(n_votes,) index array per replicate. Each replicate's fit starts from the fit to all votes. Where
the sessions are many and densely compared, fewer replicates than asked are run, so that the
bootstrap's arithmetic stays under :data:`BOOTSTRAP_WORK` (:func:`affordable_replicates`); the
ranking says how many ran.
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
# Up to this many sessions the Hessians are dense and batched over replicates; past it, sparse.
DENSE_SESSIONS = 64
# Dense (batch, n, n) matrices held at once while bootstrapping [values]: 250 x 64 x 64 (8 MB).
DENSE_BATCH_VALUES = 250 * DENSE_SESSIONS ** 2
# Multinomial draws held at once (batch x categories) [values]: 32 MB.
DRAW_BATCH_VALUES = 4_000_000
# The bootstrap's budget in multiply-adds of its factorisations (~25 s on one busy core).
BOOTSTRAP_WORK = 5e10
# Newton steps a replicate takes from the full fit, counted in the budget (3 to 6 measured).
STEPS_PER_REPLICATE = 6
# A sparse Newton step's setup (building and ordering the matrix, in Python), counted as this many
# multiply-adds: ~1 ms, measured on a chain of 1,000 sessions.
SPARSE_STEP_SETUP = 2e6
# Fewer replicates than this make no 95% percentile interval worth showing: the budget yields to it.
MIN_BOOTSTRAP = 100

# Outcome of one vote for its first session: 1 a win, 0 a loss, 0.5 a tie.
WIN, LOSS, TIE = 1.0, 0.0, 0.5


@dataclass(frozen=True)
class PairCounts:
    """Votes counted per pair of sessions: the comparison graph's edges.

    Attributes:
        n_sessions: how many sessions the indexes refer to.
        low, high: (E,) the pair's session indexes, ``low < high``.
        games: (E,) votes between them.
        wins: (E,) wins of ``low`` over ``high``, a tie counting half.
    """

    n_sessions: int
    low: npt.NDArray[np.intp]
    high: npt.NDArray[np.intp]
    games: npt.NDArray[np.float64]
    wins: npt.NDArray[np.float64]

    @classmethod
    def from_votes(cls, n_sessions: int, first: npt.ArrayLike, second: npt.ArrayLike,
                   score: npt.ArrayLike) -> PairCounts:
        pairs, outcome_counts = _categories(n_sessions, first, second, score)
        return cls.from_categories(n_sessions, pairs, outcome_counts)

    @classmethod
    def from_categories(cls, n_sessions: int, pairs: npt.NDArray[np.intp],
                        outcome_counts: npt.NDArray[np.float64]) -> PairCounts:
        """From (E, 2) pairs and (E, 3) counts of their low side's wins, losses and ties."""
        games = outcome_counts.sum(axis=-1)
        wins = outcome_counts[..., 0] + 0.5 * outcome_counts[..., 2]
        return cls(n_sessions, pairs[:, 0], pairs[:, 1], games, wins)

    def win_matrix(self) -> npt.NDArray[np.float64]:
        """(n, n) ``W[i, j]``: wins of session i over session j (ties as halves)."""
        w = np.zeros((self.n_sessions, self.n_sessions))
        w[self.low, self.high] = self.wins
        w[self.high, self.low] = self.games - self.wins
        return w


def _categories(n_sessions: int, first: npt.ArrayLike, second: npt.ArrayLike, score: npt.ArrayLike
                ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.float64]]:
    """The pairs compared, (E, 2) with low < high, and (E, 3) counts of their low side's wins,
    losses and ties."""
    f, s = np.asarray(first, dtype=np.intp), np.asarray(second, dtype=np.intp)
    sc = np.asarray(score, dtype=np.float64)
    low, high = np.minimum(f, s), np.maximum(f, s)
    low_score = np.where(f == low, sc, 1.0 - sc)
    outcome = np.where(low_score == TIE, 2, np.where(low_score == WIN, 0, 1))
    key = low * n_sessions + high
    keys, edge = np.unique(key, return_inverse=True)
    counts = np.zeros((len(keys), 3))
    np.add.at(counts, (edge.ravel(), outcome), 1.0)
    pairs = np.stack([keys // n_sessions, keys % n_sessions], axis=1).astype(np.intp) if len(keys) else \
        np.zeros((0, 2), np.intp)
    return pairs, counts


def win_matrix(n_sessions: int, first: npt.ArrayLike, second: npt.ArrayLike,
               score: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """(n, n) ``W[i, j]``: wins of session i over session j, a tie counting half to each.

    Args:
        first, second: (n_votes,) session indexes of each vote's two sides.
        score: (n_votes,) the first side's result: 1 won, 0 lost, 0.5 tie.
    """
    return PairCounts.from_votes(n_sessions, first, second, score).win_matrix()


def fit_strengths(wins: npt.ArrayLike, prior_games: float = PRIOR_GAMES) -> npt.NDArray[np.float64]:
    """Bradley-Terry log-strengths, centred to mean 0, for one or a batch of win matrices.

    Args:
        wins: (n, n) or (B, n, n) win matrices (:func:`win_matrix`).
        prior_games: virtual games of each session against a reference of strength 0.

    Returns:
        (n,) or (B, n) centred log-strengths [natural log of the odds scale].
    """
    w = np.asarray(wins, dtype=np.float64)
    single = w.ndim == 2
    w = w[None] if single else w
    n = w.shape[1]
    low, high = np.triu_indices(n, 1)
    games = w[:, low, high] + w[:, high, low]
    theta = _fit_dense(n, low, high, games, w[:, low, high], np.zeros(w.shape[:2]), prior_games)
    return theta[0] if single else theta


def fit_pairs(pairs: PairCounts, prior_games: float = PRIOR_GAMES,
              start: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.float64]:
    """Bradley-Terry log-strengths, centred to mean 0, from votes counted per pair; dense Newton
    up to :data:`DENSE_SESSIONS` sessions, sparse past them.

    Returns:
        (n,) centred log-strengths [natural log of the odds scale].
    """
    theta0 = np.zeros(pairs.n_sessions) if start is None else start
    if pairs.n_sessions <= DENSE_SESSIONS:
        return _fit_dense(pairs.n_sessions, pairs.low, pairs.high, pairs.games[None], pairs.wins[None],
                          theta0[None], prior_games)[0]
    return _fit_sparse(pairs, theta0, prior_games)


def _newton_terms(n: int, low: npt.NDArray[np.intp], high: npt.NDArray[np.intp], games: npt.NDArray[np.float64],
                  wins: npt.NDArray[np.float64], theta: npt.NDArray[np.float64], prior_games: float
                  ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """For (B, n) strengths: the log-likelihood's (B, n) gradient, the (B, E) curvature of each
    pair and the (B, n) diagonal the prior adds to the Hessian (negated)."""
    batch = theta.shape[0]
    beats = _sigmoid(theta[:, low] - theta[:, high])  # P(low beats high)
    beats_reference = _sigmoid(theta)
    rows = (np.arange(batch) * n)[:, None]
    surplus = wins - games * beats  # the low side's wins above the expected
    up = np.bincount((rows + low).ravel(), surplus.ravel(), batch * n)
    down = np.bincount((rows + high).ravel(), surplus.ravel(), batch * n)
    gradient = np.asarray(up - down, dtype=np.float64).reshape(batch, n)
    gradient += prior_games / 2 - prior_games * beats_reference
    curvature = games * beats * (1.0 - beats)
    return gradient, curvature, prior_games * beats_reference * (1.0 - beats_reference)


def _fit_dense(n: int, low: npt.NDArray[np.intp], high: npt.NDArray[np.intp], games: npt.NDArray[np.float64],
               wins: npt.NDArray[np.float64], theta: npt.NDArray[np.float64],
               prior_games: float) -> npt.NDArray[np.float64]:
    """Newton's method on (B, n, n) Hessians, each step limited to ``MAX_STEP`` per strength: the
    prior makes the likelihood strictly concave, so this converges in a few tens of steps, for a
    whole batch at once."""
    theta = np.array(theta, dtype=np.float64)
    batch = theta.shape[0]
    diagonal = np.arange(n)
    for _ in range(MAX_ITERATIONS):
        gradient, curvature, prior = _newton_terms(n, low, high, games, wins, theta, prior_games)
        hessian = np.zeros((batch, n, n))
        hessian[:, low, high] = curvature
        hessian[:, high, low] = curvature
        hessian[:, diagonal, diagonal] = -hessian.sum(axis=2) - prior
        step = np.linalg.solve(hessian, gradient[..., None])[..., 0]
        theta -= np.clip(step, -MAX_STEP, MAX_STEP)
        if np.max(np.abs(step), initial=0.0) < TOLERANCE:
            break
    return theta - theta.mean(axis=1, keepdims=True)


def _fit_sparse(pairs: PairCounts, theta: npt.NDArray[np.float64], prior_games: float) -> npt.NDArray[np.float64]:
    """Newton's method as :func:`_fit_dense`, for one replicate, on a sparse Hessian."""
    from scipy import sparse
    from scipy.sparse.linalg import spsolve

    n, low, high = pairs.n_sessions, pairs.low, pairs.high
    theta = np.array(theta, dtype=np.float64)[None]
    rows = np.concatenate([low, high, np.arange(n)])
    cols = np.concatenate([high, low, np.arange(n)])
    for _ in range(MAX_ITERATIONS):
        gradient, curvature, prior = _newton_terms(n, low, high, pairs.games[None], pairs.wins[None], theta,
                                                   prior_games)
        degree = np.bincount(low, curvature[0], n) + np.bincount(high, curvature[0], n)
        # the negated Hessian: positive definite, so the factorisation needs no pivoting for stability
        laplacian = sparse.csc_matrix((np.concatenate([-curvature[0], -curvature[0], degree + prior[0]]),
                                       (rows, cols)), shape=(n, n))
        step = -np.atleast_1d(spsolve(laplacian, gradient[0]))
        theta[0] -= np.clip(step, -MAX_STEP, MAX_STEP)
        if np.max(np.abs(step), initial=0.0) < TOLERANCE:
            break
    return theta[0] - theta[0].mean()


def _sigmoid(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def affordable_replicates(pairs: PairCounts, requested: int) -> int:
    """How many bootstrap replicates to run: ``requested``, or fewer where each costs so much that
    they would pass :data:`BOOTSTRAP_WORK` (never fewer than :data:`MIN_BOOTSTRAP`).

    A replicate's cost is ``STEPS_PER_REPLICATE`` factorisations of the (n, n) Hessian: a dense
    one's n^3 / 3 operations, or, on the sparse path, the operations of the factorisation that the
    comparison graph's pattern takes (a chain of n sessions: ~n; every pair compared: ~n^3 / 3).
    Depends on which pairs were compared alone, so the result is reproducible.
    """
    n = pairs.n_sessions
    per_step = n ** 3 / 3 if n <= DENSE_SESSIONS else _factorisation_work(pairs)
    affordable = int(BOOTSTRAP_WORK // (STEPS_PER_REPLICATE * per_step))
    return max(min(requested, affordable), min(requested, MIN_BOOTSTRAP))


def _factorisation_work(pairs: PairCounts) -> float:
    """Multiply-adds of the sparse LU that :func:`_fit_sparse` runs on this comparison graph (each
    pivot's column entries times its row entries), plus :data:`SPARSE_STEP_SETUP`."""
    from scipy import sparse
    from scipy.sparse.linalg import splu

    n = pairs.n_sessions
    ones = np.ones(len(pairs.low))
    degree = np.bincount(pairs.low, minlength=n) + np.bincount(pairs.high, minlength=n) + 1.0
    pattern = sparse.csc_matrix((np.concatenate([-ones, -ones, degree]),
                                 (np.concatenate([pairs.low, pairs.high, np.arange(n)]),
                                  np.concatenate([pairs.high, pairs.low, np.arange(n)]))), shape=(n, n))
    lu = splu(pattern)
    column_counts = np.diff(lu.L.tocsc().indptr).astype(np.float64)
    row_counts = np.diff(lu.U.tocsr().indptr).astype(np.float64)
    return float(np.sum(column_counts * row_counts)) + SPARSE_STEP_SETUP


@dataclass(frozen=True)
class Ranking:
    """A fitted ranking. Arrays are indexed by session (the order the votes' indexes use).

    Attributes:
        strength: (n,) centred log-strengths.
        low, high: (n,) bootstrap percentile interval of each strength.
        wins: (n, n) win matrix, ties as halves.
        votes: (n, n) votes between each pair (symmetric).
        confidence: the intervals' level.
        n_bootstrap: bootstrap replicates run (fewer than asked where :func:`affordable_replicates`
            says so).
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
        n_bootstrap: replicates asked for (votes resampled with replacement); fewer run where
            :func:`affordable_replicates` says so.
        confidence: the intervals' level.
        seed: the bootstrap's random seed (the result is reproducible from the inputs).
    """
    pair_list, outcome_counts = _categories(n_sessions, first, second, score)
    pairs = PairCounts.from_categories(n_sessions, pair_list, outcome_counts)
    strength = fit_pairs(pairs)
    n_bootstrap = affordable_replicates(pairs, n_bootstrap)
    replicates = _bootstrap(pairs, pair_list, outcome_counts, strength, n_bootstrap, seed)
    tail = (1.0 - confidence) / 2 * 100
    low, high = np.percentile(replicates, [tail, 100 - tail], axis=0)
    votes = np.zeros((n_sessions, n_sessions), dtype=np.int64)
    votes[pairs.low, pairs.high] = pairs.games.astype(np.int64)
    votes = votes + votes.T
    return Ranking(strength=strength, low=low, high=high, wins=pairs.win_matrix(), votes=votes,
                   confidence=confidence, n_bootstrap=n_bootstrap)


def _bootstrap(pairs: PairCounts, pair_list: npt.NDArray[np.intp], outcome_counts: npt.NDArray[np.float64],
               strength: npt.NDArray[np.float64], n_bootstrap: int, seed: int) -> npt.NDArray[np.float64]:
    """(n_bootstrap, n) centred strengths refitted on votes resampled with replacement, drawn as
    multinomial counts of each (pair, outcome)."""
    n = pairs.n_sessions
    rng = np.random.default_rng(seed)
    counts = outcome_counts.ravel()
    n_votes = int(counts.sum())
    probabilities = counts / n_votes if n_votes else counts
    replicates = np.empty((n_bootstrap, n))
    dense = n <= DENSE_SESSIONS
    batch = max(1, min(DENSE_BATCH_VALUES // max(n * n, 1) if dense else 1, DRAW_BATCH_VALUES // max(len(counts), 1)))
    for start in range(0, n_bootstrap, batch):
        size = min(batch, n_bootstrap - start)
        drawn = (rng.multinomial(n_votes, probabilities, size=size) if n_votes else
                 np.zeros((size, len(counts)), np.int64)).reshape(size, -1, 3).astype(np.float64)
        games = drawn.sum(axis=2)
        wins = drawn[..., 0] + 0.5 * drawn[..., 2]
        if dense:
            replicates[start:start + size] = _fit_dense(n, pairs.low, pairs.high, games, wins,
                                                        np.repeat(strength[None], size, axis=0), PRIOR_GAMES)
        else:
            for k in range(size):
                resampled = PairCounts(n, pair_list[:, 0], pair_list[:, 1], games[k], wins[k])
                replicates[start + k] = _fit_sparse(resampled, strength, PRIOR_GAMES)
    return replicates


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
