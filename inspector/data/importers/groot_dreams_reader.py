"""GR00T-Dreams (DreamGen) neural trajectories, read natively: what NVIDIA/GR00T-Dreams'
``IDM_dump/dump_idm_actions.py`` leaves (embodiment ``so100``; SO-101 users run the same pipeline).
This module reads a dump (its episodes as rollouts, for the app, ``report`` and ``export``);
:mod:`.groot_dreams` describes it (``inspector info``) and imports it (``inspector import groot-dreams``).

The layout (``IDM_dump/raw_to_lerobot.py`` writes it, the IDM dump fills in ``action``)::

    <root>/
      meta/
        info.json        LeRobot v2.0-style, but no codebase_version; fps 8 with --cosmos_predict2
                         (the timestamps say 16); features still 44-wide (motor_0 .. motor_43)
        episodes.jsonl   {"episode_index", "tasks", "length", "video_id"} per line
        tasks.jsonl      {"task_index", "task"}: every task prefixed "<DREAM>"
        modality.json    the embodiment's slicing of state/action by name: {"action":
                         {"main_shoulder_pan": {"start": 0, "end": 1, "absolute": false}, ...}}
        stats.json       the embodiment's statistics (so100: action means near 113, 116, 109, 74, -43, 16)
      data/chunk-000/episode_000000.parquet    observation.state (a zero placeholder), action (the
                         inverse-dynamics model's labels, in the embodiment's units), timestamp (i/16),
                         episode_index, index, task_index; no frame_index
      videos/chunk-000/observation.images.webcam/episode_000000.mp4   the generated video (256x256)

Each episode is an imagined trajectory with no real episode behind it: it becomes a one-chunk
rollout of the IDM actions (no GT) whose imagined view is the generated video, frame ``t`` at step
``t``. ``modality.json``'s slicing, not ``info.json``'s shapes, says which action columns are which
joint (mapped by name, ``main_`` dropped). The actions are in GR00T's SO-100 legacy calibration:
:mod:`.calibration` maps them onto the URDF's zeros (``--calibration`` overrides it), and a
calibration that puts most steps past a joint limit is said to be wrong. The frame rate is the
timestamps', not ``info.json``'s, and ``inspector info`` says so when they disagree.

Only ``meta/`` (and the first episode's timestamps) is read to list the episodes; an episode's
parquet file is read when it is opened, so a bad episode fails alone.
"""

from __future__ import annotations

import json
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ...errors import InspectorError, require
from ...schema import shown, whole_number
from ...units import DEFAULT_LIMIT_MARGIN_DEG, JOINT_NAMES, Units, limit_margin_in_units, limits_in_units
from ..ground_truth import GroundTruth
from ..lerobot_dataset import (
    DEFAULT_CHUNKS_SIZE,
    V21_DEFAULT_DATA_PATH,
    V21_DEFAULT_VIDEO_PATH,
    V21_TEMPLATE_FIELDS,
    EpisodeInfo,
    VideoSegment,
    read_jsonl,
    template_problem,
)
from ..session import ABSURD_VALUE, ArrayValue, Rollout, Session, json_too_large, read_json_object
from ..video import VideoClip, probe
from .calibration import WRONG_CALIBRATION_SHARE, Calibration, parse_calibration

LAYOUT = "groot-dreams"
LAYOUT_TITLE = "GR00T-Dreams neural trajectories (IDM_dump)"
LAYOUT_HINT = "meta/modality.json + meta/episodes.jsonl, info.json without codebase_version"
DEFAULT_CALIBRATION = "gr00t-so100"
MODEL_NAME = "GR00T-Dreams IDM (inverse dynamics labels of a generated video)"

