"""What a native session is: its file names and rollout kinds, and the :class:`Session` and
:class:`Rollout` a reader makes of it (:mod:`.session_reader` reads them, :mod:`.session_writer`
writes them; :mod:`.session` draws the layout on disk)."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import InspectorError
from ..units import Units
from .session_arrays import ArrayValue, NoJoints, NpyFile
from .video import VideoClip

SCHEMA = "inspector.session/1"
SESSION_FILE = "session.json"
ROLLOUT_FILE = "rollout.json"
ANNOTATIONS_FILE = "annotations.json"
# Outcomes (inspector.outcomes): in the session, or beside a raw directory imported in memory.
OUTCOMES_FILE = "outcomes.json"
OUTCOMES_SIDECAR_SUFFIX = ".inspector-outcomes.json"
ROLLOUTS_DIR = "rollouts"
ACTIONS_FILE = "actions.npy"
STATES_FILE = "states.npy"
LATENTS_FILE = "latents.npy"  # optional (n, D): a latent vector per chunk (or sample)
VIDEO_DIR = "video"
GT_DIR = "gt"

# "open_loop_replay": a chunk every executed_per_chunk steps along a real episode, each predicted
# from the real observation at its start (``inspector eval --every-chunk``), not from the last
# chunk's end as an autoregressive rollout's are. "episode": a LeRobot episode shown like a
# rollout (commanded vs measured arm), made in memory (inspector.data.episodes); sessions on
# disk hold the other three.
RolloutKind = Literal["single_chunk", "autoregressive", "open_loop_replay", "episode"]
KINDS: tuple[str, ...] = ("single_chunk", "autoregressive", "open_loop_replay")
# Kinds whose chunks follow one another along the episode, each running executed_per_chunk steps.
CHAINED_KINDS: tuple[str, ...] = ("autoregressive", "open_loop_replay")
_TAG = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")
_VIEW = _TAG
# Frame rates outside these are no camera's or robot's (LeRobot records at 10-60 fps); beyond
# them step times and video timestamps overflow or collapse (1e308 fps, 1e-300 fps) [frames/s].
MIN_FPS = 0.001
MAX_FPS = 1000.0
# A video-only rollout's length comes from rollout.json alone (no array to bound it). Its timeline
# still holds per-step arrays (~350 bytes a step): 1,000,000 steps (over 18 hours at 15 Hz) take
# report, compare and export 0.4 GB and 4-13 s (benchmarks/hostile_memory.py); 10,000,000 passed
# 3 GB [steps].
MAX_VIDEO_ONLY_STEPS = 1_000_000



def fps_problem(value: object) -> str | None:
    """What is wrong with ``value`` as a frame rate [frames/s], or None when it is one: a number
    (not a bool) in [:data:`MIN_FPS`, :data:`MAX_FPS`]."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"must be a number of frames per second, found {value!r}"
    if not MIN_FPS <= value <= MAX_FPS:  # NaN included: it compares false
        shown = f"{value:g}" if isinstance(value, float) or abs(value) < 10 ** 15 else "an integer past 1e15"
        return f"must lie in [{MIN_FPS:g}, {MAX_FPS:g}] frames per second, found {shown}"
    return None



