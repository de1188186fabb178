"""Worker processes for every command that fans work out (``report``, ``export``, the app's
overview): a spawned pool that stops promptly on Ctrl-C, and the per-worker set-up.

Jobs are plain picklable callables and arguments, so the same job runs in this process, in a
:func:`local_pool`, or as a Ray task (:mod:`inspector.jobs.ray`).

No worker outlives the command that started it. A pool's owner stops it with :func:`stop_pool`
(jobs under way interrupted, workers still running after a grace period killed, and every worker
ended before it returns). A worker also watches its parent: should the parent end without
stopping its pool (``kill -9``, ``os._exit``, a crash), the worker stops its job as on Ctrl-C and
exits within seconds, instead of waiting forever for jobs no one will send (its queues' pipes
stay open in the worker itself, so it never sees them close).
"""

from __future__ import annotations

import _thread
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager, suppress
from multiprocessing.connection import wait as wait_for_sentinels
from typing import Any, TypeVar

R = TypeVar("R")

# How long a stopped pool's workers get to end the jobs under way, once interrupted, before they
# are killed: an interrupted export removes the file it was writing [s].
STOP_GRACE_S = 5.0
# How long killed workers get to be gone before stop_pool returns anyway [s].
KILL_WAIT_S = 10.0
# How often a worker whose pipes have closed is checked until it has exited [s].
EXIT_POLL_S = 0.005
# How long stop_pool waits for the pool's own thread to end once the workers have [s] (it ends
# within milliseconds; a busy machine may take longer, and stop_pool returns anyway).
MANAGER_END_S = 5.0
# How often a worker checks that its parent is alive when the parent's pipe cannot tell (the
# parent was replaced: another process inherited that pipe, or a subreaper adopted this one) [s].
PARENT_CHECK_S = 1.0
# The exit status of a worker that ended because its parent had gone.
PARENT_GONE_EXIT = 3