INFO_PATH = "meta/info.json"
EPISODES_PATH = "meta/episodes.jsonl"
TASKS_PATH = "meta/tasks.jsonl"
MODALITY_PATH = "meta/modality.json"
STATS_PATH = "meta/stats.json"
DREAM_PREFIX = "<DREAM>"  # dump_idm_actions.py prefixes every task in tasks.jsonl with it
JOINT_PREFIX = "main_"  # modality.json names the so100 joints main_shoulder_pan ... main_gripper
ACTION_KEY = "action"
TIMESTAMP_KEY = "timestamp"
IMAGE_PREFIX = "observation.images."
CODEBASE_VERSION_KEY = "codebase_version"
# Relative difference between two frame rates that counts as a disagreement.
FPS_TOLERANCE = 0.01
# The widest action row a dump may slice a joint from (so100's rows are 44 wide; GR00T's
# embodiments stay in the hundreds): a column past it is no column of any row.
MAX_ACTION_COLUMN = 4095
# Decoded frames may differ from an episode's length by this much before it is said (encoders
# sometimes drop or repeat the last frame).
FRAME_COUNT_SLACK = 1


def is_groot_dreams(path: str | Path) -> bool:
    """True for a directory laid out as :mod:`this module <.groot_dreams_reader>` describes: ``meta/info.json``
    without ``codebase_version`` beside ``meta/modality.json`` and ``meta/episodes.jsonl``."""
    meta = Path(path) / "meta"
    if not ((meta / "modality.json").is_file() and (meta / "episodes.jsonl").is_file()
            and (meta / "info.json").is_file()):
        return False
    if json_too_large(meta / "info.json"):
        return True  # ours by its layout: the reader refuses its size
    try:
        info = json.loads((meta / "info.json").read_text())
    except (OSError, ValueError, RecursionError):
        return True  # ours by its layout: the reader says what is wrong with info.json
    return not (isinstance(info, dict) and CODEBASE_VERSION_KEY in info)


# ----------------------------------------------------------------------------------------------
# One episode


@dataclass
class Trajectory:
    """One episode's IDM actions, read and mapped.

    Attributes:
        index: episode_index.
        task: the task string as ``tasks.jsonl`` has it (``<DREAM>...``).
        dream: the task is marked ``<DREAM>`` (a generated, not a recorded, episode).
        raw: (T, 6) the file's action columns by joint name, the embodiment's units.
        actions: (T, 6) ``raw`` through the calibration: URDF zeros, degrees, gripper 0..100.
        timestamps: (T,) [s] from the file (``i / fps`` when it has none).
        fps: steps per second, from the timestamps.
        videos: camera -> the generated video of that camera (every camera the dump lists whose
            file is there).
        warnings: what the user should know (frame rate, frame count, calibration).
    """

    index: int
    task: str
    dream: bool
    raw: npt.NDArray[np.float64]
    actions: npt.NDArray[np.float64]
    timestamps: npt.NDArray[np.float64]
    fps: float
    videos: dict[str, Path]
    warnings: list[str] = field(default_factory=list)

    @property
    def video(self) -> Path | None:
        """The first camera's video, or None without any."""
        return next(iter(self.videos.values()), None)

    @property
    def length(self) -> int:
        return int(self.actions.shape[0])


@dataclass
class TrajectoryRollout(Rollout):
    """A rollout whose imagined views are files of the dataset (not under ``video/``)."""

    video_files: dict[str, Path] = field(default_factory=dict)

    def video_path(self, view: str, gt: bool = False) -> Path:
        if not gt and view in self.video_files:
            return self.video_files[view]
        return super().video_path(view, gt)


def rollout_tag(index: int) -> str:
    return f"episode_{index:06d}"


# ----------------------------------------------------------------------------------------------
# The dataset


