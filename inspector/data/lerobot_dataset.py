"""Read LeRobot datasets (codebase v3.0 and v2.1) natively: pyarrow for tables, PyAV for video.

No ``lerobot`` import and no network: a dataset is a directory on local disk. The two layouts::

    v3.0 (LeRobot >= 0.4): many episodes per file
    <root>/
      meta/
        info.json                          codebase_version, fps, features, path templates
        stats.json                         (not read here)
        tasks.parquet                      one row per task: task_index, task string as the index
        episodes/chunk-000/file-000.parquet  one row per episode: episode_index, tasks, length,
                                           dataset_from_index, dataset_to_index, data/chunk_index,
                                           data/file_index, videos/<key>/chunk_index|file_index|
                                           from_timestamp|to_timestamp, stats/...
      data/chunk-000/file-000.parquet      rows of many episodes; select by episode_index
      videos/<video_key>/chunk-000/file-000.mp4   many episodes back to back; an episode is the
                                           window [from_timestamp, to_timestamp) of the file

    v2.1 (LeRobot 0.1 - 0.3): one file per episode, chunk = episode_index // chunks_size
    <root>/
      meta/
        info.json
        episodes.jsonl                     {"episode_index", "tasks", "length"} per line
        tasks.jsonl                        {"task_index", "task"} per line
        episodes_stats.jsonl               (not read here)
      data/chunk-000/episode_000000.parquet
      videos/chunk-000/<video_key>/episode_000000.mp4

v2.0 has the v2.1 layout (they differ only in their stats files, which this reader does not use),
so it is read the same way.

Usage::

    ds = LeRobotDataset(find_dataset("~/.cache/huggingface/lerobot/me/so101_pick"))
    ep = ds.episode(2)               # joints read now, video decoded on first frame access
    ep.state                         # (T, 6) float64, JOINT_NAMES order, dataset units
    ep.frame_at("front", 1.5)        # (H, W, 3) uint8, decoded alone
    for i, rgb in ep.video("front").iter_frames(size=(320, 240)): ...   # streamed

Joint columns are mapped by *name* (``features[key]["names"]``) into
:data:`inspector.units.JOINT_NAMES` order, never by position.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import sys
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import InspectorError
from ..schema import MAX_WHOLE, shown, whole_number
from ..units import JOINT_NAMES, Units, canonical_joint_name, guess_arm_units, joint_order, parse_units
from .hub import fetch_dataset
from .session import ABSURD_VALUE, check_json_size, fps_problem, json_too_large
from .video import VideoClip

# --- versions -------------------------------------------------------------------------------------
V30 = "v3.0"
V21 = "v2.1"
V20 = "v2.0"
SUPPORTED_VERSIONS: tuple[str, ...] = (V30, V21, V20)

# --- paths (relative to the dataset root) ---------------------------------------------------------
INFO_PATH = "meta/info.json"
V30_EPISODES_DIR = "meta/episodes"
V30_EPISODES_GLOB = "chunk-*/file-*.parquet"  # under V30_EPISODES_DIR
V30_TASKS_PATH = "meta/tasks.parquet"
V30_DEFAULT_DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
V30_DEFAULT_VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
V21_EPISODES_PATH = "meta/episodes.jsonl"
V21_TASKS_PATH = "meta/tasks.jsonl"
V21_DEFAULT_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V21_DEFAULT_VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
DEFAULT_CHUNKS_SIZE = 1000

# --- info.json keys -------------------------------------------------------------------------------
CODEBASE_VERSION_KEY = "codebase_version"
FPS_KEY = "fps"
ROBOT_TYPE_KEY = "robot_type"
FEATURES_KEY = "features"
TOTAL_EPISODES_KEY = "total_episodes"
CHUNKS_SIZE_KEY = "chunks_size"
DATA_PATH_KEY = "data_path"
VIDEO_PATH_KEY = "video_path"
# Not a LeRobot key: our writer states the joint units here ({"arm": "degrees", "gripper": "0..100"}).
UNITS_KEY = "units"

# --- feature / column names -----------------------------------------------------------------------
STATE_KEY = "observation.state"
ACTION_KEY = "action"
IMAGE_PREFIX = "observation.images."
TIMESTAMP_KEY = "timestamp"
FRAME_INDEX_KEY = "frame_index"
EPISODE_INDEX_KEY = "episode_index"
INDEX_KEY = "index"
TASK_INDEX_KEY = "task_index"

# --- v3.0 meta/episodes columns -------------------------------------------------------------------
EP_TASKS = "tasks"
EP_LENGTH = "length"
EP_FROM_INDEX = "dataset_from_index"
EP_TO_INDEX = "dataset_to_index"
EP_DATA_CHUNK = "data/chunk_index"
EP_DATA_FILE = "data/file_index"


def ep_video_column(video_key: str, field_name: str) -> str:
    """``videos/<video_key>/<field>`` with field one of chunk_index, file_index, from_timestamp,
    to_timestamp (v3.0 meta/episodes)."""
    return f"videos/{video_key}/{field_name}"


# Episodes whose joints a dataset keeps in memory (a 600-frame episode's joints take ~60 kB).
EPISODE_CACHE_SIZE = 64

# Tolerated difference between decoded video frames and the episode's length: encoders sometimes
# drop or repeat the last frame; more than that is a broken file.
FRAME_COUNT_SLACK = 1


# ==================================================================================================
# Locating a dataset
# ==================================================================================================

def is_lerobot_dataset(path: str | Path) -> bool:
    """True when ``path/meta/info.json`` exists and names a ``codebase_version``."""
    info = _expand(path) / INFO_PATH
    if json_too_large(info):
        return True  # named like a dataset's: the reader refuses its size in one line
    try:
        return isinstance(obj := json.loads(info.read_text()), dict) and CODEBASE_VERSION_KEY in obj
    except (OSError, ValueError, RecursionError):
        return False


REPO_ID = re.compile(r"^[A-Za-z0-9][\w.-]*/[\w.-]+$")  # a Hugging Face repo id: org/name


def dataset_name(ds: LeRobotDataset) -> str:
    """How a dataset is named in pickers and reports: ``org/name`` under a LeRobot home, else its
    directory's name."""
    root = ds.root.resolve()
    repo = hub_snapshot_repo(root)
    if repo is not None:  # datasets--org--name
        org, _, name = repo.name[len(HUB_REPO_PREFIX):].partition("--")
        return f"{org}/{name}" if name else org
    for home in lerobot_home_dirs():
        try:
            rel = root.relative_to(home.resolve())
        except (ValueError, OSError):
            continue
        if len(rel.parts) == 2:
            return "/".join(rel.parts)
    return root.name


