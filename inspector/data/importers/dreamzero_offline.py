"""Import DreamZero-SO101 offline-inference runs (``offline_inference.py``) into a native session.

One directory per run, found recursively under the path given::

    <run>/
      predicted_actions.csv      header step,shoulder_pan,...,gripper; 24 rows per chunk
                                 (arm degrees, gripper 0..100: denormalised with so101-megamix's stats)
      predicted_video.mp4        2x2 mosaic [front|top; gripper|black], 640x352 of 320x176 views
      frames/frame_NNN.png       the same frames (mosaic), and frames/{front,top,gripper}/frame_NNN.png
      metadata.json              prompt, input_joint_positions (by joint name), chunk_count,
                                 actions_per_chunk, frame_zero_includes_conditioning_image,
                                 subsequent_chunks_drop_conditioning_frame, seeds, shapes
      inspector_gt.json          optional, written by the user: {"dataset": ..., "episode": N,
                                 "start_frame": F, "fps": 30}: where the run started in a real episode

Each chunk decodes 9 frames for its 24 actions (the first one is the conditioning image, so a
frame shows every third action); the writer keeps the first chunk's conditioning frame and drops
the later ones', so k chunks give 8k + 1 frames and frame ``f`` shows step ``3 f``. A run of k > 1
chunks is an autoregressive rollout (each chunk is fed the last predicted frame and the last of
its 24 actions, so every action of a chunk is executed); k = 1 is a single chunk.

The run carries no GT: a LeRobot dataset (``--dataset`` or the sidecar's ``dataset``) plus the
episode and start frame (flags, or the sidecar) supply it.
"""

from __future__ import annotations

import array
import csv
import math
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ...errors import InspectorError, require
from ...schema import MAX_WHOLE, finite_number, shown, whole_number
from ...units import JOINT_NAMES, Units, joint_order
from ..lerobot_dataset import LeRobotDataset, find_dataset
from ..session import SessionWriter, check_apart, check_values, fps_problem, read_json_object
from ..video import VideoClip, encode_h264, probe
from .in_memory import InMemory, import_temporarily
from .shared import MOSAIC_VIEWS, check_episode_flag, missing_episode, tag_from_name

FORMAT = "dreamzero-offline"
LAYOUT_NAME = "DreamZero-SO101 offline-inference runs"
ACTIONS_CSV = "predicted_actions.csv"
METADATA = "metadata.json"
MOSAIC_VIDEO = "predicted_video.mp4"
FRAMES_DIR = "frames"
SIDECAR = "inspector_gt.json"
# offline_inference.py writes 24 actions per chunk and decodes 9 frames for them (Wan2.1's VAE: 1 + 4 x 2).
ACTIONS_PER_CHUNK = 24
FRAMES_PER_DECODED_CHUNK = 9
# The action rate of so101-megamix-v1, the dataset the LoRA was trained on (the mp4's own --fps is
# only its playback speed) [Hz].
DEFAULT_ACTION_FPS = 30.0
UNITS = Units("degrees")
# The most actions a chunk may have (offline_inference.py's have 24), and the longest field of
# line of predicted_actions.csv (seven numbers of a few dozen characters each).
MAX_ACTIONS_PER_CHUNK = 4096
MAX_CSV_LINE_CHARS = 4096
# The three views of a run held at once while importing it (a 60-chunk run's 481 frames take
# ~245 MB); a longer run is cut view by view, decoding the mosaic three times [bytes].
VIEWS_IN_MEMORY_BYTES = 256 * 1024 * 1024


@dataclass
class GtLink:
    """Where a run started in a real episode (from flags or the sidecar)."""

    dataset: str | None = None
    episode: int | None = None
    start_frame: int = 0
    fps: float | None = None