class NeuralTrajectories:
    """A GR00T-Dreams IDM dump on local disk. Opening reads ``meta/`` and the first episode's
    timestamps; an episode is read by :meth:`trajectory`.

    Args:
        root: the dataset directory.
        calibration: ``--calibration``'s text (None: :data:`DEFAULT_CALIBRATION`).

    Raises:
        InspectorError: a ``meta/`` file is missing or malformed (naming the file and the field),
            or ``calibration`` is not one.
    """

    def __init__(self, root: str | Path, calibration: str | None = None) -> None:
        self.root = Path(root)
        try:
            self.calibration: Calibration = parse_calibration(calibration, DEFAULT_CALIBRATION)
        except ValueError as exc:
            raise InspectorError("--calibration", str(exc)) from None
        self.info = read_json_object(self.root / INFO_PATH)
        self.info_fps = self._info_fps()
        self.robot_type = self.info.get("robot_type")
        self.chunks_size = self._info_int("chunks_size", DEFAULT_CHUNKS_SIZE)
        self.data_path = self._info_template("data_path", V21_DEFAULT_DATA_PATH)
        self.video_path = self._info_template("video_path", V21_DEFAULT_VIDEO_PATH)
        self.modality = read_json_object(self.root / MODALITY_PATH)
        self.action_columns, self.actions_absolute = self._action_slicing()
        self.video_keys = self._video_keys()
        self.cameras = [k.removeprefix(IMAGE_PREFIX) for k in self.video_keys]
        self._lock = threading.Lock()
        self._cache: OrderedDict[tuple, Trajectory] = OrderedDict()

    def __repr__(self) -> str:
        return f"NeuralTrajectories({str(self.root)!r}, {len(self.episodes)} episodes, {self.calibration.spec})"

    # --- meta/ ------------------------------------------------------------------------------------

    def _info_fps(self) -> float:
        value: Any = self.info.get("fps")
        require(isinstance(value, (int, float)) and not isinstance(value, bool) and 0 < value < 1e6,
                self.root / INFO_PATH, f"fps: expected a positive number, found {value!r}")
        return float(value)

    def _info_int(self, key: str, default: int) -> int:
        return whole_number(self.info.get(key, default), self.root / INFO_PATH, key, minimum=1)

    def _info_template(self, key: str, default: str) -> str:
        value = self.info.get(key) or default
        require(isinstance(value, str), self.root / INFO_PATH, f"{key}: expected a path template, found {shown(value)}")
        fields = {**V21_TEMPLATE_FIELDS, **({"video_key": "webcam"} if key == "video_path" else {})}
        problem = template_problem(value, fields)
        require(problem is None, self.root / INFO_PATH, f"{key}: {problem}")
        return value

    def _action_slicing(self) -> tuple[npt.NDArray[np.int64], bool]:
        """The action column of each joint (:data:`JOINT_NAMES` order), by name, and whether the
        modality calls the actions absolute."""
        f = self.root / MODALITY_PATH
        parts = self.modality.get("action")
        require(isinstance(parts, dict), f, "action: expected an object naming each joint's columns")
        assert isinstance(parts, dict)
        columns: dict[str, int] = {}
        absolute = True
        for name, where in parts.items():
            joint = str(name).removeprefix(JOINT_PREFIX)
            if joint not in JOINT_NAMES:
                continue  # another part (none in so100): not drawn
            require(isinstance(where, dict), f, f"action.{name}: expected {{\"start\": i, \"end\": i + 1}} "
                                                f"(one column), found {shown(where)}")
            start = whole_number(where.get("start"), f, f"action.{name}.start", maximum=MAX_ACTION_COLUMN)
            end = whole_number(where.get("end"), f, f"action.{name}.end", maximum=MAX_ACTION_COLUMN + 1)
            require(end == start + 1, f, f"action.{name}: expected {{\"start\": i, \"end\": i + 1}} (one column), "
                                         f"found {shown(where)}")
            columns[joint] = start
            absolute = absolute and where.get("absolute", True) is not False
        missing = [f"{JOINT_PREFIX}{j}" for j in JOINT_NAMES if j not in columns]
        require(not missing, f, f"action: no slice for {missing}; found {sorted(parts)}")
        return np.array([columns[j] for j in JOINT_NAMES], dtype=np.int64), absolute

    def _video_keys(self) -> list[str]:
        features = self.info.get("features")
        keys = []
        if isinstance(features, dict):
            keys = [k for k, v in features.items() if isinstance(v, dict) and v.get("dtype") == "video"]
        video = self.modality.get("video")
        if not keys and isinstance(video, dict):  # the modality names them too
            keys = [str(v["original_key"]) for v in video.values() if isinstance(v, dict) and "original_key" in v]
        return keys

    @cached_property
    def tasks(self) -> dict[int, str]:
        """task_index -> task string (``<DREAM>...``)."""
        f = self.root / TASKS_PATH
        if not f.is_file():
            return {}
        out = {}
        for line_no, row in read_jsonl(f):
            index: Any = row.get("task_index")
            task: Any = row.get("task")
            require(isinstance(index, int) and not isinstance(index, bool) and isinstance(task, str), f,
                    f"line {line_no}: expected an integer 'task_index' and a string 'task', found {shown(row)}")
            out[whole_number(index, f, f"line {line_no}: task_index")] = task
        return out

    @cached_property
    def _episode_map(self) -> dict[int, EpisodeInfo]:
        f = self.root / EPISODES_PATH
        dreams = {t.removeprefix(DREAM_PREFIX) for t in self.tasks.values() if t.startswith(DREAM_PREFIX)}
        out: dict[int, EpisodeInfo] = {}
        for line_no, row in read_jsonl(f):
            index: Any = row.get("episode_index")
            length: Any = row.get("length")
            tasks: Any = row.get("tasks", [])
            index = whole_number(index, f, f"line {line_no}: episode_index")
            length = whole_number(length, f, f"line {line_no}: length", minimum=1)
            require(isinstance(tasks, list) and all(isinstance(t, str) for t in tasks), f,
                    f"line {line_no}: tasks: expected a list of strings, found {tasks!r}")
            require(index not in out, f, f"line {line_no}: episode_index {index} listed twice")
            # episodes.jsonl keeps the task as recorded; tasks.jsonl carries the <DREAM> mark
            shown = [DREAM_PREFIX + t if t in dreams else t for t in tasks]
            chunk = index // self.chunks_size
            data = self._path("data_path", self.data_path, episode_chunk=chunk, episode_index=index)
            videos = {cam: VideoSegment(self._path("video_path", self.video_path, episode_chunk=chunk,
                                                   video_key=key, episode_index=index))
                      for cam, key in zip(self.cameras, self.video_keys)}
            out[index] = EpisodeInfo(index, length, shown, data, videos=videos)
        return dict(sorted(out.items()))

    def _path(self, key: str, template: str, **fields: Any) -> Path:
        try:
            return self.root / template.format(**fields)
        except (KeyError, IndexError, ValueError, AttributeError, TypeError) as exc:
            raise InspectorError(self.root / INFO_PATH, f"{key}: template {template!r} cannot be filled "
                                                        f"from {sorted(fields)} ({exc})") from None

    @property
    def episodes(self) -> list[EpisodeInfo]:
        """Every episode's metadata, by episode_index (``meta/`` only)."""
        return list(self._episode_map.values())

    def episode_indexes(self) -> set[int]:
        return set(self._episode_map)

    def describe_episodes(self) -> str:
        idx = sorted(self._episode_map)
        if not idx:
            return "none"
        return f"{idx[0]}..{idx[-1]}" if idx == list(range(idx[0], idx[-1] + 1)) else f"{len(idx)} episodes"

    def episode_info(self, index: int) -> EpisodeInfo:
        try:
            return self._episode_map[int(index)]
        except KeyError:
            raise InspectorError(self.root / EPISODES_PATH, f"no episode {index}; episodes "
                                                            f"{self.describe_episodes()}") from None

    def is_dream(self, info: EpisodeInfo) -> bool:
        return any(t.startswith(DREAM_PREFIX) for t in info.tasks)

    @cached_property
    def stats_action_mean(self) -> npt.NDArray[np.float64] | None:
        """``stats.json``'s action mean by joint (the embodiment's units), or None."""
        try:
            mean = np.asarray(read_json_object(self.root / STATS_PATH)[ACTION_KEY]["mean"], dtype=np.float64)
            return mean[self.action_columns]
        except (InspectorError, KeyError, TypeError, ValueError, IndexError, OverflowError):  # 10**400
            return None

    # --- the frame rate ---------------------------------------------------------------------------

    @cached_property
    def timing(self) -> tuple[float, str]:
        """(fps, why): the first episode's timestamps' rate, else ``info.json``'s."""
        first = next(iter(self._episode_map.values()), None)
        if first is not None:
            try:
                stamps = _read_column(first.data_file, TIMESTAMP_KEY)
            except InspectorError:
                stamps = None
            rate = _rate(stamps) if stamps is not None else None
            if rate is not None:
                if rates_differ(rate, self.info_fps):
                    return rate, (f"{rate:g} fps from the timestamps; meta/info.json says {self.info_fps:g}: "
                                  "the timestamps are trusted")
                return rate, f"{rate:g} fps from the timestamps (as meta/info.json says)"
        return self.info_fps, f"{self.info_fps:g} fps from meta/info.json (no timestamps to read)"

    @property
    def fps(self) -> float:
        return self.timing[0]

    # --- one episode --------------------------------------------------------------------------------

    def trajectory(self, index: int) -> Trajectory:
        """Episode ``index``, read (kept for the next call while its file is unchanged).

        Raises:
            InspectorError: no such episode; its parquet file missing or malformed (naming the
                file and the column); a non-finite or absurd action.
        """
        info = self.episode_info(index)
        try:
            st = info.data_file.stat()
            key: tuple = (index, st.st_mtime_ns, st.st_size)
        except OSError:
            raise InspectorError(info.data_file, f"data file of episode {index} not found") from None
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        trajectory = self._read(info)
        with self._lock:
            self._cache[key] = trajectory
            while len(self._cache) > 64:
                self._cache.popitem(last=False)
        return trajectory

    def _read(self, info: EpisodeInfo) -> Trajectory:
        f = info.data_file
        table = _read_table(f, [ACTION_KEY, TIMESTAMP_KEY])
        require(table.num_rows == info.length, f, f"episode {info.index} has {table.num_rows} rows, "
                                                 f"meta/episodes.jsonl says length {info.length}")
        raw = _action_columns(table.column(ACTION_KEY), self.action_columns, f)
        bad = ~np.isfinite(raw) | (np.abs(raw) > ABSURD_VALUE)
        if bad.any():
            r, j = (int(i) for i in np.argwhere(bad)[0])
            raise InspectorError(f, f"{ACTION_KEY}: {'non-finite' if not np.isfinite(raw[r, j]) else 'absurd'} "
                                    f"value {raw[r, j]:g} at row {r}, joint {JOINT_PREFIX}{JOINT_NAMES[j]}")
        warnings: list[str] = []
        fps = self.fps
        if TIMESTAMP_KEY in table.column_names:
            stamps = table.column(TIMESTAMP_KEY).to_numpy(zero_copy_only=False).astype(np.float64)
            rate = _rate(stamps)
            if rate is not None and rates_differ(rate, fps):
                warnings.append(f"its timestamps run at {rate:g} fps, the dataset's first episode at {fps:g}")
                fps = rate
        else:
            stamps = np.arange(info.length) / fps
            warnings.append(f"no '{TIMESTAMP_KEY}' column: steps taken at {fps:g} fps")
        actions = self.calibration.apply(raw)
        if not raw.any():  # raw_to_lerobot.py's placeholder, never overwritten by the IDM dump
            warnings.append("every action is 0: the IDM labels were never written (run dump_idm_actions.py)")
        else:
            warnings += self._calibration_warnings(actions)
        videos: dict[str, Path] = {}
        several = len(info.videos) > 1
        for camera, segment in info.videos.items():  # every camera is a view
            video, which = segment.path, f"{camera}'s generated video" if several else "generated video"
            if not video.is_file():
                shown = "the arm alone is shown" if not several else "that view is not shown"
                warnings.append(f"{which} {video} not found: {shown}")
                continue
            n = probe(video).n_frames or len(VideoClip(video).timestamps())  # the header's count, else packets
            if abs(n - info.length) > FRAME_COUNT_SLACK:
                warnings.append(f"the {which} has {n} frames, the episode {info.length} steps")
            videos[camera] = video
        return Trajectory(info.index, info.task, self.is_dream(info), raw, actions, stamps, fps, videos, warnings)

    def _calibration_warnings(self, actions: npt.NDArray[np.float64]) -> list[str]:
        """A calibration that puts most steps past a joint limit is wrong for this data: say so."""
        share = steps_past_limits(actions)
        if share <= WRONG_CALIBRATION_SHARE:
            return []
        other = "none" if self.calibration.name != "none" else DEFAULT_CALIBRATION
        return [f"{share:.0%} of the steps are past a joint limit: the calibration "
                f"({self.calibration.spec}) is probably wrong for this data (try --calibration {other}, or "
                "JOINT=ZERO[:SIGN] overrides)"]

    # --- as a rollout -------------------------------------------------------------------------------

    @cached_property
    def session(self) -> Session:
        """The session the rollouts belong to (in memory: named after the dataset, no GT)."""
        return Session(root=self.root, name=self.root.resolve().name, robot="so101", units=Units("degrees"),
                       joint_names=list(JOINT_NAMES), gt_source={}, model={"name": MODEL_NAME})

    def rollout(self, index: int) -> tuple[Rollout, GroundTruth]:
        """Episode ``index`` as a one-chunk rollout of its IDM actions, the generated video its
        imagined view (frame ``t`` at step ``t``), and its GT: none.

        Raises:
            InspectorError: as :meth:`trajectory`.
        """
        tr = self.trajectory(index)
        args = rollout_args(tr, self)
        arrays: dict[str, Any] = {"actions": ArrayValue(args.pop("actions"))}
        videos = args.pop("videos")
        rollout = TrajectoryRollout(
            root=self.root, tag=rollout_tag(index), units=self.session.units,
            actions_shape=arrays["actions"].shape, horizon=tr.length, views=sorted(videos),
            session=self.session, _arrays=arrays, video_files=dict(videos), **args)  # type: ignore[arg-type]
        gt = GroundTruth(actions=None, offset=0, episode_length=None, source=NO_GT_SOURCE)
        return rollout, gt