# The Hugging Face hub cache (``huggingface_hub.snapshot_download``) keeps a dataset as
#   <hub>/datasets--<org>--<name>/snapshots/<revision>/...   every file a symlink into
#   <hub>/datasets--<org>--<name>/blobs/<hash>               the files' contents
HUB_REPO_PREFIX = "datasets--"
HUB_SNAPSHOTS_DIR = "snapshots"
HUB_BLOBS_DIR = "blobs"


def hub_snapshot_repo(root: Path) -> Path | None:
    """The hub cache repository directory (``datasets--<org>--<name>``) of a dataset that is one
    of its snapshots, else None."""
    snapshots = root.parent
    repo = snapshots.parent
    if snapshots.name == HUB_SNAPSHOTS_DIR and repo.name.startswith(HUB_REPO_PREFIX) and (repo / HUB_BLOBS_DIR).is_dir():
        return repo
    return None


def dataset_file_roots(root: Path) -> list[Path]:
    """The directories a dataset's files may resolve into: the dataset itself, and for a hub
    cache snapshot the ``blobs/`` directory its files are symlinks into (nothing else of the
    cache: not other repositories)."""
    repo = hub_snapshot_repo(root)
    return [root] if repo is None else [root, repo / HUB_BLOBS_DIR]


def lerobot_home_dirs() -> list[Path]:
    """Where LeRobot keeps datasets, most specific first (no duplicates).

    ``$HF_LEROBOT_HOME``, else ``$HF_HOME/lerobot``, else ``$XDG_CACHE_HOME/huggingface/lerobot``,
    else ``~/.cache/huggingface/lerobot`` -- the same order LeRobot resolves ``HF_LEROBOT_HOME``.
    """
    dirs: list[Path] = []
    if os.environ.get("HF_LEROBOT_HOME"):
        dirs.append(_expand(os.environ["HF_LEROBOT_HOME"]))
    if os.environ.get("HF_HOME"):
        dirs.append(_expand(os.environ["HF_HOME"]) / "lerobot")
    if os.environ.get("XDG_CACHE_HOME"):
        dirs.append(_expand(os.environ["XDG_CACHE_HOME"]) / "huggingface" / "lerobot")
    dirs.append(Path.home() / ".cache" / "huggingface" / "lerobot")
    unique: list[Path] = []
    for d in dirs:
        if d not in unique:
            unique.append(d)
    return unique


def find_dataset(path_or_repo_id: str | Path, download: bool = False) -> Path:
    """A dataset root from a directory or an ``org/name`` repo id.

    A repo id is looked up as ``<home>/<org>/<name>`` under :func:`lerobot_home_dirs`; with
    ``download``, one found nowhere is fetched from the Hub into the first of them
    (:func:`inspector.data.hub.fetch_dataset`: the ``hub`` extra, never when ``HF_HUB_OFFLINE`` is set).

    Raises:
        InspectorError: not a dataset, or not found locally (the message says how to get it).
    """
    path = _expand(path_or_repo_id)
    if path.is_dir():
        if not (path / INFO_PATH).is_file():
            raise InspectorError(path / INFO_PATH, "not a LeRobot dataset: meta/info.json is missing")
        return path
    text = str(path_or_repo_id)
    if not REPO_ID.match(text):
        raise InspectorError(path, "no such dataset directory (give a directory or an org/name repo id)")
    homes = lerobot_home_dirs()
    for home in homes:
        if is_lerobot_dataset(home / text):
            return home / text
    if download:

        return fetch_dataset(text, homes[0] / text)
    where = ", ".join(str(h / text) for h in homes)
    if importlib.util.find_spec("lerobot") is not None:
        how = (f"download it with: python -c \"from lerobot.datasets.lerobot_dataset import "
               f"LeRobotDataset; LeRobotDataset('{text}')\"")
    else:
        major, minor = sys.version_info[:2]
        py = "" if (major, minor) >= (3, 12) else f"; this is Python {major}.{minor}"
        how = (f"pass the dataset's directory, or download it: with pip install 'inspector[hub]' "
               f"(then inspector fetches it), through LeRobot after pip install 'inspector[lerobot]' "
               f"(needs Python >= 3.12{py}), or with: huggingface-cli download "
               f"{text} --repo-type dataset --local-dir {homes[0] / text}")
    raise InspectorError(text, f"dataset not found locally (looked in {where}); {how}")


_open_datasets: OrderedDict[tuple[str, int, int], LeRobotDataset] = OrderedDict()
_open_datasets_lock = threading.Lock()


