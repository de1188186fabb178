"""Import DreamZero's served predictions (dreamzero0/dreamzero ``eval_utils/serve_dreamzero_wan22.py``
run with ``--save_video_pred``) into a native session.

What the policy server writes, at each session's reset (the next session's first request)::

    video_pred_output/NNNNNN_<prompt>_<%m_%d_%H_%M_%S>.mp4

``NNNNNN`` counts the ``.mp4`` files already in the directory; ``<prompt>`` is the session's
prompt with spaces as ``_`` and only letters, digits and ``_-.`` kept, at most 80 characters
(``no_prompt`` when empty). The video (5 fps, libx264) holds the frames the Wan VAE decodes from the
latents of every inference call in order: the first call returns the conditioning image's latent
and ``num_frame_per_block`` (2) new ones, each later call 2 more; T latents decode to 1 + 4 (T - 1)
frames, so n calls give 1 + 8 n frames: the conditioning image, then 8 imagined frames per call.
Each frame tiles the model's views as its transform does (DROID: the wrist view, its pixels doubled
across the width, over the two exterior views; the SO-101 mosaic: front | top over gripper | black).
No actions are saved.

Each file becomes one video-only autoregressive rollout: one chunk per inference call, its 8
imagined frames (the conditioning frame is an observation, not imagined, and is left out), the views
cut from the tiles. Imagined frame ``j`` of call ``k`` shows step ``k E + (j + 1) S`` (``E`` the
actions the client executes per call, its ``open_loop_horizon``: 8; ``S`` the steps per imagined
frame: the call's 24 actions over its 8 frames, 3).

Given the run's recording (a LeRobot dataset episode, or the client's ``episode_N.mp4`` of
``eval_utils/run_sim_eval.py``: [right | wrist | left] tiles, one frame per control step at 15 Hz,
frame ``t`` seen before action ``t``), the recording's frame at that step is carried as the GT of
each imagined frame: the rollout's GT views pair frame by frame with its imagined ones.
"""

from __future__ import annotations

import hashlib
import re
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ...errors import InspectorError, require
from ...units import Units
from ..lerobot_dataset import LeRobotDataset, find_dataset
from ..session import SessionWriter, check_apart
from ..video import VideoClip, encode_h264, probe
from .in_memory import InMemory, import_temporarily
from .shared import MAX_TAG_CHARS, check_episode_flag, tag_from_name

FORMAT = "dreamzero-served"
LAYOUT_NAME = "DreamZero served predictions"
LAYOUT_HINT = "video_pred_output/NNNNNN_<prompt>_<timestamp>.mp4"
# serve_dreamzero_wan22.py's f"{len(existing):06}_{safe_prompt}_{%m_%d_%H_%M_%S}.mp4"
NAME = re.compile(r"^(?P<number>\d{6,})_(?P<prompt>.+)_(?P<stamp>\d\d_\d\d_\d\d_\d\d_\d\d)\.mp4$")
NO_PROMPT = "no_prompt"
# 2 latents per call (num_frame_per_block) x 4 frames per latent (the Wan VAE's time stride).
FRAMES_PER_CALL = 8
LEADING_FRAMES = 1  # the conditioning image's latent, decoded once at the start
# The client's open_loop_horizon: actions executed per inference call.
EXECUTED_PER_CALL = 8
# 24 actions per call (action_horizon) over its 8 frames: an imagined frame every 3 steps
# (the 15 Hz control rate over the video's 5 fps).
STEPS_PER_FRAME = 3
# DROID's control rate in sim_evals, and the fps of the client's episode_N.mp4 [Hz].
CONTROL_HZ = 15.0
SERVED_FPS = 5.0
# Tile layouts: rows by ';', cells by ','; '-' an unused cell; a view over several cells spans them
# (its pixels repeated over them, as DROID's wrist view: every other column is taken back).
GRIDS = {
    "droid": "wrist,wrist;exterior_1,exterior_2",
    "so101": "front,top;gripper,-",
}
SO101_MOSAIC_SIZE = (640, 352)  # (width, height): four 320x176 views
# run_sim_eval.py's per-episode video: [right_image | wrist | left_image], 224x224 each; the
# client sends right_image as exterior_image_0_left, which the server feeds as exterior_image_1_left.
CLIENT_GRID = "exterior_1,wrist,exterior_2"
CLIENT_VIDEO = re.compile(r"^episode_(\d+)\.mp4$")
# A session states its arm's units; no joints come from a served video (DROID's would be radians,
# which the session format does not hold), so without a dataset this is only the default.
UNITS = Units("degrees")


