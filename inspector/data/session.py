"""Native session format: read, validate, write atomically.

Layout (every array in dataset units: arm degrees or -100..100 as ``session.json`` says, gripper
0..100)::

    sessions/<session>/
      session.json            schema, name, robot, units, joint_names, gt_source, model
      rollouts/<tag>/
        rollout.json          kind, episode_index, start_frame, prompt, fps, horizon,
                              executed_per_chunk, frames_per_chunk, views, gt {...}
        actions.npy           (n_chunks, horizon, 6) predicted chunks; absent for a video-only
                              rollout (rollout.json then says ``n_chunks``)
        states.npy            optional (n_chunks + 1, 6) state before each chunk
        video/<view>.mp4      imagined frames, H.264
        gt/actions.npy        optional (T, 6) GT joints for steps start_frame .. start_frame+T-1
        gt/video/<view>.mp4   optional; frame i shows the real scene at imagined frame i's time
      annotations.json        flags and notes from the app, written atomically

Time: rollout step ``s`` is the s-th *executed* action (chunk ``s // executed_per_chunk``); it
happens at ``s / fps`` seconds after ``start_frame``. Imagined frame ``f`` of a chunk shows step
``f * executed_per_chunk / frames_per_chunk`` of that chunk.

A rollout without ``actions.npy`` is *video only* (a simulated evaluation run without recordings,
a policy server's predicted video): its rollout.json gives ``n_chunks`` (with ``horizon`` the steps
each chunk spans), it has imagined views and maybe GT views, and every joint metric of it is null.

Writing never leaves a half-written session: a new session is built in a temporary sibling
directory and renamed into place; a rollout added to an existing session is built in a temporary
directory under ``rollouts/`` and renamed; JSON files are replaced with ``os.replace``.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import re
import shutil
import threading
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from .._files import mkdtemp_sibling, mkstemp_sibling, read_regular_file, short_name
from ..errors import InspectorError, require
from ..schema import json_text, shown, whole_number
from ..units import JOINT_NAMES, Units, parse_units
from .video import VideoClip, encode_h264, probe

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
# Joint values beyond this are no angle or gripper reading; it also keeps every squared distance
# the metrics take far below float64's overflow (~1e154 per value).
ABSURD_VALUE = 1e100
# Frame rates outside these are no camera's or robot's (LeRobot records at 10-60 fps); beyond
# them step times and video timestamps overflow or collapse (1e308 fps, 1e-300 fps) [frames/s].
MIN_FPS = 0.001
MAX_FPS = 1000.0
# A video-only rollout's length comes from rollout.json alone (no array to bound it). Its timeline
# still holds per-step arrays (~350 bytes a step): 1,000,000 steps (over 18 hours at 15 Hz) take
# report, compare and export 0.4 GB and 4-13 s (benchmarks/hostile_memory.py); 10,000,000 passed
# 3 GB [steps].
MAX_VIDEO_ONLY_STEPS = 1_000_000


# The largest JSON document read whole (metadata: session.json, rollout.json, info.json, ...; none
# is more than a few MB). Parsed JSON takes up to ~25 times its size in objects (``[[],[],...]``),
# so this keeps any one document's objects well under a GB [bytes].
MAX_JSON_BYTES = 32 * 1024 * 1024


def fps_problem(value: object) -> str | None:
    """What is wrong with ``value`` as a frame rate [frames/s], or None when it is one: a number
    (not a bool) in [:data:`MIN_FPS`, :data:`MAX_FPS`]."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"must be a number of frames per second, found {value!r}"
    if not MIN_FPS <= value <= MAX_FPS:  # NaN included: it compares false
        shown = f"{value:g}" if isinstance(value, float) or abs(value) < 10 ** 15 else "an integer past 1e15"
        return f"must lie in [{MIN_FPS:g}, {MAX_FPS:g}] frames per second, found {shown}"
    return None


# ----------------------------------------------------------------------------------------------
# Reading


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


def read_json(path: Path) -> Any:
    """Parse a JSON file as the standard defines JSON; every failure is an :class:`InspectorError`
    naming the file (and the field, for a NaN or Infinity, which JSON does not have).

    Raises:
        InspectorError: missing, not a regular file, unreadable, not UTF-8, not JSON, nested past
            the parser's depth, an integer past Python's digit limit, or a non-finite number.
    """
    return parse_json(path, read_json_bytes(path))


def read_json_bytes(path: Path) -> bytes:
    """The bytes of a JSON file :func:`read_json` would parse (the same checks before reading).

    Raises:
        InspectorError: missing, not a regular file (a FIFO is never waited on, a device never
            read), too large or unreadable.
    """
    return read_regular_file(path, MAX_JSON_BYTES, "metadata file")