@dataclass
class OfflineRun:
    """One run read from disk.

    Attributes:
        actions: (k, 24, 6) predicted chunks, JOINT_NAMES order, arm degrees, gripper 0..100.
        states: (k + 1, 6): the input joints, then the last action of each chunk (what the next
            chunk was fed), or None when metadata.json has no ``input_joint_positions``.
        n_frames: frames in the video (or PNG sequence).
        frames_per_chunk: new frames each chunk adds (8 for the writer's 8k + 1).
        video: the mosaic file, or None when only PNG frames are there.
    """

    path: Path
    actions: npt.NDArray[np.float64]
    states: npt.NDArray[np.float64] | None
    prompt: str
    n_frames: int
    frames_per_chunk: int
    video: Path | None
    metadata: dict[str, Any]
    gt: GtLink
    warnings: list[str] = field(default_factory=list)

    @property
    def n_chunks(self) -> int:
        return int(self.actions.shape[0])

    @property
    def kind(self) -> str:
        return "autoregressive" if self.n_chunks > 1 else "single_chunk"


def is_offline_run(path: Path) -> bool:
    return (path / ACTIONS_CSV).is_file()


def find_runs(src: str | Path) -> list[Path]:
    """Every run directory at or under ``src`` (sorted by path); empty when there is none."""
    src = Path(src)
    if not src.is_dir():
        return []
    if is_offline_run(src):
        return [src]
    return sorted(p.parent for p in src.rglob(ACTIONS_CSV) if p.is_file())


# ----------------------------------------------------------------------------------------------
# Reading one run


def read_run(path: Path, link: GtLink | None = None, start_frame: int | None = None) -> OfflineRun:
    """Read and check one run (frames are counted, not decoded).

    Args:
        link, start_frame: GT dataset, episode, fps and start frame given on the command line;
            they take precedence over the sidecar's.

    Raises:
        InspectorError: naming the file and the field at fault.
    """
    meta = read_json_object(path / METADATA) if (path / METADATA).is_file() else {}
    warnings = [] if meta else [f"{METADATA} not found: chunk layout inferred from the files"]
    per_chunk = _positive_int(meta, "actions_per_chunk", path / METADATA, ACTIONS_PER_CHUNK,
                              maximum=MAX_ACTIONS_PER_CHUNK)
    # The frames first (the video's packets, or the PNGs): they bound the chunks, and so the rows
    # of the CSV worth reading; a CSV of millions of rows beside a short video is read no further.
    video, n_frames = _count_frames(path)
    keeps_first, drops_later = _frame_rule(meta, path)
    new_frames = FRAMES_PER_DECODED_CHUNK - (1 if drops_later else 0)
    most_chunks = max(0, n_frames - (1 if drops_later and keeps_first else 0)) // new_frames
    flat = _read_actions_csv(path / ACTIONS_CSV, max_rows=most_chunks * per_chunk,
                             why=f"{video or path / FRAMES_DIR}'s {n_frames} frames make at most {most_chunks} "
                                 f"chunk(s) of {per_chunk} actions")
    require(flat.shape[0] % per_chunk == 0, path / ACTIONS_CSV,
            f"{flat.shape[0]} rows are not whole chunks of {per_chunk} (metadata.json actions_per_chunk)")
    n_chunks = flat.shape[0] // per_chunk
    if "chunk_count" in meta:
        count = _positive_int(meta, "chunk_count", path / METADATA, None)
        require(count == n_chunks, path / METADATA,
                f"chunk_count: {count}, but {ACTIONS_CSV} holds {n_chunks} chunks of {per_chunk} rows")
    actions = flat.reshape(n_chunks, per_chunk, len(JOINT_NAMES))
    prompt = meta.get("prompt", "")
    require(isinstance(prompt, str), path / METADATA, f"prompt: expected a string, found {prompt!r}")
    states = None
    if "input_joint_positions" in meta:
        start = _joints_by_name(meta["input_joint_positions"], path / METADATA, "input_joint_positions")
        states = np.vstack([start[None], actions[:, -1]])  # each chunk is fed the last action before it
    else:
        warnings.append("no input_joint_positions: the arm's starting pose is unknown")
    frames_per_chunk = _frames_per_chunk(meta, path, n_chunks, n_frames, video)
    gt = _gt_link(path, link, start_frame)
    return OfflineRun(path=path, actions=actions, states=states, prompt=prompt, n_frames=n_frames,
                      frames_per_chunk=frames_per_chunk, video=video, metadata=meta, gt=gt,
                      warnings=warnings)


