"""Joint coherence: does each joint move in phase with the real one, and do the joints keep the
real arm's coupling?

**Phase offset** (per joint): the lag ``l`` (steps, within +-:data:`MAX_LAG_S`) that maximises the
Pearson correlation of the predicted joint's velocity at ``t`` with the GT's at ``t - l``, over the
in-episode steps; positive: the prediction runs behind the GT. Null ("not determined") for a
joint whose GT hardly moves (velocity standard deviation under :data:`MIN_MOTION` per step), where
no lag is defined, and for a best lag at the edge of the search window (the window shrinks to a
third of the series, so on a short chunk the correlation often just keeps rising towards the edge:
the true lag may lie beyond it, and such an argmax says nothing).

**Coupling error** (per pair of neighbouring joints a-b: shoulder_lift-elbow_flex,
elbow_flex-wrist_flex): the RMS over in-episode steps of the predicted relative angle
``q_a - q_b`` against the GT's [deg]: how far the prediction bends one joint against the other
differently from the real arm.
"""

from __future__ import annotations

import functools
from typing import NamedTuple, TypedDict

import numpy as np
import numpy.typing as npt

from ..units import JOINT_NAMES

MAX_LAG_S = 1.0
MIN_MOTION = 0.05  # [deg / step]
Array = npt.NDArray[np.float64]
COUPLED_PAIRS = (("shoulder_lift", "elbow_flex"), ("elbow_flex", "wrist_flex"))
PHASE_FLAG_STEPS = 6  # |offset| above this many steps (0.2 s at 30 fps) is reported as out of phase


def phase_offset(pred: npt.ArrayLike, gt: npt.ArrayLike, max_lag: int) -> int | None:
    """Best lag [steps] of one joint's (T,) predicted series against its GT (see the module)."""
    return phase_offsets(np.asarray(pred, np.float64)[:, None], np.asarray(gt, np.float64)[:, None], max_lag)[0]


class GtMotion(NamedTuple):
    """The GT side of :func:`phase_offsets` for (n + 1, J) GT series: the same for every rollout
    of a batch (they share their GT), so computed once for them all."""

    v: Array  # (J, n) velocities
    moving: npt.NDArray[np.bool_]  # (J,) velocity std >= MIN_MOTION
    c: Array  # (J, n + 1) cumulative sums of v, from 0
    c2: Array  # ... of v * v
    spectrum: npt.NDArray[np.complex128]  # (J, n + 1) conj(rfft(v, 2n))


def gt_motion(gt: npt.ArrayLike) -> GtMotion:
    vg = np.diff(np.asarray(gt, np.float64), axis=0).T
    zero = np.zeros((vg.shape[0], 1))
    n = vg.shape[1]
    return GtMotion(vg, vg.std(axis=1) >= MIN_MOTION if n else np.zeros(vg.shape[0], bool),
                    np.hstack([zero, np.cumsum(vg, axis=1)]), np.hstack([zero, np.cumsum(vg * vg, axis=1)]),
                    np.conj(np.fft.rfft(vg, 2 * n)) if n else np.zeros((vg.shape[0], 1), np.complex128))


def phase_offsets(pred: npt.ArrayLike, gt: npt.ArrayLike | GtMotion, max_lag: int) -> list[int | None]:
    """Best lag [steps] of each joint of (T, J) predicted series against their GT (the series,
    or their :func:`gt_motion`).

    Every lag and joint at once: the cross products from one FFT cross-correlation, the
    windows' sums and squares from cumulative sums (a lag loop of ``np.corrcoef`` cost 60 ms a
    rollout). Among equally good lags the smallest (in magnitude) wins.
    """
    g = gt if isinstance(gt, GtMotion) else gt_motion(gt)
    vp = np.diff(np.asarray(pred, np.float64), axis=0).T  # (J, n)
    vg = g.v
    n = vg.shape[1]
    if n < 4:
        return [None] * vg.shape[0]
    max_lag = search_window(n, max_lag)
    lags = _lags(max_lag)
    # sum_t vp[t] vg[t - lag], every lag at once as a circular cross-correlation by FFT, long
    # enough (2n) that no wanted lag wraps around (np.correlate per joint cost 4x as much)
    size = 2 * n
    cross = np.fft.irfft(np.fft.rfft(vp, size) * g.spectrum, size)[:, lags % size]
    zero = np.zeros((vp.shape[0], 1))
    cp, cp2 = np.hstack([zero, np.cumsum(vp, axis=1)]), np.hstack([zero, np.cumsum(vp * vp, axis=1)])
    cg, cg2 = g.c, g.c2
    pos = lags >= 0
    # lag >= 0 pairs vp[lag:] with vg[:n - lag]; lag < 0 pairs vp[:n + lag] with vg[-lag:]
    p_lo, p_hi = np.where(pos, lags, 0), np.where(pos, n, n + lags)
    g_lo, g_hi = np.where(pos, 0, -lags), np.where(pos, n - lags, n)
    m = (p_hi - p_lo).astype(np.float64)
    sp, sp2 = cp[:, p_hi] - cp[:, p_lo], cp2[:, p_hi] - cp2[:, p_lo]
    sg, sg2 = cg[:, g_hi] - cg[:, g_lo], cg2[:, g_hi] - cg2[:, g_lo]
    var_p, var_g = sp2 - sp * sp / m, sg2 - sg * sg / m
    ok = (var_p > 1e-12 * np.maximum(sp2, 1.0)) & (var_g > 1e-12 * np.maximum(sg2, 1.0))
    # (the square roots apart: joint values of ~1e80 and more, out of any joint's range, would
    # overflow their product; such a rollout gets a lag, not a warning)
    with np.errstate(over="ignore", invalid="ignore"):
        r = np.where(ok, (cross - sp * sg / m) / (np.sqrt(np.where(ok, var_p, 1.0)) * np.sqrt(np.where(ok, var_g, 1.0))),
                     -np.inf)
    r = np.nan_to_num(r, nan=-np.inf)
    best = lags[np.argmax(r, axis=1)]
    return [int(b) if mv and k.any() else None for b, mv, k in zip(best, g.moving, ok)]


