"""``--ray``: the report's and the export's per-rollout jobs as Ray tasks, on a local Ray instance
or on an existing cluster.

The jobs are the very ones the local path runs (:func:`inspector.report_jobs.run_task` on the
same :class:`~inspector.report_jobs.Task` objects, :func:`inspector.export_jobs.run_export_job`),
so results are the same by construction; Ray only decides where they run. Jobs name rollouts by
path and carry no data: every worker reads them from disk, so sessions and their GT datasets must
sit on storage each node mounts at the same path. Only summary rows (or the path of a written
recording) come back to the driver, as each task finishes.

Addresses, as Ray names them: ``local`` starts a Ray instance of ``jobs`` CPUs in this process for
the run (no dashboard, no usage statistics) and stops it at the end; ``auto`` joins the cluster
this machine belongs to; ``HOST:PORT`` (the head's GCS) or ``ray://HOST:PORT`` (Ray Client) join
that cluster. An address is probed before Ray is asked, so one that nothing answers at is a
one-line error within seconds rather than Ray's minutes of retries. When this process is already
connected (``ray.init`` called by a notebook or a test), that connection is used and left open.

Ray is an optional dependency: ``pip install 'inspector[ray]'``.
"""

from __future__ import annotations

import logging
import os
import re
import socket
import sys
import warnings
from contextlib import contextmanager, suppress
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterable, Iterator, Sequence, TypeVar

from .cache import ENV_DIR as CACHE_ENV_DIR
from .errors import InspectorError
from .report_jobs import EpisodeTask, Outcome, Task, default_jobs, rollouts_per_task, worker_died

LOCAL = "local"
INSTALL_HINT = "install with pip install 'inspector[ray]'"
# How long an address may take to accept a TCP connection before it counts as unreachable [s].
PROBE_TIMEOUT_S = 5.0
_ADDRESS = re.compile(r"(?:ray://)?(?P<host>\[[^\]]+\]|[^\s:/\[\]]+):(?P<port>\d{1,5})")

J = TypeVar("J")
R = TypeVar("R")


