"""``inspector export`` of several rollouts: one job per rollout, in local worker processes or as
Ray tasks (``--ray``), each writing its recording where the driver asked (for Ray, on storage the
workers share), atomically as :func:`inspector.export.recording.write_recording` does.

A job names its rollout by path, as a report task does, and the worker reads it from disk; what
comes back is the written file's size, or the one-line error that kept it from being written,
printed by the driver exactly as an export in this process prints it. Local workers are replaced
every few recordings, so a session of any size is written in bounded memory.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from ..analysis.measure_settings import DEFAULT_MEASURES, MeasureSettings
from ..cache import MetricsCache
from ..data.session import load_session_rollout, read_session_with_gt
from ..errors import InspectorError
from ..jobs.pool import init_worker, interruptible, local_pool
from ..jobs.ray import ray_workers
from ..progress import progress_bar, take_unsaid, warn_once
from .files import format_size

# Recordings a worker process writes, on average, before fresh processes take over: rerun's SDK
# keeps a few MB of native memory per recording it ever wrote (rerun-io/rerun#12623), so one
# long-lived writer would grow with the session.
EXPORTS_PER_WORKER = 8


@dataclass(frozen=True)
class ExportJob:
    """One rollout to write as a recording.

    Attributes:
        session_root: the session directory.
        tag: the rollout's tag.
        dest: the ``.rrd`` file to write.
        views: camera views to include, of those the rollout has (None: all).
        dataset: a GT dataset that replaces the session's (``--dataset``), or None.
        limit_margin_deg: joint-limit margin [deg].
        use_cache: read and write the metrics cache.
        outcome_source: the outcome source the recording shows (None: the precedence rule).
        measures: the sanity measures' tolerances.
        cameras_file, outcomes_file: where the session's cameras and outcomes live when not in
            its directory (a raw directory's sidecars), or None.
    """

    session_root: str
    tag: str
    dest: str
    views: tuple[str, ...] | None
    dataset: str | None
    limit_margin_deg: float
    use_cache: bool = True
    outcome_source: str | None = None
    measures: MeasureSettings = DEFAULT_MEASURES
    cameras_file: str | None = None
    outcomes_file: str | None = None


@dataclass(frozen=True)
class ExportOutcome:
    """A job's result: the written file's size, or the one-line error that kept it from being written."""

    tag: str
    dest: str
    size: int | None = None
    error_file: str | None = None
    error: str | None = None
    worker_pid: int | None = None  # the process that wrote it
    cache_warning: str | None = None  # a cache could not be written (for the driver to say, once)

    @classmethod
    def died(cls, job: ExportJob, why: str) -> ExportOutcome:
        return cls(job.tag, job.dest, error_file=str(Path(job.session_root) / "rollouts" / job.tag),
                   error=f"the worker process writing it died ({why})")


def run_export_job(job: ExportJob) -> ExportOutcome:
    """What a worker does: read the rollout, write its recording (video metrics via the cache)."""
    init_worker()
    from .recording import export_rollout  # here: the driver writes no recording (see .files)

    try:
        session = read_session_with_gt(job.session_root, job.dataset, job.cameras_file, job.outcomes_file)
        rollout = load_session_rollout(session, job.tag)
        dest = export_rollout(rollout, Path(job.dest), job.views, job.limit_margin_deg,
                              MetricsCache(enabled=job.use_cache), outcome_source=job.outcome_source, measures=job.measures)
    except InspectorError as exc:
        return ExportOutcome(job.tag, job.dest, error_file=exc.file, error=exc.what, worker_pid=os.getpid(),
                             cache_warning=take_unsaid())
    return ExportOutcome(job.tag, job.dest, size=dest.stat().st_size, worker_pid=os.getpid(),
                         cache_warning=take_unsaid())


def export_on_ray(targets: Sequence[tuple], address: str, views: Sequence[str] | None,
                  limit_margin_deg: float, use_cache: bool, outcome_source: str | None = None,
                  measures: MeasureSettings = DEFAULT_MEASURES) -> int:
    """Write ``targets`` (``[(session, tag, dest)]``) as Ray tasks; print each file written and each
    error as ``inspector export`` does, in the targets' order (each once those before it are done:
    the same lines whatever finishes first); returns how many failed."""
    printer = _OutcomePrinter(targets, views, limit_margin_deg, use_cache, outcome_source, measures)
    if printer.jobs:
        position = {job.dest: i for i, job in enumerate(printer.jobs)}
        finished: dict[int, ExportOutcome] = {}
        shown = 0
        with ray_workers(address) as workers:
            for job, outcome, lost in workers.imap(run_export_job, printer.jobs):
                finished[position[job.dest]] = (cast(ExportOutcome, outcome) if lost is None
                                                else ExportOutcome.died(job, lost))
                while shown in finished:
                    printer.show(finished.pop(shown))
                    shown += 1
    return printer.failed


def export_in_processes(targets: Sequence[tuple], jobs: int, views: Sequence[str] | None,
                        limit_margin_deg: float, use_cache: bool, outcome_source: str | None = None,
                        measures: MeasureSettings = DEFAULT_MEASURES) -> int:
    """Write ``targets`` (``[(session, tag, dest)]``) in ``jobs`` local worker processes; print
    what ``inspector export`` prints, in the targets' order; returns how many failed."""
    printer = _OutcomePrinter(targets, views, limit_margin_deg, use_cache, outcome_source, measures)
    if not printer.jobs:
        return printer.failed
    printer.bar = progress_bar(len(printer.jobs), "export", unit="rollout")
    try:
        for outcome in run_export_jobs(printer.jobs, jobs):
            printer.show(outcome)
    finally:
        if printer.bar is not None:
            printer.bar.close()
    return printer.failed


