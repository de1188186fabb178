"""A LeRobot episode seen through the rollout machinery: the commanded arm against the measured one.

On a leader-follower SO-101, ``action`` is the leader's command and ``observation.state`` the
follower's measured joints: the gap between the two is the follower's tracking error. An episode
becomes a timeline of one chunk spanning all its frames, with ``action`` where a rollout has its
prediction and ``observation.state`` where it has GT, so the app, ``report`` and ``export`` show
it with the same code (labelled "commanded" and "measured": :data:`~inspector.timeline.EPISODE_LABELS`).
The dataset's cameras are its video views; nothing is decoded until a frame is shown.

Usage::

    ds = open_dataset("sessions/demo/dataset")
    rollout, gt = episode_rollout(ds, 0)
    tl = build_timeline(rollout, gt=gt)
    tl.time_aligned_drift            # (T,) tracking error |action - state| [deg, L2 over joints]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .ground_truth import GroundTruth
from .lerobot_dataset import INFO_PATH, LeRobotDataset
from .session import ArrayValue, Rollout
from .units import JOINT_NAMES

EPISODE_KIND = "episode"


@dataclass(frozen=True)
class EpisodeRef:
    """One episode of a served dataset, by name only (nothing read).

    Attributes:
        dataset: the dataset.
        index: episode_index.
        length: frames.
        task: its task string.
    """

    dataset: LeRobotDataset
    index: int
    length: int
    task: str

    @property
    def tag(self) -> str:
        return episode_tag(self.index)

    @property
    def duration_s(self) -> float:
        return self.length / self.dataset.fps


def episode_tag(index: int) -> str:
    return f"episode_{index:06d}"


def dataset_name(ds: LeRobotDataset) -> str:
    """How a dataset is named in pickers and reports: ``org/name`` under a LeRobot home, else its
    directory's name."""
    from .lerobot_dataset import lerobot_home_dirs

    root = ds.root.resolve()
    for home in lerobot_home_dirs():
        try:
            rel = root.relative_to(home.resolve())
        except (ValueError, OSError):
            continue
        if len(rel.parts) == 2:
            return "/".join(rel.parts)
    return root.name


def episode_refs(ds: LeRobotDataset) -> list[EpisodeRef]:
    """Every episode of ``ds`` from its metadata alone (no data file is read)."""
    return [EpisodeRef(ds, e.index, e.length, e.task) for e in ds.episodes]


def episode_rollout(ds: LeRobotDataset, index: int) -> tuple[Rollout, GroundTruth]:
    """Episode ``index`` as a one-chunk rollout (``action``) and its GT (``observation.state``).

    Raises:
        InspectorError: no such episode, or its data file is unreadable (naming the file).
    """
    ep = ds.episode(index)
    info = ds.episode_info(index)
    n = ep.length
    rollout = Rollout(
        root=ds.root, tag=episode_tag(index), kind=EPISODE_KIND, prompt=ep.task, episode_index=index,
        start_frame=0, fps=ep.fps, horizon=n, executed_per_chunk=n, frames_per_chunk=n, views=[],
        units=ep.units, actions_shape=(1, n, len(JOINT_NAMES)), gt_episode_length=n,
        extra={"dataset": str(ds.root), "dataset_name": dataset_name(ds), "units_reason": ds.units_reason},
        _arrays={"actions": ArrayValue(ep.action[None])},
    )
    gt = GroundTruth(
        actions=ep.state, offset=0, episode_length=n,
        source=f"measured joints (observation.state) of {dataset_name(ds)} episode {index}",
        views=list(ep.cameras), clips={cam: ep.clip_from(cam, 0) for cam in ep.cameras},
        dataset_key=(str(ds.root.resolve()), index, 0),
        files=[ds.root / INFO_PATH, info.data_file, *(v.path for v in info.videos.values())],
        _frames_in_clip={cam: n for cam in ep.cameras},
    )
    return rollout, gt


def episode_summary(tl: Any) -> dict[str, Any]:
    """The JSON record of an episode for dataset triage (``report DATASET``).

    Tracking error is ``action - state`` per joint (the commanded arm ahead of or behind the
    measured one); joint ranges and limit violations are those of the measured arm and of the
    commanded arm.
    """
    from . import metrics
    from .report_row import limit_record

    r = tl.rollout
    err = np.abs(tl.joint_error)
    state = tl.gt_aligned
    measured_excess = metrics.limit_excess(state, tl.limits)
    measured = metrics.LimitSummary.of(measured_excess > tl.limit_margin, measured_excess)
    return {
        "dataset": r.extra.get("dataset_name"),
        "episode_index": r.episode_index,
        "task": r.prompt,
        "length": tl.n_steps,
        "duration_s": tl.n_steps / tl.fps,
        "units": tl.units.label(),
        "tracking_error": {
            "l2_mean": float(tl.time_aligned_drift.mean()), "l2_max": float(tl.time_aligned_drift.max()),
            "mean": {j: float(v) for j, v in zip(JOINT_NAMES, err.mean(axis=0))},
            "max": {j: float(v) for j, v in zip(JOINT_NAMES, err.max(axis=0))},
            "rmse": tl.chunk_errors.per_joint_rmse.tolist() if tl.chunk_errors is not None else None,
        },
        "ee_tracking_error_mm": {"mean": float(tl.ee_error_mm.mean()), "max": float(tl.ee_error_mm.max())},
        "limit_violations": {"measured": limit_record(measured, tl.limit_margin_deg),
                             "commanded": limit_record(tl.limit_summary(), tl.limit_margin_deg)},
        "joint_range": {j: [float(lo), float(hi)] for j, lo, hi in zip(JOINT_NAMES, state.min(axis=0), state.max(axis=0))},
    }