def spawn_pool(workers: int, initializer: Callable[..., None] | None = None,
               initargs: tuple = ()) -> ProcessPoolExecutor:
    """A pool of ``workers`` spawned processes (a clean interpreter each: no inherited locks),
    each ending on its own when this process ends (see the module docstring); ``initializer``
    then runs in each worker as ProcessPoolExecutor's would. Stop it with :func:`stop_pool` or
    ``shutdown()``."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init_spawned_worker, initargs=(initializer, initargs))


def stop_pool(pool: ProcessPoolExecutor, grace_s: float = STOP_GRACE_S) -> None:
    """Stop ``pool`` now and return once its workers have ended: jobs not started are cancelled,
    jobs under way are interrupted (SIGINT: an :func:`interruptible` job stops as on Ctrl-C,
    cleaning up after itself), and a worker still running ``grace_s`` later is killed.

    A worker being started meanwhile (a ``submit`` on another thread) is one of them: no worker
    starts once this has begun. A worker that is not running a job ignores SIGINT and ends when
    the pool tells it to.
    """
    # The pool forgets its processes on shutdown: keep its mapping (the dict itself, which the
    # pool fills as it starts workers). shutdown() waits for a submit that is starting a worker
    # (both hold the pool's lock), and no worker starts after it: the mapping is then complete.
    started = getattr(pool, "_processes", None)
    # (and its thread, with its result pipe's write end: see _unblock_manager)
    manager = getattr(pool, "_executor_manager_thread", None)
    results = getattr(getattr(pool, "_result_queue", None), "_writer", None)
    pool.shutdown(wait=False, cancel_futures=True)
    processes = list(dict(started or {}).values())  # a copy: the pool's manager thread changes it
    if grace_s > 0:
        for process in processes:
            with suppress(ProcessLookupError, ValueError, AttributeError):  # already ended, or closed
                if process.exitcode is None:
                    os.kill(process.pid, signal.SIGINT)
    running = _wait_until_ended(processes, grace_s)
    for process in running:
        with suppress(ProcessLookupError, ValueError, AttributeError):
            process.kill()
    _wait_until_ended(running, KILL_WAIT_S)
    _unblock_manager(manager, results)


def _unblock_manager(manager: threading.Thread | None, results: Any) -> None:
    """Let the pool's own thread end, even where a killed worker left it reading half a result.

    That thread reads each result whole (a blocking ``recv``): a worker killed between a large
    result's header and its bytes left it waiting for bytes no one would send, since this
    process holds the pipe's write end too, and so forever; at exit the interpreter joins it,
    and the command never ended. Only workers write there, and they have all ended: closing this
    process's write end leaves what they sent readable, then gives the thread the end of the
    pipe (a broken pool, and it ends).
    """
    if results is not None:
        with suppress(OSError):
            results.close()
    if manager is not None:
        manager.join(MANAGER_END_S)


def _wait_until_ended(processes: list, timeout: float) -> list:
    """Wait up to ``timeout`` seconds until every process has ended; returns those still running.

    A process has ended once it has exited (the kernel keeps only its exit status), not when its
    sentinel fires: that pipe closes as the exiting process drops its files, before it is done
    exiting, and a killed worker at a low priority on a busy machine can stay a while between
    the two, still running as far as anyone can see.
    """
    deadline = time.monotonic() + timeout
    running = [p for p in processes if not _has_exited(p)]
    while running:
        try:
            sentinels = {p.sentinel: p for p in running}
        except ValueError:  # a process object already closed: it had ended
            running = [p for p in running if _sentinel_or_none(p) is not None]
            continue
        left = deadline - time.monotonic()
        if left <= 0:
            break
        closed = wait_for_sentinels(list(sentinels), left)
        # the pipe closed: exiting, soon exited (polled, as there is nothing else to wait on)
        running = [p for s, p in sentinels.items() if s not in closed or not _has_exited(p)]
        if running and closed:
            time.sleep(min(EXIT_POLL_S, max(0.0, deadline - time.monotonic())))
    return running


def _has_exited(process) -> bool:
    """``process`` (a child of this process) has exited: reaped, here or by its pool's thread,
    or a zombie."""
    try:
        if process.exitcode is not None:  # reaps it once exited, as join() does
            return True
        pid = process.pid
    except ValueError:  # closed: it had ended
        return True
    if pid is None:  # never started
        return True
    if not hasattr(os, "waitid"):  # Windows: the sentinel is the process handle, signalled at exit
        sentinel = _sentinel_or_none(process)
        return sentinel is None or bool(wait_for_sentinels([sentinel], 0))
    try:
        # Looked at, not reaped (WNOWAIT): the pool's own thread joins its workers too.
        return os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None
    except ChildProcessError:  # reaped meanwhile (by the pool's thread)
        return True


def _sentinel_or_none(process) -> int | None:
    try:
        return process.sentinel
    except ValueError:
        return None


@contextmanager
def local_pool(workers: int) -> Iterator[Any]:
    """A pool of ``workers`` spawned processes for :func:`interruptible` jobs that stops promptly.

    Ctrl-C reaches every process of the terminal's group. The driver handles it: no job starts
    after it (not even one already queued to a worker), the jobs under way are stopped by it, and
    the pool is stopped (:func:`stop_pool`), so no worker is left once the command ends. An
    interrupt of the driver alone (``kill -INT``, or SIGTERM, which the command line turns into
    one) interrupts the workers' jobs too. Between jobs a worker ignores SIGINT; it would
    otherwise die printing a traceback.
    """
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    pool = spawn_pool(workers, _init_local_worker, (stop,))
    try:
        yield pool
    except BaseException:  # Ctrl-C, SIGTERM, an error, or the caller closing its generator early
        stop.set()
        stop_pool(pool)
        raise
    pool.shutdown(wait=True, cancel_futures=True)


_STOP: Any = None  # a local pool's stop event, in its workers
_IDLE = threading.Event()  # in a worker: no interruptible job is under way
_IDLE.set()


def _init_spawned_worker(initializer: Callable[..., None] | None, initargs: tuple) -> None:
    _exit_with_parent()
    if initializer is not None:
        initializer(*initargs)


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
    _IDLE.clear()
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return fn(job)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        _IDLE.set()


def _exit_with_parent() -> None:
    """In a spawned worker: end this process soon after its parent is gone.

    A thread waits on the parent's pipe, which the kernel closes when the parent ends however it
    ends (a portable parent-death signal), checking every :data:`PARENT_CHECK_S` that the parent
    is still this process's parent. Then the job under way is interrupted as by Ctrl-C (an
    :func:`interruptible` job cleans up after itself) and the process exits, at the latest
    :data:`STOP_GRACE_S` later.
    """
    parent = multiprocessing.parent_process()
    if parent is None:  # not started by multiprocessing
        return

    def parent_alive() -> bool:
        return os.getppid() == parent.pid and parent.is_alive()

    def watch() -> None:
        while parent_alive():
            parent.join(PARENT_CHECK_S)  # returns at once when the parent's pipe closes
        _thread.interrupt_main(signal.SIGINT)  # does nothing while SIGINT is ignored (no job)
        _IDLE.wait(STOP_GRACE_S)
        os._exit(PARENT_GONE_EXIT)

    if not parent_alive():  # gone already, while this process was starting
        os._exit(PARENT_GONE_EXIT)
    threading.Thread(target=watch, name="inspector-parent-watch", daemon=True).start()


def init_worker() -> None:
    """One thread per worker process: the pool already keeps every core busy. A cache warning is
    handed back with the job's result, so that the command says it once, not once per worker."""
    from ..progress import hold_warnings

    hold_warnings()
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"  # before numpy loads in this process
    # Imported here, not at the top: these variables must be set before numpy loads.
    from ..analysis import metrics
    from ..data import video

    video.DECODE_THREADS = "NONE"  # FFmpeg's default slice threads cost 25% more CPU a frame here
    metrics.DTW_THREADS = 1
    metrics.KDTREE_WORKERS = 1


def init_background_worker(niceness: int) -> None:
    """A worker computing in the background of a serving process (the app's overview): a report
    worker at CPU priority ``niceness``, which Ctrl-C leaves alone (its owner stops it; at a
    terminal, Ctrl-C reaches every process of the group). Started by a thread already at that
    niceness, the worker has it already on Linux: it is not added twice (nice 19, all but stopped
    on busy cores).

    It lives here, beside :func:`init_worker`, because a spawned worker imports the module of its
    initializer before running it: from the app's modules that import was the whole app (viser,
    meshes; ~1.4 s of CPU and ~100 MB per worker), and numpy loaded before :func:`init_worker`
    could give it one thread, so each worker's BLAS threads spun against the other's."""
    with suppress(AttributeError, OSError):
        os.nice(max(0, niceness - os.nice(0)))
    init_worker()
    signal.signal(signal.SIGINT, signal.SIG_IGN)


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