# ----------------------------------------------------------------------------------------------
# Tile layouts


@dataclass(frozen=True)
class Grid:
    """A tile layout: ``cells[row][col]`` the view there (None: unused)."""

    spec: str
    cells: tuple[tuple[str | None, ...], ...]

    @property
    def shape(self) -> tuple[int, int]:
        return len(self.cells), len(self.cells[0])

    @property
    def views(self) -> list[str]:
        seen: list[str] = []
        for row in self.cells:
            for c in row:
                if c is not None and c not in seen:
                    seen.append(c)
        return seen

    def span(self, view: str) -> tuple[int, int, int, int]:
        """(row, col, rows, cols) of the cells ``view`` covers."""
        at = [(r, c) for r, row in enumerate(self.cells) for c, v in enumerate(row) if v == view]
        rows, cols = {r for r, _ in at}, {c for _, c in at}
        return min(rows), min(cols), len(rows), len(cols)

    def check_divides(self, width: int, height: int, path: Path) -> None:
        rows, cols = self.shape
        require(width % cols == 0 and height % rows == 0, path,
                f"tile layout {self.spec!r} ({rows} row(s) x {cols} column(s)) does not divide the "
                f"{width}x{height} frame")

    def cut(self, frame: npt.NDArray[np.uint8], view: str) -> npt.NDArray[np.uint8]:
        """``view``'s pixels of one tiled frame (a view over several cells: every r-th row and
        c-th column, undoing the pixel repetition that stretched it over them)."""
        rows, cols = self.shape
        h, w = frame.shape[0] // rows, frame.shape[1] // cols
        r, c, nr, nc = self.span(view)
        return np.ascontiguousarray(frame[r * h:(r + nr) * h:nr, c * w:(c + nc) * w:nc])


def parse_grid(spec: str) -> Grid:
    """A :class:`Grid` from ``--views``: a preset name (:data:`GRIDS`) or a spec such as
    ``front,top;gripper,-``.

    Raises:
        InspectorError: ragged rows, a bad name, or a view whose cells are not one rectangle.
    """
    text = GRIDS.get(spec, spec)
    rows = [[c.strip() for c in row.split(",")] for row in text.split(";")]
    where = Path("--views")
    require(len({len(r) for r in rows}) == 1, where,
            f"{spec!r}: every row needs as many cells (rows by ';', cells by ','); presets: {', '.join(GRIDS)}")
    for name in {c for r in rows for c in r}:
        require(name == "-" or re.fullmatch(r"[A-Za-z0-9_.-]+", name) is not None, where,
                f"{spec!r}: {name!r} is not a view name (letters, digits, _.-) or '-'")
    grid = Grid(spec, tuple(tuple(None if c == "-" else c for c in r) for r in rows))
    require(bool(grid.views), where, f"{spec!r}: no view")
    for view in grid.views:
        r, c, nr, nc = grid.span(view)
        block = [grid.cells[i][j] for i in range(r, r + nr) for j in range(c, c + nc)]
        require(all(v == view for v in block), where, f"{spec!r}: {view}'s cells are not one rectangle")
    return grid


def default_grid(width: int, height: int) -> Grid:
    """The SO-101 mosaic for its 640x352 frames, else DreamZero's DROID layout."""
    return parse_grid("so101" if (width, height) == SO101_MOSAIC_SIZE else "droid")


# ----------------------------------------------------------------------------------------------
# Finding served videos


@dataclass
class ServedVideo:
    """One served video; ``tag`` its rollout's tag (unique among the directory's, see
    :func:`find_served`)."""

    path: Path
    number: int
    prompt: str
    stamp: str
    tag: str = ""

    def __post_init__(self) -> None:
        self.tag = self.tag or tag_from_name(self.path.stem)


