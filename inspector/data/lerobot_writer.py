"""Write a small LeRobot **v3.0** dataset in the layout LeRobot 0.4 writes (no ``lerobot`` import).

Used for the bundled demo's ground truth and for tests; the result opens with
:class:`inspector.data.lerobot_dataset.LeRobotDataset` and with LeRobot itself::

    <root>/
      meta/info.json                       codebase_version "v3.0", features (video info incl.)
      meta/stats.json                      per feature: min, max, mean, std, count
      meta/tasks.parquet                   task_index + task string as the pandas index
      meta/episodes/chunk-000/file-000.parquet   one row per episode
      data/chunk-000/file-000.parquet      all episodes' rows, one row group per episode
      videos/observation.images.<camera>/chunk-000/file-000.mp4   all episodes back to back (H.264)

Everything goes into one data file and one video file per camera (LeRobot rolls over to a new
file past ``data_files_size_in_mb`` / ``video_files_size_in_mb``; demo-sized datasets never reach that).

Usage::

    write_lerobot_dataset("out/so101_demo", [EpisodeData("Pick the red cube", state, action,
                                                          {"front": frames})], fps=30)
"""

from __future__ import annotations

import os
import shutil
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import InspectorError
from ..schema import json_text
from ..units import JOINT_NAMES, Units
from .lerobot_format import (
    ACTION_KEY,
    CODEBASE_VERSION_KEY,
    DEFAULT_CHUNKS_SIZE,
    EP_DATA_CHUNK,
    EP_DATA_FILE,
    EP_FROM_INDEX,
    EP_LENGTH,
    EP_TASKS,
    EP_TO_INDEX,
    EPISODE_INDEX_KEY,
    FRAME_INDEX_KEY,
    IMAGE_PREFIX,
    INDEX_KEY,
    INFO_PATH,
    STATE_KEY,
    TASK_INDEX_KEY,
    TIMESTAMP_KEY,
    UNITS_KEY,
    V30,
    V30_DEFAULT_DATA_PATH,
    V30_DEFAULT_VIDEO_PATH,
    V30_EPISODES_DIR,
    V30_TASKS_PATH,
    ep_video_column,
)
from .video import encode_h264

STATS_PATH = "meta/stats.json"
# LeRobot 0.4's defaults, recorded in info.json.
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
VIDEO_CODEC = "h264"
JOINT_FEATURE_NAMES = [f"{j}.pos" for j in JOINT_NAMES]


@dataclass
class EpisodeData:
    """One episode to write.

    Attributes:
        task: the task / prompt string.
        state: (T, 6) ``observation.state`` in :data:`JOINT_NAMES` order, dataset units
            (arm degrees, gripper 0..100).
        action: (T, 6) ``action``, same order and units.
        frames: camera name (e.g. ``"front"``) -> (T, H, W, 3) uint8 RGB.
    """

    task: str
    state: npt.NDArray[np.floating]
    action: npt.NDArray[np.floating]
    frames: dict[str, npt.NDArray[np.uint8]] = field(default_factory=dict)
    # more per-frame scalar columns, e.g. ``{"next.reward": (T,) float32, "next.success": (T,) bool}``
    # (what ``lerobot-eval --eval.recording`` adds); every episode names the same ones
    columns: dict[str, npt.NDArray[Any]] = field(default_factory=dict)


