"""What a LeRobot dataset's ``meta/`` says, with no data file read: ``info.json`` checked when the
dataset opens (version, fps, features, path templates, joint names, stated units), then each
episode's metadata (where its rows and video windows are) and the tasks, on first use.

LeRobot keeps the same seam (``LeRobotDatasetMetadata`` reads only ``meta/``): a picker listing a
thousand episodes, or ``inspector info``, needs none of their joints.
:class:`inspector.data.lerobot_dataset.LeRobotDataset` adds the episodes' data on top.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import InspectorError
from ..schema import MAX_WHOLE, shown, whole_number
from ..units import JOINT_NAMES, Units, canonical_joint_name, joint_order, parse_units
from .lerobot_format import (
    ACTION_KEY,
    CHUNKS_SIZE_KEY,
    CODEBASE_VERSION_KEY,
    DATA_PATH_KEY,
    DEFAULT_CHUNKS_SIZE,
    EP_DATA_CHUNK,
    EP_DATA_FILE,
    EP_FROM_INDEX,
    EP_LENGTH,
    EP_TASKS,
    EP_TO_INDEX,
    EPISODE_INDEX_KEY,
    FEATURES_KEY,
    FPS_KEY,
    INFO_PATH,
    ROBOT_TYPE_KEY,
    STATE_KEY,
    SUPPORTED_VERSIONS,
    TASK_INDEX_KEY,
    TOTAL_EPISODES_KEY,
    UNITS_KEY,
    V21_DEFAULT_DATA_PATH,
    V21_DEFAULT_VIDEO_PATH,
    V21_EPISODES_PATH,
    V21_TASKS_PATH,
    V21_TEMPLATE_FIELDS,
    V30,
    V30_DEFAULT_DATA_PATH,
    V30_DEFAULT_VIDEO_PATH,
    V30_EPISODES_DIR,
    V30_EPISODES_GLOB,
    V30_TASKS_PATH,
    V30_TEMPLATE_FIELDS,
    VIDEO_PATH_KEY,
    _camera_name,
    _check_episode,
    _check_index_columns,
    _describe_indices,
    _expand,
    _feature_names,
    _is_whole,
    ep_video_column,
    read_jsonl,
    template_problem,
)
from .session import check_json_size, fps_problem


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



class LeRobotMetadata:
    """A LeRobot dataset's ``meta/`` on local disk. Opening reads ``meta/info.json`` only; episode
    metadata is read on first use of :attr:`episodes`.

    Args:
        root: the dataset directory (use :func:`inspector.data.lerobot_dataset.find_dataset` for
            repo ids).

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

        # Stated units; None until the dataset guesses them from an episode's joints.
        self._units: Units | None = None
        self.units_reason: str = ""
        if UNITS_KEY in info:
            try:
                self._units = parse_units(info[UNITS_KEY], f"{INFO_PATH} {UNITS_KEY}")
            except ValueError as exc:
                raise InspectorError(self._info_file, str(exc)) from None
            self.units_reason = f"stated in {INFO_PATH}"

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
