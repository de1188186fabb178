"""Read LeRobot datasets (codebase v3.0 and v2.1) natively: pyarrow for tables, PyAV for video.

No ``lerobot`` import and no network: a dataset is a directory on local disk, its layout drawn in
:mod:`inspector.data.lerobot_format`. The reader comes in three parts, the seams LeRobot's own
code keeps: :mod:`~inspector.data.lerobot_locate` finds a dataset (a directory or an ``org/name``
repo id), :mod:`~inspector.data.lerobot_meta` reads what ``meta/`` says, and this module reads an
episode's joints and streams its video, and shares one open dataset per process
(:func:`open_dataset`). The names callers use are all importable from here.

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

import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import InspectorError
from ..units import JOINT_NAMES, Units, guess_arm_units

# The names callers import from this module, wherever they live now.
from .lerobot_format import ACTION_KEY as ACTION_KEY
from .lerobot_format import DEFAULT_CHUNKS_SIZE as DEFAULT_CHUNKS_SIZE
from .lerobot_format import EPISODE_INDEX_KEY as EPISODE_INDEX_KEY
from .lerobot_format import FRAME_INDEX_KEY as FRAME_INDEX_KEY
from .lerobot_format import IMAGE_PREFIX as IMAGE_PREFIX
from .lerobot_format import INFO_PATH as INFO_PATH
from .lerobot_format import STATE_KEY as STATE_KEY
from .lerobot_format import TIMESTAMP_KEY as TIMESTAMP_KEY
from .lerobot_format import V21_DEFAULT_DATA_PATH as V21_DEFAULT_DATA_PATH
from .lerobot_format import V21_DEFAULT_VIDEO_PATH as V21_DEFAULT_VIDEO_PATH
from .lerobot_format import V21_TEMPLATE_FIELDS as V21_TEMPLATE_FIELDS
from .lerobot_format import _expand
from .lerobot_format import ep_video_column as ep_video_column
from .lerobot_format import read_jsonl as read_jsonl
from .lerobot_format import template_problem as template_problem
from .lerobot_locate import REPO_ID as REPO_ID
from .lerobot_locate import dataset_file_roots as dataset_file_roots
from .lerobot_locate import dataset_name as dataset_name
from .lerobot_locate import find_dataset as find_dataset
from .lerobot_locate import is_lerobot_dataset as is_lerobot_dataset
from .lerobot_locate import lerobot_home_dirs as lerobot_home_dirs
from .lerobot_meta import EpisodeInfo as EpisodeInfo
from .lerobot_meta import LeRobotMetadata
from .lerobot_meta import VideoSegment as VideoSegment
from .session import ABSURD_VALUE
from .video import VideoClip

# Episodes whose joints a dataset keeps in memory (a 600-frame episode's joints take ~60 kB).
EPISODE_CACHE_SIZE = 64

# Tolerated difference between decoded video frames and the episode's length: encoders sometimes
# drop or repeat the last frame; more than that is a broken file.
FRAME_COUNT_SLACK = 1


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



class LeRobotDataset(LeRobotMetadata):
    """A LeRobot dataset on local disk. Opening reads ``meta/info.json`` only.

    Episode metadata is read on first use of :attr:`episodes` (:class:`~.lerobot_meta.LeRobotMetadata`);
    joint data per episode by :meth:`episode`; video when a frame is asked for.

    Args:
        root: the dataset directory (use :func:`find_dataset` for repo ids).

    Raises:
        InspectorError: missing or invalid ``info.json``, unsupported version, missing or malformed
            ``observation.state`` / ``action`` features.
    """

    def __init__(self, root: str | Path, unnamed_joints_in_so101_order: bool = False) -> None:
        """As :class:`~.lerobot_meta.LeRobotMetadata`, with the caches episode reading needs."""
        super().__init__(root, unnamed_joints_in_so101_order)
        # Episodes' joints, most recently used last: many rollouts of one episode read it once.
        self._episode_cache: OrderedDict[tuple, Episode] = OrderedDict()
        self._episodes_lock = threading.Lock()

    def __repr__(self) -> str:
        return (f"LeRobotDataset({str(self.root)!r}, {self.codebase_version}, {self.num_episodes} episodes, "
                f"{self.fps:g} fps, cameras={self.cameras})")

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