NO_GT_SOURCE = "none: a generated (neural) trajectory, no real episode behind it"


def rollout_args(tr: Trajectory, ds: NeuralTrajectories) -> dict[str, Any]:
    """What a rollout of ``tr`` is made of, for :class:`TrajectoryRollout` and for
    :meth:`SessionWriter.add_rollout` alike (so an imported session shows what the app shows)."""
    n = tr.length
    ranges = {j: [round(float(lo), 3), round(float(hi), 3)]
              for j, lo, hi in zip(JOINT_NAMES, tr.actions.min(axis=0), tr.actions.max(axis=0))}
    facts = [
        ["layout", f"{LAYOUT_TITLE}: IDM actions of a generated video, no GT"],
        ["dream", "yes: the task is marked <DREAM> (generated, not recorded)" if tr.dream else "no <DREAM> mark"],
        ["calibration", ds.calibration.describe()],
        ["frame rate", ds.timing[1] if not rates_differ(tr.fps, ds.fps) else f"{tr.fps:g} fps from this episode's timestamps"],
        ["joint ranges (deg, gripper 0..100)", ", ".join(f"{j} {lo:.1f}..{hi:.1f}" for j, (lo, hi) in ranges.items())],
        *[["warning", w] for w in tr.warnings],
    ]
    return dict(
        kind="single_chunk", prompt=tr.task, episode_index=None, start_frame=0, fps=tr.fps,
        executed_per_chunk=n, frames_per_chunk=n, actions=tr.actions[None],
        videos=dict(tr.videos),
        extra={"source": {"format": LAYOUT, "path": str(ds.root.resolve()), "episode_index": tr.index,
                          "dream": tr.dream, "calibration": ds.calibration.to_json(), "fps": tr.fps,
                          "info_fps": ds.info_fps, "raw_range": {j: [float(lo), float(hi)] for j, lo, hi in
                                                                 zip(JOINT_NAMES, tr.raw.min(0), tr.raw.max(0))}},
               "joint_range": ranges, "warnings": list(tr.warnings), "facts": facts},
    )