def search_window(n_velocities: int, max_lag: int) -> int:
    """The lags searched, +-this many steps: ``max_lag``, at most a third of the ``n_velocities``
    velocity steps (so that every lag still pairs two thirds of the series)."""
    return max(0, min(max_lag, n_velocities // 3))


@functools.lru_cache(maxsize=8)
def _lags(max_lag: int) -> npt.NDArray[np.int64]:
    """-max_lag..max_lag, smallest magnitude first (so that argmax prefers it among ties)."""
    return np.array(sorted(range(-max_lag, max_lag + 1), key=lambda v: (abs(v), v)))


def coupling_error(pred: npt.ArrayLike, gt: npt.ArrayLike, a: int, b: int) -> float:
    """RMS of ``(pred_a - pred_b) - (gt_a - gt_b)`` over (T, 6) series [data units]."""
    p, g = np.asarray(pred, np.float64), np.asarray(gt, np.float64)
    d = (p[:, a] - p[:, b]) - (g[:, a] - g[:, b])
    return float(np.sqrt(np.mean(d * d)))


class CoherenceJson(TypedDict):
    """The ``joint_coherence`` field of a report row."""

    phase_offset_steps: dict[str, int | None]  # null: not determined (phase_undetermined says why)
    phase_offset_s: dict[str, float | None]
    phase_window_steps: int  # the lags searched: +-this many steps
    phase_undetermined: dict[str, str]  # joint -> why its offset is null
    coupling_error_deg: dict[str, float]
    out_of_phase: list[str]  # determined offsets over PHASE_FLAG_STEPS only (never a window edge)


def coherence_record(pred: npt.ArrayLike, gt_aligned: npt.ArrayLike, in_episode: npt.ArrayLike, fps: float,
                     motion: GtMotion | None = None) -> CoherenceJson | None:
    """Joint coherence over the in-episode steps (None with fewer than 8 of them).

    Args:
        motion: :func:`gt_motion` of ``gt_aligned[in_episode]``, if already known.
    """
    inside = np.asarray(in_episode, bool)
    p = np.asarray(pred, np.float64)[inside]
    g = np.asarray(gt_aligned, np.float64)[inside]
    if len(p) < 8:
        return None
    max_lag = int(round(MAX_LAG_S * fps))
    window = search_window(len(p) - 1, max_lag)
    motion = gt_motion(g) if motion is None else motion
    best = phase_offsets(p, motion, max_lag)
    steps: dict[str, int | None] = {}
    undetermined: dict[str, str] = {}
    for name, lag, moving in zip(JOINT_NAMES, best, motion.moving):
        if lag is None:
            undetermined[name] = "the GT joint hardly moves" if not moving else "the predicted joint does not move"
        elif abs(lag) >= window:  # the correlation still rising at the edge: the lag may lie beyond
            undetermined[name] = f"best lag at the edge of the +-{window}-step window"
        steps[name] = None if name in undetermined else lag
    index = {name: j for j, name in enumerate(JOINT_NAMES)}
    coupling = {f"{a}-{b}": round(coupling_error(p, g, index[a], index[b]), 4) for a, b in COUPLED_PAIRS}
    return {"phase_offset_steps": steps,
            "phase_offset_s": {k: None if v is None else round(v / fps, 4) for k, v in steps.items()},
            "phase_window_steps": window,
            "phase_undetermined": undetermined,
            "coupling_error_deg": coupling,
            "out_of_phase": [k for k, v in steps.items() if v is not None and abs(v) > PHASE_FLAG_STEPS]}