def parse_json(path: Path, raw: bytes) -> Any:
    """:func:`read_json` of bytes already read from ``path`` (named in the errors).

    Raises:
        InspectorError: not UTF-8, not JSON, nested past the parser's depth, an integer past
            Python's digit limit, or a non-finite number.
    """
    return parse_json_text(path, raw)


def parse_json_text(path: Path, text: str | bytes, where: str = "") -> Any:
    """:func:`parse_json` of one JSON text inside ``path`` (``where`` it is, e.g. ``"line 12"`` of a
    JSON-lines file, starts every error).

    Raises:
        InspectorError: not UTF-8, not JSON, nested past the parser's depth, an integer past
            Python's digit limit, or a non-finite number (naming its field).
    """
    at = f"{where}: " if where else ""
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:  # bad UTF-8, bad JSON, an int of 5000 digits, [[[[...
        raise InspectorError(path, f"{at}invalid JSON ({type(exc).__name__}: {exc})") from None
    found = _first_non_finite(data)
    if found is not None:
        raise InspectorError(path, f"{at}{found[0]}: non-finite number {found[1]} (JSON has no NaN or Infinity)")
    return data


def check_json_size(path: Path) -> None:
    """Refuse a JSON document past :data:`MAX_JSON_BYTES` before it is read.

    Raises:
        InspectorError: naming the file and its size.
    """
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise InspectorError(path, f"cannot read ({exc.strerror or exc})") from None
    require(size <= MAX_JSON_BYTES, path, f"{size:,} bytes: larger than any metadata file "
                                          f"(at most {MAX_JSON_BYTES:,} bytes are read)")


def json_too_large(path: Path) -> bool:
    """True for a file past :data:`MAX_JSON_BYTES` (a layout's detection, which reads a JSON file
    to tell whose it is, leaves it to the reader, whose :func:`check_json_size` refuses it)."""
    try:
        return path.stat().st_size > MAX_JSON_BYTES
    except OSError:
        return False


def read_json_object(path: Path) -> dict[str, Any]:
    """:func:`read_json` of a file that must hold an object."""
    data = read_json(path)
    require(isinstance(data, dict), path, f"expected a JSON object, found {type(data).__name__}")
    return data


def _first_non_finite(data: Any) -> tuple[str, float] | None:
    """(field, value) of the first NaN/Infinity in document order, e.g. ``("per_joint_rmse[2]", nan)``.

    Iterative: a document as deep as the parser allows must not exhaust the stack here.
    """
    stack: list[tuple[str, Any]] = [("(top level)", data)]
    while stack:
        where, value = stack.pop()
        if isinstance(value, float) and not math.isfinite(value):
            return where, value
        top = "" if where == "(top level)" else where
        if isinstance(value, dict):
            stack.extend((f"{top}.{k}" if top else str(k), v) for k, v in reversed(list(value.items())))
        elif isinstance(value, list):
            stack.extend((f"{top}[{i}]", v) for i, v in reversed(list(enumerate(value))))
    return None


def open_session(root: str | Path, check: Callable[[Path], None] | None = None, lazy: bool = False) -> Session:
    """Read ``session.json`` and every rollout under ``rollouts/`` (bad ones go to ``errors``).

    Args:
        root: the session directory.
        check: called with ``session.json`` and with each rollout directory before it is read;
            an :class:`InspectorError` it raises refuses the session (for ``session.json``) or
            that rollout (it goes to ``errors``). The app uses it to refuse symbolic links that
            lead outside the served roots (``inspector.data.sources.check_confined``).
        lazy: read the rollouts' arrays on first use (see :func:`load_rollout`).

    Raises:
        InspectorError: ``session.json`` itself is missing or invalid (or refused by ``check``).
    """
    session = read_session(root, check)
    for child in rollout_dirs(session.root):
        try:
            if check is not None:
                check(child)
            rollout = load_rollout(child, session.units, lazy=lazy)
            rollout.session = session
            session.rollouts[child.name] = rollout
        except InspectorError as exc:
            session.errors[child.name] = exc
    return session


def read_session_with_gt(session_root: str | Path, dataset: str | None) -> Session:
    """A session as a worker reads it (``session.json`` alone), its GT replaced by ``dataset``
    (``--dataset``) when given."""
    session = read_session(Path(session_root))
    if dataset is not None:
        session.gt_source["dataset"] = dataset
    return session


def load_session_rollout(session: Session, tag: str) -> Rollout:
    """The rollout ``tag`` of ``session`` (from :func:`read_session_with_gt`), read and validated."""
    rollout = load_rollout(session.root / ROLLOUTS_DIR / tag, session.units)
    rollout.session = session
    return rollout


