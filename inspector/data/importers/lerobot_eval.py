"""Import ``lerobot-eval`` outputs (huggingface/lerobot ``lerobot_eval.py``) into a native session.

What a policy evaluation in simulation leaves in its output directory::

    <output_dir>/
      eval_info.json                  per_task[]: task_group, task_id, metrics {sum_rewards,
                                      max_rewards, successes, video_paths, predicted_video_paths}
                                      (one value per episode); per_group; overall
      videos/<group>_<id>/eval_episode_N.mp4   what the simulator rendered (N counts per task)
      videos/<group>_<id>/pred_episode_N.mp4   a world-action policy's predicted video (views side
                                               by side, at the env's fps)
      recordings/<group>_<id>/        with --eval.recording=true: a LeRobot v3.0 dataset per task
                                      (observation.state, action, next.reward, next.success,
                                      next.done, task, the env's cameras); env_<k>/ per env when
                                      several envs ran side by side

Each evaluated episode becomes one rollout of a single chunk spanning the episode: the recorded
``action`` (what the policy commanded) where a rollout has its prediction, the recorded
``observation.state`` (what the arm executed) where it has GT, the predicted video as its imagined
view and what the simulator rendered (the render, the env's cameras) as its GT views, one frame per
step. Success and rewards come from ``eval_info.json`` (``extra.outcome``). An episode without a
recording (lerobot-eval's default) is a video-only rollout: the predicted video, split into the
env's cameras (its width over the render's), is its imagined views, the first named ``render``
beside the simulator's render as its GT; one step per predicted frame, no joints.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ...errors import InspectorError, require
from ...schema import number_problem, shown, whole_number
from ...units import Units
from ..lerobot_dataset import INFO_PATH, LeRobotDataset
from ..session import SessionWriter, check_apart, check_json_size
from ..video import VideoClip, encode_h264, probe
from .in_memory import InMemory, import_temporarily
from .shared import tag_from_name

FORMAT = "lerobot-eval"
LAYOUT_NAME = "lerobot-eval outputs"
EVAL_INFO = "eval_info.json"
VIDEOS_DIR = "videos"
RECORDINGS_DIR = "recordings"
RENDER_VIEW = "render"  # the simulator's rendered video (videos/<task>/eval_episode_N.mp4)
PREDICTED_VIEW = "predicted"
METRIC_LISTS = ("sum_rewards", "max_rewards", "successes")
# Episodes of a task that the output directory holds nothing of (no video, no recording), and so
# nothing to show of, listed one by one (each an error saying so); past these, one error of the
# task counts the rest. eval_info.json can list any number of episodes: a million such rows would
# be gigabytes of objects and a minute of look-ups for nothing.
MAX_UNHELD_LISTED = 100
# The two arms of an evaluated episode, in the words the app, report and export use.
ARM_LABELS = {"pred": "commanded (action)", "gt": "executed (state)", "drift": "tracking error"}


@dataclass
class EvalEpisode:
    """One evaluated episode, located (nothing decoded).

    Attributes:
        task: ``<group>_<id>``, as lerobot-eval names the task's folders.
        index: the episode's number within its task (N of eval_episode_N).
        recording: (dataset, episode index in it), or None without a recording.
        render, predicted: the simulator's and the policy's videos, or None.
    """

    task: str
    task_group: str
    task_id: int
    index: int
    success: bool | None
    sum_reward: float | None
    max_reward: float | None
    render: Path | None = None
    predicted: Path | None = None
    recording: tuple[LeRobotDataset, int] | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def tag(self) -> str:
        return tag_from_name(f"{self.task}_ep{self.index:03d}")

    def outcome(self) -> dict[str, Any]:
        return {"task": self.task, "task_group": self.task_group, "task_id": self.task_id, "episode": self.index,
                "success": self.success, "sum_reward": self.sum_reward, "max_reward": self.max_reward}


def is_eval_output(path: Path) -> bool:
    return path.is_dir() and (path / EVAL_INFO).is_file()


recognises = is_eval_output


# ----------------------------------------------------------------------------------------------
# Reading eval_info.json and locating each episode's files


@dataclass
class EvalTask:
    """What ``eval_info.json`` says of one task, counted over every episode it lists (also those
    not materialised as :class:`EvalEpisode`: see :data:`MAX_UNHELD_LISTED`)."""

    task: str
    episodes: int
    successes: int


def read_eval(root: Path) -> tuple[list[EvalEpisode], dict[str, InspectorError], list[EvalTask]]:
    """Every episode ``eval_info.json`` lists that the directory holds a file of (a video, a
    recording), and the first :data:`MAX_UNHELD_LISTED` of each task that it holds nothing of;
    the others of those are one error per task saying how many. A task whose entry or recording
    is broken is an error of its own (keyed by the task) and the others stay.

    Raises:
        InspectorError: ``eval_info.json`` itself is unreadable or has no ``per_task`` list.
    """
    info_file = root / EVAL_INFO
    info = _read_eval_info(info_file)
    per_task = info.get("per_task")
    if not isinstance(per_task, list):
        raise InspectorError(info_file, f"per_task: expected a list of tasks, found {type(per_task).__name__}")
    episodes: list[EvalEpisode] = []
    errors: dict[str, InspectorError] = {}
    tasks: list[EvalTask] = []
    for i, entry in enumerate(per_task):
        where = f"per_task[{i}]"
        try:
            held, task, unlisted = _task_episodes(root, entry, where)
        except InspectorError as exc:
            name = (f"{entry.get('task_group')}_{entry.get('task_id')}" if isinstance(entry, dict) else where)
            errors[tag_from_name(name)] = exc
            continue
        episodes += held
        tasks.append(task)
        if unlisted:
            first, count = unlisted
            errors[tag_from_name(f"{task.task}_ep{first:03d}_and_later")] = InspectorError(
                Path(RECORDINGS_DIR) / task.task,
                f"{count:,} more episodes from episode {first} on ({EVAL_INFO} {where} lists {task.episodes:,}): "
                "neither a recording nor a video of them, so nothing to show; not listed one by one "
                "(lerobot-eval records them with --eval.recording=true)")
    return episodes, errors, tasks


def _read_eval_info(path: Path) -> dict[str, Any]:
    """``eval_info.json`` as lerobot-eval writes it: Python's JSON, where an average over no
    episodes is ``NaN`` (in per_group / overall, which are not read); the fields read are checked
    where they are used."""
    check_json_size(path)
    try:
        info = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise InspectorError(path, f"cannot read: {exc}") from None
    except (ValueError, RecursionError) as exc:
        raise InspectorError(path, f"invalid JSON: {exc}") from None
    require(isinstance(info, dict), path, "expected a JSON object")
    return info


def _task_episodes(root: Path, entry: Any, where: str
                   ) -> tuple[list[EvalEpisode], EvalTask, tuple[int, int] | None]:
    """The task's episodes that the directory holds a file of, and the first
    :data:`MAX_UNHELD_LISTED` of those it holds nothing of; its counts; and (first, how many) of
    the episodes held nothing of and not listed, or None. What the directory holds is read once
    per task (a listing of ``videos/<task>/``, the recordings' episode indexes), not per episode."""
    info_file = root / EVAL_INFO
    require(isinstance(entry, dict), info_file, f"{where}: expected an object, found {shown(entry)}")
    group, task_id, metrics = entry.get("task_group"), entry.get("task_id"), entry.get("metrics")
    require(isinstance(group, str) and group != "", info_file, f"{where}.task_group: expected a name, found {shown(group)}")
    task_id = whole_number(task_id, info_file, f"{where}.task_id")
    require(isinstance(metrics, dict), info_file, f"{where}.metrics: expected an object, found {shown(metrics)}")
    lists = {}
    for key in METRIC_LISTS:
        values = metrics.get(key, [])
        require(isinstance(values, list), info_file, f"{where}.metrics.{key}: expected a list, found {shown(values)}")
        fine = (all(v is True or v is False for v in values) if key == "successes"
                else all(type(v) is float and math.isfinite(v) for v in values))  # the usual case, fast
        for j, v in enumerate([] if fine else values):
            problem = (None if isinstance(v, bool) else f"expected true or false, found {shown(v)}") \
                if key == "successes" else number_problem(v)
            require(problem is None, info_file, f"{where}.metrics.{key}[{j}]: {problem}")
        lists[key] = values
    n = max(len(v) for v in lists.values())
    require(n > 0, info_file, f"{where}.metrics: no episodes (sum_rewards, max_rewards and successes are empty)")
    task = f"{group}_{task_id}"
    videos = {key: _paths(metrics.get(key, []), info_file, f"{where}.metrics.{key}")
              for key in ("video_paths", "predicted_video_paths")}
    recordings = _recordings(root / RECORDINGS_DIR / task)
    recorded = [ds.episode_indexes() for ds in recordings]
    video_dir = root / VIDEOS_DIR / task
    try:
        in_video_dir = set(os.listdir(video_dir)) if video_dir.is_dir() else set()
    except OSError:
        in_video_dir = set()
    # The episodes the directory may hold a file of, from what it holds (not one look-up per listed episode).
    held = {i * len(recordings) + env for env, indexes in enumerate(recorded) for i in indexes}
    for name in in_video_dir:
        stem, _, number = name.removesuffix(".mp4").rpartition("_")
        if stem in ("eval_episode", "pred_episode") and number.isdigit() and name.endswith(".mp4"):
            held.add(int(number))
    for key in ("video_paths", "predicted_video_paths"):
        held.update(k for k, p in enumerate(videos[key][:n])
                    if os.path.basename(p) in in_video_dir or os.path.isfile(p))
    held = {k for k in held if k < n}
    unheld = n - len(held)
    shown_unheld = list(itertools.islice((k for k in range(n) if k not in held), MAX_UNHELD_LISTED))
    out = []
    for k in sorted(held.union(shown_unheld)):
        env = k % len(recordings) if recordings else 0  # batched envs: episode k ran in env k % n_envs
        index = k // len(recordings) if recordings else k
        ep = EvalEpisode(task, group, task_id, k,
                         success=_at(lists["successes"], k), sum_reward=_at(lists["sum_rewards"], k),
                         max_reward=_at(lists["max_rewards"], k),
                         render=_video(root, task, videos["video_paths"], k, "eval_episode", in_video_dir),
                         predicted=_video(root, task, videos["predicted_video_paths"], k, "pred_episode",
                                          in_video_dir))
        if recordings and index in recorded[env]:
            ep.recording = (recordings[env], index)
        out.append(ep)
    successes = sum(v is True for v in lists["successes"][:n])
    unlisted = None
    if unheld > MAX_UNHELD_LISTED:
        first = next(k for k in range(shown_unheld[-1] + 1, n) if k not in held)
        unlisted = (first, unheld - MAX_UNHELD_LISTED)
    return out, EvalTask(task, n, successes), unlisted


def _at(values: list, k: int) -> Any:
    return values[k] if k < len(values) else None


def _paths(value: Any, file: Path, where: str) -> list[str]:
    require(isinstance(value, list) and all(isinstance(p, str) for p in value), file,
            f"{where}: expected a list of paths, found {value!r}")
    return value


def _video(root: Path, task: str, listed: list[str], k: int, stem: str, in_video_dir: set[str]) -> Path | None:
    """Episode ``k``'s video: the path eval_info.json lists (as written, or moved with the output
    directory: under ``videos/<task>/``), else the name lerobot-eval gives it. ``in_video_dir``:
    the names in ``videos/<task>/``, so that a name not there costs no look-up on disk (this runs
    for every episode eval_info.json lists: strings, not paths, until one is found)."""
    video_dir = root / VIDEOS_DIR / task
    if k < len(listed):
        if os.path.isfile(listed[k]):
            return Path(listed[k])
        name = os.path.basename(listed[k])
        if name in in_video_dir and (video_dir / name).is_file():
            return video_dir / name
    name = f"{stem}_{k}.mp4"
    return video_dir / name if name in in_video_dir and (video_dir / name).is_file() else None


def _recordings(task_dir: Path) -> list[LeRobotDataset]:
    """The task's recorded datasets: the folder itself, or one per env (``env_<k>``, in k order)."""
    if (task_dir / INFO_PATH).is_file():
        roots = [task_dir]
    else:
        envs = [p for p in task_dir.glob("env_*") if p.name[4:].isdigit() and (p / INFO_PATH).is_file()]
        roots = sorted(envs, key=lambda p: int(p.name[4:]))
    return [LeRobotDataset(r, unnamed_joints_in_so101_order=True) for r in roots]


# ----------------------------------------------------------------------------------------------
# Import


def _retimed(clip: VideoClip, n_src: int, n: int) -> Iterator[npt.NDArray[np.uint8]]:
    """``n`` frames of a clip of ``n_src``: frame t is source frame floor(t n_src / n), streamed
    (the same frames when the counts agree; the render's extra last observation is left out)."""
    want = [t * n_src // n for t in range(n)]
    t = 0
    for index, rgb in clip.iter_frames():
        while t < n and want[t] == index:
            yield rgb
            t += 1
        if t >= n:
            return
    require(t == n, clip.path, f"{t} frames decoded, {n} wanted")


def _episode_args(ep: EvalEpisode, scratch: Path, units: Units) -> dict[str, Any]:
    if ep.recording is None:
        return _video_only_args(ep, scratch)
    ds, index = ep.recording
    require(ds.units.arm == units.arm, ds.root / INFO_PATH,
            f"arm units {ds.units.label()} differ from the session's {units.label()}")
    rec = ds.episode(index)
    n = rec.length
    scratch.mkdir(parents=True)
    warnings = list(ep.warnings)
    if ds.unnamed_joints:
        warnings.append(f"{', '.join(ds.unnamed_joints)}: joints not named in {INFO_PATH}; taken in SO-101 order")
    videos: dict[str, Path] = {}
    gt_videos: dict[str, Path] = {}
    for view, src, into in ((PREDICTED_VIEW, ep.predicted, videos), (RENDER_VIEW, ep.render, gt_videos)):
        if src is None:
            continue
        clip = VideoClip(src)
        n_src = len(clip)
        require(n_src >= 1, src, "video has no frames")
        if n_src not in (n, n + 1):
            warnings.append(f"{src.name}: {n_src} frames for {n} steps; frames spread evenly over the steps")
        dest = scratch / f"{view}.mp4"
        encode_h264(dest, _retimed(clip, n_src, n), ds.fps)
        into[view] = dest
    for cam in rec.cameras:
        dest = scratch / f"{cam}.mp4"
        clip = rec.video(cam)
        encode_h264(dest, _retimed(clip, len(clip), n), ds.fps)
        gt_videos[cam] = dest
    return dict(
        kind="single_chunk", actions=rec.action[None], prompt=rec.task or ep.task, episode_index=None,
        start_frame=0, fps=ds.fps, executed_per_chunk=n, frames_per_chunk=n, videos=videos,
        gt_actions=rec.state, gt_videos=gt_videos, gt_episode_length=n,
        extra={"source": {"format": FORMAT, "recording": str(ds.root.resolve()), "recording_episode": index,
                          "render": str(ep.render) if ep.render else None,
                          "predicted": str(ep.predicted) if ep.predicted else None},
               "outcome": ep.outcome(), "arm_labels": dict(ARM_LABELS),
               **({"warnings": warnings} if warnings else {})},
    )


def split_count(predicted: Path, render: Path | None) -> int:
    """How many camera views the predicted video holds side by side: its width over the render's
    (one camera's image) when the heights agree and the width divides; one otherwise."""
    if render is None:
        return 1
    pred, rend = probe(predicted), probe(render)
    if pred.height == rend.height and rend.width > 0 and pred.width % rend.width == 0:
        return max(1, pred.width // rend.width)
    return 1


def imagined_view_names(n_views: int) -> list[str]:
    """The imagined views of a split predicted video: the first camera pairs with the simulator's
    render (``env.render()`` shows the env's first camera), the others are numbered."""
    return [RENDER_VIEW] + [f"camera_{i}" for i in range(1, n_views)]


def _video_only_args(ep: EvalEpisode, scratch: Path) -> dict[str, Any]:
    """An episode run without ``--eval.recording``: no joints, its predicted video split into the
    env's camera views (the first beside the render, which is its GT), one step per frame."""
    if ep.predicted is None and ep.render is None:
        raise InspectorError(Path(VIDEOS_DIR) / ep.task, f"episode {ep.index}: neither a recording nor a video, "
                                                         "so nothing to show (lerobot-eval records joints with "
                                                         "--eval.recording=true)")
    scratch.mkdir(parents=True)
    first = ep.predicted if ep.predicted is not None else ep.render
    assert first is not None
    fps = probe(first).fps
    n = len(VideoClip(first))
    require(n >= 1, first, "video has no frames")
    warnings = list(ep.warnings)
    videos: dict[str, Path] = {}
    gt_videos: dict[str, Path] = {}
    if ep.render is not None:
        clip = VideoClip(ep.render)
        n_src = len(clip)
        require(n_src >= 1, ep.render, "video has no frames")
        if n_src not in (n, n + 1):
            warnings.append(f"{ep.render.name}: {n_src} frames for {n} predicted; frames spread evenly over the steps")
        gt_videos[RENDER_VIEW] = scratch / "gt_render.mp4"
        encode_h264(gt_videos[RENDER_VIEW], _retimed(clip, n_src, n), fps)
    if ep.predicted is not None:
        k = split_count(ep.predicted, ep.render)
        width = probe(ep.predicted).width // k
        for i, view in enumerate(imagined_view_names(k)):
            videos[view] = scratch / f"{view}.mp4"
            encode_h264(videos[view], (rgb[:, i * width:(i + 1) * width] for _, rgb in
                                       VideoClip(ep.predicted).iter_frames()), fps)
    return dict(
        kind="single_chunk", actions=None, n_chunks=1, horizon=n, prompt=ep.task, episode_index=None,
        start_frame=0, fps=fps, executed_per_chunk=n, frames_per_chunk=n, videos=videos,
        gt_videos=gt_videos, gt_episode_length=n,
        extra={"source": {"format": FORMAT, "recording": None,
                          "render": str(ep.render) if ep.render else None,
                          "predicted": str(ep.predicted) if ep.predicted else None},
               "outcome": ep.outcome(), **({"warnings": warnings} if warnings else {})},
    )


def _session_units(episodes: list[EvalEpisode]) -> Units:
    for ep in episodes:
        if ep.recording is not None:
            try:
                return ep.recording[0].units
            except InspectorError:
                continue  # that episode reports it
    return Units("degrees")


def import_eval(src: str | Path, dest: str | Path, *, overwrite: bool = False, keep_going: bool = False,
                log: Callable[[str], None] = print) -> tuple[Path, dict[str, InspectorError]]:
    """Import every evaluated episode under ``src`` (an output directory holding eval_info.json).

    Args:
        keep_going: a bad episode (or task) is returned among the errors and the others are
            imported; otherwise the first one raises and nothing is written.

    Returns:
        (session directory, {tag: error} of what was left out).
    """
    src = Path(src)
    if not is_eval_output(src):
        raise InspectorError(src, f"no {EVAL_INFO}: not a lerobot-eval output directory")
    check_apart(dest, src)
    episodes, errors, _ = read_eval(src)
    if errors and not keep_going:
        raise next(iter(errors.values()))
    units = _session_units(episodes)
    with SessionWriter.create(dest, name=Path(dest).name, units=units, model={"name": "lerobot-eval"},
                              overwrite=overwrite) as writer, \
            tempfile.TemporaryDirectory(prefix="inspector-eval-") as scratch:
        for ep in episodes:
            try:
                args = _episode_args(ep, Path(scratch) / ep.tag, units)
                writer.add_rollout(ep.tag, **args)
            except InspectorError as exc:
                if not keep_going:
                    raise
                errors[ep.tag] = exc
                log(f"{ep.tag}: error: {exc}")
                continue
            log(f"{ep.tag}: {'success' if ep.success else 'failure'}, reward {ep.sum_reward}, "
                f"{args['horizon'] if args['actions'] is None else args['actions'].shape[1]} steps"
                f"{' (video only)' if args['actions'] is None else ''}, prompt {args['prompt']!r}")
    return Path(dest), errors


def import_command(src: str | Path, dest: str | Path, *, overwrite: bool = False) -> Path:
    """``inspector import lerobot-eval SRC -o DEST``."""
    return import_eval(src, dest, overwrite=overwrite)[0]


def load_in_memory(src: Path, dataset: str | Path | None = None) -> InMemory:
    """Import into a temporary session (``report``/``serve``/``export``); bad episodes are left
    out and returned among the errors. ``dataset`` is not used: the recordings carry the arm."""
    return import_temporarily(Path(src).resolve().name, lambda dest: import_eval(
        src, dest, keep_going=True, log=lambda _: None)[1])


# ----------------------------------------------------------------------------------------------
# info


def describe(src: Path, calibration: str | None = None) -> dict[str, Any]:
    """What ``inspector info`` says about an output directory (nothing decoded; no ``calibration``)."""
    episodes, errors, listed = read_eval(src)
    tasks: dict[str, dict[str, Any]] = {t.task: {"task": t.task, "episodes": t.episodes, "successes": t.successes,
                                                 "recorded": 0} for t in listed}
    rows = []
    for ep in episodes:
        tasks[ep.task]["recorded"] += ep.recording is not None
        fps = ep.recording[0].fps if ep.recording else None
        cams = list(ep.recording[0].cameras) if ep.recording else []
        rows.append({"tag": ep.tag, "task": ep.task, "episode": ep.index, "success": ep.success,
                     "sum_reward": ep.sum_reward, "max_reward": ep.max_reward,
                     "length": ep.recording[0].episode_info(ep.recording[1]).length if ep.recording else None,
                     "fps": fps, "predicted_video": ep.predicted is not None, "render": ep.render is not None,
                     "video_only": ep.recording is None,
                     "cameras": cams})
    for t in tasks.values():
        t["success_rate"] = t["successes"] / t["episodes"]
    warnings = []
    unrecorded = sum(t["episodes"] - t["recorded"] for t in tasks.values())
    if unrecorded:
        warnings.append(f"{unrecorded} episode(s) without a recording: video only, no joints "
                        "(lerobot-eval records them with --eval.recording=true)")
    unnamed = sorted({k for ep in episodes if ep.recording for k in ep.recording[0].unnamed_joints})
    if unnamed:
        warnings.append(f"{', '.join(unnamed)}: joints not named in the recordings; taken in SO-101 order")
    units = _session_units(episodes)
    return {"format": FORMAT, "layout": LAYOUT_NAME, "units": units.to_json(), "units_label": units.label(),
            "tasks": list(tasks.values()), "episodes": rows, "warnings": warnings,
            **({"errors": {k: str(v) for k, v in errors.items()}} if errors else {})}


def format_description(info: dict[str, Any]) -> str:
    lines = [f"{info['layout']}: {len(info['episodes'])} episode(s) in {len(info['tasks'])} task(s), "
             f"units: {info['units_label']}"]
    lines += [f"  task {t['task']}: {t['successes']}/{t['episodes']} succeeded ({100 * t['success_rate']:.0f}%), "
              f"{t['recorded']} recorded" for t in info["tasks"]]
    width = max([12] + [len(r["tag"]) for r in info["episodes"]])
    lines.append(f"{'episode':<{width}} {'success':<7} {'reward':>8} {'steps':>6} {'fps':>5}  videos")
    for r in info["episodes"]:
        vids = [v for v, have in (("predicted", r["predicted_video"]), ("render", r["render"])) if have] + r["cameras"]
        reward = "-" if r["sum_reward"] is None else f"{r['sum_reward']:.3g}"
        lines.append(f"{r['tag']:<{width}} {'yes' if r['success'] else 'no':<7} {reward:>8} "
                     f"{r['length'] if r['length'] is not None else '-':>6} {r['fps'] or '-':>5}  {', '.join(vids) or '-'}"
                     f"{'  (video only)' if r.get('video_only') else ''}")
    lines += [f"warning: {w}" for w in info["warnings"]]
    lines += [f"{k} error: {v}" for k, v in info.get("errors", {}).items()]
    return "\n".join(lines)