def open_dataset(root: str | Path) -> LeRobotDataset:
    """A :class:`LeRobotDataset`, shared by every caller in this process while its
    ``meta/info.json`` is unchanged: a thousand rollouts of one dataset read its metadata once.

    Raises:
        InspectorError: as :class:`LeRobotDataset`.
    """
    path = _expand(root).resolve()
    try:
        st = (path / INFO_PATH).stat()
        key = (str(path), st.st_mtime_ns, st.st_size)
    except OSError:
        return LeRobotDataset(path)  # raises the reader's own error
    with _open_datasets_lock:
        ds = _open_datasets.get(key)
        if ds is not None:
            _open_datasets.move_to_end(key)
            return ds
    ds = LeRobotDataset(path)
    with _open_datasets_lock:
        _open_datasets[key] = ds
        while len(_open_datasets) > 8:
            _open_datasets.popitem(last=False)
    return ds


# ==================================================================================================
# Data model
# ==================================================================================================

@dataclass(frozen=True)
class VideoSegment:
    """Where one episode's frames of one camera live.

    Attributes:
        path: the mp4 file.
        from_timestamp: start of the episode in the file [s] (0 for v2.1, one file per episode).
        to_timestamp: end of the episode in the file [s], exclusive; None = end of file.
        video_key: the camera's feature (``observation.images.<camera>``), naming the window's
            columns of the episode index in errors.
    """

    path: Path
    from_timestamp: float = 0.0
    to_timestamp: float | None = None
    video_key: str = ""


@dataclass(frozen=True)
class EpisodeInfo:
    """One episode's metadata (no data read).

    Attributes:
        index: episode_index.
        length: number of frames.
        tasks: the episode's task strings (usually one).
        data_file: the parquet file holding its rows.
        from_index, to_index: its rows' global ``index`` range [from, to) (v3.0; None for v2.1).
        videos: camera name -> :class:`VideoSegment`.
    """

    index: int
    length: int
    tasks: list[str]
    data_file: Path
    from_index: int | None = None
    to_index: int | None = None
    videos: dict[str, VideoSegment] = field(default_factory=dict)

    @property
    def task(self) -> str:
        """The task as one string (several tasks are joined with ``"; "``)."""
        return "; ".join(self.tasks)


@dataclass
class Episode:
    """One episode's joints, read now, and its video, streamed when asked for.

    Attributes:
        index: episode_index.
        fps: frames per second.
        length: T, number of frames.
        task: the task string.
        timestamps: (T,) float64 [s] from the episode's start.
        frame_index: (T,) int64.
        state: (T, 6) float64 ``observation.state`` in :data:`JOINT_NAMES` order, dataset units.
        action: (T, 6) float64 ``action`` in :data:`JOINT_NAMES` order, dataset units.
        units: the dataset's joint units.
        cameras: camera names, e.g. ``["front", "wrist"]``.
        videos: camera -> :class:`VideoSegment`.
        source: the dataset root (for error messages).
    """

    index: int
    fps: float
    length: int
    task: str
    timestamps: npt.NDArray[np.float64]
    frame_index: npt.NDArray[np.int64]
    state: npt.NDArray[np.float64]
    action: npt.NDArray[np.float64]
    units: Units
    cameras: list[str]
    videos: dict[str, VideoSegment]
    source: Path = Path(".")

    def video(self, camera: str) -> VideoClip:
        """The camera's clip for this episode (frame i is the episode's frame i), its frame count
        checked against the episode's length from the container's packets (nothing decoded).

        Raises:
            InspectorError: unknown camera, missing/unreadable file, or a frame count that does
                not match the episode's length.
        """
        clip = self.clip_from(camera, 0)
        n = len(clip.timestamps())
        if abs(n - self.length) > FRAME_COUNT_SLACK:
            seg = self.videos[camera]
            window = (f" in [{seg.from_timestamp:.3f}, {seg.to_timestamp:.3f}) s"
                      if seg.to_timestamp is not None else "")
            raise InspectorError(seg.path, f"{IMAGE_PREFIX}{camera}: {n} frames{window}, "
                                           f"episode {self.index} has {self.length}")
        return clip

    def clip_from(self, camera: str, start_frame: int) -> VideoClip:
        """The camera's frames from the episode's frame ``start_frame`` on (frame i of the clip is
        episode frame ``start_frame + i``); nothing is read.

        Raises:
            InspectorError: unknown camera, or a window in the file that is not a span of seconds
                (one episode's index row: the other episodes still read).
        """
        if camera not in self.videos:
            raise InspectorError(self.source / INFO_PATH, f"episode {self.index} has no camera {camera!r}; "
                                                          f"cameras: {self.cameras}")
        seg = self.videos[camera]
        for name, value in (("from_timestamp", seg.from_timestamp), ("to_timestamp", seg.to_timestamp)):
            if value is not None and not (np.isfinite(value) and value >= 0):
                raise InspectorError(seg.path, f"episode {self.index}: the episode index gives "
                                               f"'{ep_video_column(seg.video_key, name)}' = {value}, "
                                               f"not a time in this file [s]")
        return VideoClip(seg.path, seg.from_timestamp + start_frame / self.fps, seg.to_timestamp)

    def frame(self, camera: str, index: int, size: tuple[int, int] | None = None) -> npt.NDArray[np.uint8]:
        """(H, W, 3) uint8 frame ``index`` of ``camera`` (clamped into the episode), decoded alone."""
        index = int(np.clip(index, 0, self.length - 1))
        frame = self.clip_from(camera, index).frame(0, size)
        if frame is None:
            raise InspectorError(self.videos[camera].path, f"{IMAGE_PREFIX}{camera}: no frame {index} "
                                                           f"in episode {self.index}")
        return frame

    def frame_at(self, camera: str, t_s: float) -> npt.NDArray[np.uint8]:
        """(H, W, 3) uint8 frame of ``camera`` showing at ``t_s`` [s] from the episode's start."""
        return self.frame(camera, int(np.floor(t_s * self.fps + 1e-6)))