def write_lerobot_dataset(root: str | Path, episodes: list[EpisodeData], fps: int = 30,
                          robot_type: str = "so101_follower", *, units: Units | None = Units(),
                          overwrite: bool = False, crf: int = 23, joint_names: bool = True,
                          keyframe_every: int | None = None) -> Path:
    """Write ``episodes`` as a LeRobot v3.0 dataset at ``root``, atomically.

    The dataset is built in a temporary directory next to ``root`` and renamed into place when
    complete, so a failure never leaves a half-written dataset or damages an existing one.

    Args:
        root: the dataset directory to create.
        episodes: at least one episode; every episode has the same cameras, and each camera the
            same frame size in every episode.
        fps: frames per second of state, action and video.
        robot_type: ``info.json`` robot_type.
        units: joint units stated in ``info.json`` (key ``units``, ours; LeRobot ignores it);
            None leaves them unstated, as LeRobot itself does.
        overwrite: replace an existing non-empty ``root`` (only once the new one is complete).
        crf: H.264 quality (lower is better, 18 near-lossless).
        joint_names: name the six joints in ``features`` (False writes ``names: null``, as
            ``lerobot-eval`` records them).
        keyframe_every: frames at most between keyframes (None: x264's 250; LeRobot writes 2, so
            any frame decodes on its own quickly).

    Returns:
        ``root`` as a Path.

    Raises:
        InspectorError: ``root`` exists and is not empty (without ``overwrite``), or an episode's
            arrays have the wrong shape, non-finite values, or cameras that do not match.
    """
    root = Path(root).expanduser()
    if root.exists() and not root.is_dir():
        raise InspectorError(root, "exists and is not a directory")
    if root.is_dir() and any(root.iterdir()) and not overwrite:
        raise InspectorError(root, "already exists and is not empty (pass overwrite=True to replace it)")
    cameras = _validate(root, episodes)

    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = root.parent / f".{root.name}.tmp-{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    try:
        _write_all(tmp, episodes, cameras, fps, robot_type, units, crf, joint_names, keyframe_every)
        _replace_dir(tmp, root)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return root


# ==================================================================================================
# validation
# ==================================================================================================

def _validate(root: Path, episodes: list[EpisodeData]) -> list[str]:
    """Check shapes and values; returns the camera names (the same for every episode)."""
    if not episodes:
        raise InspectorError(root, "no episodes to write")
    cameras = list(episodes[0].frames)
    sizes: dict[str, tuple[int, ...]] = {}
    for i, ep in enumerate(episodes):
        for name in ("state", "action"):
            a = np.asarray(getattr(ep, name))
            if a.ndim != 2 or a.shape[1] != len(JOINT_NAMES) or a.shape[0] < 1:
                raise InspectorError(root, f"episode {i}: {name} has shape {a.shape}, expected (T, 6)")
            if not np.isfinite(a).all():
                r, j = np.argwhere(~np.isfinite(a))[0]
                raise InspectorError(root, f"episode {i}: {name} is non-finite at row {r}, "
                                           f"joint {JOINT_NAMES[j]}")
        T = len(ep.state)
        if len(ep.action) != T:
            raise InspectorError(root, f"episode {i}: action has {len(ep.action)} rows, state {T}")
        if list(ep.frames) != cameras:
            raise InspectorError(root, f"episode {i}: cameras {list(ep.frames)}, episode 0 has {cameras}")
        for cam, frames in ep.frames.items():
            if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) != T:
                raise InspectorError(root, f"episode {i}: frames[{cam!r}] is {frames.dtype} {frames.shape}, "
                                           f"expected uint8 ({T}, H, W, 3)")
            if sizes.setdefault(cam, frames.shape[1:3]) != frames.shape[1:3]:
                raise InspectorError(root, f"episode {i}: frames[{cam!r}] are {frames.shape[1:3]}, "
                                           f"episode 0's are {sizes[cam]}")
    return cameras


# ==================================================================================================
# writing
# ==================================================================================================

def _write_all(out: Path, episodes: list[EpisodeData], cameras: list[str], fps: int, robot_type: str,
               units: Units | None, crf: int, joint_names: bool = True, keyframe_every: int | None = None) -> None:
    tasks: list[str] = []  # task_index order = order of first appearance
    for ep in episodes:
        if ep.task not in tasks:
            tasks.append(ep.task)
    lengths = [len(ep.state) for ep in episodes]
    starts = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)  # global index of each episode

    # Videos first: their encoded size goes into info.json (odd sizes are padded to even).
    video_shapes: dict[str, tuple[int, int]] = {}
    for cam in cameras:
        frames = np.concatenate([ep.frames[cam] for ep in episodes])
        path = out / V30_DEFAULT_VIDEO_PATH.format(video_key=IMAGE_PREFIX + cam, chunk_index=0, file_index=0)
        encode_h264(path, frames, fps, crf=crf, keyframe_every=keyframe_every)
        h, w = frames.shape[1:3]
        video_shapes[cam] = (h + h % 2, w + w % 2)

    features = _features(cameras, video_shapes, fps)
    if not joint_names:
        for key in (ACTION_KEY, STATE_KEY):
            features[key]["names"] = None
    for name, values in episodes[0].columns.items():
        features[name] = {"dtype": "bool" if np.asarray(values).dtype == bool else "float32", "shape": [1],
                          "names": None}
    per_episode_stats = [_episode_stats(ep, e, int(starts[e]), tasks.index(ep.task), cameras, fps)
                         for e, ep in enumerate(episodes)]

    _write_data(out / V30_DEFAULT_DATA_PATH.format(chunk_index=0, file_index=0), episodes, starts, tasks, fps)
    _write_episodes(out / V30_EPISODES_DIR / "chunk-000" / "file-000.parquet", episodes, starts, tasks,
                    cameras, fps, per_episode_stats)
    _write_tasks(out / V30_TASKS_PATH, tasks)
    _write_json(out / STATS_PATH, _aggregate_stats(per_episode_stats))

    info: dict[str, Any] = {
        CODEBASE_VERSION_KEY: V30,
        "robot_type": robot_type,
        "total_episodes": len(episodes),
        "total_frames": int(starts[-1]),
        "total_tasks": len(tasks),
        "chunks_size": DEFAULT_CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB,
        "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB,
        "fps": fps,
        "splits": {"train": f"0:{len(episodes)}"},
        "data_path": V30_DEFAULT_DATA_PATH,
        "video_path": V30_DEFAULT_VIDEO_PATH if cameras else None,
        "features": features,
    }
    if units is not None:
        info[UNITS_KEY] = units.to_json()
    _write_json(out / INFO_PATH, info)