def _read_actions_csv(path: Path, max_rows: int | None = None, why: str = "") -> npt.NDArray[np.float64]:
    """(N, 6) rows of ``predicted_actions.csv`` in JOINT_NAMES order (columns mapped by name),
    streamed row by row into one array. ``max_rows``: the most rows the run can hold (``why``
    says why); a row past them is refused before any more of the file is read."""
    flat = array.array("d")
    try:
        with path.open(newline="") as f:
            rows = csv.reader(_bounded_lines(f, path))
            first = next(rows, None)
            require(first is not None, path, "empty file: expected the header step,shoulder_pan,...,gripper")
            assert first is not None
            header = [h.strip() for h in first]
            require("step" in header, path, f"header: no 'step' column (found {shown(header, 200)})")
            joints = [h for h in header if h != "step"]
            try:
                order = joint_order(joints, "header")
            except ValueError as exc:
                raise InspectorError(path, str(exc)) from None
            columns = [header.index(j) for j in joints]
            step_col = header.index("step")
            for i, row in enumerate(rows):
                line = i + 2
                require(max_rows is None or i < max_rows, path,
                        f"line {line}: more than {max_rows} rows, but {why}")
                require(len(row) == len(header), path, f"line {line}: {len(row)} fields, the header has {len(header)}")
                try:
                    step = int(row[step_col])
                except ValueError:
                    raise InspectorError(path, f"line {line}, step: not a whole number ({shown(row[step_col])})") from None
                require(step == i, path, f"line {line}, step: {shown(step)}, expected {i} (steps count from 0 row by row)")
                for j, c in enumerate(columns):
                    try:
                        value = float(row[c])
                    except ValueError:
                        raise InspectorError(path, f"line {line}, {joints[j]}: not a number ({shown(row[c])})") from None
                    require(math.isfinite(value), path, f"line {line}, {joints[j]}: non-finite number {value}")
                    flat.append(value)
    except UnicodeDecodeError:
        raise InspectorError(path, "not a text CSV file") from None
    except csv.Error as exc:
        raise InspectorError(path, f"not a readable CSV file ({exc})") from None
    values = np.frombuffer(flat, dtype=np.float64).reshape(-1, len(JOINT_NAMES)).copy()
    require(values.shape[0] >= 1, path, "no rows under the header")
    values = values[:, order]
    check_values(values, path)
    return values


def _bounded_lines(f: Any, path: Path) -> Iterator[str]:
    """The lines of text file ``f``, each at most :data:`MAX_CSV_LINE_CHARS` long (a longer one,
    a million fields on one line, is refused before it is held)."""
    while line := f.readline(MAX_CSV_LINE_CHARS + 1):
        require(len(line) <= MAX_CSV_LINE_CHARS, path, f"a line longer than {MAX_CSV_LINE_CHARS} characters")
        yield line


def _joints_by_name(value: Any, path: Path, key: str) -> npt.NDArray[np.float64]:
    require(isinstance(value, dict), path, f"{key}: expected an object of joint name -> value, found {value!r}")
    try:
        order = joint_order(list(value), key)
    except ValueError as exc:
        raise InspectorError(path, str(exc)) from None
    raw = [finite_number(v, path, f"{key}.{name}") for name, v in value.items()]
    return np.asarray(raw, dtype=np.float64)[order]


def _count_frames(path: Path) -> tuple[Path | None, int]:
    """(mosaic video or None, frame count): the mp4 when there is one, else the PNG frames."""
    video = path / MOSAIC_VIDEO
    if video.is_file():
        info = probe(video)
        require(info.width % 2 == 0 and info.height % 2 == 0, video,
                f"mosaic {info.width}x{info.height}: sides must be even (a 2x2 grid of views)")
        n = len(VideoClip(video))
        require(n >= 1, video, "video has no frames")
        return video, n
    pngs = _png_frames(path)
    require(bool(pngs["front"]), path, f"neither {MOSAIC_VIDEO} nor {FRAMES_DIR}/front/frame_NNN.png found")
    return None, len(pngs["front"])