# ==================================================================================================
# The dataset
# ==================================================================================================

class LeRobotDataset:
    """A LeRobot dataset on local disk. Opening reads ``meta/info.json`` only.

    Episode metadata is read on first use of :attr:`episodes`; joint data per episode by
    :meth:`episode`; video when a frame is asked for.

    Args:
        root: the dataset directory (use :func:`find_dataset` for repo ids).

    Raises:
        InspectorError: missing or invalid ``info.json``, unsupported version, missing or malformed
            ``observation.state`` / ``action`` features.
    """

    def __init__(self, root: str | Path, unnamed_joints_in_so101_order: bool = False) -> None:
        """Args:
            unnamed_joints_in_so101_order: take a 6-value ``observation.state`` / ``action`` whose
                ``names`` is null (as ``lerobot-eval --eval.recording`` writes them) in
                :data:`JOINT_NAMES` order, instead of refusing it; :attr:`unnamed_joints` lists them.
        """
        self.root = _expand(root)
        self._unnamed_ok = unnamed_joints_in_so101_order
        self.unnamed_joints: list[str] = []
        self._info_file = self.root / INFO_PATH
        info = self._read_info()
        self.info: dict[str, Any] = info
        self.codebase_version: str = info[CODEBASE_VERSION_KEY]
        self.fps: float = self._info_fps()
        self.robot_type: str | None = info.get(ROBOT_TYPE_KEY)
        self.features: dict[str, dict[str, Any]] = info[FEATURES_KEY]
        self.num_episodes: int = int(self._info_number(TOTAL_EPISODES_KEY))
        self.chunks_size: int = (int(self._info_number(CHUNKS_SIZE_KEY, positive=True))
                                 if info.get(CHUNKS_SIZE_KEY) is not None else DEFAULT_CHUNKS_SIZE)
        v3 = self.codebase_version == V30
        self.data_path: str = self._info_template(
            DATA_PATH_KEY, V30_DEFAULT_DATA_PATH if v3 else V21_DEFAULT_DATA_PATH)
        self.video_path: str = self._info_template(
            VIDEO_PATH_KEY, V30_DEFAULT_VIDEO_PATH if v3 else V21_DEFAULT_VIDEO_PATH)

        self.video_keys: list[str] = [k for k, f in self.features.items()
                                      if isinstance(f, dict) and f.get("dtype") == "video"]
        self.cameras: list[str] = [_camera_name(k) for k in self.video_keys]
        self._camera_key = dict(zip(self.cameras, self.video_keys))

        # Column order on disk -> JOINT_NAMES order, per joint feature.
        self._order = {key: self._joint_feature_order(key) for key in (STATE_KEY, ACTION_KEY)}
        names = _feature_names(self.features[STATE_KEY]) or list(JOINT_NAMES)  # None: taken in SO-101 order
        self.joint_names: list[str] = [canonical_joint_name(names[i]) for i in self._order[STATE_KEY]]

        self._units: Units | None = None
        self.units_reason: str = ""
        # Episodes' joints, most recently used last: many rollouts of one episode read it once.
        self._episode_cache: OrderedDict[tuple, Episode] = OrderedDict()
        self._episodes_lock = threading.Lock()
        if UNITS_KEY in info:
            try:
                self._units = parse_units(info[UNITS_KEY], f"{INFO_PATH} {UNITS_KEY}")
            except ValueError as exc:
                raise InspectorError(self._info_file, str(exc)) from None
            self.units_reason = f"stated in {INFO_PATH}"

    def __repr__(self) -> str:
        return (f"LeRobotDataset({str(self.root)!r}, {self.codebase_version}, {self.num_episodes} episodes, "
                f"{self.fps:g} fps, cameras={self.cameras})")

    # --- info.json --------------------------------------------------------------------------------

    def _read_info(self) -> dict[str, Any]:
        f = self._info_file
        if not f.is_file():
            raise InspectorError(f, "not a LeRobot dataset: meta/info.json is missing")
        check_json_size(f)
        try:
            info = json.loads(f.read_text())
        except (OSError, UnicodeDecodeError) as exc:
            raise InspectorError(f, f"cannot read: {exc}") from None
        except (ValueError, RecursionError) as exc:  # bad JSON, an int of 5000 digits, [[[[...
            raise InspectorError(f, f"invalid JSON: {exc}") from None
        if not isinstance(info, dict):
            raise InspectorError(f, "expected a JSON object")
        version = info.get(CODEBASE_VERSION_KEY)
        if version not in SUPPORTED_VERSIONS:
            raise InspectorError(f, f"{CODEBASE_VERSION_KEY} {version!r} is not supported; "
                                    f"supported: {list(SUPPORTED_VERSIONS)}")
        features = info.get(FEATURES_KEY)
        if not isinstance(features, dict):
            raise InspectorError(f, f"'{FEATURES_KEY}' is missing or not an object")
        for key in (STATE_KEY, ACTION_KEY):
            if not isinstance(features.get(key), dict):
                raise InspectorError(f, f"features has no {key!r}; features: {sorted(features)}")
        return info

    def _info_number(self, key: str, positive: bool = False) -> float:
        value = self.info.get(key)
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or not (isinstance(value, int) or np.isfinite(value)) or value < 0 or (positive and value == 0)
                or value > MAX_WHOLE):
            raise InspectorError(self._info_file, f"'{key}' must be a {'positive' if positive else 'non-negative'}"
                                                  f" number no larger than {MAX_WHOLE}, found {shown(value)}")
        return value

    def _info_fps(self) -> float:
        problem = fps_problem(self.info.get(FPS_KEY))
        if problem is not None:
            raise InspectorError(self._info_file, f"'{FPS_KEY}' {problem}")
        return self.info[FPS_KEY]  # as written (30, not 30.0: `info` shows it)

    def _info_template(self, key: str, default: str) -> str:
        """A path template from info.json (LeRobot writes null for video_path without videos),
        checked now (:func:`template_problem`): a bad one is refused when the dataset opens, not
        when a path is filled from it."""
        value = self.info.get(key)
        if value is None:
            return default
        if not isinstance(value, str):
            raise InspectorError(self._info_file, f"'{key}' must be a path template string, found {shown(value)}")
        fields = V30_TEMPLATE_FIELDS if self.codebase_version == V30 else V21_TEMPLATE_FIELDS
        problem = template_problem(value, fields if key == DATA_PATH_KEY else {**fields, "video_key": "front"})
        if problem is not None:
            raise InspectorError(self._info_file, f"'{key}': {problem}")
        return value

    def _joint_feature_order(self, key: str) -> npt.NDArray[np.int64]:
        feature = self.features[key]
        names = _feature_names(feature)
        shape = feature.get("shape")
        if names is None and self._unnamed_ok and shape == [len(JOINT_NAMES)]:
            self.unnamed_joints.append(key)
            return np.arange(len(JOINT_NAMES), dtype=np.int64)
        if names is None:
            raise InspectorError(self._info_file, f"features.{key}.names is missing; expected the 6 "
                                                  f"SO-101 joints {list(JOINT_NAMES)}")
        if isinstance(shape, list) and shape != [len(names)]:
            raise InspectorError(self._info_file, f"features.{key}.shape is {shape}, "
                                                  f"but it names {len(names)} values")
        try:
            return joint_order(names, f"features.{key}.names")
        except ValueError as exc:
            raise InspectorError(self._info_file, str(exc)) from None

    # --- units ------------------------------------------------------------------------------------

    @property
    def units(self) -> Units:
        """Joint units: stated in info.json, or guessed from the first episode whose joints read
        (read on first access; :attr:`units_reason` says why). A broken episode is skipped here,
        so it fails alone when it is read, not every episode with it.

        Raises:
            InspectorError: every episode's joints are unreadable (the first one's error).
        """
        if self._units is None:
            first_error: InspectorError | None = None
            for info in self.episodes:
                try:
                    state, action, _ = self._read_joints(info)
                except InspectorError as exc:
                    first_error = first_error or exc
                    continue
                self._guess_units(info, state, action)
                break
            else:
                if first_error is not None:
                    raise first_error
                self._units, self.units_reason = Units(guessed=True), "no episodes; assuming degrees"
        assert self._units is not None
        return self._units

    def _guess_units(self, info: EpisodeInfo, state: npt.NDArray[np.float64], action: npt.NDArray[np.float64]) -> None:
        units, reason = guess_arm_units(np.concatenate([state, action]))
        if info is not self.episodes[0]:
            reason += f" (from episode {info.index}: the episodes before it are unreadable)"
        self._units, self.units_reason = units, reason

    # --- episode metadata -------------------------------------------------------------------------

    @cached_property
    def _episode_map(self) -> dict[int, EpisodeInfo]:
        infos = self._load_episodes_v30() if self.codebase_version == V30 else self._load_episodes_v21()
        infos.sort(key=lambda e: e.index)
        twice = next((a.index for a, b in zip(infos, infos[1:]) if a.index == b.index), None)
        if twice is not None:  # which row would be the episode? neither silently
            where = self.root / (V30_EPISODES_DIR if self.codebase_version == V30 else V21_EPISODES_PATH)
            raise InspectorError(where, f"'{EPISODE_INDEX_KEY}' {twice} is listed twice")
        return {e.index: e for e in infos}

    @property
    def episodes(self) -> list[EpisodeInfo]:
        """All episodes' metadata, by episode_index (read from ``meta/`` on first access)."""
        return list(self._episode_map.values())

    def episode_info(self, index: int) -> EpisodeInfo:
        """Metadata of episode ``index``.

        Raises:
            InspectorError: no such episode (the message gives the available range).
        """
        try:
            return self._episode_map[int(index)]
        except KeyError:
            raise InspectorError(self.root, f"episode {index} is out of range; available: "
                                            f"{_describe_indices(list(self._episode_map))}") from None

    def episode_indexes(self) -> set[int]:
        """The episode indexes the dataset holds."""
        return set(self._episode_map)

    def describe_episodes(self) -> str:
        """The episode indexes in a few words (``"0..41"``, gaps listed)."""
        return _describe_indices(list(self._episode_map))

    def task(self, index: int) -> str:
        """The task string of episode ``index``."""
        return self.episode_info(index).task

    @cached_property
    def tasks(self) -> list[str]:
        """All task strings, in task_index order."""
        return self._load_tasks_v30() if self.codebase_version == V30 else self._load_tasks_v21()

    def _format_path(self, template_key: str, template: str, **fields: Any) -> Path:
        try:
            path = self.root / template.format(**fields)
        except (KeyError, IndexError, ValueError, AttributeError, TypeError) as exc:
            raise InspectorError(self._info_file, f"'{template_key}' template {template!r} cannot be "
                                                  f"filled from {sorted(fields)} ({exc})") from None
        # info.json is input: its templates must not point outside the dataset
        if ".." in Path(template).parts or Path(template).is_absolute():
            raise InspectorError(self._info_file,
                                 f"'{template_key}' template {template!r} leaves the dataset")
        return path

    def _load_episodes_v30(self) -> list[EpisodeInfo]:
        import pyarrow.parquet as pq

        files = sorted((self.root / V30_EPISODES_DIR).glob(V30_EPISODES_GLOB))
        if not files:
            raise InspectorError(self.root / V30_EPISODES_DIR,
                                 f"no episode metadata ({V30_EPISODES_GLOB}) for a v3.0 dataset")
        video_fields = ("chunk_index", "file_index", "from_timestamp", "to_timestamp")
        needed = [EPISODE_INDEX_KEY, EP_TASKS, EP_LENGTH, EP_FROM_INDEX, EP_TO_INDEX, EP_DATA_CHUNK,
                  EP_DATA_FILE] + [ep_video_column(k, f) for k in self.video_keys for f in video_fields]
        infos: list[EpisodeInfo] = []
        for f in files:
            try:
                _check_index_columns(f, pq.read_schema(f), needed)
                rows = pq.read_table(f, columns=needed).to_pylist()  # skip the wide stats/ columns
            except InspectorError:
                raise
            except Exception as exc:
                raise InspectorError(f, f"cannot read parquet ({type(exc).__name__}: {exc})") from None
            for row_no, row in enumerate(rows):
                if any(row[c] is None for c in needed if c != EP_TASKS):
                    raise InspectorError(f, f"row {row_no}: null in "
                                            f"{[c for c in needed if row[c] is None and c != EP_TASKS]}")
                _check_episode(f, f"row {row_no}", row[EPISODE_INDEX_KEY], row[EP_LENGTH])
                ep = int(row[EPISODE_INDEX_KEY])
                data_file = self._format_path(DATA_PATH_KEY, self.data_path,
                                              chunk_index=row[EP_DATA_CHUNK], file_index=row[EP_DATA_FILE])
                videos = {}
                for cam, key in self._camera_key.items():
                    v = {fld: row[ep_video_column(key, fld)] for fld in video_fields}
                    path = self._format_path(VIDEO_PATH_KEY, self.video_path, video_key=key,
                                             chunk_index=v["chunk_index"], file_index=v["file_index"])
                    videos[cam] = VideoSegment(path, float(v["from_timestamp"]), float(v["to_timestamp"]), key)
                infos.append(EpisodeInfo(ep, int(row[EP_LENGTH]), [str(t) for t in row[EP_TASKS] or []],
                                         data_file, int(row[EP_FROM_INDEX]), int(row[EP_TO_INDEX]), videos))
        return infos

    def _load_episodes_v21(self) -> list[EpisodeInfo]:
        f = self.root / V21_EPISODES_PATH
        infos: list[EpisodeInfo] = []
        for line_no, row in read_jsonl(f):
            ep, length = row.get(EPISODE_INDEX_KEY), row.get(EP_LENGTH)
            if not (_is_whole(ep) and _is_whole(length)):
                raise InspectorError(f, f"line {line_no}: needs integer '{EPISODE_INDEX_KEY}' and "
                                        f"'{EP_LENGTH}', found {shown(ep)} and {shown(length)}")
            assert isinstance(ep, int) and isinstance(length, int)
            tasks = [str(t) for t in row.get(EP_TASKS) or []] if isinstance(row.get(EP_TASKS), list) else []
            _check_episode(f, f"line {line_no}", ep, length)
            chunk = ep // self.chunks_size
            data_file = self._format_path(DATA_PATH_KEY, self.data_path, episode_chunk=chunk,
                                          episode_index=ep)
            videos = {cam: VideoSegment(self._format_path(VIDEO_PATH_KEY, self.video_path,
                                                          episode_chunk=chunk, video_key=key,
                                                          episode_index=ep))
                      for cam, key in self._camera_key.items()}
            infos.append(EpisodeInfo(ep, length, tasks, data_file, None, None, videos))
        return infos

    def _load_tasks_v30(self) -> list[str]:
        import pyarrow.parquet as pq

        f = self.root / V30_TASKS_PATH
        if not f.is_file():
            raise InspectorError(f, "tasks file not found")
        try:
            table = pq.read_table(f)
        except Exception as exc:
            raise InspectorError(f, f"cannot read parquet ({type(exc).__name__}: {exc})") from None
        # LeRobot writes a pandas DataFrame indexed by the task string: the strings sit in the
        # pandas index column (``__index_level_0__``); older writers used a 'task' column.
        names = table.column_names
        index_cols = [c for c in names if c.startswith("__index_level_")]
        text_col = "task" if "task" in names else (index_cols[0] if index_cols else None)
        if TASK_INDEX_KEY not in names or text_col is None:
            raise InspectorError(f, f"expected columns '{TASK_INDEX_KEY}' and the task string, found {names}")
        pairs = sorted(zip(table.column(TASK_INDEX_KEY).to_pylist(), table.column(text_col).to_pylist()))
        return [str(task) for _, task in pairs]

    def _load_tasks_v21(self) -> list[str]:
        f = self.root / V21_TASKS_PATH
        pairs = []
        for line_no, row in read_jsonl(f):
            try:
                pairs.append((whole_number(row[TASK_INDEX_KEY], f, f"line {line_no}: '{TASK_INDEX_KEY}'"),
                              str(row["task"])))
            except (KeyError, TypeError, ValueError, OverflowError):
                raise InspectorError(f, f"line {line_no}: needs integer '{TASK_INDEX_KEY}' and "
                                        f"'task'") from None
        return [task for _, task in sorted(pairs)]

    # --- episode data -----------------------------------------------------------------------------

    def _read_joints(self, info: EpisodeInfo) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64],
                                                         dict[str, npt.NDArray[Any]]]:
        """Read one episode's rows: state (T, 6), action (T, 6) in JOINT_NAMES order, and the
        timestamp / frame_index columns, validated (count, width, finiteness)."""
        import pyarrow.parquet as pq

        f = info.data_file
        if not f.is_file():
            raise InspectorError(f, f"data file of episode {info.index} not found")
        columns = [STATE_KEY, ACTION_KEY, TIMESTAMP_KEY, FRAME_INDEX_KEY, EPISODE_INDEX_KEY]
        try:
            names = pq.read_schema(f).names
            missing = [c for c in columns if c not in names]
            if missing:
                raise InspectorError(f, f"missing column(s) {missing}")
            # v3.0 files hold many episodes: the filter lets pyarrow skip other row groups.
            table = pq.read_table(f, columns=columns, filters=[(EPISODE_INDEX_KEY, "=", info.index)])
        except InspectorError:
            raise
        except Exception as exc:
            raise InspectorError(f, f"cannot read parquet ({type(exc).__name__}: {exc})") from None
        if table.num_rows != info.length:
            raise InspectorError(f, f"episode {info.index} has {table.num_rows} rows, its metadata "
                                    f"says length {info.length}")
        frame_index = table.column(FRAME_INDEX_KEY).to_numpy().astype(np.int64)
        rows = np.argsort(frame_index, kind="stable")  # rows are written in order; make sure
        cols = {TIMESTAMP_KEY: table.column(TIMESTAMP_KEY).to_numpy().astype(np.float64)[rows],
                FRAME_INDEX_KEY: frame_index[rows]}
        joints = []
        for key in (STATE_KEY, ACTION_KEY):
            values = _fixed_width(table.column(key), len(JOINT_NAMES), f, key)[rows]
            values = values[:, self._order[key]]
            bad = ~np.isfinite(values) | (np.abs(values) > ABSURD_VALUE)
            if bad.any():
                r, j = np.argwhere(bad)[0]
                kind = "non-finite" if not np.isfinite(values[r, j]) else "absurd"
                raise InspectorError(f, f"{key}: {kind} value {values[r, j]:g} in episode {info.index} "
                                        f"at frame_index {cols[FRAME_INDEX_KEY][r]} (row {r} of the "
                                        f"episode), joint {JOINT_NAMES[j]}")
            joints.append(values)
        return joints[0], joints[1], cols

    def episode(self, index: int) -> Episode:
        """Episode ``index``: joints read now (kept for the next call), video streamed on demand.

        Raises:
            InspectorError: out of range, missing/malformed data file, NaN/inf joints.
        """
        info = self.episode_info(index)
        try:  # a data file rewritten (or removed) since it was read is read again
            st = info.data_file.stat()
            key: tuple = (index, st.st_mtime_ns, st.st_size)
        except OSError:
            return self._read_episode(index)  # raises the reader's own error
        with self._episodes_lock:
            cached = self._episode_cache.get(key)
            if cached is not None:
                self._episode_cache.move_to_end(key)
                return cached
        episode = self._read_episode(index)
        with self._episodes_lock:
            self._episode_cache[key] = episode
            while len(self._episode_cache) > EPISODE_CACHE_SIZE:
                self._episode_cache.popitem(last=False)
        return episode

    def _read_episode(self, index: int) -> Episode:
        info = self.episode_info(index)
        state, action, cols = self._read_joints(info)
        if self._units is None and info is self.episodes[0]:
            self._guess_units(info, state, action)
        return Episode(index=info.index, fps=float(self.fps), length=info.length, task=info.task,
                       timestamps=cols[TIMESTAMP_KEY], frame_index=cols[FRAME_INDEX_KEY], state=state,
                       action=action, units=self.units, cameras=list(self.cameras), videos=dict(info.videos),
                       source=self.root)


