"""``inspector eval SERVER DATASET -o SESSION``: a served checkpoint, open loop, against a dataset.

For each sample (an episode and a start frame): a fresh ``session_id``, a ``reset``, one ``infer``
with the real observation at that frame; the reply is checked and written at once as a
single-chunk rollout of the session, its GT the dataset's. So an interrupted run keeps every
finished sample and ``--resume`` goes on with the others. A sample that fails (an error reply, no
reply in time, a closed connection, a bad chunk) is one line; the run goes on (reconnecting where
the server closed) and ends with exit code 2.

The destination is checked before the dataset is read or the server contacted: a new session
goes where nothing is (or into an empty directory); ``--resume`` continues a session, each of
its rollouts read and validated first, and a broken one (a truncated file, a bad value) is asked
again and replaced atomically.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..data.lerobot_dataset import Episode, LeRobotDataset, dataset_name, find_dataset, open_dataset
from ..data.session import (
    ROLLOUT_FILE,
    ROLLOUTS_DIR,
    SESSION_FILE,
    RolloutKind,
    Session,
    SessionWriter,
    is_session,
    load_rollout,
    read_session,
    rollout_dirs,
)
from ..data.video import probe
from ..errors import InspectorError
from ..progress import progress_bar
from .client import DEFAULT_MAX_REPLY_MB, PolicyClient, SampleError, ServerConfig, server_url, shorten
from .observation import FrameReader, Observation, Prefetcher, map_cameras
from .replies import MAX_HORIZON, ReplyError, chunk_from_reply

DEFAULT_SAMPLES = 8  # start frames per episode: the seed's zero-shot protocol
# Frames of GT left after the last evenly spaced start (the DreamZero-SO101 horizon) [steps].
SPACING_HORIZON = 24
DEFAULT_EXECUTED = 9  # actions a chunk runs before the next (what imagined frames span)
DEFAULT_VIDEO_KEY = "video"


REPLAY_KIND: RolloutKind = "open_loop_replay"


@dataclass
class Sample:
    """One rollout to make: an episode and the frames to request a chunk at (one for a
    single-chunk sample; a chunk every ``executed_per_chunk`` frames for an open-loop replay)."""

    episode: int
    frames: list[int]
    replay: bool = False

    @property
    def tag(self) -> str:
        return f"ep{self.episode:03d}_replay" if self.replay else f"ep{self.episode:03d}_f{self.frames[0]:04d}"

    @property
    def kind(self) -> RolloutKind:
        return REPLAY_KIND if self.replay else "single_chunk"


@dataclass
class EvalPlan:
    """What ``inspector eval`` was asked to do (the CLI's flags).

    Attributes:
        server: ``ws://host:port`` or ``host:port``.
        dataset: a LeRobot dataset (a directory or ``org/name``).
        output: the session directory to write (or, with ``resume``, to continue).
        episodes: episode indexes (None: all).
        samples: start frames evenly spaced in each episode (used when ``frames`` is None).
        frames: these start frames in each episode.
        every_chunk: instead, one open-loop replay per episode: a chunk every
            ``executed_per_chunk`` frames, each from the real observation there.
        cameras: ``--camera`` server key -> dataset camera.
        prompt: the prompt for every sample (None: each episode's task).
        timeout_s: longest wait for a connection or a reply [s].
        resume: continue an existing session, skipping the samples it holds.
        executed_per_chunk: steps a chunk runs before the next in a replay, and that the
            imagined frames of a chunk span.
        video_keys: reply key -> view name of predicted frames to keep (None: ``video`` as the
            first mapped camera).
        model: the ``model`` record of the session (name, checkpoint).
        max_reply_mb: the largest message accepted from the server [MB]; also bounds the
            predicted frames a replay holds before it is written (twice this).
    """

    server: str
    dataset: str
    output: str
    episodes: list[int] | None = None
    samples: int = DEFAULT_SAMPLES
    frames: list[int] | None = None
    every_chunk: bool = False
    cameras: dict[str, str] = field(default_factory=dict)
    prompt: str | None = None
    timeout_s: float = 300.0
    resume: bool = False
    executed_per_chunk: int = DEFAULT_EXECUTED
    video_keys: dict[str, str] | None = None
    model: dict[str, Any] = field(default_factory=dict)
    max_reply_mb: float = DEFAULT_MAX_REPLY_MB

    @property
    def max_reply_bytes(self) -> int:
        return max(1, int(self.max_reply_mb * 1e6))


@dataclass
class EvalResult:
    """What a run did.

    Attributes:
        session: the session directory.
        written: tags written by this run.
        skipped: tags already in the session (``--resume``).
        redone: tags among ``written`` whose rollout was in the session but broken (``--resume``).
        failed: tag -> one line saying why.
        latency_s: per request of a written sample, from sending ``infer`` to its reply [s].
        client_s: per written sample and request, the time spent outside the server's replies [s].
        cameras: server key -> dataset camera.
    """

    session: Path
    written: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    redone: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    latency_s: list[float] = field(default_factory=list)
    client_s: list[float] = field(default_factory=list)
    cameras: dict[str, str] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.failed


def plan_samples(dataset: LeRobotDataset, episodes: Sequence[int] | None, samples: int,
                 frames: Sequence[int] | None, every: int | None = None) -> list[Sample]:
    """Every rollout to make, in order.

    With ``every``, one replay per episode with a chunk at frames 0, every, 2 * every, ...
    before its end. Otherwise single chunks: at ``frames`` in each episode (one past its end is
    still listed: it fails alone), or at ``samples`` start frames evenly spaced from 0 to
    ``length - 24`` (the last start leaves a horizon of GT after it), fewer where the episode is
    too short to space them.

    Raises:
        InspectorError: an episode the dataset lacks.
    """
    indexes = sorted(dataset.episode_indexes()) if episodes is None else list(episodes)
    missing = [e for e in indexes if e not in dataset.episode_indexes()]
    if missing:
        raise InspectorError("--episodes", f"dataset {dataset_name(dataset)} has no episode "
                                           f"{', '.join(map(str, missing))} (episodes {dataset.describe_episodes()})")
    out = []
    for e in indexes:
        if every is not None:
            out.append(Sample(e, list(range(0, dataset.episode_info(e).length, every)), replay=True))
            continue
        if frames is not None:
            starts = sorted(set(frames))
        else:
            last = max(0, dataset.episode_info(e).length - SPACING_HORIZON)
            starts = sorted({int(round(v)) for v in np.linspace(0, last, samples)})
        out += [Sample(e, [f]) for f in starts]
    return out


def connect(url: str, timeout_s: float, max_reply_bytes: int) -> PolicyClient:
    """A connection, or the one-line reason there is none as an :class:`InspectorError`."""
    try:
        return PolicyClient(url, timeout_s, max_reply_bytes)
    except SampleError as exc:
        raise InspectorError(url, str(exc)) from None


@dataclass
class Existing:
    """What ``--resume`` found in the session at ``-o``.

    Attributes:
        session: its ``session.json``, read.
        done: tags of the rollouts that read back whole (validated as ``report`` reads them).
        broken: tag -> why, for the rollout directories that do not (asked again, replaced).
    """

    session: Session
    done: set[str]
    broken: dict[str, str]


NEW_OUTPUT_ADVICE = ("eval writes a new session where nothing is (or into an empty directory), and --resume "
                     "continues a session; choose another -o")


def check_output(plan: EvalPlan) -> Existing | None:
    """Where the session goes, checked before the dataset is read or the server contacted.

    Returns:
        None for a new session (nothing at ``-o``, or an empty directory); with ``--resume`` and a
        session there, what it holds.

    Raises:
        InspectorError: ``-o`` is a session without ``--resume``, a file, a directory that is not a
            session, or cannot be created; with ``--resume``, a ``session.json`` that cannot be read.
    """
    out = Path(plan.output)
    if is_session(out):
        if not plan.resume:
            raise InspectorError(out, "already exists (pass --resume to continue it)")
        return _read_existing(out)
    if os.path.lexists(out):
        if out.is_symlink() or not out.is_dir():
            what = "a symbolic link" if out.is_symlink() else "a file"
            raise InspectorError(out, f"exists and is {what}, not a session; {NEW_OUTPUT_ADVICE}")
        try:
            empty = not any(out.iterdir())
        except OSError as exc:
            raise InspectorError(out, f"cannot read ({exc.strerror or exc})") from None
        if not empty:
            raise InspectorError(out, f"is a directory that is not a session (no {SESSION_FILE}); {NEW_OUTPUT_ADVICE}")
        return None
    parent = out.absolute().parent
    while not os.path.lexists(parent):
        parent = parent.parent
    if not parent.is_dir():
        raise InspectorError(out, f"cannot be created: {parent} is a file, not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InspectorError(out, f"cannot be created: {parent} is not writable")
    return None


def _read_existing(out: Path) -> Existing:
    """Every rollout of the session at ``out`` read back: its arrays' shapes and values, its
    videos' headers, a horizon a reply may have."""
    session = read_session(out)
    done: set[str] = set()
    broken: dict[str, str] = {}
    for child in rollout_dirs(out):
        try:
            rollout = load_rollout(child, session.units, lazy=True)
            if rollout.horizon > MAX_HORIZON:
                raise InspectorError(child / ROLLOUT_FILE, f"horizon: {rollout.horizon} steps, more than the "
                                                           f"{MAX_HORIZON} a reply may have")
            _ = (rollout.actions, rollout.states, rollout.gt_actions)  # read now: a bad value fails here
            rollout.release_arrays()
            for view in rollout.views:
                probe(rollout.video_path(view))
        except InspectorError as exc:
            broken[child.name] = str(exc)
            continue
        done.add(child.name)
    return Existing(session, done, broken)


def open_output(plan: EvalPlan, existing: Existing | None, dataset: LeRobotDataset, config: ServerConfig,
                url: str, cameras: Mapping[str, str]) -> SessionWriter:
    """The session to write into: ``existing`` (checked by :func:`check_output`), or a new one
    created now, empty, so every sample lands in place as it is done.

    Raises:
        InspectorError: the new session's place was taken meanwhile.
    """
    out = Path(plan.output)
    if existing is not None:
        return SessionWriter(out, None, existing.session.units)
    model = {"name": url, **plan.model, "server": url, "server_config": _json_safe(config.raw),
             "cameras": dict(cameras)}
    writer = SessionWriter.create(out, units=dataset.units, model=model, dataset=str(Path(dataset.root).resolve()))
    writer.commit()
    return SessionWriter(out, None, dataset.units)


def _check_same_dataset(existing: Existing, dataset: LeRobotDataset) -> None:
    dataset_root = str(Path(dataset.root).resolve())
    theirs = existing.session.gt_source.get("dataset")
    if theirs is not None and str(Path(theirs).resolve()) != dataset_root:
        raise InspectorError(existing.session.root / SESSION_FILE,
                             f"holds samples of dataset {shorten(theirs)}, not {dataset_root}; "
                             "--resume continues a run on the same dataset")


MAX_CONFIG_DEPTH = 16  # a server's config nested deeper is shown as "..." (msgpack nests to 1023)


def _json_safe(value: Any, depth: int = 0) -> Any:
    """A server's config as JSON can hold it: arrays as lists, bytes as text, a non-finite number
    as its name (JSON has none), whatever else as its type's name, nesting past
    :data:`MAX_CONFIG_DEPTH` as ``"..."`` (the same value always gives the same result)."""
    if depth > MAX_CONFIG_DEPTH:
        return "..."
    if isinstance(value, (np.ndarray, np.generic)):
        value = value.tolist()
    if isinstance(value, dict):
        return {str(_json_safe(k, depth + 1)): _json_safe(v, depth + 1) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v, depth + 1) for v in value]
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return type(value).__name__  # msgpack's ExtType, Timestamp


def evaluate(plan: EvalPlan, log: Callable[[str], None] = lambda line: print(line, file=sys.stderr),
             progress: bool | None = None) -> EvalResult:
    """Run ``plan``: every sample requested, checked, written.

    Args:
        plan: what to do.
        log: where the camera mapping and each failed sample's line go (stderr by default).
        progress: a progress bar on stderr (default: when stderr is a terminal).

    Raises:
        InspectorError: nothing could start (the dataset, the server, the handshake, the camera
            mapping, the output); a failed sample is never raised, it is in ``failed``.
    """
    url = server_url(plan.server)
    existing = check_output(plan)  # before the dataset is read and the server bothered
    dataset = open_dataset(find_dataset(plan.dataset))
    if existing is not None:
        _check_same_dataset(existing, dataset)
    samples = plan_samples(dataset, plan.episodes, plan.samples, plan.frames,
                           plan.executed_per_chunk if plan.every_chunk else None)
    client: PolicyClient | None = connect(url, plan.timeout_s, plan.max_reply_bytes)
    assert client is not None
    config = client.config
    try:
        cameras = map_cameras(config, dataset.cameras, plan.cameras, str(dataset.root), url)
    except InspectorError:
        client.close()
        raise
    video_keys = plan.video_keys if plan.video_keys is not None else (
        {DEFAULT_VIDEO_KEY: next(iter(cameras.values()))} if cameras else {})
    shown = _json_safe(config.raw)
    log(shorten(f"server {url}: {', '.join(f'{k} {shorten(json.dumps(v), 80)}' for k, v in shown.items())}", 600))
    log("cameras: " + (", ".join(f"{key} <- {name}" for key, name in cameras.items()) or "none"))
    try:
        writer = open_output(plan, existing, dataset, config, url, cameras)
    except BaseException:
        client.close()
        raise
    done = existing.done if existing is not None else set()
    broken = existing.broken if existing is not None else {}
    result = EvalResult(writer.root, cameras=cameras)
    result.skipped = [s.tag for s in samples if s.tag in done]
    todo = [s for s in samples if s.tag not in done]
    blocked = {s.tag: why for s in todo if (why := _blocked(writer.root / ROLLOUTS_DIR / s.tag, s.tag in broken))}
    todo = [s for s in todo if s.tag not in blocked]
    for s in todo:
        if s.tag in broken:
            log(f"redo {s.tag}: {shorten(broken[s.tag])}")
    size = None if config.image_resolution is None else (config.image_resolution[1], config.image_resolution[0])
    reader = FrameReader(size)
    requests = [(s.episode, f) for s in todo for f in s.frames]
    prefetch = Prefetcher(dataset, requests, cameras, reader)
    first_request = np.cumsum([0] + [len(s.frames) for s in todo])
    # the bar counts requests: a replay of a long episode makes many
    bar = progress_bar(sum(len(s.frames) for s in todo), "eval", unit="request", show=progress)

    def fail(tag: str, why: str) -> None:
        result.failed[tag] = shorten(why)
        line = f"error: {tag}: {result.failed[tag]}"
        if bar is not None:
            bar.write(line, file=sys.stderr)
        else:
            log(line)

    for tag, why in blocked.items():
        fail(tag, why)
    try:
        for i, sample in enumerate(todo):
            started = time.perf_counter()
            try:
                if client is None:
                    client = PolicyClient(url, plan.timeout_s, plan.max_reply_bytes)
                    if _json_safe(client.config.raw) != _json_safe(config.raw):  # arrays compared by value
                        raise SampleError("the server's config changed on reconnecting: "
                                          f"{json.dumps(_json_safe(client.config.raw))}")
                waited = _one_sample(plan, dataset, sample, client, cameras, video_keys,
                                     lambda k: prefetch.get(int(first_request[i]) + k), writer, result, url,
                                     redo=sample.tag in broken)
                result.client_s += [(time.perf_counter() - started - waited) / len(sample.frames)] * len(sample.frames)
            except ReplyError as exc:  # a bad chunk: the connection is still good
                fail(sample.tag, str(exc))
            except SampleError as exc:
                fail(sample.tag, str(exc))
                if client is not None:
                    client.close()
                client = None
            except InspectorError as exc:  # this sample's data (a frame past the end, a broken video)
                fail(sample.tag, str(exc))
            if bar is not None:
                bar.update(len(sample.frames))
                if result.failed:
                    bar.set_postfix_str(f"{len(result.failed)} failed", refresh=False)
    finally:
        if bar is not None:
            bar.close()
        if client is not None:
            client.close()
        prefetch.close()
        reader.close()
    return result


def _blocked(dest: Path, broken: bool) -> str | None:
    """Why the rollout directory ``dest`` may not be written, if it may not: something there that
    is no broken rollout (a file, a link, a directory without ``rollout.json``) is the user's."""
    if not os.path.lexists(dest):
        return None
    if broken and not dest.is_symlink() and dest.is_dir() and (
            (dest / ROLLOUT_FILE).is_file() or not any(dest.iterdir())):
        return None
    what = ("a symbolic link" if dest.is_symlink() else "a file" if not dest.is_dir()
            else f"a directory without {ROLLOUT_FILE}")
    return (f"{dest} is {what}, not a rollout: --resume replaces only a broken rollout; move it away to "
            "ask for this sample again")


def _one_sample(plan: EvalPlan, dataset: LeRobotDataset, sample: Sample, client: PolicyClient,
                cameras: Mapping[str, str], video_keys: Mapping[str, str], observation: Callable[[int], Observation],
                writer: SessionWriter, result: EvalResult, url: str, redo: bool = False) -> float:
    """Request, check and write one rollout: a reset, then a chunk at each of its frames, all
    under one session id. ``observation(k)`` reads the k-th frame's. Returns the time spent
    waiting on the server [s]. With ``redo``, the broken rollout of the same tag is replaced
    (atomically: the old one goes only once the new one is in place)."""
    episode: Episode = dataset.episode(sample.episode)
    obs = observation(0)  # a frame past the episode's end fails here, before the server is asked
    session_id = str(uuid.uuid4())
    prompt = plan.prompt if plan.prompt is not None else episode.task
    t0 = time.perf_counter()
    client.reset(session_id)
    waited = time.perf_counter() - t0
    chunks, latencies, states = [], [], []
    video_bytes = 0
    for k, frame in enumerate(sample.frames):
        obs = obs if k == 0 else observation(k)
        t1 = time.perf_counter()
        reply = client.infer(obs.message(prompt, session_id))
        latencies.append(time.perf_counter() - t1)
        waited += latencies[-1]
        chunks.append(chunk_from_reply(reply, video_keys))
        del reply  # the reply's other arrays
        states.append(obs.state)
        video_bytes += sum(v.nbytes for v in chunks[-1].videos.values())
        if video_bytes > 2 * plan.max_reply_bytes:
            raise ReplyError(f"reply: the predicted frames of this replay pass {2 * plan.max_reply_bytes / 1e6:g} MB "
                             f"by the chunk at frame {frame} (twice --max-reply-mb)")
        if chunks[-1].actions.shape != chunks[0].actions.shape:
            raise ReplyError(f"reply: the chunk at frame {frame} has shape {chunks[-1].actions.shape}, "
                             f"the first had {chunks[0].actions.shape}")
    horizon = chunks[0].actions.shape[0]
    executed = min(plan.executed_per_chunk, horizon)
    if sample.replay and plan.executed_per_chunk > horizon:
        raise ReplyError(f"reply: chunks of {horizon} steps cannot run {plan.executed_per_chunk} each "
                         "(--executed-per-chunk)")
    videos = _joined_videos([c.videos for c in chunks])
    frames_per_chunk = max((len(v) // len(chunks) for v in videos.values()), default=executed)
    record: dict[str, Any] = {
        "server": url, "session_id": session_id, "reply_form": chunks[0].form, "cameras": dict(cameras),
        "image_shapes": {k: list(v) for k, v in obs.image_shapes.items()}}
    if sample.replay:
        record.update(frames=list(sample.frames), latency_s=[round(v, 6) for v in latencies],
                      states=[[float(v) for v in s] for s in states])
    else:
        record.update(latency_s=round(latencies[0], 6), state=[float(v) for v in states[0]])
    writer.add_rollout(
        sample.tag, kind=sample.kind, actions=np.stack([c.actions for c in chunks]), prompt=prompt,
        episode_index=sample.episode, start_frame=sample.frames[0], fps=episode.fps,
        executed_per_chunk=executed, frames_per_chunk=frames_per_chunk, videos=videos or None,
        gt_episode_length=episode.length, extra={"eval": record}, overwrite=redo,
    )
    result.written.append(sample.tag)
    if redo:
        result.redone.append(sample.tag)
    result.latency_s += latencies
    return waited


def _joined_videos(per_chunk: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Each view's predicted frames, chunk after chunk, where every chunk has as many of one size
    (a view some chunk lacks, or with frames of another size, is dropped rather than misaligned)."""
    first = per_chunk[0]
    return {view: np.concatenate([v[view] for v in per_chunk]) for view in first
            if all(view in v and v[view].shape == first[view].shape for v in per_chunk)}


def format_result(result: EvalResult) -> str:
    """The run's summary: counts, latency p50 / p95, the client's own time per request."""
    done = len(result.written)
    parts = [f"{done} rollout(s) written"]
    if result.redone:
        n = len(result.redone)
        parts.append(f"{n} broken rollout{'s' if n > 1 else ''} redone ({', '.join(sorted(result.redone))})")
    if result.skipped:
        parts.append(f"{len(result.skipped)} already there (--resume)")
    if result.failed:
        parts.append(f"{len(result.failed)} failed ({', '.join(sorted(result.failed))})")
    lines = [f"wrote {result.session}: " + ", ".join(parts)]
    if result.latency_s:
        p50, p95 = np.percentile(result.latency_s, [50, 95])
        c50 = float(np.percentile(result.client_s, 50)) if result.client_s else float("nan")
        lines.append(f"latency (infer to reply): p50 {p50:.3f} s, p95 {p95:.3f} s; "
                     f"client time per request: p50 {c50 * 1000:.1f} ms")
    return "\n".join(lines)
