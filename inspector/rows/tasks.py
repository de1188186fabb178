"""The work of ``inspector report``, cut into tasks that run anywhere: in this process, in a pool
of worker processes (``--jobs``), or on any executor that can call :func:`run_task`.

A task names rollouts by (session directory, tag), never carries their data: a worker reads
them from disk, so tasks stay tiny and a worker holds one task's rollouts at a time. Rollouts
that share a GT episode go to the same task, where their joint metrics run as one batch and
their videos are compared in one pass over the GT clip (decoded once per task, not once per
rollout). Each result is the rollout's summary row, stored in the metrics cache.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterator, Sequence
from concurrent.futures import as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

from ..analysis.camera_measures import ViewCameraPass, cameras_of, feeding, view_records
from ..analysis.measure_settings import DEFAULT_MEASURES, MeasureSettings
from ..analysis.measures_switch import sanity_measures_on
from ..analysis.timeline import batch_key, build_timeline, build_timelines
from ..analysis.video_break import clip_quality
from ..analysis.video_metrics import VideoMetrics, compare_clips, resizes_whole_frame
from ..cache import MetricsCache, rollout_key
from ..data.episodes import episode_rollout, episode_tag
from ..data.ground_truth import resolve_ground_truth
from ..data.importers import NeuralTrajectories, open_trajectories
from ..data.lerobot_dataset import open_dataset
from ..data.session import CHAINED_KINDS, load_session_rollout, read_session_with_gt
from ..errors import InspectorError
from ..jobs.pool import init_worker, interruptible, local_pool
from ..jobs.ray import RayWorkers
from ..progress import take_unsaid
from .entries import read_entry, write_entry
from .rollout import episode_summary, rollout_summary
from .trajectories import trajectory_summary

# Rollouts per task at most: a task's rollouts are compared against their GT in one pass, one
# open decoder each.
MAX_TASK_ROLLOUTS = 32
# Rollouts whose rows a report looks up in the metrics cache itself before it starts its workers
# for the rest anyway: about a second of look-ups, what starting two workers costs.
LOOK_UP_HERE = 48


@dataclass(frozen=True)
class Task:
    """Rollouts of one session for one worker.

    Attributes:
        session_root: the session directory.
        tags: the rollouts' tags.
        dataset: a GT dataset that replaces the session's (``--dataset``), or None.
        limit_margin_deg: joint-limit margin [deg].
        cache_dir: the metrics cache directory (None: the default one).
        use_cache: read and write the metrics cache.
        measures: the sanity measures' tolerances.
        cameras_file: where the session's cameras live when not in its directory (a raw
            directory's sidecar), or None.
    """

    session_root: str
    tags: tuple[str, ...]
    dataset: str | None
    limit_margin_deg: float
    cache_dir: str | None = None
    use_cache: bool = True
    measures: MeasureSettings = DEFAULT_MEASURES
    cameras_file: str | None = None


@dataclass(frozen=True)
class EpisodeTask:
    """Episodes of one LeRobot dataset for one worker (``report DATASET``: per-episode rows).

    Attributes:
        dataset_root: the dataset directory.
        indexes: the episodes' indexes.
        limit_margin_deg: joint-limit margin [deg].
        calibration: a GR00T-Dreams dump's calibration spec (None: a LeRobot dataset).
    """

    dataset_root: str
    indexes: tuple[int, ...]
    limit_margin_deg: float
    calibration: str | None = None

    @property
    def session_root(self) -> str:  # where outcomes say they come from
        return self.dataset_root

    @property
    def tags(self) -> tuple[str, ...]:

        return tuple(episode_tag(i) for i in self.indexes)


@dataclass(frozen=True)
class Outcome:
    """One rollout's result: its row, or the one-line error that kept it from one."""

    session_root: str
    tag: str
    row: dict[str, Any] | None = None
    error_file: str | None = None
    error: str | None = None
    cached: bool = False
    cache_warning: str | None = None  # the metrics cache could not be written (a worker's, for the driver to say)


