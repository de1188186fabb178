"""No process outlives its command: after ``inspector serve``, ``report`` or ``export`` ends, however
it is stopped (Ctrl-C at a terminal, SIGINT or SIGTERM to the command alone, SIGKILL of it, or
``stop()`` of an app in this process), every process it started is gone within seconds.

Each stop comes while the command's worker processes are busy (a session of long rollouts with
video, a fresh metrics cache): every descendant of the command is recorded while it runs, then
the test waits, with a generous deadline, until none of them is alive, and fails listing the
survivors' command lines. (A worker left behind waits forever for jobs no one sends: its queue's
pipe is held open by the worker itself, so it never reads the end of it.)
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import psutil
import pytest

from inspector.app import HeadlessClient, serve
from inspector.data.session import SessionWriter
from inspector.data.sources import BUNDLED_DEMO
from inspector.jobs.pool import init_background_worker, spawn_pool, stop_pool

pytestmark = pytest.mark.slow

ROLLOUTS = 160  # each 60 chunks with two 540-frame views: minutes of work, stopped after seconds
SOURCE = BUNDLED_DEMO / "rollouts" / "overrun_60chunks"
START_TIMEOUT_S = 240.0  # a command starting, and its workers getting busy, on a loaded 2-core machine
GONE_TIMEOUT_S = 60.0  # generous: the guarantee is a few seconds


# ----------------------------------------------------------------------------------------------
# Helpers


@pytest.fixture(scope="module")
def long_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A session of :data:`ROLLOUTS` autoregressive rollouts of the demo's episode 0, each with the
    demo's videos: long enough that a command is still computing when it is stopped."""
    base = np.load(SOURCE / "actions.npy")
    rng = np.random.default_rng(0)
    dest = tmp_path_factory.mktemp("long") / "long"
    with SessionWriter.create(dest, name="long", dataset=str(BUNDLED_DEMO / "dataset")) as session:
        for i in range(ROLLOUTS):
            session.add_rollout(f"ep000_{i:04d}", kind="autoregressive", episode_index=0, start_frame=0,
                                actions=base + rng.normal(scale=0.3, size=base.shape).cumsum(axis=0),
                                videos={v: SOURCE / "video" / f"{v}.mp4" for v in ("front", "wrist")})
    return dest


class Descendants:
    """Every descendant process of ``pid`` seen while it runs (recorded every 50 ms on a thread),
    by (pid, start time): a pid reused by an unrelated process later is not taken for it."""

    def __init__(self, pid: int, only: Callable[[list[str]], bool] = lambda cmdline: True) -> None:
        self._root = psutil.Process(pid)
        self._only = only
        self._ignored = {self._key(p) for p in self._children()}  # there before: not this command's
        self.seen: dict[tuple[int, float], list[str]] = {}
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._record, daemon=True)
        self._thread.start()

    @staticmethod
    def _key(p) -> tuple[int, float]:
        try:
            return p.pid, p.create_time()
        except psutil.Error:
            return p.pid, 0.0

    def _children(self) -> list:
        try:
            return self._root.children(recursive=True)
        except psutil.Error:  # the command has ended (its orphans are no longer its children)
            return []

    def _record(self) -> None:
        while not self._done.wait(0.05):
            self.record_now()

    def record_now(self) -> None:
        for p in self._children():
            key = self._key(p)
            if key in self._ignored:
                continue
            try:
                cmdline = p.cmdline()
            except psutil.Error:
                continue
            if self._only(cmdline):  # read again each time: a process just forked shows its parent's
                self.seen[key] = cmdline  # command line until it execs

    def stop_recording(self) -> None:
        self._done.set()
        self._thread.join()

    def workers(self) -> list:
        """The spawned worker processes seen that are alive now."""
        return [p for key, cmd in self.seen.items() if is_worker(cmd) and (p := alive(key)) is not None]

    def alive(self) -> dict[int, str]:
        """{pid: command line} of the processes seen that are still alive."""
        return {key[0]: " ".join(cmd) for key, cmd in self.seen.items() if alive(key) is not None}


def is_worker(cmdline: list[str]) -> bool:
    return any("multiprocessing.spawn" in part for part in cmdline)


def alive(key: tuple[int, float]):
    """The process, if it still runs (a zombie has ended: only its exit status is left to collect)."""
    pid, started = key
    try:
        p = psutil.Process(pid)
        if abs(p.create_time() - started) > 0.01 or p.status() == psutil.STATUS_ZOMBIE:
            return None
        return p
    except psutil.Error:
        return None


def wait_until(condition: Callable[[], object], timeout: float, what: str) -> object:
    deadline = time.monotonic() + timeout
    while not (value := condition()):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.1)
    return value