def _png_frames(path: Path) -> dict[str, list[Path]]:
    """``frames/<view>/frame_NNN.png`` per view, in frame order."""
    out = {}
    for view, _, _ in MOSAIC_VIEWS:
        files = [(f, f.stem[len("frame_"):]) for f in (path / FRAMES_DIR / view).glob("frame_*.png")]
        out[view] = [f for f, n in sorted((p for p in files if p[1].isdigit()), key=lambda p: int(p[1]))]
    return out


def _frame_rule(meta: dict[str, Any], path: Path) -> tuple[bool, bool]:
    """(the first chunk keeps its conditioning frame, the later chunks drop theirs), from metadata.json."""
    keeps_first = meta.get("frame_zero_includes_conditioning_image", True)
    drops_later = meta.get("subsequent_chunks_drop_conditioning_frame", True)
    for key, value in (("frame_zero_includes_conditioning_image", keeps_first),
                       ("subsequent_chunks_drop_conditioning_frame", drops_later)):
        require(isinstance(value, bool), path / METADATA, f"{key}: expected true or false, found {shown(value)}")
    return keeps_first, drops_later


def _frames_per_chunk(meta: dict[str, Any], path: Path, n_chunks: int, n_frames: int, video: Path | None) -> int:
    keeps_first, drops_later = _frame_rule(meta, path)
    per_chunk = FRAMES_PER_DECODED_CHUNK - (1 if drops_later else 0)
    expected = per_chunk * n_chunks + (1 if drops_later and keeps_first else 0)
    if "decoded_frame_count" in meta:
        declared = _positive_int(meta, "decoded_frame_count", path / METADATA, None)
        require(declared == n_frames, video or path / FRAMES_DIR,
                f"{n_frames} frames, but metadata.json decoded_frame_count says {declared}")
    rule = "8k+1" if drops_later else "9k"
    require(n_frames == expected, video or path / FRAMES_DIR,
            f"{n_frames} frames, but {n_chunks} chunk(s) of {FRAMES_PER_DECODED_CHUNK} decoded frames give "
            f"{expected} ({rule})")
    return per_chunk


def _gt_link(path: Path, given: GtLink | None, given_start: int | None = None) -> GtLink:
    """The run's GT link: the sidecar's, each field overridden by the one given (flags)."""
    link = GtLink()
    sidecar = path / SIDECAR
    if sidecar.is_file():
        data = read_json_object(sidecar)
        unknown = sorted(set(data) - {"dataset", "episode", "start_frame", "fps"})
        require(not unknown, sidecar, f"unknown field(s) {unknown}; known: dataset, episode, start_frame, fps")
        ds = data.get("dataset")
        require(ds is None or isinstance(ds, str), sidecar, f"dataset: expected a path or org/name, found {ds!r}")
        if ds is not None and not ds.startswith("~") and (path / ds).exists():
            ds = str((path / ds).resolve())  # a path relative to the run
        link.dataset = ds
        link.episode = _index(data, "episode", sidecar, None)
        link.start_frame = _index(data, "start_frame", sidecar, 0)
        fps = data.get("fps")
        problem = None if fps is None else fps_problem(fps)
        require(problem is None, sidecar, f"fps: {problem}")
        link.fps = fps
    if given is not None:
        link.dataset = given.dataset if given.dataset is not None else link.dataset
        link.episode = given.episode if given.episode is not None else link.episode
        link.start_frame = given_start if given_start is not None else link.start_frame
        link.fps = given.fps if given.fps is not None else link.fps
    return link


def _index(data: dict[str, Any], key: str, path: Path, default: Any) -> Any:
    value = data.get(key, default)
    return value if value is default else whole_number(value, path, key)


def _positive_int(meta: dict[str, Any], key: str, path: Path, default: Any, maximum: int = MAX_WHOLE) -> Any:
    return whole_number(meta.get(key, default), path, key, minimum=1, maximum=maximum)


# ----------------------------------------------------------------------------------------------
# Views


