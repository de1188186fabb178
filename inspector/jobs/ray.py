"""``--ray``: jobs as Ray tasks, on a local Ray instance or on an existing cluster.

:meth:`RayWorkers.imap` runs any picklable function over jobs; the report and the export hand it
the very jobs their local paths run (:func:`inspector.rows.tasks.run_tasks_on_ray`,
:func:`inspector.export.jobs.export_on_ray`), so results are the same by construction; Ray only
decides where they run. Jobs name rollouts by
path and carry no data: every worker reads them from disk, so sessions and their GT datasets must
sit on storage each node mounts at the same path. Only summary rows (or the path of a written
recording) come back to the driver, as each task finishes.

Addresses, as Ray names them: ``local`` starts a Ray instance of ``jobs`` CPUs in this process for
the run (no dashboard, no usage statistics) and stops it at the end; ``auto`` joins the cluster
this machine belongs to; ``HOST:PORT`` (the head's GCS) or ``ray://HOST:PORT`` (Ray Client) join
that cluster. An address is probed before Ray is asked, so one that nothing answers at is a
one-line error within seconds rather than Ray's minutes of retries. When this process is already
connected (``ray.init`` called by a notebook or a test), that connection is used and left open.

The workers run at niceness 0, as a ``--jobs`` worker does, not at Ray's 15 (:func:`worker_env`):
at 15 they yield the CPU to every other process of the node, and a report on a node that runs
anything else took up to twice as long as ``--jobs``.

Ray is an optional dependency: ``pip install 'inspector[ray]'``.
"""

from __future__ import annotations

import logging
import os
import re
import socket
import sys
import warnings
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from typing import Any, TypeVar

from ..cache import ENV_DIR as CACHE_ENV_DIR
from ..errors import InspectorError
from .pool import default_jobs

LOCAL = "local"
INSTALL_HINT = "install with pip install 'inspector[ray]'"
# How long an address may take to accept a TCP connection before it counts as unreachable [s].
PROBE_TIMEOUT_S = 5.0
# The niceness of this run's Ray workers, and the variable through which Ray takes it from a job.
WORKER_NICENESS = 0
NICENESS_ENV = "RAY_worker_niceness"
# How a driver tells Ray (>= 2.52) to send its token.
AUTH_MODE_ENV = "RAY_AUTH_MODE"
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

    def imap(self, fn: Callable[[J], R], jobs: Iterable[J]) -> Iterator[tuple[J, R | None, str | None]]:
        """``fn(job)`` for each job as a Ray task (one CPU each), as they finish: (job, result,
        None), or (job, None, why) when its worker or node was lost.

        An exception ``fn`` raised is raised here as the local path would raise it.
        """
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
    options: dict[str, Any] = {"address": address, "logging_level": logging.ERROR, "log_to_driver": True,
                               "runtime_env": {"env_vars": worker_env()}}
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


def worker_env() -> dict[str, str]:
    """Environment variables of this run's Ray workers (the job's runtime env).

    The driver's metrics cache directory, where set, so a cluster's workers share it; and the
    workers' niceness: Ray starts task workers at niceness 15, below every other process on the
    node, so on a node that also runs other work they get a fraction of a CPU each. Ours run at
    :data:`WORKER_NICENESS` (what a ``--jobs`` worker runs at), as Ray's own job supervisor does;
    ``RAY_worker_niceness`` set on the driver wins (15: Ray's default).
    """
    env = {NICENESS_ENV: os.environ.get(NICENESS_ENV, str(WORKER_NICENESS))}
    if os.environ.get(CACHE_ENV_DIR):
        env[CACHE_ENV_DIR] = os.environ[CACHE_ENV_DIR]
    return env


def check_address(address: str) -> None:
    """Refuse, in seconds, a malformed address, one where nothing accepts a connection, and one
    where something else answers (not gRPC, or a gRPC service that is neither Ray's GCS nor Ray Client).

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
    serves = _serves_ray(endpoint, client_first=address.startswith("ray://"))
    if serves is None:  # another gRPC service
        raise InspectorError(address, "a gRPC service, but not Ray's GCS or Ray Client (it knows neither's "
                                      "methods; by default the GCS listens on port 6379, Ray Client on 10001)")
    # Given an address, Ray sends no token unless told to, and retries for a minute before it fails.
    if serves == "token" and address != "auto" and os.environ.get(AUTH_MODE_ENV, "").lower() != "token":
        raise InspectorError(address, f"the cluster requires token authentication: set {AUTH_MODE_ENV}=token, "
                                      "with the cluster's token in RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH or "
                                      "~/.ray/auth_token")


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
    except TimeoutError:
        pass
    return len(head) == 9 and head[3] == 4


# A method only Ray's GCS serves, and one only Ray Client serves. Asked with an empty request, any
# answer but UNIMPLEMENTED (even an error about the request, or a missing token) says Ray is there.
_GCS_METHOD = "/ray.rpc.NodeInfoGcsService/GetClusterId"
_CLIENT_METHOD = "/ray.rpc.RayletDriver/ClusterInfo"


def _serves_ray(endpoint: tuple[str, int], client_first: bool) -> str | None:
    """None when the gRPC server at ``endpoint`` has neither Ray service (another gRPC server);
    ``token`` when Ray asked for an authentication token; ``ray`` otherwise, whatever else goes
    wrong (Ray itself then says what)."""
    try:
        import grpc  # Ray's own dependency
    except ImportError:
        return "ray"
    host, port = endpoint
    methods = (_CLIENT_METHOD, _GCS_METHOD) if client_first else (_GCS_METHOD, _CLIENT_METHOD)
    with grpc.insecure_channel(f"[{host}]:{port}" if ":" in host else f"{host}:{port}") as channel:
        for method in methods:
            try:
                channel.unary_unary(method)(b"", timeout=PROBE_TIMEOUT_S)  # bytes in, bytes out
            except grpc.RpcError as exc:
                if exc.code() == grpc.StatusCode.UNIMPLEMENTED:
                    continue
                if exc.code() == grpc.StatusCode.UNAUTHENTICATED:
                    return "token"
            return "ray"
    return None


def _auto_endpoint() -> tuple[str, int] | None:
    """Where ``auto`` leads (``$RAY_ADDRESS``, else the cluster last started on this machine)."""
    try:  # Ray's own lookup (private): only to probe before Ray's long retries; Ray decides
        from ray._private.services import canonicalize_bootstrap_address

        match = _ADDRESS.fullmatch(canonicalize_bootstrap_address("auto") or "")
    except Exception:
        return None  # none found: ray.init says so at once
    return None if match is None else (match["host"].strip("[]"), int(match["port"]))


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