def assert_all_gone(descendants: Descendants, what: str) -> None:
    deadline = time.monotonic() + GONE_TIMEOUT_S
    while (left := descendants.alive()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not left, f"{what}: still running {GONE_TIMEOUT_S:g} s later:\n" + "\n".join(
        f"  {pid}: {cmd}" for pid, cmd in left.items())


def in_a_job(p) -> bool:
    """The worker has a video open: every job here decodes the rollouts' and their GT's videos,
    for most of its time, and no worker's start-up opens one. (Seen the moment it is so, where a
    worker's CPU time, past what its start-up takes, was seen seconds into the job.)"""
    try:
        return any(f.path.endswith(".mp4") for f in p.open_files())
    except psutil.Error:
        return False


def wait_busy(descendants: Descendants, proc: subprocess.Popen | None, workers: int, out: Callable[[], str]) -> None:
    """Wait until ``workers`` spawned workers are in the middle of a job (while the command still runs)."""
    def busy():
        assert proc is None or proc.poll() is None, f"the command ended before it was stopped:\n{out()}"
        return sum(in_a_job(p) for p in descendants.workers()) >= workers
    wait_until(busy, START_TIMEOUT_S, f"{workers} worker process(es) in a job")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _sigint_at_default() -> None:
    """In the child before exec: SIGINT at its default (a shell running the tests as a background
    job hands its children SIGINT ignored, and Ctrl-C would then do nothing)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@contextmanager
def command(args: list[str], cache_dir: Path) -> Iterator[tuple[subprocess.Popen, Callable[[], str]]]:
    """``inspector ARGS`` in its own process group (as a terminal runs it), its output collected."""
    proc = subprocess.Popen([sys.executable, "-m", "inspector", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True,
                            preexec_fn=_sigint_at_default,
                            env=dict(os.environ, PYTHONUNBUFFERED="1", INSPECTOR_CACHE_DIR=str(cache_dir)))
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout or ()), daemon=True)
    reader.start()
    try:
        yield proc, lambda: "".join(lines)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=60)
        # The output pipe closes once every process holding it has ended, leftovers included:
        # not waited for here, the descendants are checked one by one.
        reader.join(timeout=1)


STOPS = {
    "ctrl-c": (lambda proc: os.killpg(proc.pid, signal.SIGINT)),  # the terminal's whole group
    "sigint": (lambda proc: proc.send_signal(signal.SIGINT)),  # `kill -INT`: the command alone
    "sigterm": (lambda proc: proc.send_signal(signal.SIGTERM)),  # `kill`, a timeout, a benchmark
    "sigkill": (lambda proc: proc.send_signal(signal.SIGKILL)),  # `kill -9`: no clean-up at all
}


def stop_and_check(proc: subprocess.Popen, descendants: Descendants, how: str, out: Callable[[], str],
                   exit_codes: dict[str, int]) -> None:
    descendants.record_now()
    STOPS[how](proc)
    try:
        proc.wait(timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail(f"still running 120 s after {how}:\n{out()}")
    descendants.stop_recording()
    assert descendants.seen, "the command started no process: nothing was tested"
    assert_all_gone(descendants, f"after {how} of the command (exit {proc.returncode})")
    assert proc.returncode == exit_codes[how], out()


# ----------------------------------------------------------------------------------------------
# inspector serve, its overview computing rows


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm", "sigkill"])
def test_serve_leaves_no_process(long_session, tmp_path, how):
    port = free_port()
    with command(["serve", str(long_session), "--port", str(port)], tmp_path / "cache") as (proc, out):
        descendants = Descendants(proc.pid)
        wait_until(lambda: f":{port}" in out() or proc.poll() is not None, START_TIMEOUT_S, "serve to start")
        assert proc.poll() is None, out()
        with HeadlessClient(port):  # a tab: the overview shows (many rollouts) and computes rows
            wait_busy(descendants, proc, 1, out)
            stop_and_check(proc, descendants, how, out, {"ctrl-c": 0, "sigterm": 0, "sigkill": -signal.SIGKILL})


def test_stopping_an_app_in_this_process_ends_its_worker(long_session, tmp_path):
    descendants = Descendants(os.getpid(), only=is_worker)  # this process's other children aside
    app = serve([long_session], port=0, block=False, use_cache=False)  # every row to compute
    try:
        with HeadlessClient(app.port):
            wait_busy(descendants, None, 1, str)
            descendants.record_now()
    finally:
        app.stop()
    descendants.stop_recording()
    left = descendants.alive()  # stop() returns once its worker has ended: no waiting here
    assert not left, f"running after stop() returned: {left}"


# ----------------------------------------------------------------------------------------------
# Stopping a pool while a worker is exiting, starting, or being let go


STOP_ROUNDS = 5  # pools stopped in a row: a worker caught exiting in one of them fails the test


def _spin(seconds: float) -> float:
    """A job that keeps its worker busy."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass
    return seconds


def _no_outcomes(task) -> list:
    """The overview's job, computing nothing."""
    return []


def has_exited(pid: int) -> bool:
    """The process is gone, or a zombie (only its exit status is left to collect)."""
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


@contextmanager
def busy_cores() -> Iterator[None]:
    """Every core busy meanwhile, as on the shared machine where a worker was seen exiting after
    its pool had been stopped."""
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 1)]
    try:
        yield
    finally:
        for p in spinners:
            p.kill()
        for p in spinners:
            p.wait()