def parse_name(path: Path) -> ServedVideo | None:
    m = NAME.match(path.name)
    if m is None:
        return None
    prompt = "" if m["prompt"] == NO_PROMPT else m["prompt"].replace("_", " ")
    return ServedVideo(path, int(m["number"]), prompt, m["stamp"])


def find_served(src: Path) -> list[ServedVideo]:
    """The served videos at ``src`` (one file, or a directory's), by their number, each with its own
    tag (:func:`distinct_tags`)."""
    if src.is_file():
        one = parse_name(src)
        return [one] if one is not None else []
    if not src.is_dir():
        return []
    found = [v for v in (parse_name(p) for p in src.iterdir() if p.suffix == ".mp4") if v is not None]
    return distinct_tags(sorted(found, key=lambda v: (v.number, v.path.name)))


def distinct_tags(videos: list[ServedVideo]) -> list[ServedVideo]:
    """``videos`` with no two sharing a tag. Names that differ only in characters a tag cannot hold
    (``000003_a b_...`` and ``000003_a_b_...``), or only in case (one directory on a case-blind
    disk), make the same tag: each of those gets a suffix from a hash of its file name, so its tag
    does not depend on the order the directory lists them in."""
    by_tag: dict[str, list[ServedVideo]] = {}
    for v in videos:
        by_tag.setdefault(v.tag.lower(), []).append(v)
    taken = {v.tag.lower() for v in videos}
    for group in by_tag.values():
        for v in group if len(group) > 1 else []:
            digest = hashlib.sha1(v.path.name.encode("utf-8", "surrogateescape")).hexdigest()
            width = 8
            tag = _suffixed(v.tag, digest[:width])
            while tag.lower() in taken and width < len(digest):  # a hash suffix that another name spells
                width += 4
                tag = _suffixed(v.tag, digest[:width])
            v.tag = tag
            taken.add(tag.lower())
    return videos


def _suffixed(tag: str, suffix: str) -> str:
    """``tag_suffix`` within the tag length, cutting ``tag``."""
    head = tag[: MAX_TAG_CHARS - len(suffix) - 1].rstrip("._-")
    return f"{head}_{suffix}" if head else suffix


def is_served(path: Path) -> bool:
    return bool(find_served(path))


recognises = is_served


# ----------------------------------------------------------------------------------------------
# Timing


@dataclass(frozen=True)
class Timing:
    """How imagined frames map to control steps (flags; defaults from DreamZero's server and client)."""

    frames_per_call: int = FRAMES_PER_CALL
    executed_per_call: int = EXECUTED_PER_CALL
    steps_per_frame: float = STEPS_PER_FRAME
    control_hz: float | None = None  # None: the recording's fps, else CONTROL_HZ

    def n_calls(self, n_frames: int, path: Path) -> int:
        """Inference calls behind a video of ``n_frames`` (1 + F n).

        Raises:
            InspectorError: a count no whole number of calls gives.
        """
        f = self.frames_per_call
        require(n_frames > LEADING_FRAMES and (n_frames - LEADING_FRAMES) % f == 0, path,
                f"{n_frames} frames: not 1 + {f} n (a conditioning frame, then {f} per inference call); "
                "--frames-per-call sets the frames each call adds")
        return (n_frames - LEADING_FRAMES) // f

    def frame_steps(self, n_calls: int) -> npt.NDArray[np.float64]:
        """(n F,) the step each imagined frame shows (frame j of call k: k E + (j + 1) S)."""
        k, j = np.divmod(np.arange(n_calls * self.frames_per_call), self.frames_per_call)
        return k * self.executed_per_call + (j + 1) * self.steps_per_frame


# ----------------------------------------------------------------------------------------------
# Recordings


