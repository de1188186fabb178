"""The overview's rows: one summary row per served rollout, computed once and shared by every tab.

Rows come from the report machinery (:mod:`inspector.report.tasks`) and its on-disk metrics cache.
A first pass takes every row the cache holds, and the rollouts that cannot be read, without
decoding any video, so a cached evaluation of 1,000 rollouts lists in seconds; a second pass
computes the rest, a few rollouts per task, and each task's rows appear as it finishes. Only
summary rows are kept (a few kB each), never timelines or frames.

The cache pass runs on one daemon thread; rows are computed in one spawned worker process at a
lower CPU priority (never under the server's GIL), so tabs load and scrub smoothly while rows are
computed. Stopping the app ends that process at once (the task under way is dropped), and the
process ends on its own should the app's process end without stopping it. A rollout that fails
becomes an error row; it never stops the others.

Dataset episodes (served LeRobot datasets) are not listed: their rows measure something else
(the follower's tracking error) and they open from the picker.
"""

from __future__ import annotations

import os
import signal
import threading
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..cache import warn_once
from ..jobs.pool import init_worker as _init_worker
from ..jobs.pool import spawn_pool, stop_pool
from ..report.tasks import Outcome, cached_outcomes, plan_tasks, run_task
from ..units import DEFAULT_LIMIT_MARGIN_DEG
from ._listeners import Listeners, Notifying

# Rollouts per computing task: tasks of rollouts sharing a GT episode decode its clip once, and
# smaller tasks show their rows sooner; a few is the balance.
COMPUTE_TASK_ROLLOUTS = 6
# How much less CPU priority (nice) the computing thread takes than the serving threads.
BACKGROUND_NICENESS = 10


@dataclass(frozen=True)
class OverviewRow:
    """One served rollout in the overview.

    Attributes:
        key: its catalog key (what the picker shows and a tab opens).
        session: its session's name in the picker.
        tag, kind, prompt: as the rollout says (kind ``unreadable`` when it failed to load).
        session_root: the session directory (for its annotations).
        summary: its report row (:func:`inspector.report.rows.rollout_summary`), None until
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

    Attributes:
        done: set once every row is computed (or failed).
        n_cached, n_computed: rows read from the metrics cache / computed here.
    """

    def __init__(self, catalog, limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG) -> None:
        self._margin = limit_margin_deg
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
        """Stop computing; returns once the worker process has ended (the task under way is
        dropped with its rows: the app is going). No worker starts afterwards: the pool is made
        under the lock, after a last look at the stop flag, and a worker that its first job is
        starting as this runs is waited for (:func:`~inspector.jobs.pool.stop_pool`), as is one
        that the computing thread is letting go after the last row."""
        with self._lock:
            self._stop.set()
            pool = self._pool  # the computing thread forgets it once its workers have ended
        if pool is not None:
            stop_pool(pool, grace_s=0)  # no grace: a killed cache write never leaves an entry

    def _run(self) -> None:

        _lower_priority()
        try:
            tasks = plan_tasks(list(self._sessions.values()), 1, self._margin, self._cache_dir, self._use_cache,
                               self._measures)
            to_compute = []
            for task in tasks:  # first every cached row: the whole table at once
                if self._stop.is_set():
                    return
                outcomes, missing = _guarded(task, cached_outcomes, with_missing=True)
                self._publish(outcomes)
                self._notify()
                for i in range(0, len(missing), COMPUTE_TASK_ROLLOUTS):
                    to_compute.append(replace(task, tags=missing[i:i + COMPUTE_TASK_ROLLOUTS]))
            if to_compute:
                # In a worker process: computing in this one would hold the GIL against the
                # threads that serve the tabs (pages took minutes to load on two busy cores).
                with self._lock:
                    if self._stop.is_set():
                        return
                    self._pool = pool = spawn_pool(1, _init_background_worker)
                try:
                    for task in to_compute:
                        outcomes = _guarded(task, lambda t: pool.submit(run_task, t).result())
                        if self._stop.is_set():  # stopped meanwhile: its worker was killed
                            return
                        self._publish(outcomes)
                        self._notify()
                finally:
                    # Forgotten only once its worker has ended: stop() meanwhile waits for it too.
                    pool.shutdown(wait=True)
                    with self._lock:
                        self._pool = None
        finally:
            self.done.set()
            self._notify()

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


def _guarded(task, fn, with_missing: bool = False):
    """``fn(task)``; anything unforeseen becomes an error outcome for each of its rollouts."""
    try:
        return fn(task)
    except Exception as exc:
        failed = [Outcome(task.session_root, tag, error_file=str(Path(task.session_root) / "rollouts" / tag),
                          error=f"cannot compute its row ({type(exc).__name__}: {exc})") for tag in task.tags]
        return (failed, ()) if with_missing else failed


def _init_background_worker() -> None:
    """The computing worker: a report worker at the computing thread's lower CPU priority, which
    Ctrl-C leaves alone (the app stops it; at a terminal, Ctrl-C reaches every process of the
    group). Started by that thread, the worker has its niceness already on Linux: it is not added
    twice (nice 19, all but stopped on busy cores)."""
    try:
        os.nice(max(0, BACKGROUND_NICENESS - os.nice(0)))
    except (AttributeError, OSError):
        pass
    _init_worker()
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _lower_priority() -> None:
    """Lower this thread's CPU priority (Linux: nice applies per thread, and threads it starts,
    such as video decoders, inherit it). Elsewhere nothing changes."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), BACKGROUND_NICENESS)
    except (AttributeError, OSError):
        pass