def test_stop_pool_returns_once_its_workers_have_exited():
    """A killed worker's pipes close as it starts exiting, before it has exited: stop_pool waits
    for the exit itself. A worker at the lowest priority on busy cores stays long between the two."""
    caught: list[int] = []
    with busy_cores():
        for _ in range(STOP_ROUNDS):
            pool = spawn_pool(2)
            futures = [pool.submit(_spin, 60.0) for _ in range(2)]
            workers = list(pool._processes.values())
            for w in workers:
                psutil.Process(w.pid).nice(19)
            try:
                stop_pool(pool, grace_s=0)
                caught += [w.pid for w in workers if not has_exited(w.pid)]
            finally:
                for w in workers:
                    w.kill()
                    w.join()
            assert all(f.done() for f in futures)
    assert not caught, f"running after stop_pool returned: {caught}"


def test_stop_pool_ends_a_worker_that_a_submit_is_starting():
    """stop_pool while another thread's submit is starting the pool's first worker: that worker
    ends too (it used to be missed, and ran the job)."""
    pool = spawn_pool(1)
    started = pool._processes  # the pool's own mapping, filled as it starts workers
    spawning = threading.Event()
    spawn = pool._spawn_process

    def slow_spawn() -> None:
        spawning.set()
        time.sleep(1.0)  # stop_pool is called meanwhile
        spawn()

    pool._spawn_process = slow_spawn  # type: ignore[method-assign]
    submitter = threading.Thread(target=lambda: pool.submit(_spin, 60.0))
    submitter.start()
    try:
        assert spawning.wait(60)
        stop_pool(pool, grace_s=0)
        left = [w.pid for w in list(started.values()) if not has_exited(w.pid)]
    finally:
        submitter.join(60)
        for w in list(started.values()):
            w.kill()
            w.join()
    assert started, "no worker was started: nothing was tested"
    assert not left, f"running after stop_pool returned: {left}"


def _half_a_result(ready: str) -> None:
    """A job that sends the header of a 1 MiB result on its worker's result pipe and no bytes
    after it, then waits: a worker killed half way through sending a large result."""
    import struct

    frame = sys._getframe()
    while frame is not None and frame.f_code.co_name != "_process_worker":
        frame = frame.f_back
    assert frame is not None, "not in a pool's worker"
    os.write(frame.f_locals["result_queue"]._writer.fileno(), struct.pack("!i", 1 << 20))
    Path(ready).touch()
    time.sleep(600)


def test_stop_pool_ends_the_pools_thread_that_a_half_sent_result_left_reading(tmp_path):
    """A worker killed between a large result's header and its bytes left the pool's own thread
    reading forever (this process holds that pipe's write end too), and a command joining it at
    exit never ended: stop_pool ends that thread."""
    ready = tmp_path / "header-sent"
    pool = spawn_pool(1)
    future = pool.submit(_half_a_result, str(ready))
    wait_until(ready.exists, START_TIMEOUT_S, "the worker to send half a result")
    manager = pool._executor_manager_thread
    assert manager is not None and manager.is_alive()
    stop_pool(pool, grace_s=0)
    manager.join(60)  # (stop_pool waits for it itself: this only keeps a failure from hanging)
    assert not manager.is_alive(), "the pool's thread still waits for the rest of the result"
    assert future.done() and future.exception() is not None


def test_the_overviews_workers_load_what_reports_do_at_a_lower_priority():
    """A worker of the app's overview imports no part of the app (a spawned worker imports its
    initializer's module: it once imported viser and every app module), has numpy's BLAS on one
    thread, and runs at nice 10."""
    pool = spawn_pool(1, init_background_worker, (10,))
    try:
        # eval: a builtin, so the worker imports nothing of this module to run the job
        loaded, blas_threads, nice = pool.submit(eval, "(sorted(__import__('sys').modules.keys() & "
                                                 "{'viser', 'inspector.app', 'trimesh'}), "
                                                 "__import__('os').environ.get('OPENBLAS_NUM_THREADS'), "
                                                 "__import__('os').nice(0))").result(timeout=START_TIMEOUT_S)
    finally:
        stop_pool(pool)
    assert loaded == []
    assert blas_threads == "1"
    assert nice >= 10


