"""What the server is sent for one start frame: camera images under the server's keys, the joint
state split into ``joint_position`` / ``gripper_position``, the prompt.

Camera keys. The handshake gives a number of cameras, not their names, so by default the dataset's
cameras go to the DreamZero / RoboArena keys (which the SO-101 servers accept as aliases): a
camera named like a wrist camera (wrist, gripper, hand) to ``observation/wrist_image_left``, the
others in the dataset's order to ``observation/exterior_image_{i}_left`` (i from 0), and any key
still free to the cameras left over. ``--camera KEY=NAME`` sets a key (one of those, or any other
the server reads, such as ``observation/overhead``).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..data.lerobot_dataset import Episode
from ..data.video import RgbConverter
from ..errors import InspectorError
from ..units import JOINT_NAMES
from .client import ServerConfig

KEY_PREFIX = "observation/"
WRIST_KEY = "observation/wrist_image_left"
JOINT_POSITION_KEY = "observation/joint_position"
GRIPPER_POSITION_KEY = "observation/gripper_position"
WRIST_WORDS = ("wrist", "gripper", "hand")


def exterior_key(i: int, side: str = "left") -> str:
    return f"observation/exterior_image_{i}_{side}"


def server_camera_keys(config: ServerConfig) -> list[str]:
    """The image keys the server's config asks for, in the protocol's order."""
    sides = ("left", "right") if config.needs_stereo_camera else ("left",)
    keys = [exterior_key(i, side) for i in range(config.n_external_cameras) for side in sides]
    if config.needs_wrist_camera:
        keys += [f"observation/wrist_image_{side}" for side in sides]
    return keys


def full_key(key: str) -> str:
    """``overhead`` -> ``observation/overhead``; a key with a ``/`` stays as given."""
    return key if "/" in key else KEY_PREFIX + key


def is_wrist_camera(name: str) -> bool:
    return any(word in name.lower() for word in WRIST_WORDS)


def map_cameras(config: ServerConfig, cameras: list[str], overrides: Mapping[str, str],
                dataset: str, server: str) -> dict[str, str]:
    """Server image key -> dataset camera.

    Args:
        config: the server's config.
        cameras: the dataset's cameras, in its order.
        overrides: ``--camera`` KEY -> NAME (a KEY without ``/`` gets ``observation/``).
        dataset, server: named in errors.

    Raises:
        InspectorError: a ``--camera`` NAME the dataset lacks, or a key the server needs and no
            camera is left for (naming both sides' counts).
    """
    overrides = {full_key(k): v for k, v in overrides.items()}
    for key, name in overrides.items():
        if name not in cameras:
            raise InspectorError("--camera", f"{key}={name}: the dataset has no camera {name!r}; cameras: {cameras}")
    needed = server_camera_keys(config)
    # a camera set for one of the server's keys is taken; one sent under an extra key is not
    free = [c for c in cameras if c not in {v for k, v in overrides.items() if k in needed}]
    mapping: dict[str, str] = {}
    wrist_keys = [k for k in needed if "wrist" in k and k not in overrides]
    for key in wrist_keys:  # a wrist camera to each wrist key, by name
        found = next((c for c in free if is_wrist_camera(c)), None)
        if found is not None:
            mapping[key] = found
            free.remove(found)
    for key in needed:  # the others in order, non-wrist cameras first
        if key in mapping or key in overrides:
            continue
        found = next((c for c in free if not is_wrist_camera(c)), free[0] if free else None)
        if found is not None:
            mapping[key] = found
            free.remove(found)
    mapping.update(overrides)
    missing = [k for k in needed if k not in mapping]
    if missing:
        raise InspectorError(dataset, f"has {len(cameras)} camera(s) {cameras}; the server at {server} needs "
                                      f"{len(needed)} ({', '.join(needed)}); {', '.join(missing)} left without "
                                      "one (map it with --camera KEY=NAME)")
    return {k: mapping[k] for k in [*needed, *(k for k in mapping if k not in needed)]}


class FrameReader:
    """Frames of a dataset's cameras at any episode frame, decoded with as little work as the
    file allows: one open container per video file, a seek to the keyframe before the frame
    asked for unless it lies a little ahead of the last one read (then decoding goes on), and
    the scaling done by the decoder's converter.

    Args:
        size: (width, height) every frame is scaled to, or None for the file's size.
    """

    # Decode on rather than seek when the frame wanted lies at most this far ahead [s].
    DECODE_AHEAD_S = 0.5
    # Video files kept open, most recently used (a v2.1 dataset has one per episode and camera).
    MAX_OPEN = 16

    def __init__(self, size: tuple[int, int] | None) -> None:
        self.size = size
        self._open: OrderedDict[Path, _OpenVideo] = OrderedDict()
        self._to_rgb = RgbConverter()
        self._lock = threading.Lock()

    def frame(self, episode: Episode, camera: str, index: int) -> npt.NDArray[np.uint8]:
        """(H, W, 3) uint8 RGB of ``camera`` at episode frame ``index``.

        Raises:
            InspectorError: an unknown camera, an unreadable file, no frame there.
        """
        if camera not in episode.videos:
            raise InspectorError(episode.source, f"episode {episode.index} has no camera {camera!r}; "
                                                 f"cameras: {episode.cameras}")
        seg = episode.videos[camera]
        t = seg.from_timestamp + index / episode.fps
        with self._lock:
            video = self._open.get(seg.path)
            if video is None:
                video = self._open[seg.path] = _OpenVideo(seg.path)
                while len(self._open) > self.MAX_OPEN:
                    self._open.popitem(last=False)[1].close()
            self._open.move_to_end(seg.path)
            frame = video.frame_at(t, 0.5 / episode.fps, self.DECODE_AHEAD_S)
            if frame is None:
                raise InspectorError(seg.path, f"{camera}: no frame {index} in episode {episode.index}")
            return self._to_rgb(frame, self.size)

    def close(self) -> None:
        with self._lock:
            for video in self._open.values():
                video.close()
            self._open.clear()


class _OpenVideo:
    """One open video file and where its decoder stands."""

    def __init__(self, path: Path) -> None:
        import av

        self.path = path
        try:
            self.container = av.open(str(path))
            self.stream = self.container.streams.video[0]
        except Exception as exc:
            raise InspectorError(path, f"cannot open video ({type(exc).__name__}: {exc})") from None
        self.time_base = float(self.stream.time_base or 1 / 90000)  # MP4 streams always have one
        self._frames: Any = None  # the decoding generator, after a seek
        self._last_t = -np.inf
        self._last_frame: Any = None

    def frame_at(self, t: float, slack: float, ahead_s: float) -> Any:
        """The decoded frame showing at ``t`` [s in the file] (the first with pts >= t - slack)."""
        if self._last_frame is not None and abs(self._last_t - t) <= slack:
            return self._last_frame
        if self._frames is None or not (self._last_t < t <= self._last_t + ahead_s):
            try:
                self.container.seek(max(0, int((t - slack) / self.time_base)), stream=self.stream,
                                    backward=True, any_frame=False)
            except Exception as exc:
                raise InspectorError(self.path, f"cannot seek ({type(exc).__name__}: {exc})") from None
            self._frames = self.container.decode(self.stream)
        try:
            for frame in self._frames:
                if frame.pts is None:
                    continue
                self._last_t, self._last_frame = frame.pts * self.time_base, frame
                if self._last_t >= t - slack:
                    return frame
        except Exception as exc:
            raise InspectorError(self.path, f"cannot decode video ({type(exc).__name__}: {exc})") from None
        self._frames = None
        return None

    def close(self) -> None:
        self.container.close()


@dataclass
class Observation:
    """What is sent for one frame, before the prompt and session id are added.

    Attributes:
        images: server key -> (H, W, 3) uint8 image.
        state: (6,) the joint state, :data:`JOINT_NAMES` order, dataset units.
    """

    images: dict[str, npt.NDArray[np.uint8]]
    state: npt.NDArray[np.float64]

    @property
    def image_shapes(self) -> dict[str, tuple[int, ...]]:
        return {k: tuple(v.shape) for k, v in self.images.items()}

    def message(self, prompt: str, session_id: str) -> dict[str, Any]:
        """The ``infer`` request (without ``endpoint``). Joints go by name: ``joint_position``
        holds the five arm joints (``shoulder_pan`` .. ``wrist_roll``), ``gripper_position`` the
        gripper, both in the dataset's units, float64."""
        gripper = JOINT_NAMES.index("gripper")
        arm = [i for i in range(len(JOINT_NAMES)) if i != gripper]
        return {**self.images, JOINT_POSITION_KEY: self.state[arm].copy(),
                GRIPPER_POSITION_KEY: self.state[[gripper]].copy(), "prompt": prompt, "session_id": session_id}


def read_observation(episode: Episode, frame: int, cameras: Mapping[str, str], reader: FrameReader) -> Observation:
    """The images (scaled by ``reader``) and the state of ``episode`` at ``frame``.

    Raises:
        InspectorError: the frame lies outside the episode, or a camera's video cannot be read.
    """
    if not 0 <= frame < episode.length:
        raise InspectorError(episode.source, f"start frame {frame} lies beyond episode {episode.index} "
                                             f"({episode.length} frames)")
    images = {key: reader.frame(episode, camera, frame) for key, camera in cameras.items()}
    return Observation(images, np.asarray(episode.state[frame], np.float64))


class Prefetcher:
    """Observations read one request ahead, in a thread, so the next one's frames decode while
    the server answers this one (PyAV decodes outside the GIL).

    Args:
        dataset: what ``dataset.episode(index)`` is asked of.
        requests: (episode, frame) of every request, in the order they will be asked for.
        cameras: server key -> dataset camera.
        reader: the frame reader (used by the one worker thread only).
    """

    def __init__(self, dataset: Any, requests: Sequence[tuple[int, int]], cameras: Mapping[str, str],
                 reader: FrameReader) -> None:
        self._dataset, self._requests, self._cameras, self._reader = dataset, list(requests), cameras, reader
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="eval-prefetch")
        self._ahead: dict[int, Future[Observation]] = {}

    def _read(self, i: int) -> Observation:
        episode, frame = self._requests[i]
        return read_observation(self._dataset.episode(episode), frame, self._cameras, self._reader)

    def get(self, i: int) -> Observation:
        """Request ``i``'s observation (raising what reading it raised); starts reading ``i + 1``."""
        future = self._ahead.pop(i, None) or self._pool.submit(self._read, i)
        for stale in [k for k in self._ahead if k < i]:  # skipped: a sample failed part way
            self._ahead.pop(stale).cancel()
        if i + 1 < len(self._requests) and i + 1 not in self._ahead:
            self._ahead[i + 1] = self._pool.submit(self._read, i + 1)
        return future.result()

    def close(self) -> None:
        for future in self._ahead.values():
            future.cancel()
        self._pool.shutdown(wait=True)