def _features(cameras: list[str], video_shapes: dict[str, tuple[int, int]], fps: int) -> dict[str, Any]:
    """info.json ``features``, in the order and form LeRobot 0.4 writes them."""
    joints = {"dtype": "float32", "shape": [len(JOINT_NAMES)], "names": JOINT_FEATURE_NAMES}
    features: dict[str, Any] = {ACTION_KEY: dict(joints), STATE_KEY: dict(joints)}
    for cam in cameras:
        h, w = video_shapes[cam]
        features[IMAGE_PREFIX + cam] = {
            "dtype": "video",
            "shape": [h, w, 3],
            "names": ["height", "width", "channels"],
            "info": {"video.height": h, "video.width": w, "video.codec": VIDEO_CODEC,
                     "video.pix_fmt": "yuv420p", "video.is_depth_map": False, "video.fps": fps,
                     "video.channels": 3, "has_audio": False},
        }
    for key, dtype in ((TIMESTAMP_KEY, "float32"), (FRAME_INDEX_KEY, "int64"), (EPISODE_INDEX_KEY, "int64"),
                       (INDEX_KEY, "int64"), (TASK_INDEX_KEY, "int64")):
        features[key] = {"dtype": dtype, "shape": [1], "names": None}
    return features


# The `datasets` library's schema note that LeRobot's data files carry (LeRobot loads them through it).
_HF_JOINTS = {"feature": {"dtype": "float32", "_type": "Value"}, "length": len(JOINT_NAMES), "_type": "List"}
_HF_FEATURES = {
    ACTION_KEY: _HF_JOINTS,
    STATE_KEY: _HF_JOINTS,
    TIMESTAMP_KEY: {"dtype": "float32", "_type": "Value"},
    FRAME_INDEX_KEY: {"dtype": "int64", "_type": "Value"},
    EPISODE_INDEX_KEY: {"dtype": "int64", "_type": "Value"},
    INDEX_KEY: {"dtype": "int64", "_type": "Value"},
    TASK_INDEX_KEY: {"dtype": "int64", "_type": "Value"},
}