@dataclass
class Recording:
    """What the cameras saw while the policy ran: per view, a clip whose frame ``i`` is the
    recording's frame ``i``; ``fps`` its frame rate; joints where a dataset recorded them."""

    path: Path
    fps: float
    length: int
    clips: dict[str, VideoClip]
    grid: Grid | None = None  # a tiled client video: views cut from it
    actions: npt.NDArray[np.float64] | None = None
    units: Units | None = None
    episode: int | None = None
    warnings: list[str] = field(default_factory=list)
    _held: dict[tuple, dict[int, npt.NDArray[np.uint8]]] = field(default_factory=dict, repr=False)

    def frames(self, view: str, wanted: list[int]) -> Iterator[npt.NDArray[np.uint8]]:
        """The recording's frames ``wanted`` (any order, repeats allowed) of ``view``: each file
        decoded once for every view it tiles (only the frames wanted are kept)."""
        clip = self.clips[view]
        held = self._held.get(clip.key)
        if held is None:
            keep = set(wanted)
            held = {}
            for i, rgb in clip.iter_frames():
                if i in keep:
                    held[i] = rgb
                if i >= max(keep):
                    break
            self._held = {clip.key: held}  # one file's frames at a time
        for i in wanted:
            require(i in held, clip.path, f"frame {i}: not decoded (the file holds fewer frames than it says)")
            yield self.grid.cut(held[i], view) if self.grid is not None else held[i]


def client_recording(path: Path) -> Recording:
    """The client's ``episode_N.mp4``: its tiles are the views of :data:`CLIENT_GRID`."""
    info = probe(path)
    grid = parse_grid(CLIENT_GRID)
    grid.check_divides(info.width, info.height, path)
    clip = VideoClip(path)
    return Recording(path, info.fps, len(clip.timestamps()), {v: clip for v in grid.views}, grid=grid)


def dataset_recording(ds: LeRobotDataset, episode: int) -> Recording:
    ep = ds.episode(episode)
    return Recording(ds.root, ds.fps, ep.length, {c: ep.clip_from(c, 0) for c in ep.cameras},
                     actions=ep.action, units=ds.units, episode=episode)


def _client_video(recording: Path, episode: int) -> Path:
    if recording.is_file():
        return recording
    found = recording / f"episode_{episode}.mp4"
    require(found.is_file(), recording, f"no episode_{episode}.mp4 (run_sim_eval.py's video of episode {episode})")
    return found


# ----------------------------------------------------------------------------------------------
# Import


def rollout_args(video: ServedVideo, grid: Grid | None, timing: Timing, recording: Recording | None,
                 scratch: Path) -> dict[str, Any]:
    """``SessionWriter.add_rollout`` keyword arguments for one served video (views written to
    ``scratch``).

    Raises:
        InspectorError: a frame count no whole number of calls gives, a tile layout that does not
            divide the frame, a recording that ends before the last call.
    """
    info = probe(video.path)
    grid = grid or default_grid(info.width, info.height)
    grid.check_divides(info.width, info.height, video.path)
    n_frames = len(VideoClip(video.path).timestamps())
    n_calls = timing.n_calls(n_frames, video.path)
    control_hz = timing.control_hz or (recording.fps if recording is not None else CONTROL_HZ)
    scratch.mkdir(parents=True)
    videos: dict[str, Path] = {}
    # decoded once per view, one frame in memory at a time (holding the tiles to decode them once
    # saved no CPU time, measured: the H.264 encodes dominate, and cost ~200 MB for 30 calls)
    for view in grid.views:
        videos[view] = scratch / f"{view}.mp4"
        encode_h264(videos[view], (grid.cut(rgb, view) for i, rgb in VideoClip(video.path).iter_frames()
                                   if i >= LEADING_FRAMES), SERVED_FPS)
    steps = timing.frame_steps(n_calls)
    extra: dict[str, Any] = {
        "source": {"format": FORMAT, "path": str(video.path.resolve()), "number": video.number,
                   "saved": video.stamp, "grid": grid.spec},
        "timing": {"frames_per_call": timing.frames_per_call, "executed_per_call": timing.executed_per_call,
                   "steps_per_frame": timing.steps_per_frame, "control_hz": control_hz,
                   "frame_steps": [round(float(s), 6) for s in steps]},
    }
    args: dict[str, Any] = dict(
        kind="autoregressive" if n_calls > 1 else "single_chunk", actions=None, n_chunks=n_calls,
        horizon=timing.executed_per_call, prompt=video.prompt, fps=control_hz,
        executed_per_chunk=timing.executed_per_call, frames_per_chunk=timing.frames_per_call,
        videos=videos, extra=extra)
    if recording is not None:
        args.update(_recording_args(video, recording, grid.views, steps, n_calls, timing, control_hz, scratch, extra))
    return args