def plan_tasks(sessions: Sequence[Any], jobs: int, limit_margin_deg: float, cache_dir: str | None = None,
               use_cache: bool = True, measures: MeasureSettings = DEFAULT_MEASURES) -> list[Task]:
    """Tasks for every loaded rollout of ``sessions`` (:class:`inspector.data.session.Session`).

    Rollouts of one session that start from the same dataset episode and frame, with the same
    kind and shape, share tasks; groups are cut so that every worker gets a few tasks.
    """
    groups: dict[tuple, list[str]] = defaultdict(list)
    for session in sessions:
        dataset = session.dataset_root
        for tag in sorted(session.rollouts):
            r = session.rollouts[tag]
            same_gt: Any = ((str(dataset), r.episode_index, r.start_frame, r.kind, r.actions_shape,
                             r.steps_per_chunk) if dataset is not None and r.episode_index is not None
                            and not r.has_gt_joints and not r.gt_views else tag)
            groups[(str(session.root), same_gt)].append(tag)
    per_task = rollouts_per_task(sum(len(tags) for tags in groups.values()), jobs)
    tasks: list[Task] = []
    by_root = {str(s.root): s for s in sessions}
    for (root, _), tags in groups.items():
        override = by_root[root].gt_source.get("dataset")
        cameras = by_root[root].cameras_file
        for i in range(0, len(tags), per_task):
            tasks.append(Task(root, tuple(tags[i:i + per_task]), override, limit_margin_deg, cache_dir, use_cache,
                              measures, None if cameras is None else str(cameras)))
    return tasks


def plan_episode_tasks(datasets: Sequence[Any], jobs: int, limit_margin_deg: float) -> list[EpisodeTask]:
    """Tasks for every episode of ``datasets`` (:class:`inspector.data.lerobot_dataset.LeRobotDataset`)."""
    tasks = []
    for ds in datasets:
        indexes = [e.index for e in ds.episodes]
        per_task = max(1, min(4 * MAX_TASK_ROLLOUTS, math.ceil(len(indexes) / (2 * max(1, jobs)))))
        for i in range(0, len(indexes), per_task):
            calibration = ds.calibration.spec if isinstance(ds, NeuralTrajectories) else None
            tasks.append(EpisodeTask(str(ds.root), tuple(indexes[i:i + per_task]), limit_margin_deg, calibration))
    return tasks


def rollouts_per_task(n_rollouts: int, jobs: int) -> int:
    """Two tasks per worker: larger tasks share more GT decoding, and the last ones still balance."""
    return max(1, min(MAX_TASK_ROLLOUTS, math.ceil(n_rollouts / (2 * max(1, jobs)))))


def worker_died(task: Task | EpisodeTask, why: str) -> list[Outcome]:
    """The outcomes of a task whose worker died before it returned: each rollout, with ``why``."""
    return [Outcome(task.session_root, tag, error_file=str(Path(task.session_root) / "rollouts" / tag),
                    error=f"the worker process computing it died ({why})") for tag in task.tags]


def run_tasks(tasks: Sequence[Task | EpisodeTask], jobs: int) -> Iterator[list[Outcome]]:
    """Each task's outcomes as it finishes: here when ``jobs`` <= 1, else in worker processes,
    started only for what the metrics cache does not hold (see :func:`found_in_cache`)."""
    if jobs <= 1 or len(tasks) <= 1:
        for task in tasks:
            yield run_task(task)
        return

    found, tasks = found_in_cache(tasks, LOOK_UP_HERE)
    yield from found
    if len(tasks) <= 1:
        for task in tasks:
            yield run_task(task)
        return
    with local_pool(min(jobs, len(tasks))) as pool:
        futures = {pool.submit(interruptible, run_task, task): task for task in tasks}
        for future in as_completed(futures):
            task = futures[future]
            try:
                yield future.result()
            except BrokenProcessPool as exc:  # a worker died (killed, out of memory, a crash)
                yield worker_died(task, str(exc))


