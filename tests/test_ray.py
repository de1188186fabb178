"""``--ray``: report and export jobs as Ray tasks, on real Ray instances of 2 CPUs.

Ray starts slowly (seconds), so the instances are two, one after the other: the command line's
report is compared with the local run's JSON on a head started by ``ray start`` (as a cluster
user joins one); the rest share one local instance that this module starts in the test process
(as ``--ray`` without an address starts one) and stops at its end, checking that Ray's processes
went with it. Addresses that lead nowhere are refused in seconds without Ray.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from demo_copies import demo_copy

from inspector.errors import InspectorError
from inspector.report.build import FIELDS_SET_AFTER_CACHE as AFTER_CACHE
from inspector.report.build import build_report
from inspector.rows.tasks import Task, rollouts_per_task, run_task, run_tasks_on_ray

ray = pytest.importorskip("ray", reason="Ray is an optional extra: pip install -e '.[ray]'")

from test_export import rrd_verify  # noqa: E402

from inspector.export.command import export_cli  # noqa: E402
from inspector.jobs.ray import NICENESS_ENV, check_address, import_ray, ray_workers, worker_env  # noqa: E402
from inspector.rows.tasks import bundle_tasks  # noqa: E402

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "sessions" / "demo"
RAY_PROCESSES = ("raylet", "gcs_server")


def ray_processes() -> set[int]:
    import psutil

    pids = set()
    for p in psutil.process_iter(["name"]):
        if p.info["name"] in RAY_PROCESSES:
            pids.add(p.pid)
    return pids


def wait_gone(pids: set[int], deadline_s: float = 60) -> set[int]:
    """``pids`` still alive once they are all gone or the deadline has passed."""
    end = time.monotonic() + deadline_s
    while (alive := pids & ray_processes()) and time.monotonic() < end:
        time.sleep(0.2)
    return alive


def inspector(*args: str, cache_dir: Path, timeout: float = 600, env: dict[str, str] | None = None
              ) -> subprocess.CompletedProcess:
    env = {**os.environ, **(env or {}), "INSPECTOR_CACHE_DIR": str(cache_dir), "RAY_USAGE_STATS_ENABLED": "0"}
    return subprocess.run([sys.executable, "-m", "inspector", *map(str, args)], capture_output=True, text=True,
                          env=env, timeout=timeout)


@pytest.fixture()
def broken_demo(tmp_path: Path) -> Path:
    """Four demo rollouts, ``bias_elbow``'s wrist video truncated (undecodable after a few frames):
    it shares its GT episode, hence its task, with ``tempo_0.8x``; two single chunks of another
    episode are tasks of their own."""
    session = demo_copy(tmp_path, ("bias_elbow", "tempo_0.8x", "single_f000", "single_f076"))
    video = session / "rollouts" / "bias_elbow" / "video" / "wrist.mp4"
    video.write_bytes(video.read_bytes()[:5000])
    return session


# ----------------------------------------------------------------------------------------------
# The command line, joining a head started by ``ray start`` (as a cluster user joins one)


def free_ports(k: int) -> list[int]:
    sockets = [socket.socket() for _ in range(k)]
    for s in sockets:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in sockets]
    for s in sockets:
        s.close()
    return ports


@contextlib.contextmanager
def running_head(log: Path) -> Iterator[dict]:
    """A Ray head of 2 CPUs started by ``ray start --head`` with token authentication, as a
    cluster's is: ``{"address": HOST:PORT, "auth": the environment that carries its token}``.
    Every process it started is gone once it is stopped."""
    import psutil

    port, client_port, agent_port = free_ports(3)
    temp_dir = Path(tempfile.mkdtemp(prefix="ray-", dir="/tmp"))  # Ray's socket paths must be short
    auth = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": uuid.uuid4().hex}  # not ~/.ray/auth_token, if any
    with open(log, "w") as out:
        proc = subprocess.Popen([str(Path(sys.executable).with_name("ray")), "start", "--head", "--block",
                                 "--num-cpus", "2", "--include-dashboard=false", "--disable-usage-stats",
                                 "--node-ip-address", "127.0.0.1", "--port", str(port),
                                 "--ray-client-server-port", str(client_port),
                                 "--dashboard-agent-listen-port", str(agent_port), "--temp-dir", str(temp_dir)],
                                stdout=out, stderr=subprocess.STDOUT, env={**os.environ, **auth},
                                start_new_session=True)
    started: list = []
    try:
        deadline = time.monotonic() + 120
        while "Ray runtime started" not in log.read_text():
            assert proc.poll() is None and time.monotonic() < deadline, log.read_text()[-2000:]
            time.sleep(0.5)
        yield {"address": f"127.0.0.1:{port}", "auth": auth}
    finally:
        with contextlib.suppress(psutil.Error):
            started = psutil.Process(proc.pid).children(recursive=True)
        proc.terminate()  # ray start --block stops what it started
        proc.wait(60)
        _, alive = psutil.wait_procs(started, timeout=30)
        for p in alive:
            with contextlib.suppress(psutil.Error):
                p.kill()
        shutil.rmtree(temp_dir, ignore_errors=True)
    assert not alive, f"the head's processes outlived it: {[p.pid for p in alive]}"


# Two GT episodes: the prompt pair and another rollout of episode 0 (one task of three rollouts,
# cut in two for 2 CPUs), and two single chunks of episode 1 (a task of their own)
REPORT_TAGS = ("bias_elbow", "prompt_novel", "prompt_train", "single_f000", "single_f076")


@pytest.fixture(scope="module")
def demo_reports(tmp_path_factory) -> dict:
    """``report --json`` of a copy of five demo rollouts (:data:`REPORT_TAGS`), locally
    (``--jobs 1``: in the command's process) and with ``--ray`` on a head started for it (gone
    before this module's local instance starts), and the head asked without its token; the Ray
    run's metrics cache is kept for :func:`test_ray_workers_honour_the_metrics_cache`."""
    tmp = tmp_path_factory.mktemp("demo-reports")
    session = demo_copy(tmp, REPORT_TAGS)
    local = inspector("report", session, "--json", "--jobs", "1", cache_dir=tmp / "cache-local")
    assert local.returncode == 0, local.stderr
    with running_head(tmp / "head.log") as head:
        on_ray = inspector("report", session, "--json", "--ray", head["address"], cache_dir=tmp / "cache-ray",
                           env=head["auth"])
        assert on_ray.returncode == 0, on_ray.stderr
        start = time.monotonic()
        refused = inspector("report", session, "--ray", head["address"], cache_dir=tmp / "cache-refused",
                            env={"RAY_AUTH_MODE": "disabled"})
        refused_s = time.monotonic() - start
    return {"local": local, "ray": on_ray, "session": session, "ray_cache": tmp / "cache-ray",
            "address": head["address"], "refused": refused, "refused_s": refused_s}


def test_report_json_on_a_running_head_is_the_local_report(demo_reports):
    local, on_ray = demo_reports["local"], demo_reports["ray"]
    assert f"inspector: Ray at {demo_reports['address']}, 2 CPU(s)" in on_ray.stderr
    assert json.loads(on_ray.stdout) == json.loads(local.stdout)
    report = json.loads(on_ray.stdout)
    assert sorted(r["tag"] for r in report["rollouts"]) == sorted(REPORT_TAGS)  # every rollout copied
    assert report["prompt_divergence"]  # the prompt pair


def test_a_head_that_wants_a_token_is_one_line_without_one(demo_reports):
    """No token sent: one line, at once, not Ray's minute of retries."""
    refused, address = demo_reports["refused"], demo_reports["address"]
    assert demo_reports["refused_s"] < 30
    assert refused.returncode == 2 and refused.stderr == (
        f"error: {address}: the cluster requires token authentication: set RAY_AUTH_MODE=token, with "
        "the cluster's token in RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token\n")


@pytest.mark.parametrize("command", ["report", "export"])
def test_ray_without_an_address_is_a_local_instance(command):
    """``--ray`` alone asks for the local instance (what :func:`local_ray` starts, as the commands do)."""
    from inspector.cli import build_parser

    out = ["-o", "out"] if command == "export" else []
    assert build_parser().parse_args([command, str(DEMO), "--ray", *out]).ray == "local"
    assert build_parser().parse_args([command, str(DEMO), *out]).ray is None


def test_unreachable_cluster_is_one_line(tmp_path):
    start = time.monotonic()
    out = inspector("report", DEMO, "--ray", "ray://127.0.0.1:1", cache_dir=tmp_path / "cache")
    assert time.monotonic() - start < 60
    assert out.returncode == 2
    assert out.stderr.startswith("error: ray://127.0.0.1:1: cannot reach a Ray cluster there (")
    assert out.stderr.count("\n") == 1 and out.stdout == ""


def test_addresses_that_are_not_ray_are_refused_in_seconds():
    with socket.socket() as server:  # listens, never answers: not a gRPC server
        server.bind(("127.0.0.1", 0))
        server.listen()
        address = f"127.0.0.1:{server.getsockname()[1]}"
        start = time.monotonic()
        with pytest.raises(InspectorError, match="answers, but not as Ray's GCS or Ray Client"):
            check_address(address)
        assert time.monotonic() - start < 30
    with pytest.raises(InspectorError, match="not a Ray address"):
        check_address("sessions/demo")  # --ray ADDRESS swallowed a path


@pytest.mark.parametrize("scheme", ["", "ray://"])
def test_a_grpc_service_that_is_not_ray_is_one_line_within_seconds(tmp_path, scheme):
    """A real gRPC server (its one service knows nothing of Ray's): ``--ray`` at it is exit 2 and
    one line within 30 s (Ray itself would retry for minutes)."""
    from concurrent.futures import ThreadPoolExecutor

    import grpc

    echo = grpc.unary_unary_rpc_method_handler(lambda request, context: request)
    server = grpc.server(ThreadPoolExecutor(max_workers=2))
    server.add_generic_rpc_handlers([grpc.method_handlers_generic_handler("demo.Echo", {"Say": echo})])
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:  # it is a working gRPC server
            assert channel.unary_unary("/demo.Echo/Say")(b"hi", timeout=10) == b"hi"
        start = time.monotonic()
        out = inspector("report", DEMO, "--ray", f"{scheme}127.0.0.1:{port}", cache_dir=tmp_path / "cache", timeout=90)
        assert time.monotonic() - start < 30
    finally:
        server.stop(None)
    assert out.returncode == 2, out.stderr
    assert out.stderr == (f"error: {scheme}127.0.0.1:{port}: a gRPC service, but not Ray's GCS or Ray Client "
                          "(it knows neither's methods; by default the GCS listens on port 6379, Ray Client on 10001)\n")
    assert out.stdout == ""


def test_missing_ray_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(InspectorError, match=r"pip install 'inspector\[ray\]'"):
        import_ray()


def test_bundles_cover_every_rollout_once_and_are_not_tiny():
    small = [Task("s", (f"t{i}",), None, 2.0) for i in range(40)]  # 40 GT groups of one rollout
    big = [Task("s", tuple(f"b{i}" for i in range(100)), None, 2.0)]
    for tasks, cpus in ((small, 2), (small + big, 4), (small, 64)):
        bundles = bundle_tasks(tasks, cpus)
        tags = [tag for bundle in bundles for task in bundle for tag in task.tags]
        assert tags == [tag for task in tasks for tag in task.tags]
        sizes = [sum(len(t.tags) for t in b) for b in bundles]
        per_task = rollouts_per_task(len(tags), cpus)
        assert all(per_task <= size < 2 * per_task for size in sizes[:-1]), sizes
    assert [len(b) for b in bundle_tasks(small, 2)] == [10] * 4  # 40 rollouts, 2 CPUs: 4 bundles of 10
    assert len(bundle_tasks(big, 2)) == 4  # 100 rollouts of one group, cut in 4


# ----------------------------------------------------------------------------------------------
# One local Ray instance (2 CPUs) shared by the tests below


@pytest.fixture(scope="module")
def local_ray():
    """A local instance of 2 CPUs started as ``--ray`` without an address starts one (saying so
    in one line), stopped at the module's end with every process of Ray's gone."""
    before = ray_processes()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    said = io.StringIO()
    with contextlib.redirect_stderr(said), ray_workers("local", 2) as workers:
        assert "inspector: Ray at local, 2 CPU(s)" in said.getvalue()
        assert workers.cpus == 2
        started = ray_processes() - before
        assert started, "no raylet or gcs_server started"
        yield workers
    assert not ray.is_initialized()
    assert not wait_gone(started), "Ray processes outlived the module"


def test_a_broken_rollout_is_listed_as_locally(local_ray, broken_demo):
    local = build_report([str(broken_demo)], jobs=1, use_cache=False)
    on_ray = build_report([str(broken_demo)], ray="local", use_cache=False)  # joins the shared instance
    assert "wrist.mp4" in on_ray["errors"]["demo/bias_elbow"]
    assert on_ray == local


def test_ray_workers_honour_the_metrics_cache(demo_reports, local_ray):
    """The command's Ray workers wrote the cache its driver named (``$INSPECTOR_CACHE_DIR``,
    passed to them in the job's environment); it serves this process and this module's Ray workers."""
    cache = demo_reports["ray_cache"]
    first = json.loads(demo_reports["ray"].stdout)
    assert list(cache.rglob("*.json")), "the Ray workers wrote no cache entries"
    tags = tuple(r["tag"] for r in first["rollouts"])
    session = str(demo_reports["session"])
    again = run_task(Task(session, tags, None, 2.0, str(cache)))  # here, from what Ray's workers wrote
    assert [o.cached for o in again] == [True] * len(tags)
    # the report adds the outcomes and what the source says after the cache (they change without
    # the rollout changing)
    reported = [{k: v for k, v in r.items() if k not in AFTER_CACHE} for r in first["rollouts"]]
    assert [json.loads(json.dumps(o.row)) for o in again] == reported  # as the command writes rows
    outcomes = [o for batch in run_tasks_on_ray(local_ray, [Task(session, tags, None, 2.0, str(cache))]) for o in batch]
    assert all(o.cached for o in outcomes) and len(outcomes) == len(tags)


def test_export_on_ray_writes_what_the_local_export_writes(local_ray, broken_demo, tmp_path, capsys):
    shutil.rmtree(broken_demo / "rollouts" / "tempo_0.8x")  # keep it short: bias_elbow (broken), single_f0*
    local_out, ray_out = tmp_path / "local", tmp_path / "ray"
    assert export_cli(broken_demo, local_out, use_cache=False) == 2
    local = capsys.readouterr()
    assert export_cli(broken_demo, ray_out, use_cache=False, ray="local") == 2
    on_ray = capsys.readouterr()
    assert sorted(p.name for p in ray_out.iterdir()) == sorted(p.name for p in local_out.iterdir()) \
        == ["single_f000.rrd", "single_f076.rrd"]
    rrd_verify(ray_out / "single_f000.rrd")
    assert on_ray.err == local.err and "wrist.mp4" in on_ray.err  # the same one line
    assert on_ray.out.replace(str(ray_out), "OUT") == local.out.replace(str(local_out), "OUT")


def test_ray_workers_run_at_the_niceness_of_local_workers(local_ray, monkeypatch):
    """Ray starts task workers at niceness 15; this run's ask for 0 (a --jobs worker's), unless
    the driver's environment says otherwise."""
    assert ray.get(ray.remote(num_cpus=1)(lambda: os.nice(0)).remote()) == 0
    assert worker_env()[NICENESS_ENV] == "0"
    monkeypatch.setenv(NICENESS_ENV, "15")
    assert worker_env()[NICENESS_ENV] == "15"