def import_ray() -> Any:
    """The ``ray`` module, or an :class:`InspectorError` that says how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise InspectorError("--ray", f"Ray is not installed ({exc}); {INSTALL_HINT}") from None
    return ray


@dataclass
class RayWorkers:
    """A connection to a Ray cluster, for :func:`ray_workers`.

    Attributes:
        address: the address it was opened with.
        cpus: the cluster's CPUs when it was joined (each task takes one).
        max_in_flight: at most this many tasks submitted at once (None: all of them).
    """

    address: str
    cpus: int
    max_in_flight: int | None

    def run_tasks(self, tasks: Sequence[Task | EpisodeTask]) -> Iterator[list[Outcome]]:
        """Outcomes of ``tasks`` as Ray tasks finish: :func:`inspector.report_jobs.run_task` on each.

        Tasks are re-cut for this cluster's CPUs: large ones split, small ones bundled into one
        Ray task, so that none is smaller than its scheduling cost and every CPU gets about two.
        """
        bundles = bundle_tasks(tasks, self.cpus if self.max_in_flight is None else self.max_in_flight)
        for bundle, outcomes, lost in self._stream(_run_bundle, bundles):
            yield outcomes if lost is None else [o for task in bundle for o in worker_died(task, lost)]

    def run_exports(self, jobs: Sequence[Any]) -> Iterator[Any]:
        """:class:`inspector.export_jobs.ExportOutcome` of each export job as it finishes."""
        from .export_jobs import ExportOutcome, run_export_job

        for job, outcome, lost in self._stream(run_export_job, jobs):
            yield outcome if lost is None else ExportOutcome.died(job, lost)

    def _stream(self, fn: Callable[[J], R], jobs: Iterable[J]) -> Iterator[tuple[J, R | None, str | None]]:
        """(job, result, None), or (job, None, why) when its worker was lost, as jobs finish."""
        ray = import_ray()
        remote = ray.remote(num_cpus=1)(fn)
        todo = iter(jobs)
        pending: dict[Any, J] = {}

        def submit() -> None:
            while self.max_in_flight is None or len(pending) < self.max_in_flight:
                job = next(todo, None)
                if job is None:
                    return
                pending[remote.remote(job)] = job

        try:
            submit()
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                for ref in ready:
                    job = pending.pop(ref)
                    try:
                        yield job, ray.get(ref), None
                    except ray.exceptions.RayTaskError as exc:
                        raise _task_failure(exc, self.address) from None
                    except ray.exceptions.RayError as exc:  # the worker or its node died, out of memory
                        yield job, None, _first_line(exc)
                submit()
        finally:
            for ref in pending:  # stopped early (an error, Ctrl-C): the cluster need not go on
                with suppress(Exception):  # never hide why it stopped
                    ray.cancel(ref, force=True)


@contextmanager
def ray_workers(address: str, jobs: int | None = None) -> Iterator[RayWorkers]:
    """Join (or start, for ``local``) a Ray cluster for one run; leave it at the end.

    Args:
        address: ``local``, ``auto``, ``HOST:PORT`` or ``ray://HOST:PORT`` (see the module docstring).
        jobs: ``local``: the instance's CPUs (default: this machine's); a cluster: at most this
            many tasks at once (default: no limit, the cluster schedules them).

    Raises:
        InspectorError: Ray is missing, the address is malformed or unreachable.
    """
    ray = import_ray()
    if ray.is_initialized():  # a notebook's or a test's connection: used, and left open
        yield RayWorkers("(connected)", _cluster_cpus(ray), jobs)
        return
    check_address(address)
    local = address == LOCAL
    cpus = jobs or default_jobs()
    options: dict[str, Any] = {"address": address, "logging_level": logging.ERROR, "log_to_driver": True}
    if os.environ.get(CACHE_ENV_DIR):  # a cluster's workers see the driver's cache directory
        options["runtime_env"] = {"env_vars": {CACHE_ENV_DIR: os.environ[CACHE_ENV_DIR]}}
    if local:
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # nothing leaves the machine
        options.update(num_cpus=cpus, include_dashboard=False)
    try:
        with warnings.catch_warnings():  # Ray Client warns before it raises: the error says it all
            warnings.simplefilter("ignore")
            ray.init(**options)
    except (Exception, SystemExit) as exc:  # Ray exits the process when a GCS never answers
        raise InspectorError(address, f"cannot {'start' if local else 'join'} a Ray cluster ({_first_line(exc)})") from None
    try:
        workers = RayWorkers(address, cpus if local else _cluster_cpus(ray), None if local else jobs)
        print(f"inspector: Ray at {address}, {workers.cpus} CPU(s)", file=sys.stderr)
        yield workers
    finally:
        ray.shutdown()


def check_address(address: str) -> None:
    """Refuse a malformed address, and one where nothing accepts a connection (in seconds).

    Raises:
        InspectorError: naming the address and what is wrong with it.
    """
    if address in (LOCAL, "auto"):
        endpoint = _auto_endpoint() if address == "auto" else None
    else:
        match = _ADDRESS.fullmatch(address)
        if match is None:
            raise InspectorError(address, "not a Ray address; expected auto, HOST:PORT or ray://HOST:PORT "
                                          "(with no address, --ray goes after the paths)")
        endpoint = (match["host"].strip("[]"), int(match["port"]))
    if endpoint is None:
        return
    try:
        with socket.create_connection(endpoint, timeout=PROBE_TIMEOUT_S) as conn:
            speaks_grpc = os.environ.get("RAY_USE_TLS", "0").lower() in ("1", "true") or _answers_http2(conn)
    except OSError as exc:
        raise InspectorError(address, f"cannot reach a Ray cluster there ({exc.strerror or exc})") from None
    if not speaks_grpc:  # e.g. the dashboard's port: Ray would retry for many minutes
        raise InspectorError(address, "answers, but not as Ray's GCS or Ray Client (both speak gRPC; by "
                                      "default the GCS listens on port 6379, Ray Client on 10001)")


def _answers_http2(conn: socket.socket) -> bool:
    """True when the server opens HTTP/2 (a gRPC server's first frame is SETTINGS, type 4)."""
    conn.sendall(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]))
    head = b""
    try:
        while len(head) < 9:
            more = conn.recv(9 - len(head))
            if not more:
                break
            head += more
    except socket.timeout:
        pass
    return len(head) == 9 and head[3] == 4


def _auto_endpoint() -> tuple[str, int] | None:
    """Where ``auto`` leads (``$RAY_ADDRESS``, else the cluster last started on this machine)."""
    try:  # Ray's own lookup (private): only to probe before Ray's long retries; Ray decides
        from ray._private.services import canonicalize_bootstrap_address

        match = _ADDRESS.fullmatch(canonicalize_bootstrap_address("auto") or "")
    except Exception:
        return None  # none found: ray.init says so at once
    return None if match is None else (match["host"].strip("[]"), int(match["port"]))


def bundle_tasks(tasks: Sequence[Task | EpisodeTask], workers: int) -> list[list[Task | EpisodeTask]]:
    """``tasks`` re-cut for ``workers`` CPUs: each bundle (one Ray task) holds about
    :func:`inspector.report_jobs.rollouts_per_task` rollouts, from one task or several small ones."""
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
    """What a Ray worker runs: the local path's :func:`~inspector.report_jobs.run_task`, task by task."""
    from .report_jobs import _init_worker, run_task

    _init_worker()
    return [o for task in bundle for o in run_task(task)]


def _cluster_cpus(ray: Any) -> int:
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


def _task_failure(exc: Any, address: str) -> BaseException:
    """What a job raised on a worker, raised here as the local path would raise it."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, ImportError):
        return InspectorError(address, f"the Ray workers cannot import inspector ({cause}); install the same "
                                       "version of inspector on every node")
    return cause if isinstance(cause, BaseException) else exc


def _first_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__