def found_in_cache(tasks: Sequence[Task | EpisodeTask], at_most: int) -> tuple[list[list[Outcome]],
                                                                             list[Task | EpisodeTask]]:
    """The leading tasks' rows that the metrics cache holds, looked up in this process up to the
    first rollout still to compute (``at_most`` rollouts), and the tasks left to run: the first of
    them cut to the rollouts not looked up yet.

    A fully cached report then starts no worker processes (each one a whole interpreter to start,
    to read entries that take milliseconds); one with anything to compute starts them after a
    single look-up that misses.
    """
    found: list[list[Outcome]] = []
    sessions: dict[tuple[str, str | None, str | None], Any] = {}
    looked_up = 0
    for i, task in enumerate(tasks):
        if not isinstance(task, Task) or not task.use_cache or looked_up + len(task.tags) > at_most:
            return found, list(tasks[i:])
        where = (task.session_root, task.dataset, task.cameras_file)
        if where not in sessions:
            try:
                sessions[where] = read_session_with_gt(*where)
            except InspectorError:  # the task's worker says so, for each of its rollouts
                return found, list(tasks[i:])
        cache = MetricsCache(task.cache_dir, enabled=True)
        outcomes: list[Outcome] = []
        for j, tag in enumerate(task.tags):
            hit, todo = _look_up(replace(task, tags=(tag,)), sessions[where], cache)
            if todo:
                if outcomes:
                    found.append(outcomes)
                return found, [replace(task, tags=task.tags[j:]), *tasks[i + 1:]]
            outcomes += hit
        looked_up += len(task.tags)
        found.append(outcomes)
    return found, []


# ----------------------------------------------------------------------------------------------
# In a worker


def warm_up() -> None:
    """Nothing: a worker that runs it has imported this module (most of a worker's start-up,
    ~0.7 s of CPU), so its first task starts computing at once."""


def run_task(task: Task | EpisodeTask) -> list[Outcome]:
    """Rows of a task's rollouts (from the cache where it has them), or of its episodes."""
    if isinstance(task, EpisodeTask):
        return _run_episode_task(task)

    try:
        session = read_session_with_gt(task.session_root, task.dataset, task.cameras_file)
    except InspectorError as exc:
        return [Outcome(task.session_root, tag, error_file=exc.file, error=exc.what) for tag in task.tags]
    cache = MetricsCache(task.cache_dir, enabled=task.use_cache)
    outcomes, todo = _look_up(task, session, cache)
    for batch in _batches(todo):
        outcomes += _compute(batch, task, cache)
    warning = take_unsaid()  # None where this process prints its own warnings
    if warning is not None and outcomes:
        outcomes[0] = replace(outcomes[0], cache_warning=warning)
    return outcomes


def cached_outcomes(task: Task) -> tuple[list[Outcome], tuple[str, ...]]:
    """The first half of :func:`run_task`, computing nothing: the rows the metrics cache holds
    (and the rollouts that cannot be read), and the tags whose rows are still to compute.

    What lists a whole evaluation at once (the app's overview) before computing the rest.
    """
    try:
        session = read_session_with_gt(task.session_root, task.dataset, task.cameras_file)
    except InspectorError as exc:
        return [Outcome(task.session_root, tag, error_file=exc.file, error=exc.what) for tag in task.tags], ()
    outcomes, todo = _look_up(task, session, MetricsCache(task.cache_dir, enabled=task.use_cache))
    return outcomes, tuple(p.rollout.tag for p in todo)