def iter_view_frames(run: OfflineRun, view: str) -> Iterator[npt.NDArray[np.uint8]]:
    """Frames of ``view`` cut from the mosaic video (or read from its PNGs), one at a time."""
    row, col = next((r, c) for v, r, c in MOSAIC_VIEWS if v == view)
    if run.video is not None:
        for _, frame in VideoClip(run.video).iter_frames():
            h, w = frame.shape[0] // 2, frame.shape[1] // 2
            yield np.ascontiguousarray(frame[row * h:(row + 1) * h, col * w:(col + 1) * w])
        return
    from PIL import Image

    for f in _png_frames(run.path)[view]:
        try:
            with Image.open(f) as im:
                yield np.asarray(im.convert("RGB"))
        except OSError as exc:
            raise InspectorError(f, f"cannot read image ({exc})") from None


def _all_views(run: OfflineRun) -> dict[str, list[npt.NDArray[np.uint8]]]:
    """Every view's frames from one pass over the mosaic (decoding it once, not once per view)."""
    assert run.video is not None
    views: dict[str, list[npt.NDArray[np.uint8]]] = {v: [] for v, _, _ in MOSAIC_VIEWS}
    for _, frame in VideoClip(run.video).iter_frames():
        h, w = frame.shape[0] // 2, frame.shape[1] // 2
        for view, row, col in MOSAIC_VIEWS:
            views[view].append(np.ascontiguousarray(frame[row * h:(row + 1) * h, col * w:(col + 1) * w]))
    return views


def _write_views(run: OfflineRun, scratch: Path, fps: float) -> dict[str, Path]:
    """Each view as its own H.264 file in ``scratch``: cut from one decode of the mosaic when the
    three views fit :data:`VIEWS_IN_MEMORY_BYTES`, else streamed view by view (one frame at a time)."""
    held = None
    if run.video is not None:
        info = probe(run.video)
        if run.n_frames * info.width * info.height * 3 * 3 // 4 <= VIEWS_IN_MEMORY_BYTES:
            held = _all_views(run)
    out = {}
    for view, _, _ in MOSAIC_VIEWS:
        dest = scratch / f"{view}.mp4"
        n = encode_h264(dest, held[view] if held is not None else iter_view_frames(run, view), fps)
        require(n == run.n_frames, run.video or run.path / FRAMES_DIR / view,
                f"{view}: {n} frames decoded, {run.n_frames} counted")
        out[view] = dest
    return out


# ----------------------------------------------------------------------------------------------
# Import


def rollout_args(run: OfflineRun, videos: dict[str, Path], ds: LeRobotDataset | None, fps: float) -> dict[str, Any]:
    """``SessionWriter.add_rollout`` keyword arguments for ``run``."""
    meta = run.metadata
    args: dict[str, Any] = dict(
        kind=run.kind,
        actions=run.actions,
        states=run.states,
        prompt=run.prompt,
        episode_index=run.gt.episode,
        start_frame=run.gt.start_frame,
        fps=fps,
        # every one of a chunk's actions runs before the next chunk (fed the last of them)
        executed_per_chunk=run.actions.shape[1],
        frames_per_chunk=run.frames_per_chunk,
        videos=videos,
        extra={"source": {"format": FORMAT, "path": str(run.path.resolve()), "name": run.path.resolve().name,
                          **{k: meta[k] for k in ("action_seed", "action_seeds", "num_inference_steps",
                                                   "lora_weights", "decoded_frame_count") if k in meta}},
               "warnings": run.warnings},  # the list, so what is added below lands in it too
    )
    if ds is not None and run.gt.episode is None:
        run.warnings.append(f"no GT episode for the dataset: pass --episode N, or write it in {SIDECAR}")
    elif ds is not None and run.gt.episode is not None and run.gt.episode not in ds.episode_indexes():
        # shown without GT joints; reading the session says why (GroundTruth.warning), as for any session
        run.warnings.append(missing_episode(ds, run.gt.episode))
    elif ds is not None and run.gt.episode is not None:
        where = run.path / SIDECAR
        ep = ds.episode(run.gt.episode)
        require(run.gt.start_frame < ep.length, where,
                f"start_frame: {run.gt.start_frame} lies beyond episode {run.gt.episode} ({ep.length} frames)")
        args["gt_actions"] = ep.action[run.gt.start_frame:]
        args["gt_episode_length"] = ep.length
    if not run.warnings:
        del args["extra"]["warnings"]
    return args