# ==================================================================================================
# helpers
# ==================================================================================================

# What a path template may be filled from, with a value of each field's type (checked on it).
V30_TEMPLATE_FIELDS: dict[str, Any] = {"chunk_index": 0, "file_index": 0}
V21_TEMPLATE_FIELDS: dict[str, Any] = {"episode_chunk": 0, "episode_index": 0}
# The widest format a template field may ask for (``{episode_index:06d}`` asks for 6), and the
# longest template: a path longer than a file system takes is no path [characters].
MAX_TEMPLATE_WIDTH = 32
MAX_TEMPLATE_CHARS = 1024
_FORMAT_SPEC = re.compile(r"(?:.?[<>=^])?[+\- ]?z?#?0?(?P<width>\d*)[,_]?(?:\.(?P<precision>\d+))?[bcdeEfFgGnosxX%]?")


def template_problem(template: str, fields: dict[str, Any]) -> str | None:
    """What is wrong with ``template`` as a path template filled from ``fields`` (their names and
    example values), or None: only those names (no attribute or index lookups, no positional
    ``{}``), each formatted with a plain spec of width and precision at most
    :data:`MAX_TEMPLATE_WIDTH` (``{episode_index:>300000000}`` would be a 300 MB path), at most
    :data:`MAX_TEMPLATE_CHARS` long, filled without error from the example values, and inside the
    dataset (no ``..``, not absolute)."""
    import string

    if len(template) > MAX_TEMPLATE_CHARS:
        return f"a template of {len(template):,} characters (at most {MAX_TEMPLATE_CHARS})"
    known = sorted(fields)
    try:
        parts = list(string.Formatter().parse(template))
    except ValueError as exc:
        return f"template {shown(template)} is not a format string ({exc})"
    for _, name, spec, conversion in parts:
        if name is None:
            continue
        if name not in fields:
            return f"template {shown(template)}: unknown field {shown(name)}; known: {known}"
        match = _FORMAT_SPEC.fullmatch(spec or "")
        if match is None or conversion not in (None, "s"):
            return f"template {shown(template)}: field {name!r} has an unsupported format {shown(spec)}"
        widths = [int(w) for w in (match["width"], match["precision"]) if w]
        if any(w > MAX_TEMPLATE_WIDTH for w in widths):
            return (f"template {shown(template)}: field {name!r} asks for a width of {max(widths)} "
                    f"(at most {MAX_TEMPLATE_WIDTH})")
    try:
        template.format(**fields)
    except (KeyError, IndexError, ValueError, AttributeError, TypeError) as exc:
        return f"template {shown(template)} cannot be filled from {known} ({exc})"
    if ".." in Path(template).parts or Path(template).is_absolute():
        return f"template {shown(template)} leaves the dataset"
    return None