def _look_up(task: Task, session: Any, cache) -> tuple[list[Outcome], list[_Pending]]:
    """Outcomes of the task's rollouts found in ``cache`` or unreadable, and the others, read."""
    outcomes: list[Outcome] = []
    todo: list[_Pending] = []
    for tag in task.tags:
        try:
            rollout = load_session_rollout(session, tag)
            gt = resolve_ground_truth(rollout)
            key = rollout_key(rollout, gt, task.limit_margin_deg, task.measures)
            cached = read_entry(cache, key)
            if cached.row is not None:
                outcomes.append(Outcome(task.session_root, tag, row=cached.row, cached=True))
                continue
            todo.append(_Pending(rollout, gt, key, cached.video))
        except InspectorError as exc:
            outcomes.append(Outcome(task.session_root, tag, error_file=exc.file, error=exc.what))
    return outcomes, todo


def _run_episode_task(task: EpisodeTask) -> list[Outcome]:
    """Per-episode rows (tracking error, limits, ranges) of a dataset's episodes."""
    outcomes = []
    try:
        ds = (open_dataset(task.dataset_root) if task.calibration is None
              else open_trajectories(task.dataset_root, task.calibration))
    except InspectorError as exc:
        return [Outcome(task.dataset_root, tag, error_file=exc.file, error=exc.what) for tag in task.tags]
    for index in task.indexes:
        try:
            rollout, gt = episode_rollout(ds, index)
            tl = build_timeline(rollout, gt=gt, limit_margin_deg=task.limit_margin_deg)
            row = episode_summary(tl) if rollout.kind == "episode" else trajectory_summary(tl)
            outcomes.append(Outcome(task.dataset_root, episode_tag(index), row=row))
        except InspectorError as exc:
            outcomes.append(Outcome(task.dataset_root, episode_tag(index), error_file=exc.file, error=exc.what))
    return outcomes


@dataclass
class _Pending:
    rollout: Any
    gt: Any
    key: str
    video: dict[str, VideoMetrics]  # from the cache
    timeline: Any = None


def _batches(todo: list[_Pending]) -> list[list[_Pending]]:
    """Rollouts that can share one joint-metric batch and one pass over their GT clips."""
    groups: dict[Any, list[_Pending]] = defaultdict(list)
    for i, p in enumerate(todo):
        groups[batch_key(p.rollout, p.gt) or i].append(p)
    return list(groups.values())


def _compute(batch: list[_Pending], task: Task, cache) -> list[Outcome]:
    """Rows of a batch; a failure is pinned on its rollout by computing the batch one by one."""
    try:
        return _compute_together(batch, task, cache)
    except Exception as exc:
        if len(batch) > 1:
            return [o for p in batch for o in _compute([p], task, cache)]
        if not isinstance(exc, InspectorError):  # not foreseen: still one line, naming the rollout
            exc = InspectorError(batch[0].rollout.root, f"cannot compute its metrics ({type(exc).__name__}: {exc})")
        return [Outcome(task.session_root, batch[0].rollout.tag, error_file=exc.file, error=exc.what)]


