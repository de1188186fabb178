"""Worker processes for every command that fans work out (``report``, ``export``, the app's
overview): a spawned pool that stops promptly on Ctrl-C, and the per-worker set-up.

Jobs are plain picklable callables and arguments, so the same job runs in this process, in a
:func:`local_pool`, or as a Ray task (:mod:`inspector.jobs.ray`).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

R = TypeVar("R")


@contextmanager
def local_pool(workers: int) -> Iterator[Any]:
    """A pool of ``workers`` spawned processes for :func:`interruptible` jobs that stops promptly.

    Ctrl-C reaches every process of the terminal's group. The driver handles it: no job starts
    after it (not even one already queued to a worker), the jobs under way are stopped by it, and
    the pool is shut down. Between jobs a worker ignores it; it would otherwise die printing a
    traceback.
    """
    context = multiprocessing.get_context("spawn")  # a clean interpreter per worker (no inherited locks)
    stop = context.Event()
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_init_local_worker,
                               initargs=(stop,))
    try:
        yield pool
    except BaseException:
        stop.set()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


_STOP: Any = None  # a local pool's stop event, in its workers


def _init_local_worker(stop: Any) -> None:
    global _STOP
    init_worker()
    _STOP = stop
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def interruptible(fn: Callable[[Any], R], job: Any) -> R:
    """``fn(job)`` in a :func:`local_pool` worker, stopped by Ctrl-C (a KeyboardInterrupt the pool
    hands back to the driver, which is stopping too); not started once the driver stops."""
    if _STOP is not None and _STOP.is_set():
        raise KeyboardInterrupt
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return fn(job)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def init_worker() -> None:
    """One thread per worker process: the pool already keeps every core busy. A cache warning is
    handed back with the job's result, so that the command says it once, not once per worker."""
    from ..cache import hold_warnings

    hold_warnings()
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"  # before numpy loads in this process
    # Imported here, not at the top: these variables must be set before numpy loads.
    from ..analysis import metrics
    from ..data import video

    video.DECODE_THREADS = "NONE"  # FFmpeg's default slice threads cost 25% more CPU a frame here
    metrics.DTW_THREADS = 1


def default_jobs() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


_NOTED: set[int] = set()  # the --jobs values whose cap this process has said


def worker_count(requested: int | None, tasks: int) -> int:
    """Worker processes for ``tasks`` jobs: ``requested`` (``--jobs``; default one per core), but
    never more than there are cores or tasks, since each idle worker is a whole interpreter
    (~175 MB). When that is fewer than asked, one ``note:`` line on stderr says why."""
    cores = default_jobs()
    workers = max(1, min(cores if requested is None else requested, cores, tasks))
    if requested is not None and workers < requested and tasks and requested not in _NOTED:
        _NOTED.add(requested)  # once per command (compare reports twice)
        print(f"note: --jobs {requested}: using {workers} worker{'s' if workers != 1 else ''} "
              f"({cores} core{'s' if cores != 1 else ''}, {tasks} task{'s' if tasks != 1 else ''})",
              file=sys.stderr)
    return workers
