"""Small GR00T-Dreams IDM_dump outputs, written as NVIDIA/GR00T-Dreams writes them (pyarrow, PyAV).

What ``IDM_dump/raw_to_lerobot.py --cosmos_predict2`` then ``IDM_dump/dump_idm_actions.py`` leave for
the ``so100`` embodiment: ``meta/info.json`` without codebase_version, fps 8 and 44-wide motor_i
features; ``episodes.jsonl`` with ``video_id``; ``tasks.jsonl`` with every task prefixed ``<DREAM>``
(episodes.jsonl keeps the task as recorded); the embodiment's ``modality.json`` and ``stats.json``;
per episode a parquet file whose ``observation.state`` is 44 zeros, whose ``action`` the dump
overwrote with the 6 IDM values (float64), timestamps ``i / 16``, no ``frame_index``; and the
generated 256x256 video under ``videos/chunk-000/observation.images.webcam/``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from inspector.data.video import encode_h264

SO100_JOINTS = ["main_shoulder_pan", "main_shoulder_lift", "main_elbow_flex", "main_wrist_flex",
                "main_wrist_roll", "main_gripper"]
# IDM_dump/global_metadata/so100/stats.json, action mean and std (the embodiment's legacy calibration)
SO100_ACTION_MEAN = [113.70831298828125, 115.85425567626953, 108.63793182373047, 73.76486206054688,
                     -42.69032287597656, 16.021728515625]
SO100_ACTION_STD = [36.58, 33.65, 25.03, 22.34, 37.91, 14.06]
VIDEO_KEY = "observation.images.webcam"
TIMESTAMP_FPS = 16  # cosmos_predict2: i / 16
INFO_FPS = 8  # what info.json says with --cosmos_predict2


def modality(video_keys: tuple[str, ...] = (VIDEO_KEY,)) -> dict:
    """IDM_dump/global_metadata/so100/modality.json (one entry per camera)."""
    return {
        "state": {j: {"start": i, "end": i + 1} for i, j in enumerate(SO100_JOINTS)},
        "action": {j: {"start": i, "end": i + 1, "absolute": False} for i, j in enumerate(SO100_JOINTS)},
        "video": {k.removeprefix("observation.images."): {"original_key": k} for k in video_keys},
        "annotation": {"human.task_description": {"original_key": "task_index"}},
    }


def stats() -> dict:
    mean, std = np.array(SO100_ACTION_MEAN), np.array(SO100_ACTION_STD)
    vec = {"mean": mean.tolist(), "std": std.tolist(), "min": (mean - 2 * std).tolist(),
           "max": (mean + 2 * std).tolist(), "q01": (mean - 2 * std).tolist(), "q99": (mean + 2 * std).tolist()}
    return {"action": vec, "observation.state": vec}


def idm_actions(n: int, seed: int) -> np.ndarray:
    """(n, 6) plausible IDM labels around the so100 stats' means (legacy calibration)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n)[:, None]
    swing = np.sin(2 * np.pi * t + rng.uniform(0, 6, 6)) * np.array([20, 15, 15, 10, 20, 10])
    return np.array(SO100_ACTION_MEAN) + swing


def frames(n: int, seed: int, camera: int = 0) -> np.ndarray:
    """(n, 256, 256, 3): frame i is a block at a place and colour of its own, so frames differ
    (and each camera's blue differs: 60 + 80 c)."""
    out = np.zeros((n, 256, 256, 3), np.uint8)
    for i in range(n):
        out[i, :, :] = (40 + 3 * i) % 256, (90 + 7 * seed) % 256, 60 + 80 * camera
        x = (i * 9) % 200
        out[i, 100:160, x:x + 56] = 250, 250, 250
    return out


def write_groot_dreams(root: Path, episodes: list[tuple[str, int]], *, actions: list[np.ndarray] | None = None,
                       video: bool = True, video_frames: list[int] | None = None,
                       video_keys: tuple[str, ...] = (VIDEO_KEY,)) -> Path:
    """A dump at ``root`` with one episode per (task, length); ``actions`` overrides each episode's
    (T, 6) IDM labels; ``video_frames`` writes videos of other lengths than the episodes';
    ``video_keys`` the cameras, one generated video each."""
    meta = root / "meta"
    meta.mkdir(parents=True)
    tasks: dict[str, int] = {}
    total = 0
    with open(meta / "episodes.jsonl", "w") as f:
        for e, (task, length) in enumerate(episodes):
            tasks.setdefault(task, len(tasks))
            f.write(json.dumps({"episode_index": e, "tasks": [task], "length": length,
                                "video_id": f"clip_{e:04d}"}) + "\n")
    with open(meta / "tasks.jsonl", "w") as f:
        for task, i in tasks.items():
            f.write(json.dumps({"task_index": i, "task": f"<DREAM>{task}"}) + "\n")
    (meta / "modality.json").write_text(json.dumps(modality(video_keys), indent=4))
    (meta / "stats.json").write_text(json.dumps(stats(), indent=4))
    info = {
        "robot_type": "dream", "total_episodes": len(episodes), "total_frames": sum(n for _, n in episodes),
        "total_tasks": len(tasks), "total_videos": len(video_keys), "chunks_size": 1000, "total_chunks": 1, "fps": INFO_FPS,
        "data_path": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
        "video_path": "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4",
        "features": {
            "observation.state": {"dtype": "float32", "shape": [44], "names": [f"motor_{i}" for i in range(44)]},
            "action": {"dtype": "float32", "shape": [44], "names": [f"motor_{i}" for i in range(44)]},
            "annotation.human.task_description": {"dtype": "int64", "shape": [1]},
            **{key: {"dtype": "video", "shape": [256, 256, 3], "names": ["height", "width", "channel"],
                     "video_info": {"video.fps": 16.0, "video.codec": "h264", "video.pix_fmt": "yuv420p",
                                    "video.is_depth_map": False}} for key in video_keys},
        },
    }
    (meta / "info.json").write_text(json.dumps(info, indent=4))
    data_dir = root / "data" / "chunk-000"
    data_dir.mkdir(parents=True)
    for key in video_keys:
        (root / "videos" / "chunk-000" / key).mkdir(parents=True)
    for e, (task, n) in enumerate(episodes):
        act = actions[e] if actions is not None else idm_actions(n, e)
        table = pa.table({
            "observation.state": pa.array([np.zeros(44, np.float32)] * n, pa.list_(pa.float32())),
            "action": pa.array([np.asarray(a, np.float64) for a in act], pa.list_(pa.float64())),
            "timestamp": pa.array([i / TIMESTAMP_FPS for i in range(n)], pa.float64()),
            "episode_index": pa.array([e] * n, pa.int64()),
            "index": pa.array(np.arange(total, total + n), pa.int64()),
            "task_index": pa.array([tasks[task]] * n, pa.int64()),
            "annotation.human.task_description": pa.array([[tasks[task]]] * n, pa.list_(pa.int64())),
        })
        pq.write_table(table, data_dir / f"episode_{e:06d}.parquet")
        total += n
        if video:
            count = video_frames[e] if video_frames is not None else n
            for c, key in enumerate(video_keys):
                encode_h264(root / "videos" / "chunk-000" / key / f"episode_{e:06d}.mp4", frames(count, e, c),
                            TIMESTAMP_FPS)
    return root