def rollout_dirs(root: Path) -> list[Path]:
    """The rollout directories of a session, by name (write-in-progress directories skipped)."""
    rollouts_dir = root / ROLLOUTS_DIR
    require(not rollouts_dir.exists() or rollouts_dir.is_dir(), rollouts_dir, "expected a directory")
    if not rollouts_dir.is_dir():
        return []
    # dot-directories are temporary directories of a write in progress
    return [c for c in sorted(rollouts_dir.iterdir()) if not c.name.startswith(".") and c.is_dir()]


def read_session(root: str | Path, check: Callable[[Path], None] | None = None) -> Session:
    """``session.json`` alone, validated: a :class:`Session` with no rollouts read.

    Raises:
        InspectorError: ``session.json`` is missing or invalid (or refused by ``check``).
    """
    root = Path(root)
    meta_path = root / SESSION_FILE
    if check is not None:
        check(meta_path)
    meta = read_json_object(meta_path)
    schema = meta.get("schema")
    require(schema == SCHEMA, meta_path, f"schema: expected {SCHEMA!r}, found {schema!r}")
    try:
        units = parse_units(meta.get("units", {}), "units")
    except ValueError as exc:
        raise InspectorError(meta_path, str(exc)) from None
    joint_names = meta.get("joint_names", list(JOINT_NAMES))
    require(joint_names == list(JOINT_NAMES), meta_path,
            f"joint_names: expected {list(JOINT_NAMES)}, found {joint_names}")
    robot = meta.get("robot", "so101")
    require(robot == "so101", meta_path, f"robot: only 'so101' is supported, found {robot!r}")
    for key in ("gt_source", "model"):
        require(isinstance(meta.get(key, {}), dict), meta_path, f"{key}: expected an object")
    dataset = meta.get("gt_source", {}).get("dataset")
    require(dataset is None or (isinstance(dataset, str) and "\x00" not in dataset), meta_path,
            f"gt_source.dataset: expected a path string, found {dataset!r}")
    return Session(
        root=root,
        name=str(meta.get("name", root.name)),
        robot=robot,
        units=units,
        joint_names=joint_names,
        gt_source=dict(meta.get("gt_source", {})),
        model=dict(meta.get("model", {})),
    )