def _expand(path: str | Path) -> Path:
    """``~`` expanded; an unknown ``~user`` stays as written (``Path.expanduser`` would raise)."""
    return Path(os.path.expanduser(path))


def _camera_name(video_key: str) -> str:
    """``observation.images.front`` -> ``front``."""
    return video_key[len(IMAGE_PREFIX):] if video_key.startswith(IMAGE_PREFIX) else video_key


def _feature_names(feature: dict[str, Any]) -> list[str] | None:
    """``features[key]["names"]`` as a list; v2.0-era datasets nest it as ``{"motors": [...]}``."""
    names = feature.get("names")
    if isinstance(names, dict) and len(names) == 1:
        names = next(iter(names.values()))
    if isinstance(names, list) and all(isinstance(n, str) for n in names):
        return names
    return None


def _fixed_width(column: Any, width: int, file: Path, key: str) -> npt.NDArray[np.float64]:
    """A parquet list column (fixed-size or variable) -> (N, width) float64."""
    import pyarrow as pa

    col = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if pa.types.is_fixed_size_list(col.type):
        found = col.type.list_size
    elif pa.types.is_list(col.type) or pa.types.is_large_list(col.type):
        lengths = np.unique(col.value_lengths().to_numpy(zero_copy_only=False))
        found = int(lengths[0]) if len(lengths) == 1 else lengths.tolist()
    else:
        raise InspectorError(file, f"{key}: expected a list of {width} numbers per row, found {col.type}")
    if found != width:
        raise InspectorError(file, f"{key}: expected {width} values per row, found {found}")
    if col.null_count:
        raise InspectorError(file, f"{key}: {col.null_count} null row(s)")
    flat = col.flatten().to_numpy(zero_copy_only=False).astype(np.float64)
    return flat.reshape(len(col), width)