def test_stopping_the_overview_as_it_lets_its_worker_go_waits_for_that_worker(monkeypatch):
    """OverviewRows.stop() while the computing thread, every row done, is shutting its pool down:
    stop() returns once the worker has ended (it used to find no pool and return at once)."""
    import inspector.app._overview_rows as overview_rows
    from inspector.app._catalog import Catalog
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    letting_go, go_on = threading.Event(), threading.Event()
    workers: list = []

    def spawn(*args, **kwargs):
        pool = spawn_pool(*args, **kwargs)
        workers.append(pool._processes)  # the pool's own mapping, filled as it starts workers
        shutdown = pool.shutdown

        def slow_shutdown(wait: bool = True, **kw) -> None:
            if wait:  # the computing thread letting the pool go (stop_pool does not wait)
                letting_go.set()
                go_on.wait(60)
            shutdown(wait=wait, **kw)

        pool.shutdown = slow_shutdown
        return pool

    monkeypatch.setattr(overview_rows, "spawn_pool", spawn)
    monkeypatch.setattr(overview_rows, "run_task", _no_outcomes)
    catalog = Catalog(open_sources([BUNDLED_DEMO], confine=True, datasets=True), None, {},
                      metrics_cache=MetricsCache(enabled=False))
    rows = overview_rows.OverviewRows(catalog)
    rows.start()
    try:
        assert letting_go.wait(START_TIMEOUT_S), "the overview computed no row in a worker"
        rows.stop()
        pids = [w.pid for mapping in workers for w in list(mapping.values())]
        left = [pid for pid in pids if not has_exited(pid)]
    finally:
        go_on.set()
        assert rows.done.wait(60)
    assert pids, "no worker was started: nothing was tested"
    assert not left, f"running after stop() returned: {left}"


def test_stopping_the_overview_as_it_hands_its_tasks_over_ends_it_quietly(monkeypatch):
    """OverviewRows.stop() between the computing thread making its pool and handing it the tasks:
    the thread ends as stopped (it raised "cannot schedule new futures after shutdown")."""
    import inspector.app._overview_rows as overview_rows
    from inspector.app._catalog import Catalog
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    stopped, raised = threading.Event(), []

    def spawn(*args, **kwargs):
        pool = spawn_pool(*args, **kwargs)
        submit = pool.submit

        def submit_once_stopped(*a, **kw):
            if not stopped.is_set():  # stop() from another thread, as the server's shutdown does
                threading.Thread(target=lambda: (rows.stop(), stopped.set())).start()
                assert stopped.wait(START_TIMEOUT_S)
            return submit(*a, **kw)

        pool.submit = submit_once_stopped
        return pool

    monkeypatch.setattr(overview_rows, "spawn_pool", spawn)
    monkeypatch.setattr(threading, "excepthook", lambda args: raised.append(args.exc_value))
    catalog = Catalog(open_sources([BUNDLED_DEMO], confine=True, datasets=True), None, {},
                      metrics_cache=MetricsCache(enabled=False))
    rows = overview_rows.OverviewRows(catalog)
    rows.start()
    assert rows.done.wait(START_TIMEOUT_S), "the computing thread never ended"
    assert stopped.is_set(), "the pool was never handed a task: nothing was tested"
    assert raised == []


# ----------------------------------------------------------------------------------------------
# report and export, their workers computing


COMMAND_EXITS = {"ctrl-c": 130, "sigint": 130, "sigterm": 143, "sigkill": -signal.SIGKILL}


# Report's Ctrl-C is test_scale's (its workers, gone, by the run's own check at its end), and
# SIGKILL leaves workers to notice their parent is gone as export's do (one pool, one watch).
@pytest.mark.parametrize("how", ["sigint", "sigterm"])
def test_report_leaves_no_process(long_session, tmp_path, how):
    with command(["report", str(long_session), "--jobs", "2", "--no-cache", "--json"], tmp_path / "cache") as (proc, out):
        descendants = Descendants(proc.pid)
        wait_busy(descendants, proc, 2, out)
        stop_and_check(proc, descendants, how, out, COMMAND_EXITS)


@pytest.mark.parametrize("how", list(STOPS))
def test_export_leaves_no_process_and_no_partial_file(long_session, tmp_path, how):
    dest = tmp_path / "out"
    with command(["export", str(long_session), "-o", str(dest), "--jobs", "2", "--no-cache"],
                 tmp_path / "cache") as (proc, out):
        descendants = Descendants(proc.pid)
        wait_busy(descendants, proc, 2, out)
        stop_and_check(proc, descendants, how, out, COMMAND_EXITS)
    # An interrupted worker removes the recording it was writing (with SIGKILL, it notices that
    # its parent is gone and is interrupted as on Ctrl-C).
    partial = [p.name for p in dest.rglob("*") if p.name.endswith(".partial")] if dest.exists() else []
    assert not partial, partial