def _recording_args(video: ServedVideo, rec: Recording, imagined: list[str], steps: npt.NDArray[np.float64],
                    n_calls: int, timing: Timing, control_hz: float, scratch: Path,
                    extra: dict[str, Any]) -> dict[str, Any]:
    """The recording's frames at the steps the imagined frames show, carried as GT views."""
    last_call = (n_calls - 1) * timing.executed_per_call
    last_call_frame = round(last_call * rec.fps / control_hz)
    require(last_call_frame < rec.length, rec.path,
            f"{rec.length} frames, but {video.path.name}'s {n_calls} calls run to step {last_call} "
            f"(frame {last_call_frame} at {rec.fps:g} fps): the recording is shorter than the dream")
    wanted = [round(float(s) * rec.fps / control_hz) for s in steps]
    # frames past the recording's end: the first one ends the carried GT (the later ones have none)
    paired = next((i for i, w in enumerate(wanted) if w >= rec.length), len(wanted))
    gt_frames = wanted[:paired]
    gt_videos: dict[str, Path] = {}
    shared = [v for v in rec.clips if v in imagined]
    if not shared:
        rec.warnings.append(f"{rec.path.name}: no view in common with the imagined ones "
                            f"({', '.join(imagined)}; recorded: {', '.join(rec.clips)}): nothing to compare")
    for view in shared if gt_frames else []:
        gt_videos[view] = scratch / f"gt_{view}.mp4"
        encode_h264(gt_videos[view], rec.frames(view, gt_frames), SERVED_FPS)
    extra["recording"] = {"path": str(rec.path.resolve()), "episode": rec.episode, "fps": rec.fps,
                          "frames": rec.length, "frame_of_imagined": gt_frames,
                          "imagined_without_gt": len(wanted) - paired}
    if rec.warnings:
        extra["warnings"] = list(rec.warnings)
    out: dict[str, Any] = {"gt_videos": gt_videos, "gt_episode_length": round(rec.length * control_hz / rec.fps)}
    if rec.actions is not None:
        out["gt_actions"] = rec.actions
    if rec.episode is not None:
        out["episode_index"] = rec.episode
    return out


def import_served(src: str | Path, dest: str | Path, *, views: str | None = None, timing: Timing = Timing(),
                  dataset: str | Path | None = None, recording: str | Path | None = None,
                  episode: int | None = None, overwrite: bool = False, keep_going: bool = False,
                  log: Callable[[str], None] = print) -> tuple[Path, dict[str, InspectorError]]:
    """Import every served video at ``src`` (a file, or the directory the server wrote).

    Args:
        views: the tile layout (``--views``: a preset of :data:`GRIDS` or a spec); None: by frame size.
        dataset, recording: the run's recording, a LeRobot dataset or the client's video(s)
            (``episode_N.mp4``, or their directory); the k-th served video (by number) pairs with
            episode ``episode + k`` (default 0).
        keep_going: a bad video is returned among the errors and the others are imported.

    Returns:
        (session directory, {tag: error} of the videos left out).
    """
    src = Path(src)
    served = find_served(src)
    if not served:
        raise InspectorError(src, f"no {LAYOUT_NAME.lower()} ({LAYOUT_HINT})")
    check_apart(dest, src)
    grid = parse_grid(views) if views is not None else None
    ds = LeRobotDataset(find_dataset(dataset)) if dataset is not None else None
    if ds is not None:
        check_apart(dest, ds.root, "the recording's dataset")
        check_episode_flag(ds, episode)
    units = ds.units if ds is not None else UNITS
    errors: dict[str, InspectorError] = {}
    with SessionWriter.create(dest, name=Path(dest).name, units=units, model={"name": "DreamZero (served)"},
                              overwrite=overwrite) as writer, \
            tempfile.TemporaryDirectory(prefix="inspector-served-") as scratch:
        for k, video in enumerate(served):
            try:
                rec = None
                if ds is not None:
                    rec = dataset_recording(ds, (episode or 0) + k)
                elif recording is not None:
                    rec = client_recording(_client_video(Path(recording), (episode or 0) + k))
                # numbered, not tagged: a tag is a file name's, and two names may only differ in case
                args = rollout_args(video, grid, timing, rec, Path(scratch) / f"{k:06}")
                writer.add_rollout(video.tag, **args)
            except InspectorError as exc:
                if not keep_going:
                    raise
                errors[video.tag] = exc
                log(f"{video.tag}: error: {exc}")
                continue
            log(f"{video.tag}: {args['n_chunks']} call(s), views {', '.join(args['videos'])}, "
                f"prompt {video.prompt!r}" + (f", recording {rec.path.name}" if rec is not None else ""))
    return Path(dest), errors