def read_jsonl(f: Path) -> list[tuple[int, dict[str, Any]]]:
    """(line number, object) for every non-empty line of a JSON-lines file."""
    if not f.is_file():
        raise InspectorError(f, "file not found")
    try:
        text = f.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InspectorError(f, f"cannot read: {exc}") from None
    out = []
    for line_no, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except (ValueError, RecursionError) as exc:
            raise InspectorError(f, f"line {line_no}: invalid JSON ({exc})") from None
        if not isinstance(row, dict):
            raise InspectorError(f, f"line {line_no}: expected a JSON object")
        out.append((line_no, row))
    return out


def _check_index_columns(f: Path, schema: Any, needed: list[str]) -> None:
    """The v3.0 episode index holds every column it needs, each of its expected type: whole
    numbers for indexes and lengths, numbers for timestamps, lists of strings for tasks. Checked
    on the file's schema, once for all its rows, so a wrong-typed column (an episode index
    written as strings) is one line naming it, not a comparison failing deep in the reader.

    Raises:
        InspectorError: naming ``f`` and the first column missing or of the wrong type.
    """
    import pyarrow as pa

    missing = [c for c in needed if c not in schema.names]
    if missing:
        raise InspectorError(f, f"missing column(s) {missing}")
    for name in needed:
        typ = schema.field(name).type
        if name == EP_TASKS:
            ok = pa.types.is_null(typ) or ((pa.types.is_list(typ) or pa.types.is_large_list(typ))
                                           and (pa.types.is_string(typ.value_type)
                                                or pa.types.is_large_string(typ.value_type)))
            expected = "a list of task strings"
        elif name.endswith(("from_timestamp", "to_timestamp")):
            ok, expected = pa.types.is_floating(typ) or pa.types.is_integer(typ), "numbers [s]"
        else:
            ok, expected = pa.types.is_integer(typ), "whole numbers"
        if not ok:
            raise InspectorError(f, f"column '{name}': expected {expected}, found {typ}")


