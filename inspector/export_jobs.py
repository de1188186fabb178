"""``inspector export --ray``: one job per rollout, each writing its recording where the driver
asked (on storage the workers share), atomically as :func:`inspector.export.write_recording` does.

A job names its rollout by path, as a report task does, and the worker reads it from disk; what
comes back is the written file's size, or the one-line error that kept it from being written,
printed by the driver exactly as a local export prints it.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from .errors import InspectorError


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
    """

    session_root: str
    tag: str
    dest: str
    views: tuple[str, ...] | None
    dataset: str | None
    limit_margin_deg: float
    use_cache: bool = True


@dataclass(frozen=True)
class ExportOutcome:
    """A job's result: the written file's size, or the one-line error that kept it from being written."""

    tag: str
    dest: str
    size: int | None = None
    error_file: str | None = None
    error: str | None = None

    @classmethod
    def died(cls, job: ExportJob, why: str) -> "ExportOutcome":
        return cls(job.tag, job.dest, error_file=str(Path(job.session_root) / "rollouts" / job.tag),
                   error=f"the worker process writing it died ({why})")


def run_export_job(job: ExportJob) -> ExportOutcome:
    """What a worker does: read the rollout, write its recording (video metrics via the cache)."""
    from .cache import MetricsCache
    from .export import export_rollout
    from .report_jobs import _init_worker, load_task_rollout, read_task_session

    _init_worker()
    try:
        rollout = load_task_rollout(read_task_session(job.session_root, job.dataset), job.tag)
        dest = export_rollout(rollout, Path(job.dest), job.views, job.limit_margin_deg,
                              MetricsCache(enabled=job.use_cache))
    except InspectorError as exc:
        return ExportOutcome(job.tag, job.dest, error_file=exc.file, error=exc.what)
    return ExportOutcome(job.tag, job.dest, size=dest.stat().st_size)


def export_on_ray(targets: Sequence[tuple], address: str, views: Sequence[str] | None,
                  limit_margin_deg: float, use_cache: bool) -> int:
    """Write ``targets`` (``[(session, tag, dest)]``) as Ray tasks; print each file written and each
    error as ``inspector export`` does; returns how many failed."""
    from .export import format_size
    from .ray_jobs import ray_workers

    failed = 0
    jobs = []
    shown = {}  # each file as the user named it
    for session, tag, dest in targets:
        if tag in session.errors:  # it did not even load here
            print(f"error: {session.errors[tag]}", file=sys.stderr)
            failed += 1
            continue
        shown[os.path.abspath(dest)] = dest  # absolute: a worker's directory is not ours
        jobs.append(ExportJob(str(session.root), tag, os.path.abspath(dest), None if views is None else tuple(views),
                              session.gt_source.get("dataset"), limit_margin_deg, use_cache))
    if not jobs:
        return failed
    with ray_workers(address) as workers:
        for outcome in workers.run_exports(jobs):
            if outcome.error is not None:
                print(f"error: {InspectorError(outcome.error_file or outcome.tag, outcome.error)}", file=sys.stderr)
                failed += 1
            else:
                print(f"wrote {shown[outcome.dest]} ({format_size(outcome.size)})", flush=True)
    return failed
