"""The sanity measures in a recording: seam jumps and their threshold, the imagined video's
degradation per chunk, and markers (shown in every plot) with events where a seam is flagged,
the rollout completes and a view's video breaks."""

from __future__ import annotations

import numpy as np
import rerun as rr

from ..analysis.sanity import rollout_seams, sanity_measures
from ..analysis.timeline import RolloutTimeline
from . import layout as L
from .series import IndexesFor, log_series

SEAMS = f"{L.PLOTS}/seams"
DEGRADATION = f"{L.PLOTS}/video_degradation"


def log_sanity(rec: rr.RecordingStream, tl: RolloutTimeline, indexes_for: IndexesFor) -> None:
    """The measures of ``tl`` (its video metrics as computed so far feed the degradation)."""
    m = sanity_measures(tl, tl.known_video_metrics())
    events: list[tuple[int, str, str]] = []
    seams = rollout_seams(tl)  # every seam's jump (the report row keeps the flagged ones)
    if seams is not None and len(seams.jump_norm):
        at = np.minimum(tl.chunk_start_step[1:], tl.n_steps - 1)
        log_series(rec, f"{SEAMS}/jump", at, np.round(seams.jump_norm, 4), indexes_for, "seam jump [deg]",
                   (31, 119, 180, 255), points=True)
        log_series(rec, f"{SEAMS}/threshold", at[[0, -1]], [round(seams.threshold, 4)] * 2, indexes_for,
                   "flagged above [deg]", (120, 120, 120, 255), width=1.0)
        flagged = seams.chunk[seams.flagged]
        if flagged.size:
            steps = np.minimum(tl.chunk_start_step[flagged], tl.n_steps - 1)
            log_series(rec, f"{L.MARKERS}/seam_flagged", steps, np.zeros(len(steps)), indexes_for,
                       "seam jump flagged", L.LIMIT_RGBA, points=True, marker="asterisk", marker_size=8.0)
            events += [(int(s), f"seam: chunk {k} jumps {seams.jump_norm[k - 1]:.1f} deg from chunk {k - 1}'s "
                                f"last executed action (flagged above {seams.threshold:.1f})", "WARN")
                       for k, s in zip(flagged, steps)]
    c = m["completion"]
    if c is not None and c["step"] is not None:
        log_series(rec, f"{L.MARKERS}/completion", [c["step"]], [0.0], indexes_for, "task completed",
                   (44, 160, 44, 255), points=True, marker="up", marker_size=8.0)
        events.append((c["step"], f"completes at {c['time_s']:.2f} s (GT: {c['gt_time_s']} s); drift after "
                                  f"{c['drift_after']}", "INFO"))
    for i, (view, d) in enumerate(sorted(m["video_degradation"].items())):
        curve = np.array([np.nan if v is None else v for v in d["degradation"]], dtype=np.float64)
        n = min(len(curve), tl.n_chunks)
        starts = np.minimum(tl.chunk_start_step[:n], tl.n_steps - 1)
        log_series(rec, f"{DEGRADATION}/{view}", starts, curve[:n], indexes_for, f"{view} degradation (x chunk 0)",
                   L.VIEW_RGBA[i % len(L.VIEW_RGBA)])
        b = d["break_chunk"]
        if b is not None and b < tl.n_chunks:
            s = int(min(tl.chunk_start_step[b], tl.n_steps - 1))
            log_series(rec, f"{L.MARKERS}/video_break/{view}", [s], [0.0], indexes_for, f"{view} video breaks",
                       L.LIMIT_RGBA, points=True, marker="down", marker_size=8.0)
            events.append((s, f"{view}: the imagined video stays degraded from chunk {b} on", "WARN"))
    for step, text, level in sorted(events):
        rec.send_columns(L.EVENTS, indexes_for(np.array([step])), rr.TextLog.columns(text=[text], level=[level]))
