"""What the metrics cache keeps for a rollout: its report row and its video metrics.

Every reader and writer of an entry goes through here, so an entry has one shape
(:class:`MetricsEntry`, built from the row's and the video metrics' own types) and is checked
against it on every read: a bad entry is a miss, and what is computed instead is written over it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, TypedDict, cast

from ..analysis.video_break import QUALITY_MEASURES
from ..analysis.video_metrics import VideoMetrics, VideoMetricsRecord
from ..cache import MetricsCache
from ..units import JOINT_NAMES
from .rollout import RolloutRow


class MetricsEntry(TypedDict):
    """An entry: the row (null until ``report`` computed it) and the video metrics per view."""

    row: RolloutRow | None
    video: dict[str, VideoMetricsRecord]


@dataclass
class CachedMetrics:
    """What an entry holds, ready to use (empty for a missing or bad entry).

    Attributes:
        row: the rollout's report row, or None.
        video: video metrics per view.
    """

    row: dict[str, Any] | None = None
    video: dict[str, VideoMetrics] = field(default_factory=dict)


def read_entry(cache: MetricsCache, key: str) -> CachedMetrics:
    """The entry under ``key``; empty when there is none or it is not one as written."""
    entry = cast(MetricsEntry | None, cache.get(key, MetricsEntry))
    if entry is None:
        return CachedMetrics()
    if not is_consistent(entry):
        return CachedMetrics()
    video = entry["video"]
    return CachedMetrics(cast(dict[str, Any] | None, entry["row"]),
                         {view: VideoMetrics.from_json(record) for view, record in video.items()})


def is_consistent(entry: MetricsEntry) -> bool:
    """What the entry's type cannot say: each view's record is its own, and its per-frame series
    (SSIM and the no-reference measures beside PSNR, three of those a frame; the frame match's GT
    index, confidence and tied runs) are of one length; a row's joint coherence has an offset for
    every joint, in order, and a number for each joint it calls out of phase."""
    row = entry["row"]
    coherence = row["joint_coherence"] if row is not None else None
    if coherence is not None:
        steps = coherence["phase_offset_steps"]
        if list(steps) != list(JOINT_NAMES) or list(coherence["phase_offset_s"]) != list(JOINT_NAMES):
            return False
        if any(steps.get(joint) is None for joint in coherence["out_of_phase"]):
            return False
    for view, record in entry["video"].items():
        ssim, match, quality = record["ssim"], record["match"], record["quality"]
        if record["view"] != view or (ssim is not None and len(ssim) != len(record["psnr_db"])):
            return False
        if quality is not None and (len(quality) != len(record["psnr_db"]) or any(len(q) != len(QUALITY_MEASURES) for q in quality)):
            return False
        if match is not None and not (len(match["gt_index"]) == len(match["confidence"]) == len(match["ties"])
                                      and all(len(runs) % 2 == 0 for runs in match["ties"])):
            return False
    return True


def write_entry(cache: MetricsCache, key: str, row: Mapping[str, Any] | None,
                video: Mapping[str, VideoMetrics]) -> None:
    """Keep ``row`` (or None) and ``video`` under ``key``, replacing what was there."""
    entry = {"row": None if row is None else dict(row), "video": {v: vm.to_json() for v, vm in video.items()}}
    cache.put(key, entry, MetricsEntry)
