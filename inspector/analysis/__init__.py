"""What is measured of a rollout, once, for the app, ``report`` and ``export`` alike: the metrics
(joint drift, video, video-action agreement), the sanity measures and their tolerances, the
per-rollout timeline that carries them over time (``timeline``), and ``inspector calibrate``.

Every module, one line each, is on the map in docs/development.md ("Layout of the code"),
which tests/test_layout.py checks against the package.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "RolloutTimeline": ".timeline",
    "build_timeline": ".timeline",
    "build_timelines": ".timeline",
    "VideoMetrics": ".video_metrics",
    "compare_clips": ".video_metrics",
    "SweepMetrics": ".sweep",
    "sweep_metrics": ".sweep",
    "ChunkErrors": ".metrics",
    "LimitSummary": ".metrics",
    "chunk_errors": ".metrics",
    "best_match": ".metrics",
    "time_aligned": ".metrics",
    "tempo": ".metrics",
    "dtw": ".metrics",
})

if TYPE_CHECKING:
    from .metrics import ChunkErrors as ChunkErrors
    from .metrics import LimitSummary as LimitSummary
    from .metrics import best_match as best_match
    from .metrics import chunk_errors as chunk_errors
    from .metrics import dtw as dtw
    from .metrics import tempo as tempo
    from .metrics import time_aligned as time_aligned
    from .sweep import SweepMetrics as SweepMetrics
    from .sweep import sweep_metrics as sweep_metrics
    from .timeline import RolloutTimeline as RolloutTimeline
    from .timeline import build_timeline as build_timeline
    from .timeline import build_timelines as build_timelines
    from .video_metrics import VideoMetrics as VideoMetrics
    from .video_metrics import compare_clips as compare_clips
