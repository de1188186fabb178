"""Joint coherence's phase offsets on inputs far outside any joint's range (whose squares fit a
float, the products of their variances do not): a lag or None, never a warning."""

from __future__ import annotations

import warnings

import numpy as np

from inspector.analysis.coherence import phase_offsets


def test_huge_joint_values_give_lags_without_overflow_warnings():
    t = np.arange(60, dtype=np.float64)
    gt = np.stack([np.sin(t / 5 + j) for j in range(6)], axis=1) * 1e100
    pred = np.roll(gt, 2, axis=0)  # two steps late
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lags = phase_offsets(pred, gt, max_lag=10)
    assert len(lags) == 6
    assert all(lag is None or -10 <= lag <= 10 for lag in lags)
    # the same motion at a sane scale: the planted lag
    assert phase_offsets(pred / 1e100, gt / 1e100, max_lag=10) == [2] * 6


def test_no_out_of_phase_joint_is_a_window_edge_and_every_null_offset_says_why():
    """On random series of every length from a chunk to an episode: a joint called out of phase has
    a lag inside the search window, and each null offset is explained in ``phase_undetermined``."""
    from inspector.analysis.coherence import coherence_record
    from inspector.units import JOINT_NAMES

    rng = np.random.default_rng(11)
    edges = 0
    for _ in range(60):
        n = int(rng.integers(8, 400))
        gt = np.cumsum(rng.normal(size=(n, 6)), axis=0) * rng.uniform(0, 3, 6)  # some joints still
        pred = np.roll(gt, int(rng.integers(-40, 40)), axis=0) + rng.normal(size=(n, 6))
        record = coherence_record(pred, gt, np.ones(n, bool), fps=30.0)
        assert record is not None
        window = record["phase_window_steps"]
        assert window == min(30, (n - 1) // 3)
        for joint in JOINT_NAMES:
            lag = record["phase_offset_steps"][joint]
            assert (lag is None) == (joint in record["phase_undetermined"])
            assert lag is None or abs(lag) < window
        assert all(record["phase_offset_steps"][j] is not None for j in record["out_of_phase"])
        edges += sum("edge" in why for why in record["phase_undetermined"].values())
    assert edges > 0  # the planted lags beyond the window did reach its edge