def _compute_together(batch: list[_Pending], task: Task, cache) -> list[Outcome]:

    timelines = build_timelines([p.rollout for p in batch], batch[0].gt, task.limit_margin_deg, task.measures)
    for p, tl in zip(batch, timelines):
        p.timeline = tl
        for view, vm in p.video.items():
            # an entry's view the rollout lacks would show in its row; one kept without the
            # no-reference measures (written before them) is computed again
            if view in tl.video_views() and vm.quality is not None:
                tl.set_video_metrics(vm)
    views = sorted({v for tl in timelines for v in tl.video_views()})
    cameras, cameras_note = cameras_of(batch[0].rollout.session)
    # a view with a camera is read again even where its video metrics are kept: its camera
    # measures (arm-masked PSNR, the gripper's track) ride on the same pass
    passes: list[dict[str, ViewCameraPass]] = [{} for _ in timelines]
    for view in views:
        need = [tl for tl in timelines if view in tl.video_views()
                and (view not in tl.known_video_metrics() or view in cameras)]
        if need:
            gt_clip = need[0].gt.clips[view]
            fed = [ViewCameraPass(tl, view, cameras[view]) if view in cameras else None for tl in need]
            for tl, vp in zip(need, fed):
                if vp is not None:
                    passes[timelines.index(tl)][view] = vp
            # SSIM (~10x PSNR's cost) where the video is all a rollout has to be judged by
            results = compare_clips(view, [tl.rollout.video(view) for tl in need], gt_clip,
                                    need[0].gt_index_of_frame(view), with_ssim=not need[0].has_joints,
                                    whole_frame=[resizes_whole_frame(tl.rollout.extra) for tl in need],
                                    on_pair=feeding(fed) if cameras else None)
            for tl, vm in zip(need, results):
                tl.set_video_metrics(vm)
    outcomes = []
    for p, fed_views in zip(batch, passes):
        video = p.timeline.known_video_metrics()
        camera_rows = view_records(fed_views, p.timeline.video_views(), {v: vm.note for v, vm in video.items()},
                                   cameras_note)
        row = rollout_summary(p.timeline, video, _imagined_only_quality(p.timeline), camera_rows)
        write_entry(cache, p.key, row, video)
        outcomes.append(Outcome(task.session_root, p.rollout.tag, row=row))
    return outcomes


def _imagined_only_quality(tl) -> dict[str, Any]:
    """Per-frame no-reference measures of a chained rollout's views that have no GT video (the
    others got theirs in the pass against the GT)."""
    if tl.kind not in CHAINED_KINDS or not sanity_measures_on():
        return {}
    return {view: clip_quality(tl.rollout.video(view)) for view in tl.rollout.views if view not in tl.video_views()}


# ----------------------------------------------------------------------------------------------
# On a Ray cluster (--ray)


def run_tasks_on_ray(workers: RayWorkers, tasks: Sequence[Task | EpisodeTask]) -> Iterator[list[Outcome]]:
    """Outcomes of ``tasks`` as Ray tasks finish: :func:`run_task` on each, as a local worker runs it.

    Tasks are re-cut for the cluster's CPUs: large ones split, small ones bundled into one Ray
    task, so that none is smaller than its scheduling cost and every CPU gets about two.
    """
    bundles = bundle_tasks(tasks, workers.cpus if workers.max_in_flight is None else workers.max_in_flight)
    for bundle, outcomes, lost in workers.imap(_run_bundle, bundles):
        yield cast(list[Outcome], outcomes) if lost is None else [o for task in bundle for o in worker_died(task, lost)]


def bundle_tasks(tasks: Sequence[Task | EpisodeTask], workers: int) -> list[list[Task | EpisodeTask]]:
    """``tasks`` re-cut for ``workers`` CPUs: each bundle (one Ray task) holds about
    :func:`rollouts_per_task` rollouts, from one task or several small ones."""
    per_task = rollouts_per_task(sum(len(t.tags) for t in tasks), workers)
    pieces = [_slice(t, i, i + per_task) for t in tasks for i in range(0, len(t.tags), per_task)]
    bundles: list[list[Task | EpisodeTask]] = []
    size = per_task
    for piece in pieces:
        if size >= per_task:
            bundles.append([])
            size = 0
        bundles[-1].append(piece)
        size += len(piece.tags)
    return bundles


def _slice(task: Task | EpisodeTask, start: int, stop: int) -> Task | EpisodeTask:
    """The part of ``task`` with its rollouts (or episodes) ``start:stop``."""
    if isinstance(task, EpisodeTask):
        return replace(task, indexes=task.indexes[start:stop])
    return replace(task, tags=task.tags[start:stop])


def _run_bundle(bundle: list[Task | EpisodeTask]) -> list[Outcome]:
    """What a Ray worker runs: :func:`run_task`, task by task."""
    init_worker()
    return [o for task in bundle for o in run_task(task)]