def load_rollout(root: str | Path, units: Units | None = None, lazy: bool = False) -> Rollout:
    """Read and validate one rollout directory.

    Args:
        root: ``rollouts/<tag>``.
        units: the session's units (default: read the parent session, else degrees).
        lazy: check the arrays' shapes now but read their values on first use (a bad value then
            raises there); by default they are read and checked now.

    Raises:
        InspectorError: naming the file and the field at fault.
    """
    root = Path(root)
    meta_path = root / ROLLOUT_FILE
    meta = read_json_object(meta_path)
    if units is None:
        parent = root.parent.parent / SESSION_FILE
        units = Units()
        if parent.is_file():
            try:
                units = parse_units(read_json_object(parent).get("units", {}), "units")
            except ValueError as exc:
                raise InspectorError(parent, str(exc)) from None

    def get(key: str, kind: type | tuple[type, ...], default: Any = ...) -> Any:
        if key not in meta:
            require(default is not ..., meta_path, f"missing field {key!r}")
            return default
        value = meta[key]
        ok = isinstance(value, kind) and not (isinstance(value, bool) and bool not in _as_tuple(kind))
        require(ok, meta_path, f"{key}: expected {_type_names(kind)}, found {shown(value)}")
        return value

    kind = get("kind", str)
    require(kind in KINDS, meta_path, f"kind: expected one of {list(KINDS)}, found {kind!r}")
    horizon = get("horizon", int, 24)
    executed = get("executed_per_chunk", int, 9)
    frames_per_chunk = get("frames_per_chunk", int, 9)
    try:
        fps = float(get("fps", (int, float), 30))
    except OverflowError:  # an integer past float range
        raise InspectorError(meta_path, f"fps: must be a finite number, found {meta['fps']}") from None
    start_frame = get("start_frame", int, 0)
    episode_index = get("episode_index", (int, type(None)), None)
    for name, value in (("horizon", horizon), ("executed_per_chunk", executed),
                        ("frames_per_chunk", frames_per_chunk)):
        require(value >= 1, meta_path, f"{name}: must be >= 1, found {value}")
    require(executed <= horizon, meta_path,
            f"executed_per_chunk: {executed} exceeds horizon {horizon}")
    problem = fps_problem(fps)
    require(problem is None, meta_path, f"fps: {problem}")
    require(start_frame >= 0, meta_path, f"start_frame: must be >= 0, found {start_frame}")
    require(episode_index is None or episode_index >= 0, meta_path,
            f"episode_index: must be >= 0, found {episode_index}")
    views = get("views", list, [])
    require(all(isinstance(v, str) and _VIEW.match(v) for v in views), meta_path,
            f"views: expected names like 'front', found {views}")
    require(len(set(views)) == len(views), meta_path, f"views: listed twice in {views}")
    gt = get("gt", dict, {})
    gt_views = gt.get("views", [])
    require(isinstance(gt_views, list) and all(isinstance(v, str) and _VIEW.match(v) for v in gt_views),
            meta_path, f"gt.views: expected names like 'front', found {gt_views}")
    require(len(set(gt_views)) == len(gt_views), meta_path, f"gt.views: listed twice in {gt_views}")
    gt_len = gt.get("episode_length")
    require(gt_len is None or (isinstance(gt_len, int) and not isinstance(gt_len, bool) and gt_len > 0),
            meta_path, f"gt.episode_length: expected a positive integer, found {gt_len!r}")
    for name, value, least in (("horizon", horizon, 1), ("executed_per_chunk", executed, 1),
                               ("frames_per_chunk", frames_per_chunk, 1), ("start_frame", start_frame, 0),
                               ("episode_index", episode_index, 0), ("gt.episode_length", gt_len, 1)):
        if value is not None:  # below the least is said above; this bounds them from above
            whole_number(value, meta_path, name, minimum=least)

    arrays: dict[str, NpyFile | ArrayValue] = {}
    if not (root / ACTIONS_FILE).exists() and "n_chunks" in meta:  # video only
        n_video_chunks = whole_number(get("n_chunks", int), meta_path, "n_chunks", minimum=1)
        require(n_video_chunks * horizon <= MAX_VIDEO_ONLY_STEPS, meta_path,
                f"n_chunks: {n_video_chunks} chunks of {horizon} steps: more than the "
                f"{MAX_VIDEO_ONLY_STEPS:,} steps a video-only rollout may run")
        arrays["actions"] = NoJoints((n_video_chunks, horizon, len(JOINT_NAMES)))
    else:
        arrays["actions"] = NpyFile(root / ACTIONS_FILE, ("n_chunks", horizon, len(JOINT_NAMES)))
    n_chunks = arrays["actions"].shape[0]
    require(n_chunks >= 1, root / ACTIONS_FILE, "no chunks (shape[0] == 0)")
    if kind == "single_chunk":
        require(n_chunks == 1, root / ACTIONS_FILE, f"single_chunk rollout: expected 1 chunk, found {n_chunks}")
    if (root / STATES_FILE).exists():
        arrays["states"] = NpyFile(root / STATES_FILE, (n_chunks + 1, len(JOINT_NAMES)))
    if (root / LATENTS_FILE).exists():
        arrays["latents"] = NpyFile(root / LATENTS_FILE, ("n", "D"))
        require(arrays["latents"].shape[0] >= 1, root / LATENTS_FILE, "no latent vectors (shape[0] == 0)")
    if (root / GT_DIR / ACTIONS_FILE).exists():
        arrays["gt_actions"] = NpyFile(root / GT_DIR / ACTIONS_FILE, ("T", len(JOINT_NAMES)))
        require(arrays["gt_actions"].shape[0] >= 1, root / GT_DIR / ACTIONS_FILE, "no GT steps (shape[0] == 0)")
    if not lazy:
        for f in arrays.values():
            f.load()
    for view in views:
        require((root / VIDEO_DIR / f"{view}.mp4").is_file(), root / VIDEO_DIR / f"{view}.mp4",
                f"imagined video for view {view!r} not found")
    for view in gt_views:
        require((root / GT_DIR / VIDEO_DIR / f"{view}.mp4").is_file(),
                root / GT_DIR / VIDEO_DIR / f"{view}.mp4", f"GT video for view {view!r} not found")
    prompt = get("prompt", str, "")
    extra = get("extra", dict, {})
    return Rollout(
        root=root, tag=root.name, kind=kind, prompt=prompt, episode_index=episode_index,
        start_frame=start_frame, fps=fps, horizon=horizon, executed_per_chunk=executed,
        frames_per_chunk=frames_per_chunk, views=list(views), units=units,
        actions_shape=arrays["actions"].shape, gt_views=list(gt_views), gt_episode_length=gt_len,
        extra=extra, _arrays=arrays,
    )


class ArrayValue:
    """An array held in memory, read like an :class:`NpyFile` (for rollouts made in memory)."""

    def __init__(self, values: npt.ArrayLike) -> None:
        self._values = np.asarray(values, np.float64)
        self.shape: tuple[int, ...] = tuple(self._values.shape)

    def load(self) -> npt.NDArray[np.float64]:
        return self._values

    def release(self) -> None:
        pass  # nothing to read again