def _session_dataset(runs: list[Path], dataset: str | Path | None) -> str | Path | None:
    """The one GT dataset of the session: ``dataset``, else the one the runs' sidecars agree on."""
    if dataset is not None:
        return dataset
    named = set()
    for path in runs:
        try:
            link = _gt_link(path, None)
        except InspectorError:
            continue  # the run reports it when read
        if link.dataset is not None:
            named.add(link.dataset)
    return named.pop() if len(named) == 1 else None


def import_offline(
    src: str | Path,
    dest: str | Path,
    *,
    dataset: str | Path | None = None,
    episode: int | None = None,
    start_frame: int | None = None,
    fps: float | None = None,
    overwrite: bool = False,
    keep_going: bool = False,
    log: Callable[[str], None] = print,
) -> tuple[Path, dict[str, InspectorError]]:
    """Import every run under ``src`` into a new session at ``dest``.

    Args:
        dataset: a LeRobot dataset holding the GT episode (default: the sidecars' ``dataset``).
        episode, start_frame, fps: the GT episode, the frame the run started at, and the action
            rate [Hz]; each overrides the sidecars'.
        keep_going: a bad run is returned in the errors and the others are imported; otherwise
            the first bad run raises and nothing is written.

    Returns:
        (session directory, {tag: error} of the runs left out).
    """
    src = Path(src)
    runs = find_runs(src)
    if not runs:
        raise InspectorError(src, f"no {LAYOUT_NAME[:-1]} found (expected {ACTIONS_CSV})")
    check_apart(dest, src)
    ds_name = _session_dataset(runs, dataset)
    ds = LeRobotDataset(find_dataset(ds_name)) if ds_name is not None else None
    if ds is not None:
        check_apart(dest, ds.root, "the GT dataset")
    check_episode_flag(ds, episode)
    if ds is not None and ds.units.arm != UNITS.arm:
        raise InspectorError(ds.root, f"arm units {ds.units.label()}: offline-inference actions are in degrees; "
                                      "its GT would not compare")
    link = GtLink(None, episode, 0, fps)
    errors: dict[str, InspectorError] = {}
    used: set[str] = set()
    with SessionWriter.create(dest, name=Path(dest).name, units=UNITS, model={"name": "DreamZero-SO101"},
                              dataset=str(Path(ds.root).resolve()) if ds is not None else None,
                              overwrite=overwrite) as writer, \
            tempfile.TemporaryDirectory(prefix="inspector-offline-") as scratch:
        for path in runs:
            tag = _unique_tag(path, src, used)
            try:
                run = read_run(path, link, start_frame)
                if run.gt.dataset is not None and (ds is None or Path(run.gt.dataset).resolve() != ds.root.resolve()):
                    run.warnings.append(f"{SIDECAR} names the dataset {run.gt.dataset}, but the session's GT "
                                        f"dataset is {ds.root if ds is not None else 'none'}: no GT from it")
                rate = run.gt.fps or (ds.fps if ds is not None else DEFAULT_ACTION_FPS)
                view_dir = Path(scratch) / tag
                view_dir.mkdir()
                args = rollout_args(run, _write_views(run, view_dir, _video_fps(run)), ds, rate)
                writer.add_rollout(tag, **args)
            except InspectorError as exc:
                if not keep_going:
                    raise
                errors[tag] = exc
                log(f"{tag}: error: {exc}")
                continue
            log(f"{tag}: {run.kind}, {run.n_chunks} chunk(s) x {run.actions.shape[1]} steps, "
                f"{run.n_frames} frames, {'GT joints' if 'gt_actions' in args else 'no GT joints'}, "
                f"prompt {run.prompt!r}" + "".join(f"; warning: {w}" for w in run.warnings))
    return Path(dest), errors


