"""Where a rollout's ground truth comes from: carried with the rollout, or its dataset episode.

A rollout may carry GT joints (``gt/actions.npy``) and GT video (``gt/video/<view>.mp4``, frame i at
imagined frame i's time). Otherwise the session's LeRobot dataset supplies the episode: its
``action`` column (the commands, as the model predicts commands) and its camera frames.

Nothing here decodes video: a :class:`GroundTruth` says which clip holds each view's GT frames
and which of its frames goes with each imagined frame and each step.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ..errors import InspectorError
from .lerobot_dataset import dataset_name, open_dataset
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
        views: views with GT frames.
        clips: view -> the clip holding its GT frames. A dataset clip starts at the rollout's
            start frame (its frame i shows step i); a carried clip's frame i pairs with
            imagined frame i.
        carried: True when the GT frames are carried with the rollout (paired by imagined frame).
        dataset_key: identity of the dataset episode the GT comes from (rollouts with the same key
            share their GT), or None for carried / no GT.
        files: the dataset files it was read from (caches key on their size and time).
        warning: why a GT the rollout names could not be used (a missing dataset or episode).
    """

    actions: npt.NDArray[np.float64] | None
    offset: int
    episode_length: int | None
    source: str
    views: list[str] = field(default_factory=list)
    clips: dict[str, VideoClip] = field(default_factory=dict)
    carried: bool = False
    dataset_key: tuple | None = None
    files: list[Path] = field(default_factory=list)
    warning: str | None = None
    _frames_in_clip: dict[str, int] = field(default_factory=dict, repr=False)

    @property
    def steps_in_episode(self) -> int | None:
        """Rollout steps that fall inside the real episode (later ones are post-episode)."""
        if self.actions is not None:
            return self.actions.shape[0] - self.offset
        return None if self.episode_length is None else self.episode_length - self.offset

    def frames_in_clip(self, view: str) -> int:
        """GT frames available for ``view`` (a carried clip's are counted once from its packets)."""
        if view not in self._frames_in_clip:
            self._frames_in_clip[view] = len(self.clips[view].timestamps())
        return self._frames_in_clip[view]

    def display_index(self, view: str, imagined_frame: int, step: int) -> int | None:
        """Index in ``clips[view]`` of the GT frame shown at ``step`` (None past the episode)."""
        if view not in self.clips:
            return None
        index = imagined_frame if self.carried else step
        return index if index < self.frames_in_clip(view) else None


def resolve_ground_truth(rollout: Rollout, dataset_root: Path | None = None) -> GroundTruth:
    """GT for ``rollout``: carried GT first, then the dataset (explicit or the session's).

    Carried joints win over the dataset's (they are what the evaluation compared against);
    carried video wins likewise. A dataset that is named but unreadable is an error; a missing
    one, or one without the rollout's episode, leaves the rollout without dataset GT and says so
    (``GroundTruth.warning``).
    """
    root = dataset_root
    if root is None and rollout.session is not None:
        root = rollout.session.dataset_root
    episode, dataset_files, warning = None, [], None
    if root is not None and rollout.episode_index is not None and (rollout.gt_actions is None or not rollout.gt_views):

        if Path(root).exists():
            ds = open_dataset(root)
            if rollout.episode_index not in ds.episode_indexes():
                warning = (f"dataset {dataset_name(ds)} has no episode {rollout.episode_index} "
                           f"(episodes {ds.describe_episodes()})")
        if warning is None and Path(root).exists():
            episode = ds.episode(rollout.episode_index)
            info = ds.episode_info(rollout.episode_index)
            dataset_files = [ds.root / "meta" / "info.json", info.data_file, *(v.path for v in info.videos.values())]
            if rollout.start_frame >= episode.length:
                raise InspectorError(rollout.root / "rollout.json",
                                     f"start_frame {rollout.start_frame} lies beyond episode "
                                     f"{rollout.episode_index} ({episode.length} frames)")

    dataset_key = None
    if rollout.gt_actions is not None:
        actions, offset, source = rollout.gt_actions, 0, "carried with the rollout"
        length = rollout.gt_episode_length
        length = None if length is None else length - rollout.start_frame
    elif episode is not None:
        actions, offset = episode.action, rollout.start_frame
        length, source = episode.length, f"dataset {root} episode {rollout.episode_index}"
        assert root is not None  # an episode is read only from a dataset root
        dataset_key = (str(Path(root).resolve()), episode.index, rollout.start_frame)
    else:
        actions, offset = None, 0
        source = "video carried with the rollout (no GT joints)" if rollout.gt_views else "none"
        if root is not None and not Path(root).exists():
            warning = f"dataset {root} not found"  # named but gone: say so, don't hide it
        if warning is not None:
            source = f"none ({warning})"
        length = rollout.gt_episode_length
        length = None if length is None else length - rollout.start_frame

    gt = GroundTruth(actions=actions, offset=offset, episode_length=length, source=source,
                     dataset_key=dataset_key, files=dataset_files, warning=warning)
    if rollout.gt_views:
        gt.views = list(rollout.gt_views)
        gt.clips = {v: rollout.video(v, gt=True) for v in gt.views}
        gt.carried = True
    elif episode is not None:
        gt.views = [v for v in rollout.views if v in episode.cameras] or list(episode.cameras)
        gt.clips = {v: episode.clip_from(v, rollout.start_frame) for v in gt.views}
        gt._frames_in_clip = {v: episode.length - rollout.start_frame for v in gt.views}
    return gt
