"""Where a rollout's ground truth comes from: carried with the rollout, or its dataset episode.

A rollout may carry GT joints (``gt/actions.npy``) and GT video (``gt/video/<view>.mp4``, frame i at
imagined frame i's time). Otherwise the session's LeRobot dataset supplies the episode: its
``action`` column (the commands, as the model predicts commands) and its camera frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import numpy.typing as npt

from .errors import InspectorError
from .session import Rollout
from .video import VideoClip


@dataclass
class GroundTruth:
    """GT joints and frames for one rollout.

    Attributes:
        actions: (G, 6) GT joints, dataset units, or None when no GT joints exist.
        offset: index in ``actions`` of rollout step 0.
        episode_length: frames in the real episode (from rollout step 0's episode start), if known.
        source: a short description for the UI ("dataset <root> episode 3", "carried with rollout").
        frame_for: ``frame_for(view, imagined_frame_index, step)`` -> (H, W, 3) uint8 or None.
        views: views with GT frames.
    """

    actions: npt.NDArray[np.float64] | None
    offset: int
    episode_length: int | None
    source: str
    views: list[str] = field(default_factory=list)
    _frame_for: Callable[[str, int, int], npt.NDArray[np.uint8] | None] | None = None
    clips: dict[str, VideoClip] = field(default_factory=dict)

    @property
    def steps_in_episode(self) -> int | None:
        """Rollout steps that fall inside the real episode (later ones are post-episode)."""
        if self.actions is not None:
            return self.actions.shape[0] - self.offset
        return None if self.episode_length is None else self.episode_length - self.offset

    def frame(self, view: str, imagined_frame: int, step: int) -> npt.NDArray[np.uint8] | None:
        """GT frame at the time of an imagined frame (None past the episode or with no such view)."""
        if self._frame_for is None or view not in self.views:
            return None
        return self._frame_for(view, imagined_frame, step)


def resolve_ground_truth(rollout: Rollout, dataset_root: Path | None = None) -> GroundTruth:
    """GT for ``rollout``: carried GT first, then the dataset (explicit or the session's).

    Carried joints win over the dataset's (they are what the evaluation compared against);
    carried video wins likewise. A dataset that is named but unreadable is an error; a missing
    one simply leaves the rollout without dataset GT.
    """
    root = dataset_root
    if root is None and rollout.session is not None:
        root = rollout.session.dataset_root
    episode = None
    if root is not None and rollout.episode_index is not None and (rollout.gt_actions is None or not rollout.gt_views):
        from .lerobot_dataset import LeRobotDataset

        if Path(root).exists():
            ds = LeRobotDataset(root)
            if rollout.episode_index >= ds.num_episodes:
                raise InspectorError(rollout.root / "rollout.json",
                                     f"episode_index {rollout.episode_index} not in dataset {root} "
                                     f"(episodes 0..{ds.num_episodes - 1})")
            episode = ds.episode(rollout.episode_index)
            if rollout.start_frame >= episode.length:
                raise InspectorError(rollout.root / "rollout.json",
                                     f"start_frame {rollout.start_frame} lies beyond episode "
                                     f"{rollout.episode_index} ({episode.length} frames)")

    if rollout.gt_actions is not None:
        actions, offset, source = rollout.gt_actions, 0, "carried with the rollout"
        length = rollout.gt_episode_length
        length = None if length is None else length - rollout.start_frame
    elif episode is not None:
        actions, offset = episode.action, rollout.start_frame
        length, source = episode.length, f"dataset {root} episode {rollout.episode_index}"
    else:
        actions, offset, source = None, 0, "none"
        if root is not None and not Path(root).exists():
            source = f"none (dataset {root} not found)"  # named but gone: say so, don't hide it
        length = rollout.gt_episode_length
        length = None if length is None else length - rollout.start_frame
        offset = 0

    gt = GroundTruth(actions=actions, offset=offset, episode_length=length, source=source)
    if rollout.gt_views:
        gt.views = list(rollout.gt_views)
        gt.clips = {v: rollout.video(v, gt=True) for v in gt.views}

        def carried(view: str, f: int, step: int) -> npt.NDArray[np.uint8] | None:
            clip = gt.clips[view]
            return clip.frames[f] if f < len(clip) else None

        gt._frame_for = carried
    elif episode is not None:
        gt.views = [v for v in rollout.views if v in episode.cameras] or list(episode.cameras)

        def from_dataset(view: str, f: int, step: int) -> npt.NDArray[np.uint8] | None:
            clip = episode.video(view)
            index = rollout.start_frame + step
            return clip.frames[index] if index < len(clip) else None

        gt.clips = {v: _LazyEpisodeClip(episode, v) for v in gt.views}  # type: ignore[misc]
        gt._frame_for = from_dataset
    return gt


class _LazyEpisodeClip:
    """A dataset camera behaving like a VideoClip (decoded on first use)."""

    def __init__(self, episode, camera: str) -> None:
        self._episode, self._camera = episode, camera

    @property
    def frames(self) -> npt.NDArray[np.uint8]:
        return self._episode.video(self._camera).frames

    def __len__(self) -> int:
        return len(self.frames)