class NoJoints(ArrayValue):
    """The actions of a video-only rollout: NaN of the shape its rollout.json gives, made when
    first read (a long rollout's steps cost nothing until then)."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.shape = tuple(shape)
        self._nan: npt.NDArray[np.float64] | None = None

    def load(self) -> npt.NDArray[np.float64]:
        if self._nan is None:
            self._nan = np.full(self.shape, np.nan)
        return self._nan

    def release(self) -> None:
        self._nan = None


class NpyFile:
    """A numeric ``.npy`` file: its header checked now, its values read (and checked) on first use.

    Args:
        path: the file.
        shape: expected shape; a string entry (e.g. ``"n_chunks"``) matches any size.

    Raises:
        InspectorError: unreadable, not numeric, or another shape (naming the file).
    """

    def __init__(self, path: Path, shape: tuple[int | str, ...]) -> None:
        self.path = path
        self.shape: tuple[int, ...] = _read_npy_header(path, shape)
        self._values: npt.NDArray[np.float64] | None = None
        self._lock = threading.Lock()

    def load(self) -> npt.NDArray[np.float64]:
        """The values as float64, checked (finite, not absurd); kept until :meth:`release`."""
        with self._lock:
            if self._values is None:
                self._values = load_array(self.path, self.shape)
            return self._values

    def release(self) -> None:
        with self._lock:
            self._values = None


def _read_npy_header(path: Path, shape: tuple[int | str, ...]) -> tuple[int, ...]:
    """The shape in a ``.npy`` header, checked against ``shape`` and a numeric dtype."""
    if not path.is_file():
        raise InspectorError(path, "file not found")
    try:
        # reads the header, maps the rest; a header whose shape overflows the size fails here
        # (numpy would only warn and go on)
        with np.errstate(over="raise"):
            mapped = np.load(path, mmap_mode="r", allow_pickle=False)
        found, dtype = mapped.shape, mapped.dtype
        del mapped
    except FloatingPointError:
        raise InspectorError(path, "the shape in its header is too large for any array") from None
    except Exception as exc:
        raise InspectorError(path, f"not a readable .npy array ({type(exc).__name__}: {exc})") from None
    require(dtype.kind in "fiu", path, f"expected a numeric array, found dtype {dtype}")
    _check_shape(path, shape, found)
    return tuple(int(n) for n in found)


def _check_shape(path: Path, expected: tuple[int | str, ...], found: tuple[int, ...]) -> None:
    pattern = "(" + ", ".join(str(s) for s in expected) + ")"
    require(len(found) == len(expected) and all(isinstance(e, str) or e == a for e, a in zip(expected, found)),
            path, f"shape: expected {pattern}, found {tuple(found)}")


def load_array(path: Path, shape: tuple[int | str, ...]) -> npt.NDArray[np.float64]:
    """Load a numeric ``.npy`` and check its shape and values.

    Args:
        path: the file.
        shape: expected shape; a string entry (e.g. ``"n_chunks"``) matches any size.

    Returns:
        float64 array.
    """
    if not path.is_file():
        raise InspectorError(path, "file not found")
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise InspectorError(path, f"not a readable .npy array ({type(exc).__name__}: {exc})") from None
    require(isinstance(arr, np.ndarray) and arr.dtype.kind in "fiu", path,
            f"expected a numeric array, found dtype {getattr(arr, 'dtype', type(arr).__name__)}")
    _check_shape(path, shape, arr.shape)
    arr = arr.astype(np.float64, copy=False)
    check_values(arr, path)
    return arr


def check_values(arr: npt.NDArray[np.float64], file: str | Path, what: str = "") -> None:
    """Raise unless every value is finite and no larger than :data:`ABSURD_VALUE` in magnitude.

    Args:
        what: prefix naming the field (e.g. ``"actions_pred: "``), empty for a whole file.
    """
    bad = ~np.isfinite(arr)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InspectorError(file, f"{what}non-finite value {arr[where]} at index {list(where)}")
    huge = np.abs(arr) > ABSURD_VALUE
    if huge.any():
        where = tuple(int(i) for i in np.argwhere(huge)[0])
        raise InspectorError(file, f"{what}absurd value {arr[where]:g} at index {list(where)} "
                                   f"(joint values must lie within +-{ABSURD_VALUE:g})")


def _as_tuple(kind: type | tuple[type, ...]) -> tuple[type, ...]:
    return kind if isinstance(kind, tuple) else (kind,)


def _type_names(kind: type | tuple[type, ...]) -> str:
    names = {"NoneType": "null", "str": "a string", "int": "an integer", "float": "a number",
             "list": "a list", "dict": "an object"}
    return " or ".join(names.get(k.__name__, k.__name__) for k in _as_tuple(kind))


# ----------------------------------------------------------------------------------------------
# Writing


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON so that the file is either the old one or the complete new one."""
    write_bytes_atomic(path, (json_text(data, indent=2) + "\n").encode())