def run_export_jobs(jobs: Sequence[ExportJob], workers: int) -> Iterator[ExportOutcome]:
    """Each job's outcome, in the jobs' order, from ``workers`` spawned processes.

    The jobs run in rounds of ``workers`` x :data:`EXPORTS_PER_WORKER`, each round in a pool of
    its own, so no process writes more than one round's recordings. (Not ``max_tasks_per_child``:
    on Python 3.11-3.13 a pool stops replacing its workers once one exits at that limit, and the
    export hangs; CPython gh-115634.) A worker that dies (killed, out of memory) fails what is
    left of its round; the next round starts in a fresh pool.
    """
    per_round = max(1, workers) * EXPORTS_PER_WORKER
    for start in range(0, len(jobs), per_round):
        round_jobs = jobs[start:start + per_round]
        with local_pool(min(workers, len(round_jobs))) as pool:
            futures = [pool.submit(interruptible, run_export_job, job) for job in round_jobs]
            for job, future in zip(round_jobs, futures):  # in order: the same lines whatever finishes first
                try:
                    yield future.result()
                except BrokenProcessPool as exc:  # a worker died (killed, out of memory, a crash)
                    yield ExportOutcome.died(job, str(exc) or "killed")


class _OutcomePrinter:
    """Jobs for the targets that loaded, and the lines ``inspector export`` prints for outcomes.

    A target that did not even load is printed (and counted as failed) at once.
    """

    def __init__(self, targets: Sequence[tuple], views: Sequence[str] | None, limit_margin_deg: float,
                 use_cache: bool, outcome_source: str | None = None, measures: MeasureSettings = DEFAULT_MEASURES) -> None:
        self.failed = 0
        self.jobs: list[ExportJob] = []
        self.bar: Any = None
        self._shown: dict[str, str] = {}  # each file as the user named it
        for session, tag, dest in targets:
            if tag in session.errors:
                print(f"error: {session.errors[tag]}", file=sys.stderr)
                self.failed += 1
                continue
            self._shown[os.path.abspath(dest)] = str(dest)  # absolute: a worker's directory is not ours
            self.jobs.append(ExportJob(str(session.root), tag, os.path.abspath(dest),
                                       None if views is None else tuple(views),
                                       session.gt_source.get("dataset"), limit_margin_deg, use_cache,
                                       outcome_source, measures, _path_or_none(session.cameras_file),
                                       _path_or_none(session.outcomes_file)))

    def show(self, outcome: ExportOutcome) -> None:
        warn_once(outcome.cache_warning)
        if outcome.error is not None:
            line, stream = f"error: {InspectorError(outcome.error_file or outcome.tag, outcome.error)}", sys.stderr
            self.failed += 1
        else:
            assert outcome.size is not None  # an outcome without an error has its size
            line, stream = f"wrote {self._shown[outcome.dest]} ({format_size(outcome.size)})", sys.stdout
        if self.bar is not None:
            self.bar.write(line, file=stream)  # above the bar, which is drawn again below it
            self.bar.update(1)
        else:
            print(line, file=stream, flush=True)


def _path_or_none(path: Path | None) -> str | None:
    return None if path is None else str(path)
