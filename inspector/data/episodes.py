"""A LeRobot episode seen through the rollout machinery: the commanded arm against the measured one.

On a leader-follower SO-101, ``action`` is the leader's command and ``observation.state`` the
follower's measured joints: the gap between the two is the follower's tracking error. An episode
becomes a timeline of one chunk spanning all its frames, with ``action`` where a rollout has its
prediction and ``observation.state`` where it has GT, so the app, ``report`` and ``export`` show
it with the same code (labelled "commanded" and "measured": :data:`~inspector.analysis.timeline.EPISODE_LABELS`).
The dataset's cameras are its video views; nothing is decoded until a frame is shown.

Usage::

    ds = open_dataset("sessions/demo/dataset")
    rollout, gt = episode_rollout(ds, 0)
    tl = build_timeline(rollout, gt=gt)
    tl.time_aligned_drift            # (T,) tracking error |action - state| [deg, L2 over joints]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from ..units import JOINT_NAMES
from .ground_truth import GroundTruth
from .importers import NeuralTrajectories
from .lerobot_dataset import INFO_PATH, LeRobotDataset, dataset_name
from .session import ArrayValue, Rollout

EPISODE_KIND: Final = "episode"


@dataclass(frozen=True)
class EpisodeRef:
    """One episode of a served dataset, by name only (nothing read).

    Attributes:
        dataset: the dataset.
        index: episode_index.
        length: frames.
        task: its task string.
    """

    dataset: LeRobotDataset | NeuralTrajectories
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


def episode_refs(ds: LeRobotDataset | NeuralTrajectories) -> list[EpisodeRef]:
    """Every episode of ``ds`` from its metadata alone (no data file is read)."""
    return [EpisodeRef(ds, e.index, e.length, e.task) for e in ds.episodes]


def episode_rollout(ds: LeRobotDataset | NeuralTrajectories, index: int) -> tuple[Rollout, GroundTruth]:
    """Episode ``index`` as a one-chunk rollout (``action``) and its GT (``observation.state``).

    A GR00T-Dreams dump's episode is its IDM actions instead, with no GT (:meth:`NeuralTrajectories.rollout`).

    Raises:
        InspectorError: no such episode, or its data file is unreadable (naming the file).
    """
    if isinstance(ds, NeuralTrajectories):
        return ds.rollout(index)
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