def steps_past_limits(actions: npt.ArrayLike, margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG) -> float:
    """Share of the steps of (T, 6) URDF-zero degrees with any joint past its URDF limit (+margin)."""
    a = np.asarray(actions, dtype=np.float64)
    if a.size == 0:
        return 0.0
    units = Units("degrees")
    limits, margin = limits_in_units(units), limit_margin_in_units(units, margin_deg)
    past = (a < limits[:, 0] - margin) | (a > limits[:, 1] + margin)
    return float(past.any(axis=1).mean())


# ----------------------------------------------------------------------------------------------
# helpers


def _read_table(f: Path, columns: list[str]) -> Any:
    """The parquet file's ``columns`` that it has (``action`` is required)."""
    import pyarrow.parquet as pq

    if not f.is_file():
        raise InspectorError(f, "data file not found")
    try:
        with pq.ParquetFile(f) as pf:  # not read_table: its dataset machinery costs more than these small files
            names = pf.schema_arrow.names
            require(ACTION_KEY in names, f, f"no '{ACTION_KEY}' column; columns: {names}")
            return pf.read(columns=[c for c in columns if c in names])
    except InspectorError:
        raise
    except Exception as exc:
        raise InspectorError(f, f"cannot read parquet ({type(exc).__name__}: {exc})") from None