@dataclass
class Rollout:
    """One rollout of a session, validated on load (videos are streamed when read).

    Arrays are read when first used (their shapes are checked on load; values on first use), so a
    session of thousands of rollouts opens without holding their arrays.

    Attributes:
        actions: (n_chunks, horizon, 6) predicted chunks, dataset units, JOINT_NAMES order.
        states: (n_chunks + 1, 6) or None.
        gt_actions: (T, 6) GT joints from ``start_frame`` on, or None (then the session's
            dataset may supply them).
        actions_shape: ``actions.shape``, known without reading the array.
    """

    root: Path
    tag: str
    kind: RolloutKind
    prompt: str
    episode_index: int | None
    start_frame: int
    fps: float
    horizon: int
    executed_per_chunk: int
    frames_per_chunk: int
    views: list[str]
    units: Units
    actions_shape: tuple[int, ...]
    gt_views: list[str] = field(default_factory=list)
    gt_episode_length: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)  # importer provenance, reference metrics
    session: Session | None = None
    _arrays: dict[str, NpyFile | ArrayValue] = field(default_factory=dict, repr=False)

    @property
    def actions(self) -> npt.NDArray[np.float64]:
        return self._arrays["actions"].load()

    @property
    def states(self) -> npt.NDArray[np.float64] | None:
        f = self._arrays.get("states")
        return None if f is None else f.load()

    @property
    def gt_actions(self) -> npt.NDArray[np.float64] | None:
        f = self._arrays.get("gt_actions")
        return None if f is None else f.load()

    @property
    def latents(self) -> npt.NDArray[np.float64] | None:
        """(n, D) latent vectors (one per chunk or sample), or None when the rollout has none."""
        f = self._arrays.get("latents")
        return None if f is None else f.load()

    @property
    def n_chunks(self) -> int:
        return int(self.actions_shape[0])

    @property
    def has_joints(self) -> bool:
        """False for a video-only rollout (no ``actions.npy``): its :attr:`actions` are NaN, so
        that the timeline keeps its shape while every joint measure of it stays undefined."""
        return not isinstance(self._arrays.get("actions"), NoJoints)

    @property
    def has_gt_joints(self) -> bool:
        return "gt_actions" in self._arrays

    def release_arrays(self) -> None:
        """Let go of the arrays read so far (they are read again when next used)."""
        for f in self._arrays.values():
            f.release()

    @property
    def steps_per_chunk(self) -> int:
        """Timeline steps each chunk covers: an autoregressive rollout executes the first
        ``executed_per_chunk`` actions of each chunk; a single chunk (or an episode, one chunk of
        all its frames) is judged on its whole horizon."""
        return self.executed_per_chunk if self.kind in CHAINED_KINDS else self.horizon

    def executed_actions(self) -> npt.NDArray[np.float64]:
        """(n_steps, 6) the actions that run, chained chunk after chunk (see :attr:`steps_per_chunk`)."""
        return self.actions[:, : self.steps_per_chunk].reshape(-1, self.actions.shape[-1])

    def video_path(self, view: str, gt: bool = False) -> Path:
        base = self.root / GT_DIR / VIDEO_DIR if gt else self.root / VIDEO_DIR
        return base / f"{view}.mp4"

    def video(self, view: str, gt: bool = False) -> VideoClip:
        """The imagined (or carried GT) clip of ``view``; nothing is decoded until it is read."""
        known = self.gt_views if gt else self.views
        if view not in known:
            raise InspectorError(self.root / ROLLOUT_FILE, f"no {'GT ' if gt else ''}view {view!r}; views: {known}")
        return VideoClip(self.video_path(view, gt))


@dataclass
class Session:
    """A session directory: its metadata, the rollouts that loaded and the errors of those that did not.

    One bad rollout never hides the others: it lands in ``errors`` with the message naming its file.
    """

    root: Path
    name: str
    robot: str
    units: Units
    joint_names: list[str]
    gt_source: dict[str, Any]
    model: dict[str, Any]
    rollouts: dict[str, Rollout] = field(default_factory=dict)
    errors: dict[str, InspectorError] = field(default_factory=dict)
    # where its outcomes live when not in the session directory: a raw directory imported in
    # memory keeps them in a sidecar beside it (inspector.outcomes.sidecar_path)
    outcomes_file: Path | None = None
    # likewise its cameras (cameras.json; inspector.data.cameras reads and writes them)
    cameras_file: Path | None = None

    @property
    def dataset_root(self) -> Path | None:
        """The GT dataset directory, resolved against the session directory when relative."""
        ds = self.gt_source.get("dataset")
        if not ds:
            return None
        p = Path(os.path.expanduser(ds))  # Path.expanduser raises on '~nosuchuser'
        return p if p.is_absolute() else (self.root / p).resolve()

    def tags(self) -> list[str]:
        return sorted([*self.rollouts, *self.errors])


def is_session(path: str | Path) -> bool:
    return (Path(path) / SESSION_FILE).is_file()


def is_rollout(path: str | Path) -> bool:
    return (Path(path) / ROLLOUT_FILE).is_file()

