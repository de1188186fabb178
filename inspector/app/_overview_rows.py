"""The overview's rows: one summary row per served rollout, computed once and shared by every tab.

Rows come from the report machinery (:mod:`inspector.rows.tasks`), as ``report`` computes them:
the same tasks (rollouts sharing a GT episode together, two tasks per worker), the same worker
function and the same on-disk metrics cache, in a pool of spawned worker processes (never under
the server's GIL), so tabs load and scrub smoothly while rows are computed. A worker takes the
rows the cache holds and computes the others, and each task's rows appear as it finishes: a
cached evaluation of 1,000 rollouts lists in seconds, an uncached one in about ``report``'s time.
Only summary rows are kept (a few kB each), never timelines or frames.

One worker per core for rollouts without video (what ``report`` uses); one worker where rollouts
have videos, whose decoders hold clips beside the tabs' frame cache (the server stays under 1 GB
with 60 such rollouts opened). Workers run at a lower CPU priority than the serving threads.
The workers may be started before the sessions are read (:func:`start_workers`, from
``serve``): they import the report's modules on the core the server's own start-up leaves idle,
rather than after it, beside the server's first tab. Stopping the app ends them at once (the tasks under way are dropped), and they end on their own
should the app's process end without stopping them. A rollout that fails becomes an error row;
it never stops the others.

Dataset episodes (served LeRobot datasets) are not listed: their rows measure something else
(the follower's tracking error) and they open from the picker.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..data.session import GT_DIR, ROLLOUTS_DIR, VIDEO_DIR, is_session
from ..jobs.pool import default_jobs, init_background_worker, spawn_pool, stop_pool, worker_count
from ..progress import warn_once
from ..rows.tasks import Outcome, Task, plan_tasks, run_task, warm_up
from ..units import DEFAULT_LIMIT_MARGIN_DEG
from ._listeners import Listeners, Notifying

# Rollouts per task where rollouts have videos: tasks of rollouts sharing a GT episode decode its
# clip once, and smaller tasks show their rows sooner; a few is the balance.
VIDEO_TASK_ROLLOUTS = 6
# How much less CPU priority (nice) the computing workers take than the serving threads.
BACKGROUND_NICENESS = 10


@dataclass(frozen=True)
class OverviewRow:
    """One served rollout in the overview.

    Attributes:
        key: its catalog key (what the picker shows and a tab opens).
        session: its session's name in the picker.
        tag, kind, prompt: as the rollout says (kind ``unreadable`` when it failed to load).
        session_root: the session directory (for its annotations).
        summary: its report row (:func:`inspector.rows.rollout.rollout_summary`), None until
            computed or when it failed.
        error: why it has no row (one line), or None.
        cached: the row came from the metrics cache.
    """

    key: str
    session: str
    tag: str
    kind: str
    prompt: str
    session_root: Path
    summary: dict[str, Any] | None = None
    error: str | None = None
    cached: bool = False

    @property
    def pending(self) -> bool:
        return self.summary is None and self.error is None


class OverviewRows(Notifying):
    """Summary rows of every rollout a catalog serves, computed in the background on demand.
    Listeners are called on the computing thread whenever rows arrive, and once when all are done.

    Args:
        catalog: the app's :class:`~._catalog.Catalog` (its sessions and metrics cache).
        limit_margin_deg: joint-limit margin [deg], as the app's timelines use.
        workers: a pool from :func:`start_workers`, now owned by these rows: used where the plan
            wants as many workers, else stopped and replaced; stopped with the rows.

    Attributes:
        done: set once every row is computed (or failed).
        n_cached, n_computed: rows read from the metrics cache / computed here.
    """

    def __init__(self, catalog, limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG,
                 workers: ProcessPoolExecutor | None = None) -> None:
        self._margin = limit_margin_deg
        self._started_workers = workers
        self._measures = catalog.measures
        cache = catalog.metrics_cache
        self._cache_dir = str(cache.root) if cache is not None else None
        self._use_cache = bool(cache is not None and cache.enabled)
        self._lock = threading.Lock()
        self._rows: dict[str, OverviewRow] = {}  # catalog order
        self._key_of: dict[tuple[str, str], str] = {}  # (session root, tag) -> catalog key
        self._sessions: dict[str, Any] = {}  # root -> Session with rollouts to compute
        for entry in catalog.entries.values():
            if entry.session is None:
                continue  # a dataset episode (see the module docstring)
            rollout = entry.rollout
            root = str(entry.session.root)
            # The picker's key is "<session name> / <tag>": the name is what the picker shows.
            name = entry.key[: len(entry.key) - len(entry.tag) - len(" / ")]
            self._rows[entry.key] = OverviewRow(
                entry.key, name, entry.tag, entry.kind, (rollout.prompt or "") if rollout is not None else "",
                Path(root), error=str(entry.error) if entry.error is not None else None)
            self._key_of[(root, entry.tag)] = entry.key
            if rollout is not None:
                self._sessions[root] = entry.session
        self._listeners = Listeners()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._pool: Any = None  # the computing worker's pool, while rows are computed
        self.done = threading.Event()
        self.n_cached = 0
        self.n_computed = 0
        if not self._sessions:
            self.done.set()

    def drop_started_workers(self) -> None:
        """Stop the pool from :func:`start_workers` unless rows are computed with it (the app
        shows no overview)."""
        with self._lock:
            pool, self._started_workers = self._started_workers, None
        if pool is not None:
            stop_pool(pool, grace_s=0)

    # -- reading --------------------------------------------------------------------------------
    def rows(self) -> list[OverviewRow]:
        """Every row now, in the picker's order."""
        with self._lock:
            return list(self._rows.values())

    def __len__(self) -> int:
        return len(self._rows)

    def session_names(self) -> list[str]:
        """The sessions' picker names, in the picker's order."""
        return list(dict.fromkeys(r.session for r in self._rows.values()))

    # -- computing ------------------------------------------------------------------------------
    def start(self) -> None:
        """Start computing (once; later calls, and calls once stopped, do nothing)."""
        with self._lock:
            if self._thread is not None or self.done.is_set() or self._stop.is_set():
                return
            self._thread = threading.Thread(target=self._run, name="inspector-overview-rows", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop computing; returns once the worker processes have ended (the tasks under way are
        dropped with their rows: the app is going). No worker starts afterwards: the pool is made
        under the lock, after a last look at the stop flag, and a worker that its first job is
        starting as this runs is waited for (:func:`~inspector.jobs.pool.stop_pool`), as is one
        that the computing thread is letting go after the last row."""
        with self._lock:
            self._stop.set()
            pool = self._pool  # the computing thread forgets it once its workers have ended
            started, self._started_workers = self._started_workers, None
        for p in (pool, started):
            if p is not None:
                stop_pool(p, grace_s=0)  # no grace: a killed cache write never leaves an entry

    def _run(self) -> None:
        _lower_priority()  # this thread only collects rows (and redraws tabs); the workers compute
        try:
            tasks, workers = self._plan()
            wanted = worker_count(workers, len(tasks))
            with self._lock:
                if self._stop.is_set():
                    return
                started, self._started_workers = self._started_workers, None
            # as many as the plan wants (start_workers starts one per core), all alive (a worker
            # that died while starting broke it)
            if started is not None and (wanted != default_jobs() or getattr(started, "_broken", False)):
                stop_pool(started, grace_s=0)
                started = None
            with self._lock:
                if self._stop.is_set():
                    if started is not None:
                        stop_pool(started, grace_s=0)
                    return
                self._pool = pool = started or spawn_pool(wanted, init_background_worker, (BACKGROUND_NICENESS,))
            try:
                try:
                    futures = {pool.submit(run_task, task): task for task in tasks}
                except RuntimeError:  # stop() shut the pool down as the tasks were handed over
                    if self._stop.is_set():
                        return
                    raise
                for future in as_completed(futures):
                    outcomes = _guarded(futures[future], lambda _: future.result())
                    if self._stop.is_set():  # stopped meanwhile: its workers were killed
                        return
                    self._publish(outcomes)
                    self._notify()
                self._finish()  # every row is in: tabs draw the last ones now, not once workers exit
            finally:
                # Forgotten only once its workers have ended: stop() meanwhile waits for them too.
                pool.shutdown(wait=True, cancel_futures=True)
                with self._lock:
                    self._pool = None
        finally:
            self._finish()

    def _finish(self) -> None:
        """Set ``done`` and tell the listeners (once)."""
        with self._lock:
            if self.done.is_set():
                return
            self.done.set()
        self._notify()

    def _plan(self) -> tuple[list[Task], int]:
        """The tasks and how many workers run them: ``report``'s plan, one worker per core; where
        a rollout has videos, one worker and tasks of a few rollouts, which show their rows
        sooner (a video rollout's row takes about a second)."""
        sessions = list(self._sessions.values())
        if not any(r.views or r.gt_views for s in sessions for r in s.rollouts.values()):
            return (plan_tasks(sessions, default_jobs(), self._margin, self._cache_dir, self._use_cache, self._measures),
                    default_jobs())
        tasks = plan_tasks(sessions, 1, self._margin, self._cache_dir, self._use_cache, self._measures)
        return [replace(t, tags=t.tags[i:i + VIDEO_TASK_ROLLOUTS])
                for t in tasks for i in range(0, len(t.tags), VIDEO_TASK_ROLLOUTS)], 1

    def _publish(self, outcomes) -> None:
        with self._lock:
            for o in outcomes:
                warn_once(o.cache_warning)  # the worker's: the server says it once, as a command does
                key = self._key_of.get((o.session_root, o.tag))
                if key is None:
                    continue
                row = self._rows[key]
                if o.row is not None:
                    self._rows[key] = replace(row, summary=o.row, cached=o.cached, error=None)
                    if o.cached:
                        self.n_cached += 1
                    else:
                        self.n_computed += 1
                else:
                    where = f"{o.error_file}: " if o.error_file else ""
                    self._rows[key] = replace(row, error=f"{where}{o.error or 'failed'}")


def start_workers(paths: Sequence[str | Path]) -> ProcessPoolExecutor | None:
    """The overview's workers, started now and importing the report's modules, where ``paths``
    are sessions that hold more than one rollout between them (the app opens on the overview)
    and their first rollout has no video directory (one worker per core, as the rows' plan then
    wants); else None. Cheap: directory listings only. The caller hands the pool to
    :class:`OverviewRows`, which stops it when it is not wanted after all."""
    sessions = [Path(p) for p in paths if is_session(p)]
    rollouts = [d for s in sessions if (s / ROLLOUTS_DIR).is_dir()
                for d in sorted((s / ROLLOUTS_DIR).iterdir()) if not d.name.startswith(".")]
    if len(rollouts) < 2 or (rollouts[0] / VIDEO_DIR).exists() or (rollouts[0] / GT_DIR / VIDEO_DIR).exists():
        return None
    jobs = default_jobs()
    pool = spawn_pool(jobs, init_background_worker, (BACKGROUND_NICENESS,))
    for _ in range(jobs):  # each submit while no worker is idle starts one more
        pool.submit(warm_up)
    return pool


def _guarded(task, fn):
    """``fn(task)``; anything unforeseen becomes an error outcome for each of its rollouts."""
    try:
        return fn(task)
    except Exception as exc:
        return [Outcome(task.session_root, tag, error_file=str(Path(task.session_root) / "rollouts" / tag),
                        error=f"cannot compute its row ({type(exc).__name__}: {exc})") for tag in task.tags]


def _lower_priority() -> None:
    """Lower this thread's CPU priority (Linux: nice applies per thread, and threads it starts,
    such as video decoders, inherit it). Elsewhere nothing changes."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), BACKGROUND_NICENESS)
    except (AttributeError, OSError):
        pass