def _video_fps(run: OfflineRun) -> float:
    fps = probe(run.video).fps if run.video is not None else 0.0
    return fps if fps > 0 else DEFAULT_ACTION_FPS


def _unique_tag(path: Path, root: Path, used: set[str]) -> str:
    base = tag_from_name(path.name if path != root else root.resolve().name)
    tag, n = base, 2
    while tag in used:
        tag = f"{base}_{n}"
        n += 1
    used.add(tag)
    return tag


def recognises(path: Path) -> bool:
    """At least one run at or under ``path``."""
    return bool(find_runs(path))


def import_command(src: str | Path, dest: str | Path, *, overwrite: bool = False, dataset: str | None = None,
                   episode: int | None = None, start_frame: int | None = None, fps: float | None = None) -> Path:
    """``inspector import dreamzero-offline SRC -o DEST [--dataset --episode --start-frame --fps]``."""
    return import_offline(src, dest, dataset=dataset, episode=episode, start_frame=start_frame, fps=fps,
                          overwrite=overwrite)[0]


def load_in_memory(src: Path, dataset: str | Path | None = None) -> InMemory:
    """Import into a temporary session (for ``report``/``serve``/``export``); a bad run is left
    out and returned among the errors, the others are imported."""
    return import_temporarily(Path(src).resolve().name, lambda dest: import_offline(
        src, dest, dataset=dataset, keep_going=True, log=lambda _: None)[1])


# ----------------------------------------------------------------------------------------------
# info


def describe(src: Path, calibration: str | None = None) -> dict[str, Any]:
    """What ``inspector info`` says about the runs under ``src`` (nothing decoded; the runs'
    joints need no ``calibration``)."""
    runs: list[dict[str, Any]] = []
    errors: dict[str, str] = {}
    used: set[str] = set()
    for path in find_runs(src):
        tag = _unique_tag(path, src, used)
        try:
            run = read_run(path)
        except InspectorError as exc:
            errors[tag] = str(exc)
            continue
        runs.append({"tag": tag, "kind": run.kind, "n_chunks": run.n_chunks, "horizon": int(run.actions.shape[1]),
                     "frames": run.n_frames, "frames_per_chunk": run.frames_per_chunk,
                     "views": [v for v, _, _ in MOSAIC_VIEWS],
                     "video": MOSAIC_VIDEO if run.video is not None else f"{FRAMES_DIR}/<view>/frame_NNN.png",
                     "fps": run.gt.fps or DEFAULT_ACTION_FPS, "prompt": run.prompt,
                     "gt": {"dataset": run.gt.dataset, "episode": run.gt.episode, "start_frame": run.gt.start_frame}
                     if run.gt.episode is not None else None,
                     "warnings": run.warnings + ([] if run.gt.episode is not None else
                                                 [f"no GT: pass --dataset and --episode, or write {SIDECAR}"])})
    return {"format": FORMAT, "layout": LAYOUT_NAME, "units": UNITS.to_json(), "units_label": UNITS.label(),
            "runs": runs, **({"errors": errors} if errors else {})}


def format_description(info: dict[str, Any]) -> str:
    lines = [f"{info['layout']}: {len(info['runs'])} run(s), units: {info['units_label']}"]
    width = max([12] + [len(r["tag"]) for r in info["runs"]])
    lines.append(f"{'run':<{width}} {'kind':<15} {'chunks':>6} {'frames':>6} {'fps':>5}  {'GT':<12}  views")
    for r in info["runs"]:
        gt = r["gt"]
        where = f"ep {gt['episode']} @ {gt['start_frame']}" if gt else "none"
        lines.append(f"{r['tag']:<{width}} {r['kind']:<15} {r['n_chunks']:>6} {r['frames']:>6} "
                     f"{r['fps']:>5g}  {where:<12}  {', '.join(r['views'])} ({r['video']})")
        lines += [f"{'':<{width}} warning: {w}" for w in r["warnings"]]
    for tag, err in info.get("errors", {}).items():
        lines.append(f"{tag:<{width}} error: {err}")
    return "\n".join(lines)