def _write_data(path: Path, episodes: list[EpisodeData], starts: npt.NDArray[np.int64], tasks: list[str],
                fps: int) -> None:
    """All rows in one file, one row group per episode (so a filtered read skips the others)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    joints_type = pa.list_(pa.float32(), len(JOINT_NAMES))
    extra = {name: pa.bool_() if np.asarray(v).dtype == bool else pa.float32()
             for name, v in episodes[0].columns.items()}
    schema = pa.schema([(ACTION_KEY, joints_type), (STATE_KEY, joints_type), (TIMESTAMP_KEY, pa.float32()),
                        (FRAME_INDEX_KEY, pa.int64()), (EPISODE_INDEX_KEY, pa.int64()),
                        (INDEX_KEY, pa.int64()), (TASK_INDEX_KEY, pa.int64()), *extra.items()],
                       metadata={"huggingface": json_text({"info": {"features": _HF_FEATURES}})})
    path.parent.mkdir(parents=True, exist_ok=True)
    with pq.ParquetWriter(path, schema) as writer:
        for e, ep in enumerate(episodes):
            T = len(ep.state)
            frame_index = np.arange(T, dtype=np.int64)
            writer.write_table(pa.table({
                ACTION_KEY: _joints_array(ep.action, joints_type),
                STATE_KEY: _joints_array(ep.state, joints_type),
                TIMESTAMP_KEY: (frame_index / fps).astype(np.float32),
                FRAME_INDEX_KEY: frame_index,
                EPISODE_INDEX_KEY: np.full(T, e, dtype=np.int64),
                INDEX_KEY: starts[e] + frame_index,
                TASK_INDEX_KEY: np.full(T, tasks.index(ep.task), dtype=np.int64),
                **{name: pa.array(np.asarray(ep.columns[name]).reshape(T), t) for name, t in extra.items()},
            }, schema=schema))


def _joints_array(values: npt.ArrayLike, joints_type: Any) -> Any:
    import pyarrow as pa

    flat = pa.array(np.asarray(values, dtype=np.float32).reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, type=joints_type)


def _write_episodes(path: Path, episodes: list[EpisodeData], starts: npt.NDArray[np.int64], tasks: list[str],
                    cameras: list[str], fps: int, stats: list[dict[str, dict[str, Any]]]) -> None:
    """meta/episodes: the columns LeRobot 0.4 writes (stats limited to min/max/mean/std/count)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    n = len(episodes)
    lengths = [len(ep.state) for ep in episodes]
    cols: dict[str, Any] = {
        EPISODE_INDEX_KEY: pa.array(range(n), pa.int64()),
        EP_TASKS: pa.array([[ep.task] for ep in episodes], pa.list_(pa.string())),
        EP_LENGTH: pa.array(lengths, pa.int64()),
        EP_DATA_CHUNK: pa.array([0] * n, pa.int64()),
        EP_DATA_FILE: pa.array([0] * n, pa.int64()),
        EP_FROM_INDEX: pa.array(starts[:-1], pa.int64()),
        EP_TO_INDEX: pa.array(starts[1:], pa.int64()),
    }
    for cam in cameras:
        key = IMAGE_PREFIX + cam
        # Episodes sit back to back in the file: episode e spans [start_e, end_e) / fps seconds.
        cols[ep_video_column(key, "chunk_index")] = pa.array([0] * n, pa.int64())
        cols[ep_video_column(key, "file_index")] = pa.array([0] * n, pa.int64())
        cols[ep_video_column(key, "from_timestamp")] = pa.array(starts[:-1] / fps, pa.float64())
        cols[ep_video_column(key, "to_timestamp")] = pa.array(starts[1:] / fps, pa.float64())
    for feature in stats[0]:
        for stat in ("min", "max", "mean", "std", "count"):
            cols[f"stats/{feature}/{stat}"] = pa.array([s[feature][stat] for s in stats])
    cols["meta/episodes/chunk_index"] = pa.array([0] * n, pa.int64())
    cols["meta/episodes/file_index"] = pa.array([0] * n, pa.int64())
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.table(cols), path)