def _is_whole(value: Any) -> bool:
    """An integer, and not a bool (JSON's ``true`` is no episode index)."""
    return isinstance(value, int) and not isinstance(value, bool)


def _check_episode(f: Path, where: str, index: Any, length: Any) -> None:
    """An episode's metadata row names a non-negative index and a positive length (both no
    larger than :data:`MAX_WHOLE`)."""
    if not index >= 0 or not length >= 1:
        raise InspectorError(f, f"{where}: '{EPISODE_INDEX_KEY}' must be >= 0 and '{EP_LENGTH}' >= 1, "
                                f"found {shown(index)} and {shown(length)}")
    whole_number(index, f, f"{where}: '{EPISODE_INDEX_KEY}'")
    whole_number(length, f, f"{where}: '{EP_LENGTH}'", minimum=1)


def _describe_indices(indices: list[int]) -> str:
    """``[0, 1, 2]`` -> ``"0..2"``; gaps are listed (shortened when long)."""
    if not indices:
        return "none"
    idx = sorted(indices)
    if idx == list(range(idx[0], idx[-1] + 1)):
        return f"{idx[0]}..{idx[-1]}"
    return str(idx) if len(idx) <= 12 else f"{idx[:5]} ... {idx[-5:]} ({len(idx)} episodes)"