def import_command(src: str | Path, dest: str | Path, *, overwrite: bool = False, views: str | None = None,
                   frames_per_call: int = FRAMES_PER_CALL, open_loop_horizon: int = EXECUTED_PER_CALL,
                   steps_per_frame: float = STEPS_PER_FRAME, control_hz: float | None = None,
                   dataset: str | None = None, recording: str | None = None, episode: int | None = None) -> Path:
    """``inspector import dreamzero-served SRC -o DEST`` with its layout, timing and recording flags."""
    timing = Timing(frames_per_call=frames_per_call, executed_per_call=open_loop_horizon,
                    steps_per_frame=steps_per_frame, control_hz=control_hz)
    return import_served(src, dest, views=views, timing=timing, dataset=dataset, recording=recording,
                         episode=episode, overwrite=overwrite)[0]


def load_in_memory(src: Path, dataset: str | Path | None = None) -> InMemory:
    """Import into a temporary session (``report``/``serve``/``export``) with the default layout
    and timing; bad videos are left out and returned among the errors. ``dataset``: the recording."""
    return import_temporarily(Path(src).resolve().name.removesuffix(".mp4"), lambda dest: import_served(
        src, dest, dataset=dataset, keep_going=True, log=lambda _: None)[1])


# ----------------------------------------------------------------------------------------------
# info


def describe(src: Path, calibration: str | None = None) -> dict[str, Any]:
    """What ``inspector info`` says about served predictions (nothing decoded; no ``calibration``)."""
    rows, errors = [], {}
    for video in find_served(src):
        try:
            info = probe(video.path)
            grid = default_grid(info.width, info.height)
            n_frames = len(VideoClip(video.path).timestamps())
            n_calls = Timing().n_calls(n_frames, video.path)
        except InspectorError as exc:
            errors[video.tag] = str(exc)
            continue
        rows.append({"tag": video.tag, "number": video.number, "prompt": video.prompt, "saved": video.stamp,
                     "frames": n_frames, "calls": n_calls, "width": info.width, "height": info.height,
                     "views": grid.views, "grid": grid.spec, "video_only": True})
    return {"format": FORMAT, "layout": LAYOUT_NAME, "rollouts": rows, **({"errors": errors} if errors else {})}


def format_description(info: dict[str, Any]) -> str:
    lines = [f"{info['layout']}: {len(info['rollouts'])} video(s), video only (the server saves no actions)"]
    width = max([12] + [len(r["tag"]) for r in info["rollouts"]])
    lines.append(f"{'tag':<{width}} {'calls':>5} {'frames':>6}  {'size':<9}  views  prompt")
    for r in info["rollouts"]:
        lines.append(f"{r['tag']:<{width}} {r['calls']:>5} {r['frames']:>6}  {r['width']}x{r['height']:<5}  "
                     f"{', '.join(r['views'])}  {r['prompt'] or '-'}")
    lines += [f"{k} error: {v}" for k, v in info.get("errors", {}).items()]
    return "\n".join(lines)
