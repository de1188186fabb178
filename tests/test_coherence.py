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