def write_bytes_atomic(path: Path, raw: bytes) -> None:
    """Write ``raw`` so that the file is either the old one or the complete new one (synced to
    disk before it replaces the old one)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = mkstemp_sibling(path)  # as open() would create it, not mkstemp's 0600
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def make_staging_dir(dest: Path) -> Path:
    """A fresh hidden sibling of ``dest`` to build it in (``.<name>.<random>.partial``), with the
    mode ``mkdir`` would give (``mkdtemp``'s 0700 would stick to the directory once renamed)."""
    return mkdtemp_sibling(dest)


def check_replaceable(dest: Path, overwrite: bool, kind: str, marker: str) -> bool:
    """Decide what a write may do at ``dest``, the one rule for sessions and rollouts.

    Free to write: ``dest`` does not exist, or is an empty directory. With ``overwrite``, also
    a directory that holds ``marker`` (``session.json`` / ``rollout.json``). Anything else (a
    file, a symbolic link, a directory that is not a ``kind``) is the user's and is never
    replaced.

    Returns:
        True when ``dest`` holds a ``kind`` that the write will replace.

    Raises:
        InspectorError: ``dest`` may not be replaced.
    """
    if not os.path.lexists(dest):
        return False
    if dest.is_symlink() or not dest.is_dir():
        what = "a symbolic link" if dest.is_symlink() else "a file"
        raise InspectorError(dest, f"exists and is {what}, not a {kind}; refusing to replace it")
    if not any(dest.iterdir()):
        return False
    if not overwrite:
        raise InspectorError(dest, "already exists (pass overwrite=True / --overwrite to replace it)")
    if not (dest / marker).is_file():
        raise InspectorError(dest, f"is not a {kind} (no {marker}); --overwrite replaces only a {kind}, "
                                   "refusing to delete this directory")
    return True


def check_apart(dest: str | Path, source: str | Path, what: str = "the source") -> None:
    """Refuse to write a session at ``dest`` that overlaps what it is made from: ``dest`` is
    ``source``, holds it, or lies inside it, read through symbolic links (and bind mounts: each
    directory is compared by its device and inode too). Replacing such a session
    (``--overwrite``) would delete its own input; writing one inside its input changes it.
    Nothing is written or read but the two paths' metadata.

    Args:
        what: how the error names ``source`` (``the source``, ``the GT dataset``).

    Raises:
        InspectorError: naming ``dest``, and ``source`` in its text.
    """
    dest, source = Path(os.path.expanduser(dest)), Path(os.path.expanduser(source))
    relation = _overlap(dest, source)
    if relation is None:
        return
    why = {"same": f"is {what} {source} itself, which the session would replace",
           "holds": f"holds {what} {source}, which replacing the session would delete",
           "inside": f"lies inside {what} {source}, which the session would be written into"}[relation]
    links = [f"{p} resolves to {os.path.realpath(p)}" for p in (dest, source)
             if os.path.realpath(p) != os.path.abspath(p)]
    raise InspectorError(dest, why + (f" ({'; '.join(links)})" if links else "") + "; write the session elsewhere")


def _overlap(a: Path, b: Path) -> str | None:
    """How ``a`` stands to ``b``: ``same``, ``holds`` (b lies under a), ``inside`` (a lies under
    b), or None. Paths are resolved; existing directories also compare by (device, inode)."""
    ra, rb = a.resolve(), b.resolve()
    if ra == rb:
        return "same"
    if rb.is_relative_to(ra):
        return "holds"
    if ra.is_relative_to(rb):
        return "inside"

    def identity(p: Path) -> tuple[int, int] | None:
        try:
            st = p.stat()
        except OSError:
            return None
        return st.st_dev, st.st_ino

    ia, ib = identity(ra), identity(rb)
    if ia is not None and ia == ib:
        return "same"
    if ia is not None and any(identity(p) == ia for p in rb.parents):
        return "holds"
    if ib is not None and any(identity(p) == ib for p in ra.parents):
        return "inside"
    return None


def _replace_dir(staged: Path, dest: Path, overwrite: bool, kind: str, marker: str) -> None:
    """Move a complete staged directory to ``dest``; an old ``dest`` goes only once the new is in.

    Raises:
        InspectorError: ``dest`` may not be replaced (:func:`check_replaceable`), or another
            write took the place meanwhile. ``staged`` is left for the caller to remove.
    """
    if check_replaceable(dest, overwrite, kind, marker):
        trash = dest.with_name(f".{short_name(dest.name)}.old-{uuid.uuid4().hex[:8]}")
        os.replace(dest, trash)
        try:
            os.replace(staged, dest)
        except OSError:
            with contextlib.suppress(OSError):
                os.replace(trash, dest)  # put the old one back
            raise InspectorError(dest, f"another write replaced this {kind} at the same time; "
                                       "this one was dropped") from None
        shutil.rmtree(trash, ignore_errors=True)
        return
    try:
        os.replace(staged, dest)  # onto nothing, or onto an empty directory
    except OSError as exc:
        if exc.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
            raise InspectorError(dest, f"appeared while this {kind} was written (another write to "
                                       "the same place?); this one was dropped") from None
        raise


class SessionWriter:
    """Writes a session. What an evaluation script calls.

    Usage::

        from inspector.data.session import SessionWriter

        with SessionWriter.create("sessions/my_eval", name="my eval",
                                  model={"name": "my-wam", "checkpoint": "step-72000"},
                                  dataset="~/.cache/huggingface/lerobot/me/so101_pick") as session:
            session.add_rollout("ep000", kind="autoregressive", actions=chunks,   # (60, 24, 6)
                                episode_index=0, start_frame=0, prompt="Pick the red cube",
                                videos={"front": frames})                          # (540, H, W, 3)

    A new session appears at its path only when the ``with`` block ends without error.
    """

    def __init__(self, root: Path, final: Path | None, units: Units, overwrite: bool = False):
        self.root = root  # where files are written now
        self._final = final  # where a new session lands on commit (None: appending in place)
        self.units = units
        self._overwrite = overwrite
        self.tags: list[str] = []

    @classmethod
    def create(cls, dest: str | Path, *, name: str | None = None, units: Units = Units(),
               model: Mapping[str, Any] | None = None, dataset: str | Path | None = None,
               repo_id: str | None = None, overwrite: bool = False) -> SessionWriter:
        """Start a new session at ``dest`` (staged in a temporary sibling until committed)."""
        dest = Path(dest)
        check_replaceable(dest, overwrite, "session", SESSION_FILE)  # refuse before any work
        dest.parent.mkdir(parents=True, exist_ok=True)
        staged = make_staging_dir(dest)
        gt_source: dict[str, Any] = {}
        if dataset is not None:
            gt_source["dataset"] = str(dataset)
        if repo_id is not None:
            gt_source["repo_id"] = repo_id
        try:
            write_json_atomic(staged / SESSION_FILE, {
                "schema": SCHEMA,
                "name": name or dest.name,
                "robot": "so101",
                "units": units.to_json(),
                "joint_names": list(JOINT_NAMES),
                "gt_source": gt_source,
                "model": dict(model or {}),
            })
            (staged / ROLLOUTS_DIR).mkdir()
        except BaseException:
            shutil.rmtree(staged, ignore_errors=True)
            raise
        return cls(staged, dest, units, overwrite)

    @classmethod
    def append(cls, root: str | Path) -> SessionWriter:
        """Add rollouts to an existing session; each rollout appears atomically."""
        session = open_session(root)
        return cls(Path(root), None, session.units)

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()

    def commit(self) -> Path:
        """Move a new session into place. Returns its final path.

        A commit that fails (the place was taken meanwhile, a rename failed) drops the staged
        session: nothing is left behind but what was at the destination before.
        """
        if self._final is None:
            return self.root
        try:
            _replace_dir(self.root, self._final, self._overwrite, "session", SESSION_FILE)
        except BaseException:
            self.abort()
            raise
        self.root, self._final = self._final, None
        return self.root

    def abort(self) -> None:
        """Drop a new session that was not committed (nothing appears at its path)."""
        if self._final is not None:
            shutil.rmtree(self.root, ignore_errors=True)

    def add_rollout(
        self,
        tag: str,
        *,
        kind: RolloutKind,
        actions: npt.ArrayLike | None,
        prompt: str = "",
        episode_index: int | None = None,
        start_frame: int = 0,
        fps: float = 30.0,
        executed_per_chunk: int = 9,
        frames_per_chunk: int = 9,
        states: npt.ArrayLike | None = None,
        videos: Mapping[str, Any] | None = None,
        gt_actions: npt.ArrayLike | None = None,
        gt_videos: Mapping[str, Any] | None = None,
        gt_episode_length: int | None = None,
        extra: Mapping[str, Any] | None = None,
        latents: npt.ArrayLike | None = None,
        overwrite: bool = False,
        n_chunks: int | None = None,
        horizon: int | None = None,
    ) -> Path:
        """Write one rollout (validated by reading it back before it becomes visible).

        Args:
            tag: directory name, letters/digits/``_.-``.
            kind: ``"single_chunk"``, ``"autoregressive"`` or ``"open_loop_replay"``.
            actions: (n_chunks, horizon, 6) predicted chunks in the session's units, or None for
                a video-only rollout (then ``n_chunks`` and ``horizon`` give its length: chunks,
                and steps each chunk spans).
            states: optional (n_chunks + 1, 6) state before each chunk.
            videos: ``{view: frames (N, H, W, 3) uint8 | path to a video}``; paths are copied if
                already H.264, otherwise re-encoded.
            gt_actions: optional (T, 6) GT joints from ``start_frame`` on.
            gt_videos: optional ``{view: frames | path}``; frame i at imagined frame i's time.
            gt_episode_length: length of the real episode [frames], when known.
            extra: provenance and reference values to keep (JSON-serialisable).
            latents: optional (n, D) latent vectors, one per chunk (or sample), for the latent
                stability test (``latents.npy``).

        Returns:
            The rollout directory.
        """
        if not _TAG.match(tag):
            raise InspectorError(tag, "rollout tag must be 1-128 letters, digits or _.- (not starting with . _ -)")
        dest = self.root / ROLLOUTS_DIR / tag
        if tag in self.tags or (dest.exists() and not overwrite):
            raise InspectorError((self._final or self.root) / ROLLOUTS_DIR / tag,
                                 f"rollout {tag!r} already exists in this session")
        if actions is None:
            if n_chunks is None or horizon is None:
                raise InspectorError(tag, "a video-only rollout (actions=None) needs n_chunks and horizon")
            actions_arr = np.zeros((int(n_chunks), int(horizon), 0))
        else:
            actions_arr = np.asarray(actions, dtype=np.float64)
        staged = make_staging_dir(dest)
        try:
            if actions is not None:
                np.save(staged / ACTIONS_FILE, actions_arr)
            if states is not None:
                np.save(staged / STATES_FILE, np.asarray(states, dtype=np.float64))
            if latents is not None:
                np.save(staged / LATENTS_FILE, np.asarray(latents, dtype=np.float64).reshape(
                    len(np.asarray(latents)), -1))
            if gt_actions is not None:
                (staged / GT_DIR).mkdir()
                np.save(staged / GT_DIR / ACTIONS_FILE, np.asarray(gt_actions, dtype=np.float64))
            for view, src in (videos or {}).items():
                _write_video(staged / VIDEO_DIR / f"{view}.mp4", src, fps)
            for view, src in (gt_videos or {}).items():
                _write_video(staged / GT_DIR / VIDEO_DIR / f"{view}.mp4", src, fps)
            meta: dict[str, Any] = {
                "kind": kind,
                "prompt": prompt,
                "episode_index": episode_index,
                "start_frame": int(start_frame),
                "fps": float(fps),
                "horizon": int(actions_arr.shape[1]) if actions_arr.ndim == 3 else 0,
                "executed_per_chunk": int(executed_per_chunk),
                "frames_per_chunk": int(frames_per_chunk),
                "views": sorted(videos or {}),
                "gt": {"views": sorted(gt_videos or {}), "episode_length": gt_episode_length},
                "units": self.units.to_json(),
            }
            if actions is None:
                meta["n_chunks"] = int(actions_arr.shape[0])
            if extra:
                meta["extra"] = dict(extra)
            write_json_atomic(staged / ROLLOUT_FILE, meta)
            load_rollout(staged, self.units)  # validate before it becomes visible
            _replace_dir(staged, dest, overwrite, "rollout", ROLLOUT_FILE)
        except (InspectorError, OSError) as exc:  # bad data, or a write error (disk full, ...)
            shutil.rmtree(staged, ignore_errors=True)
            if isinstance(exc, InspectorError):
                file, what = exc.file, exc.what
            else:
                file, what = str(exc.filename or staged), exc.strerror or str(exc)
            # name the file where it would have been, not in the temporary directory that is gone
            final = (self._final or self.root) / ROLLOUTS_DIR / tag
            raise InspectorError(file.replace(str(staged), str(final)), what) from None
        except BaseException:
            shutil.rmtree(staged, ignore_errors=True)
            raise
        self.tags.append(tag)
        return dest


def _write_video(dest: Path, src: Any, fps: float) -> None:
    """An H.264 file is copied as it is; any other video, or frames, are encoded frame by frame."""
    if isinstance(src, (str, Path)):
        info = probe(src)
        dest.parent.mkdir(parents=True, exist_ok=True)
        if info.codec == "h264":
            shutil.copyfile(src, dest)
            return
        frames: Any = (rgb for _, rgb in VideoClip(Path(src)).iter_frames())
    else:
        frames = np.asarray(src)
        if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
            raise InspectorError(dest, f"video frames: expected (N, H, W, 3) uint8, found {frames.shape} {frames.dtype}")
    encode_h264(dest, frames, fps)
