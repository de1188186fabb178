"""Joint coherence: does each joint move in phase with the real one, and do the joints keep the
real arm's coupling?

**Phase offset** (per joint): the lag ``l`` (steps, within +-:data:`MAX_LAG_S`) that maximises the
Pearson correlation of the predicted joint's velocity at ``t`` with the GT's at ``t - l``, over the
in-episode steps; positive: the prediction runs behind the GT. Null for a joint whose GT hardly
moves (velocity standard deviation under :data:`MIN_MOTION` per step), where no lag is defined.

**Coupling error** (per pair of neighbouring joints a-b: shoulder_lift-elbow_flex,
elbow_flex-wrist_flex): the RMS over in-episode steps of the predicted relative angle
``q_a - q_b`` against the GT's [deg]: how far the prediction bends one joint against the other
differently from the real arm.
"""

from __future__ import annotations

from typing import TypedDict

import numpy as np
import numpy.typing as npt

from ..units import JOINT_NAMES

MAX_LAG_S = 1.0
MIN_MOTION = 0.05  # [deg / step]
COUPLED_PAIRS = (("shoulder_lift", "elbow_flex"), ("elbow_flex", "wrist_flex"))
PHASE_FLAG_STEPS = 6  # |offset| above this many steps (0.2 s at 30 fps) is reported as out of phase


def phase_offset(pred: npt.ArrayLike, gt: npt.ArrayLike, max_lag: int) -> int | None:
    """Best lag [steps] of one joint's (T,) predicted series against its GT (see the module)."""
    vp = np.diff(np.asarray(pred, np.float64))
    vg = np.diff(np.asarray(gt, np.float64))
    if len(vg) < 4 or vg.std() < MIN_MOTION:
        return None
    max_lag = max(0, min(max_lag, len(vg) // 3))
    best, best_r = None, -np.inf
    for lag in range(-max_lag, max_lag + 1):
        a = vp[lag:] if lag >= 0 else vp[:lag]
        b = vg[:len(vg) - lag] if lag >= 0 else vg[-lag:]
        if a.std() == 0 or b.std() == 0:
            continue
        r = float(np.corrcoef(a, b)[0, 1])
        if r > best_r + 1e-12 or (abs(r - best_r) <= 1e-12 and best is not None and abs(lag) < abs(best)):
            best, best_r = lag, r
    return best


def coupling_error(pred: npt.ArrayLike, gt: npt.ArrayLike, a: int, b: int) -> float:
    """RMS of ``(pred_a - pred_b) - (gt_a - gt_b)`` over (T, 6) series [data units]."""
    p, g = np.asarray(pred, np.float64), np.asarray(gt, np.float64)
    d = (p[:, a] - p[:, b]) - (g[:, a] - g[:, b])
    return float(np.sqrt(np.mean(d * d)))


class CoherenceJson(TypedDict):
    """The ``joint_coherence`` field of a report row."""

    phase_offset_steps: dict[str, int | None]
    phase_offset_s: dict[str, float | None]
    coupling_error_deg: dict[str, float]
    out_of_phase: list[str]


def coherence_record(pred: npt.ArrayLike, gt_aligned: npt.ArrayLike, in_episode: npt.ArrayLike, fps: float
                     ) -> CoherenceJson | None:
    """Joint coherence over the in-episode steps (None with fewer than 8 of them)."""
    inside = np.asarray(in_episode, bool)
    p = np.asarray(pred, np.float64)[inside]
    g = np.asarray(gt_aligned, np.float64)[inside]
    if len(p) < 8:
        return None
    max_lag = int(round(MAX_LAG_S * fps))
    steps = {name: phase_offset(p[:, j], g[:, j], max_lag) for j, name in enumerate(JOINT_NAMES)}
    index = {name: j for j, name in enumerate(JOINT_NAMES)}
    coupling = {f"{a}-{b}": round(coupling_error(p, g, index[a], index[b]), 4) for a, b in COUPLED_PAIRS}
    return {"phase_offset_steps": steps,
            "phase_offset_s": {k: None if v is None else round(v / fps, 4) for k, v in steps.items()},
            "coupling_error_deg": coupling,
            "out_of_phase": [k for k, v in steps.items() if v is not None and abs(v) > PHASE_FLAG_STEPS]}