def _write_tasks(path: Path, tasks: list[str]) -> None:
    """meta/tasks.parquet as LeRobot writes it: a pandas DataFrame indexed by the task string.

    pandas is not a dependency, so the pandas schema note that makes ``pd.read_parquet`` restore
    the index is written by hand (the same as in LeRobot's own files).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [{"name": None, "field_name": None, "pandas_type": "unicode",
                            "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": TASK_INDEX_KEY, "field_name": TASK_INDEX_KEY, "pandas_type": "int64",
             "numpy_type": "int64", "metadata": None},
            {"name": None, "field_name": "__index_level_0__", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": None},
        ],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
    }
    schema = pa.schema([(TASK_INDEX_KEY, pa.int64()), ("__index_level_0__", pa.large_string())],
                       metadata={"pandas": json_text(pandas_meta)})
    table = pa.table({TASK_INDEX_KEY: list(range(len(tasks))), "__index_level_0__": tasks}, schema=schema)
    pq.write_table(table, path)


# ==================================================================================================
# stats
# ==================================================================================================

def _vector_stats(values: npt.ArrayLike) -> dict[str, Any]:
    """(N, D) or (N,) -> per-dimension min/max/mean/std and count [N], as JSON-able lists."""
    v = np.asarray(values)
    v = v.reshape(len(v), -1)
    # min/max keep the column's type (ints stay ints, as in LeRobot's files); mean/std are floats
    return {"min": v.min(0).tolist(), "max": v.max(0).tolist(), "mean": v.mean(0, dtype=np.float64).tolist(),
            "std": v.std(0, dtype=np.float64).tolist(), "count": [len(v)]}


def _image_stats(frames: npt.NDArray[np.uint8]) -> dict[str, Any]:
    """Per-channel stats of (T, H, W, 3) uint8 frames scaled to [0, 1], shaped (3, 1, 1) like
    LeRobot's. Accumulated frame by frame so a long episode is never converted to float at once."""
    total = np.zeros(3)
    total_sq = np.zeros(3)
    for frame in frames:
        f = frame.reshape(-1, 3).astype(np.float64) / 255.0
        total += f.sum(0)
        total_sq += (f * f).sum(0)
    n = frames.shape[0] * frames.shape[1] * frames.shape[2]
    mean = total / n
    std = np.sqrt(np.maximum(total_sq / n - mean * mean, 0.0))
    lo = frames.min(axis=(0, 1, 2)) / 255.0
    hi = frames.max(axis=(0, 1, 2)) / 255.0

    def c11(x: npt.NDArray[np.float64]) -> list[list[list[float]]]:
        return [[[float(c)]] for c in x]

    return {"min": c11(lo), "max": c11(hi), "mean": c11(mean), "std": c11(std), "count": [len(frames)]}


def _episode_stats(ep: EpisodeData, e: int, start: int, task_index: int, cameras: list[str], fps: int
                   ) -> dict[str, dict[str, Any]]:
    """Stats of one episode, per feature, in info.json's feature order."""
    T = len(ep.state)
    frame_index = np.arange(T)
    stats = {
        ACTION_KEY: _vector_stats(np.asarray(ep.action, np.float32)),
        STATE_KEY: _vector_stats(np.asarray(ep.state, np.float32)),
    }
    for cam in cameras:
        stats[IMAGE_PREFIX + cam] = _image_stats(ep.frames[cam])
    stats[TIMESTAMP_KEY] = _vector_stats((frame_index / fps).astype(np.float32))
    stats[FRAME_INDEX_KEY] = _vector_stats(frame_index)
    stats[EPISODE_INDEX_KEY] = _vector_stats(np.full(T, e))
    stats[INDEX_KEY] = _vector_stats(start + frame_index)
    stats[TASK_INDEX_KEY] = _vector_stats(np.full(T, task_index))
    return stats


def _aggregate_stats(per_episode: list[dict[str, dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    """Dataset stats from episode stats: count-weighted mean and pooled std (LeRobot's formula)."""
    out: dict[str, dict[str, Any]] = {}
    for feature in per_episode[0]:
        parts = [s[feature] for s in per_episode]
        counts = np.array([p["count"][0] for p in parts], dtype=np.float64)
        shape = np.asarray(parts[0]["mean"]).shape
        w = counts.reshape((-1,) + (1,) * len(shape))
        means = np.array([p["mean"] for p in parts])
        stds = np.array([p["std"] for p in parts])
        mean = (means * w).sum(0) / counts.sum()
        var = ((stds ** 2 + (means - mean) ** 2) * w).sum(0) / counts.sum()
        out[feature] = {"min": np.min([p["min"] for p in parts], axis=0).tolist(),
                        "max": np.max([p["max"] for p in parts], axis=0).tolist(),
                        "mean": mean.tolist(), "std": np.sqrt(var).tolist(), "count": [int(counts.sum())]}
    return out


# ==================================================================================================
# files
# ==================================================================================================

def _write_json(path: Path, obj: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json_text(obj, indent=4) + "\n")


def _replace_dir(new: Path, root: Path) -> None:
    """Move the complete ``new`` directory to ``root``; an old ``root`` is removed only after."""
    if root.is_dir() and any(root.iterdir()):
        old = root.parent / f".{root.name}.old-{uuid.uuid4().hex[:8]}"
        os.replace(root, old)
        try:
            os.replace(new, root)
        except BaseException:
            os.replace(old, root)  # put the good one back
            raise
        shutil.rmtree(old, ignore_errors=True)
    else:
        if root.is_dir():
            root.rmdir()  # empty: rename cannot target a directory on every platform
        os.replace(new, root)