def _read_column(f: Path, column: str) -> npt.NDArray[np.float64] | None:
    import pyarrow.parquet as pq

    try:
        if column not in pq.read_schema(f).names:
            return None
        return pq.read_table(f, columns=[column]).column(column).to_numpy(zero_copy_only=False).astype(np.float64)
    except Exception:
        return None


def _action_columns(column: Any, columns: npt.NDArray[np.int64], f: Path) -> npt.NDArray[np.float64]:
    """(T, 6) the joints' columns of a list column whose rows may be wider (info.json's 44)."""
    import pyarrow as pa

    col = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if not (pa.types.is_list(col.type) or pa.types.is_large_list(col.type) or pa.types.is_fixed_size_list(col.type)):
        raise InspectorError(f, f"{ACTION_KEY}: expected a list of numbers per row, found {col.type}")
    require(col.null_count == 0, f, f"{ACTION_KEY}: {col.null_count} null row(s)")
    if pa.types.is_fixed_size_list(col.type):
        widths = np.full(len(col), col.type.list_size, dtype=np.int64)
        offsets = np.arange(len(col) + 1, dtype=np.int64) * col.type.list_size
    else:
        offsets = col.offsets.to_numpy(zero_copy_only=False).astype(np.int64)
        widths = np.diff(offsets)
        offsets = offsets - offsets[0]
    need = int(columns.max()) + 1
    short = np.flatnonzero(widths < need)
    if short.size:
        r = int(short[0])
        raise InspectorError(f, f"{ACTION_KEY}: row {r} has {int(widths[r])} values; meta/modality.json puts "
                                f"{JOINT_PREFIX}{JOINT_NAMES[int(np.argmax(columns))]} at column {int(columns.max())}")
    try:
        flat = col.flatten().to_numpy(zero_copy_only=False).astype(np.float64)
    except (TypeError, ValueError, pa.ArrowException) as exc:
        raise InspectorError(f, f"{ACTION_KEY}: values are not numbers ({exc})") from None
    return flat[offsets[:-1, None] + columns[None, :]]


def _rate(stamps: npt.NDArray[np.float64] | None) -> float | None:
    """Steps per second from timestamps (their median step), or None when they say nothing."""
    if stamps is None or stamps.size < 2 or not np.isfinite(stamps).all():
        return None
    step = float(np.median(np.diff(stamps)))
    return round(1.0 / step, 6) if step > 0 else None


def rates_differ(a: float, b: float) -> bool:
    return abs(a - b) > FPS_TOLERANCE * max(a, b)
