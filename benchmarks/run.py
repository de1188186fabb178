"""Speed and memory of inspector as users run it, each beside a naive baseline measured in the same run.

    python benchmarks/run.py [--quick] [--json FILE] [--latest] [--only NAME...]

The command-line figures time the ``inspector`` command as a whole process (start to exit) and
take the peak of the summed RSS of its process tree (workers included), sampled every 20 ms;
each gets a fresh metrics cache unless the figure is about the cache. Baselines
(``benchmarks/naive.py``) run as processes too; where a naive run would take the machine down,
it runs on two smaller subsets and its time and memory are extrapolated along the line through
them (the table says so). The app's per-step figures (open, scrub) are server-side, in process.

Prints a markdown table: figure, ours (time, peak RSS), naive baseline, ratio (baseline / ours),
target, ok (``benchmarks/table.py``); ``--latest`` merges the figures into ``benchmarks/latest.json``
(replacing those of the same name) and rewrites the table in ``benchmarks/README.md``. Absolute
times drift on a shared machine; ratios measured back to back are what to compare between runs.
``--quick`` uses fewer repetitions and smaller counts (a few minutes).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO.parent / "shared" / "fixtures" / "dreamzero_so101"
DEMO = REPO / "sessions" / "demo"
NAIVE = Path(__file__).resolve().parent / "naive.py"
sys.path.insert(0, str(Path(__file__).resolve().parent))

import table  # noqa: E402
from eval_session import make_eval_session  # noqa: E402


@dataclass
class Figure:
    name: str
    ours: float
    unit: str
    target: str
    ok: bool
    ours_rss_mib: float | None = None
    baseline: float | None = None
    baseline_rss_mib: float | None = None
    note: str = ""

    @property
    def ratio(self) -> float | None:
        if self.baseline is None or not self.ours:
            return None
        # a rate (higher is better) divides the other way round
        return self.ours / self.baseline if self.unit.endswith("/s") else self.baseline / self.ours


@dataclass
class Measured:
    wall_s: float
    peak_mib: float
    stdout: str


def run_process(args: Sequence[str], env: dict[str, str] | None = None, timeout: float = 1800,
                also: int | None = None) -> Measured:
    """Run a command to its end: wall time and the peak summed RSS of its process tree, plus the
    processes started meanwhile under the process ``also`` (a Ray head: the workers of the run)."""
    # Output goes to files: a pipe nobody reads while the command runs would block a command that
    # writes more than the pipe holds (a report's JSON), and it would never end.
    with tempfile.TemporaryFile("w+") as out_file, tempfile.TemporaryFile("w+") as err_file:
        start = time.perf_counter()
        proc = subprocess.Popen(list(args), stdout=out_file, stderr=err_file, text=True,
                                env={**os.environ, **(env or {})})
        peak = _sample_peak_rss(proc, lambda: proc.poll() is not None, timeout, also)
        wall = time.perf_counter() - start
        out_file.seek(0)
        err_file.seek(0)
        out, err = out_file.read(), err_file.read()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, args))} exited {proc.returncode}: {err[-2000:]}")
    return Measured(wall, peak / 2**20, out)


def _sample_peak_rss(proc: subprocess.Popen, done: Callable[[], bool], timeout: float,
                     also: int | None = None) -> int:
    """Peak summed RSS of ``proc`` and its descendants (and of the descendants of process ``also``
    that were not there at the start), sampled every 20 ms until ``done()``.

    Finding the descendants scans every process of the machine (~2 ms of CPU), so the tree is
    looked up every 0.25 s and only its members' RSS read in between: the sampler stays well
    under 1% of a core instead of taking a tenth of one from the command it measures.
    """
    import psutil

    root = psutil.Process(proc.pid)
    tree: list[psutil.Process] = [root]
    other = psutil.Process(also) if also is not None else None
    there = {p.pid for p in other.children(recursive=True)} if other is not None else set()
    peak = 0
    deadline = time.monotonic() + timeout
    next_lookup = 0.0
    while not done():
        now = time.monotonic()
        if now > deadline:
            proc.kill()
            raise TimeoutError(f"pid {proc.pid} still running after {timeout} s")
        if now >= next_lookup:
            with contextlib.suppress(psutil.Error):
                tree = [root, *root.children(recursive=True)]
            if other is not None:
                with contextlib.suppress(psutil.Error):
                    tree += [p for p in other.children(recursive=True) if p.pid not in there]
            next_lookup = now + 0.25
        total = 0
        for p in tree:
            with contextlib.suppress(psutil.Error):
                total += p.memory_info().rss
        peak = max(peak, total)
        time.sleep(0.02)
    return peak


def inspector_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "inspector", *map(str, args)]


def fresh_cache(tmp: Path) -> dict[str, str]:
    """Environment for a process that starts with an empty metrics cache."""
    return {"INSPECTOR_CACHE_DIR": str(tmp / f"cache-{uuid.uuid4().hex[:8]}")}


def extrapolate(measure: Callable[[int], Measured], n_small: int, n_large: int, n: int) -> tuple[float, float]:
    """(time, peak MiB) at ``n``, on the line through the measurements at two subset sizes."""
    a, b = measure(n_small), measure(n_large)

    def line(ya: float, yb: float) -> float:
        return yb + (yb - ya) / (n_large - n_small) * (n - n_large)

    return line(a.wall_s, b.wall_s), line(a.peak_mib, b.peak_mib)


# ----------------------------------------------------------------------------------------------
# Kinematics (in process: a library figure)


def bench_fk(quick: bool) -> list[Figure]:
    """Batched FK vs a per-frame yourdfpy loop on the same inputs.

    ``fk``: the tool point of 1 M configurations (what every metric uses); ``fk_all_links``: every
    link's full pose (what the app and the export draw).
    """
    from inspector.robot.description import GRIPPER_FRAME, load_urdf
    from inspector.robot.kinematics import kinematics
    from inspector.units import JOINT_NAMES

    fk = kinematics()
    rng = np.random.default_rng(0)
    n = 200_000 if quick else 1_000_000
    q = rng.uniform(-1.5, 1.5, size=(n, 6))
    fk.link_origins(q[:1000], GRIPPER_FRAME)  # warm up
    tool = _best_of(lambda: fk.link_origins(q, GRIPPER_FRAME), 1 if quick else 3) / n
    all_links = _best_of(lambda: fk.link_poses(q), 1 if quick else 2) / n
    urdf = load_urdf(load_meshes=False).urdf
    m = 200

    def loop(links: list[str]) -> None:
        for i in range(m):
            urdf.update_cfg({j: q[i, k] for k, j in enumerate(JOINT_NAMES)})
            for link in links:
                urdf.get_transform(link, "base_link")

    base_tool = _best_of(lambda: loop([GRIPPER_FRAME]), 2) / m
    base_all = _best_of(lambda: loop(fk.link_names), 2) / m
    return [
        Figure("fk", 1.0 / tool, "configurations/s", ">= 1e6 /s and >= 50x",
               1.0 / tool >= 1e6 and base_tool / tool >= 50, baseline=1.0 / base_tool),
        Figure("fk_all_links", 1.0 / all_links, "configurations/s", ">= 50x", base_all / all_links >= 50,
               baseline=1.0 / base_all),
    ]


def _best_of(fn: Callable[[], object], repeat: int) -> float:
    """Fastest of ``repeat`` runs [s] (the least disturbed by other work on the machine)."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


# ----------------------------------------------------------------------------------------------
# inspector report (whole processes)


def bench_report(tmp: Path, quick: bool) -> list[Figure]:
    """``inspector report``: the demo, 1,000 rollouts without video, 200 with two views (cold,
    then warm from the metrics cache)."""
    n_many, n_video = (300, 60) if quick else (1000, 200)
    many = _eval_session(tmp, "many", n_many, video=False)
    video = _eval_session(tmp, "video", n_video, video=True)
    figures = []

    demo = run_process(inspector_cmd("report", DEMO, "--json"), env=fresh_cache(tmp))
    naive_demo = run_process([sys.executable, NAIVE, "report", DEMO])
    figures.append(Figure("report_demo", demo.wall_s, "s", "< 5 s and < 1 GB",
                          demo.wall_s < 5 and demo.peak_mib < 1024, demo.peak_mib,
                          naive_demo.wall_s, naive_demo.peak_mib))

    ours = run_process(inspector_cmd("report", many, "--json"), env=fresh_cache(tmp))
    # subsets of a tenth and a fifth: at 25 and 50 rollouts the start-up's jitter set the slope
    # (the same code's baseline came out at 7 s and at 46 s in two runs of one day)
    small, large = n_many // 10, n_many // 5
    naive_t, naive_m = extrapolate(lambda k: run_process([sys.executable, NAIVE, "report", many, "-n", str(k)]),
                                   small, large, n_many)
    figures.append(Figure(f"report_{n_many}", ours.wall_s, "s", "< 10 s and < 1 GB",
                          ours.wall_s < 10 and ours.peak_mib < 1024, ours.peak_mib, naive_t, naive_m,
                          f"naive extrapolated from {small} and {large} rollouts"))

    env = fresh_cache(tmp)
    cold = run_process(inspector_cmd("report", video, "--json"), env=env)
    naive_t, naive_m = extrapolate(lambda k: run_process([sys.executable, NAIVE, "report", video, "-n", str(k)]),
                                   5, 10, n_video)
    figures.append(Figure(f"report_{n_video}_video", cold.wall_s, "s", "< 60 s and < 1.5 GB",
                          cold.wall_s < 60 and cold.peak_mib < 1536, cold.peak_mib, naive_t, naive_m,
                          "two 540-frame views each; naive extrapolated from 5 and 10 rollouts"))
    warm = run_process(inspector_cmd("report", video, "--json"), env=env)
    figures.append(Figure(f"report_{n_video}_video_warm", warm.wall_s, "s", ">= 10x faster than cold",
                          cold.wall_s / warm.wall_s >= 10, warm.peak_mib, cold.wall_s, cold.peak_mib,
                          "second run, metrics cache; baseline = the cold run"))
    if json.loads(warm.stdout) != json.loads(cold.stdout):
        raise AssertionError("the warm report differs from the cold one")
    return figures


def _groot_dump(tmp: Path, n: int) -> Path:
    """A GR00T-Dreams IDM dump of ``n`` 93-step episodes (the test suite's writer; the videos are
    hard links of one 256x256 clip, the parquet files one per episode as the dump writes them)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sys.path.insert(0, str(REPO / "tests"))
    from groot_dreams_layout import write_groot_dreams

    root = write_groot_dreams(tmp / f"groot_{n}", [("pick the grape", 93)])
    lines = [json.dumps({"episode_index": e, "tasks": ["pick the grape"], "length": 93, "video_id": f"c{e}"})
             for e in range(n)]
    (root / "meta" / "episodes.jsonl").write_text("\n".join(lines) + "\n")
    first = root / "data" / "chunk-000" / "episode_000000.parquet"
    video = root / "videos" / "chunk-000" / "observation.images.webcam" / "episode_000000.mp4"
    table = pq.read_table(first)
    column = table.column_names.index("episode_index")
    for e in range(1, n):
        pq.write_table(table.set_column(column, "episode_index", pa.array([e] * 93, pa.int64())),
                       first.with_name(f"episode_{e:06d}.parquet"))
        os.link(video, video.with_name(f"episode_{e:06d}.mp4"))
    return root


def bench_groot(tmp: Path, quick: bool) -> list[Figure]:
    """A GR00T-Dreams dump of 1,000 neural trajectories read as it is: listed in the app (the
    index only) and reported, vs importing it into a session first (the converter it replaces)."""
    from inspector.app import InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    n = 300 if quick else 1000
    dump = _groot_dump(tmp, n)
    start = time.perf_counter()
    app = InspectorApp(open_sources([dump], confine=True, datasets=True), port=0,
                       metrics_cache=MetricsCache(enabled=False))
    listed = time.perf_counter() - start
    try:
        assert len(app.catalog.keys()) == n
    finally:
        app.stop()
    imported = run_process(inspector_cmd("import", "groot-dreams", dump, "-o", tmp / f"groot_session_{n}"))
    figures = [Figure(f"groot_list_{n}", listed, "s", "< 5 s", listed < 5, None, imported.wall_s, imported.peak_mib,
                      "the app's picker filled from meta/ alone; baseline: inspector import groot-dreams first")]
    ours = run_process(inspector_cmd("report", dump, "--json"), env=fresh_cache(tmp))
    session = run_process(inspector_cmd("report", tmp / f"groot_session_{n}", "--json"), env=fresh_cache(tmp))
    figures.append(Figure(f"groot_report_{n}", ours.wall_s, "s", "< 10 s and < 1 GB",
                          ours.wall_s < 10 and ours.peak_mib < 1024, ours.peak_mib,
                          imported.wall_s + session.wall_s, max(imported.peak_mib, session.peak_mib),
                          "93-step episodes; baseline: import into a session, then report it"))
    if len(json.loads(ours.stdout)["neural_trajectories"]) != n:
        raise AssertionError("the report lost episodes")
    return figures


def bench_served(tmp: Path, quick: bool) -> list[Figure]:
    """DreamZero served predictions against the client's recordings (DROID tiles, 640x320 at
    5 fps; recordings 672x224 at 15 fps): ``import dreamzero-served --recording`` then ``report``,
    as a user runs them, vs decoding every video whole and comparing the arrays."""
    sys.path.insert(0, str(REPO / "tests"))
    from served_layout import save_client_episode, save_prediction, served_frames

    n, calls = (3, 15) if quick else (8, 30)  # 30 calls: 241 frames, a 240-step episode
    out, runs = tmp / "served" / "video_pred_output", tmp / "served" / "runs"
    for k in range(n):
        save_prediction(out, f"put the cube in the bowl {k}", served_frames(calls))
        save_client_episode(runs, k, 8 * calls)
    imported = run_process(inspector_cmd("import", "dreamzero-served", out, "-o", tmp / "served_session",
                                         "--recording", runs))
    report = run_process(inspector_cmd("report", tmp / "served_session", "--json"), env=fresh_cache(tmp))
    naive = run_process([sys.executable, str(REPO / "benchmarks" / "naive.py"), "served", str(out), str(runs)])
    ours = imported.wall_s + report.wall_s
    if len(json.loads(report.stdout)["rollouts"]) != n:
        raise AssertionError("the report lost rollouts")
    return [Figure(f"served_import_report_{n}x{calls}", ours, "s", "< 1 GB, no slower than the baseline",
                   ours <= naive.wall_s and max(imported.peak_mib, report.peak_mib) < 1024,
                   max(imported.peak_mib, report.peak_mib), naive.wall_s, naive.peak_mib,
                   f"{n} served videos of {calls} calls, each with its recording: import + report (PSNR and SSIM "
                   "per chunk, SSIM ~36 ms a frame of each view); baseline: every video decoded whole and held, "
                   "PSNR and SSIM on the arrays")]


def _eval_session(tmp: Path, name: str, n: int, video: bool) -> Path:
    dest = tmp / name
    if not dest.exists():
        make_eval_session(dest, n, video=video)
    return dest


# ----------------------------------------------------------------------------------------------
# inspector report --ray (whole process)


def bench_ray(tmp: Path, quick: bool) -> list[Figure]:
    """``report --ray`` against ``--jobs`` on the same rollouts with two views, each run a whole
    process with a fresh metrics cache.

    As a cluster user runs it: a Ray head of 1 and then 2 CPUs is started (``ray start --head``)
    before the timing and stopped after it, and ``report --ray ADDRESS`` alternates with
    ``report --jobs N`` (ABBA..., medians); its peak RSS counts the workers the head started for
    it. Then ``--ray`` with no address once (a local instance, started and stopped by the
    command), and both paths on a warm cache (what is left is each path's fixed cost)."""
    import importlib.util

    if importlib.util.find_spec("ray") is None:
        print("  ray: skipped (pip install -e '.[ray]')", file=sys.stderr)
        return []
    n = 60 if quick else 200
    reps = 2 if quick else 3
    video = _eval_session(tmp, "video", n, video=True)
    quiet = {"RAY_USAGE_STATS_ENABLED": "0"}
    figures, outputs = [], []
    warm = fresh_cache(tmp)  # filled by the first --jobs 2 run, read by the warm runs
    for cpus in (2, 1):
        with ray_head(cpus, tmp) as (address, head_pid, auth):
            ray_runs, local_runs = [], []
            for rep in range(reps):
                for side in ("jobs", "ray") if rep % 2 == 0 else ("ray", "jobs"):
                    if side == "jobs":
                        env = warm if cpus == 2 and rep == 0 else fresh_cache(tmp)
                        local_runs.append(run_process(inspector_cmd("report", video, "--json", "--jobs", cpus), env=env))
                    else:
                        ray_runs.append(run_process(inspector_cmd("report", video, "--json", "--ray", address),
                                                    env={**fresh_cache(tmp), **quiet, **auth}, also=head_pid))
            outputs += [m.stdout for m in ray_runs + local_runs]
            if cpus == 2:
                warm_head = run_process(inspector_cmd("report", video, "--json", "--ray", address),
                                        env={**warm, **quiet, **auth}, also=head_pid)
        on_ray, local = _median_run(ray_runs), _median_run(local_runs)
        ratio = statistics.median(r.wall_s / j.wall_s for r, j in zip(ray_runs, local_runs))
        figures.append(Figure(f"ray_head_{cpus}cpu_{n}_video", on_ray.wall_s, "s", "Ray <= 1.25x --jobs",
                              ratio <= 1.25, on_ray.peak_mib, local.wall_s, local.peak_mib,
                              f"--ray to a running head of {cpus} CPU(s) (ray start --head) vs --jobs {cpus}, cold "
                              f"cache, whole process, alternated x{reps}, medians; median Ray / --jobs of the "
                              f"pairs {ratio:.2f}x; Ray's RSS counts the workers the head started for the run"))
    on_local = run_process(inspector_cmd("report", video, "--json", "--ray", "--jobs", 2),
                           env={**fresh_cache(tmp), **quiet})
    outputs.append(on_local.stdout)
    warm_local = run_process(inspector_cmd("report", video, "--json", "--jobs", 2), env=warm)
    warm_ray = run_process(inspector_cmd("report", video, "--json", "--ray", "--jobs", 2), env={**warm, **quiet})
    figures.append(Figure(f"ray_local_instance_2cpu_{n}_video", on_local.wall_s, "s", "report only", True,
                          on_local.peak_mib, figures[0].baseline, figures[0].baseline_rss_mib,
                          "--ray with no address: a local Ray instance of 2 CPUs started and stopped by the "
                          "command, vs the median --jobs 2 above; cold cache, once"))
    figures.append(Figure("ray_fixed_cost", warm_ray.wall_s, "s", "report only", True, warm_ray.peak_mib,
                          warm_local.wall_s, warm_local.peak_mib,
                          "warm metrics cache (no decoding): a local Ray instance's start and stop vs the local pool's"))
    figures.append(Figure("ray_head_fixed_cost", warm_head.wall_s, "s", "report only", True, warm_head.peak_mib,
                          warm_local.wall_s, warm_local.peak_mib,
                          "warm metrics cache (no decoding): joining a running head of 2 CPUs and its "
                          "workers' start vs the local pool's"))
    reports = outputs + [warm_ray.stdout, warm_local.stdout, warm_head.stdout]
    if any(json.loads(out) != json.loads(outputs[0]) for out in reports):
        raise AssertionError("report --ray differs from the local report")
    return figures


def _median_run(runs: list[Measured]) -> Measured:
    """The median wall time and the median peak RSS of ``runs``."""
    return Measured(statistics.median(m.wall_s for m in runs), statistics.median(m.peak_mib for m in runs), "")


@contextlib.contextmanager
def ray_head(cpus: int, tmp: Path) -> Iterator[tuple[str, int, dict[str, str]]]:
    """A Ray head of ``cpus`` CPUs (``ray start --head --block``, no dashboard), addressed at
    127.0.0.1, as (address, pid of ``ray start``, the environment a driver needs: its token);
    stopped at the end, every process it started gone before this returns. Its ports are free
    ones (another head may run on this machine); it requires a token of its own (Ray >= 2.52
    otherwise takes ~/.ray/auth_token where one exists, and drivers given an address send none)."""
    import psutil

    ray_cli = Path(sys.executable).with_name("ray")
    port, client_port, agent_port = _free_ports(3)
    temp_dir = Path(tempfile.mkdtemp(prefix="ray-", dir="/tmp"))  # short: Ray's socket paths must fit
    log = tmp / f"ray-head-{port}.log"
    auth = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": uuid.uuid4().hex}
    with open(log, "w") as out:
        head = subprocess.Popen([str(ray_cli), "start", "--head", "--block", "--num-cpus", str(cpus),
                                 "--include-dashboard=false", "--disable-usage-stats",
                                 "--node-ip-address", "127.0.0.1", "--port", str(port),
                                 "--ray-client-server-port", str(client_port),
                                 "--dashboard-agent-listen-port", str(agent_port), "--temp-dir", str(temp_dir)],
                                stdout=out, stderr=subprocess.STDOUT, env={**os.environ, **auth, "RAY_USAGE_STATS_ENABLED": "0"},
                                start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while "Ray runtime started" not in log.read_text():
            if head.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"ray start --head failed: {log.read_text()[-2000:]}")
            time.sleep(0.5)
        yield f"127.0.0.1:{port}", head.pid, auth
    finally:
        started = [head, *(_children(psutil.Process(head.pid)))]
        head.terminate()  # ray start --block stops what it started
        with contextlib.suppress(subprocess.TimeoutExpired):
            head.wait(60)
        _, alive = psutil.wait_procs([p for p in started if isinstance(p, psutil.Process)], timeout=30)
        for p in [*alive, *([head] if head.poll() is None else [])]:
            with contextlib.suppress(psutil.Error, ProcessLookupError):
                p.kill()
        head.wait(30)
        import shutil

        shutil.rmtree(temp_dir, ignore_errors=True)


def _children(process) -> list:
    import psutil

    with contextlib.suppress(psutil.Error):
        return process.children(recursive=True)
    return []


def _free_ports(k: int) -> list[int]:
    sockets = [socket.socket() for _ in range(k)]
    try:
        for s in sockets:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in sockets]
    finally:
        for s in sockets:
            s.close()


# ----------------------------------------------------------------------------------------------
# inspector export (whole process)


def _fixture_session(tmp: Path) -> Path:
    """Both 60-chunk fixture rollouts (three views each), imported into a session once."""
    from inspector.data.importers.dreamzero_so101 import import_dreamzero

    dest = tmp / "fixture"
    if not dest.exists():
        import_dreamzero(FIXTURES / "train_rollout", dest, log=lambda _: None)
    return dest


def bench_export(tmp: Path, quick: bool) -> list[Figure]:
    """The 60-chunk fixture rollout with three views to .rrd, cold (empty caches), vs decoding the
    clips and logging one image per frame; then a session of rollouts with two views each to a
    directory, vs the same exporter writing them one after another in one process."""
    session = _fixture_session(tmp)
    out = tmp / "export.rrd"
    runs = [run_process(inspector_cmd("export", session, "--rollout", "ep000_train", "-o", out),
                        env=fresh_cache(tmp)) for _ in range(1 if quick else 2)]
    ours = min(runs, key=lambda m: m.wall_s)
    size_mb = out.stat().st_size / 1e6
    naive = run_process([sys.executable, NAIVE, "export", session, "ep000_train", tmp / "naive.rrd"])
    naive_mb = (tmp / "naive.rrd").stat().st_size / 1e6
    n = 16 if quick else 64
    many = _eval_session(tmp, f"video{n}", n, video=True)
    all_ours = run_process(inspector_cmd("export", many, "-o", tmp / "all"), env=fresh_cache(tmp))
    all_one = run_process([sys.executable, NAIVE, "export-all", many, tmp / "all_one"], env=fresh_cache(tmp))
    return [Figure("export", ours.wall_s, "s", "< 3 s and < 700 MB",
                   ours.wall_s < 3 and ours.peak_mib < 700, ours.peak_mib, naive.wall_s, naive.peak_mib,
                   "whole process, empty metrics cache"),
            Figure("export_size", size_mb, "MB", "< 10 MB", size_mb < 10, baseline=naive_mb),
            Figure(f"export_{n}_video", all_ours.wall_s, "s", "< 1 GB, faster than one process",
                   all_ours.peak_mib < 1024 and all_ours.wall_s < all_one.wall_s, all_ours.peak_mib,
                   all_one.wall_s, all_one.peak_mib,
                   "a session to a directory, empty caches; baseline: one process, one rollout after another")]


# ----------------------------------------------------------------------------------------------
# inspector eval against a local policy server


def _camera_frames(n: int, seed: int) -> np.ndarray:
    """(n, 480, 640, 3) frames that encode like a camera's: a gradient, a moving block, sensor noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:480, 0:640]
    base = np.stack([x * 255 // 640, y * 255 // 480, (x + y) * 255 // 1120], -1).astype(np.int16)
    out = np.empty((n, 480, 640, 3), np.uint8)
    for i in range(n):
        frame = base.copy()
        cx, cy = 100 + (3 * i) % 400, 120 + (2 * i) % 200
        frame[cy:cy + 80, cx:cx + 120] = (200, 60 + 40 * seed, 40)
        out[i] = np.clip(frame + rng.integers(-3, 4, frame.shape, dtype=np.int16), 0, 255)
    return out


def bench_eval(tmp: Path, quick: bool) -> list[Figure]:
    """``inspector eval`` of a 3-camera 640x480 dataset (keyframes every 2 frames, as LeRobot
    writes) against a local echo server (a fixed chunk at once, so the figures are the client's):
    samples per second, and the client's own time per sample (everything outside the server's
    replies: frames, request, checks, write), beside a first loop (``naive.py eval``)."""
    from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset

    sys.path.insert(0, str(REPO / "tests"))
    from policy_server import policy_server

    dataset = tmp / "eval_dataset"
    n_frames, per_episode = (90, 10) if quick else (150, 40)
    if not dataset.exists():
        t = np.arange(n_frames)[:, None]
        episodes = []
        for e in range(2):
            state = 20 * np.sin(t / 10 + np.arange(6) + e) + 30
            episodes.append(EpisodeData(f"task {e}", state, state + 1,
                                        {cam: _camera_frames(n_frames, i + e) for i, cam in enumerate(("front", "top", "wrist"))}))
        write_lerobot_dataset(dataset, episodes, keyframe_every=2)
    config = {"image_resolution": (480, 640), "n_external_cameras": 2, "needs_wrist_camera": True,
              "needs_stereo_camera": False, "needs_session_id": True, "action_space": "joint_position"}
    with policy_server(echo=True, config=config) as server:
        ours = run_process(inspector_cmd("eval", server.url, dataset, "-o", tmp / "eval_ours", "--samples", per_episode))
        naive = run_process([sys.executable, NAIVE, "eval", server.url, dataset, tmp / "eval_naive", "-n", str(per_episode)])
    n = 2 * per_episode
    match = re.search(r"client time per request: p50 ([0-9.]+) ms", ours.stdout)
    if match is None:
        raise RuntimeError(f"inspector eval printed no client time: {ours.stdout}")
    client_ms, naive_ms = float(match[1]), json.loads(naive.stdout)["client_ms_p50"]
    return [Figure("eval_client", client_ms, "ms", "< 20 ms per sample", client_ms < 20, baseline=naive_ms,
                   note="3 cameras of 640x480 sent at that size, echo server; median time per sample outside the server's replies"),
            Figure("eval_rate", n / ours.wall_s, "samples/s", "report only", True, ours.peak_mib, n / naive.wall_s,
                   naive.peak_mib, f"{n} samples, whole process (start-up included)")]


# ----------------------------------------------------------------------------------------------
# The app


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def _app_tab(session: Path) -> Iterator[tuple[object, str]]:
    """The app (in process) serving ``session`` with one headless tab: yields (tab, a key the tab
    has not opened yet, after its default rollout has settled)."""
    from inspector.app import HeadlessClient, InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    app = InspectorApp(open_sources([session]), port=_free_port(), metrics_cache=MetricsCache(enabled=False))
    try:
        with HeadlessClient(app.port):
            tab = app.wait_for_tabs(1)[0]
            key = next(k for k in app.catalog.keys() if k.endswith("ep000_train"))
            assert tab.key != key
            if tab.loaded is not None:
                tab.loaded.frames.done.wait(timeout=120)
            yield tab, key
    finally:
        app.stop()


def bench_open(tmp: Path, quick: bool) -> Figure:
    """A 60-chunk rollout with its GT and three views ready to scrub (every frame in the cache),
    through the app's own path, vs one thread decoding every clip whole."""
    session = _fixture_session(tmp)

    def open_untouched() -> tuple[float, float]:
        """(seconds until every frame is in the cache, until the frame match is in too)."""
        with _app_tab(session) as (tab, key):  # a fresh app: nothing of that rollout loaded yet
            start = time.perf_counter()
            tab.open(key)
            tab.loaded.frames.decoded.wait(timeout=120)
            framed = time.perf_counter() - start
            tab.loaded.frames.done.wait(timeout=120)
            return framed, time.perf_counter() - start

    ours, matched = min(open_untouched() for _ in range(1 if quick else 3))

    def naive() -> None:
        from inspector.analysis.timeline import build_timeline
        from inspector.data.session import load_rollout

        r = load_rollout(session / "rollouts" / "ep000_train")
        build_timeline(r)
        for view in r.views:
            r.video(view).decode()
            r.video(view, gt=True).decode()

    base = _best_of(naive, 1)
    return Figure("open", ours, "s", "< 1.5 s", ours < 1.5, baseline=base,
                  note=f"server side, in process; the video-action frame match was in {matched:.2f} s after the open")


def bench_scrub(tmp: Path, quick: bool) -> Figure:
    """One scrub step server-side (FK, both arms, video frames, plot cursor): median of 200."""
    session = _fixture_session(tmp)
    with _app_tab(session) as (tab, key):
        tab.open(key)
        tab.loaded.frames.done.wait(timeout=120)
        rollout = tab.loaded.timeline.rollout
        rng = np.random.default_rng(0)
        steps = rng.integers(0, tab.loaded.timeline.n_steps, size=60 if quick else 200)
        times = []
        for s in steps:
            t = time.perf_counter()
            tab.set_step(int(s))
            times.append(time.perf_counter() - t)
        ours = float(np.median(times))

    # baseline: the same frames decoded from the files on every step (seek + decode)
    clips = [rollout.video(v) for v in rollout.views] + [rollout.video(v, gt=True) for v in rollout.gt_views]
    base_times = []
    for s in steps[:20]:
        t = time.perf_counter()
        for clip in clips:
            clip.frame(int(s))
        base_times.append(time.perf_counter() - t)
    base = float(np.median(base_times))
    return Figure("scrub", ours * 1e3, "ms", "median < 15 ms", ours < 0.015, baseline=base * 1e3,
                  note="server side, in process")


def bench_playback(tmp: Path, quick: bool) -> list[Figure]:
    """Video frames per second the page presents while playing at 1x, in headless Debian Chromium
    (WebGL in software), once playback's clip is on screen; beside the same page stepping images
    (clips off, what playback was before). Also: seconds from Play to the clip's first frame, the
    first time (clips encoded) and again (cached)."""
    sys.path.insert(0, str(REPO / "tests"))
    from browser import launch, skip_reason, wait_until

    if (reason := skip_reason()) is not None:
        print(f"  playback: skipped ({reason})", file=sys.stderr)
        return []
    from playwright.sync_api import sync_playwright

    from inspector.app import _playback_clip, serve

    count_images = """() => { window.__seen = 0; let last = null; const tick = () => {
        const e = document.querySelector("img.inspector-frame[data-kind='imagined']");
        const s = e && e.getAttribute('data-frame');
        if (s !== last) { window.__seen++; last = s; } requestAnimationFrame(tick); }; tick(); }"""
    # frames the clip's element has presented so far (that element, even once another replaced it)
    presented = """() => { const v = window.__clip || document.querySelector("video.inspector-frame[data-kind='imagined']");
        if (!v || v.paused || v.currentTime === 0) return null; window.__clip = v;
        const q = v.getVideoPlaybackQuality(); return q.totalVideoFrames - q.droppedVideoFrames; }"""
    no_clip = """() => { window.__clip = null; return !document.querySelector("video.inspector-frame"); }"""
    window_s = 4.0 if quick else 6.0  # within the demo's 14.7 s clip
    rates, start_s = {}, {}
    app = serve([DEMO], port=0, block=False)
    try:
        with sync_playwright() as pw:
            browser = launch(pw)
            for clips in (True, False):
                _playback_clip.ENABLED = clips
                page, tab = _demo_page(browser, app)
                if clips:
                    for attempt in ("first", "again"):  # the first Play encodes; the second finds them cached
                        tab.set_step(0)
                        page.wait_for_timeout(1000)
                        t0 = time.monotonic()
                        tab.play()
                        first = wait_until(lambda: page.evaluate(presented), timeout=120, interval=0.05,
                                           what="the playback clip to play")
                        start_s[attempt] = time.monotonic() - t0
                        if attempt == "first":
                            tab.pause()
                            wait_until(lambda: page.evaluate(no_clip), timeout=120, what="the images back")
                    t1 = time.monotonic()
                    page.wait_for_timeout(window_s * 1000)
                    last = page.evaluate(presented) or first
                    rates[clips] = (last - first) / (time.monotonic() - t1)
                else:
                    page.evaluate(count_images)
                    t1 = time.monotonic()
                    tab.play()
                    page.wait_for_timeout(window_s * 1000)
                    rates[clips] = page.evaluate("() => window.__seen") / (time.monotonic() - t1)
                tab.pause()
                page.close()
            browser.close()
    finally:
        _playback_clip.ENABLED = True
        app.stop()
    note = "headless Chromium, 1600x1000, demo prompt_train; baseline: images stepped by the server"
    return [Figure("playback", rates[True], "frames/s", ">= 20 /s at 1x", rates[True] >= 20,
                   baseline=rates[False], note=note),
            Figure("playback_start", start_s["first"], "s", "< 10 s", start_s["first"] < 10,
                   baseline=start_s["again"], note="Play to the clip's first frame in the page, images "
                   "playing meanwhile; baseline: a second Play (clips cached)")]


def bench_clock(tmp: Path, quick: bool) -> list[Figure]:
    """The arms and the video on one clock, in headless Chromium (1600x1000, WebGL in software,
    Light 3D ticked by the page) on the demo's ``prompt_train`` at 1x, its clips cached: the median
    gap between the step the readout over the arms says and the step the playing clip shows, over
    the whole playback; and Pause, pressed as a user presses 2 s into the clip: the time to the
    images and readout of one step. Beside the same with the server's own clock (before)."""
    sys.path.insert(0, str(REPO / "tests"))
    from browser import ARM_AND_VIDEO_STEP, launch, play_on_one_clock, skip_reason, wait_until

    if (reason := skip_reason()) is not None:
        print(f"  clock: skipped ({reason})", file=sys.stderr)
        return []
    from playwright.sync_api import sync_playwright

    from inspector.app import _clip_clock, serve

    presses = 2 if quick else 3
    measured = {}
    app = serve([DEMO], port=0, block=False)
    try:
        with sync_playwright() as pw:
            browser = launch(pw)
            for follow in (True, False):
                _clip_clock.ENABLED = follow
                page, tab = _demo_page(browser, app)
                tab.play()  # encode (or find) the clips: the measured Play starts them at once
                wait_until(lambda: tab._clip is not None, timeout=180, what="the playback clips")
                tab.pause()
                tab.set_step(0)
                wait_until(lambda: page.evaluate(ARM_AND_VIDEO_STEP)["images"], timeout=60, what="the images back")
                measured[follow] = play_on_one_clock(page, tab, presses)
                page.close()
            browser.close()
    finally:
        _clip_clock.ENABLED = True
        app.stop()

    def summary(m: dict) -> tuple[float, float, float, float]:
        """median gap [steps], median Pause answer [s], its worst, median |stop - clip| [steps]"""
        answers = [p["s"] for p in m["pauses"]]
        stops = [abs(p["step"] - p["clip_step"]) for p in m["pauses"]]
        return (statistics.median(m["gaps"]), statistics.median(answers), max(answers), statistics.median(stops))

    (gap, answer, worst, stop), (gap_0, answer_0, worst_0, stop_0) = summary(measured[True]), summary(measured[False])
    frames = (f"the page's 3D frames {measured[True]['frame_s'] * 1e3:.0f} ms long "
              f"({measured[False]['frame_s'] * 1e3:.0f} ms before; median by time spent in them)")
    return [Figure("clock_gap", gap, "steps", "median <= 3 steps", gap <= 3, baseline=gap_0,
                   note=f"headless Chromium, 1600x1000, demo prompt_train at 1x, clips cached; |readout step - "
                        f"clip step| over {len(measured[True]['gaps'])} looks while the clip played; {frames}; "
                        "baseline: the server's own clock"),
            Figure("pause_answer", answer, "s", "< 1 s", worst < 1, baseline=answer_0,
                   note=f"median of {presses} presses of Pause (worst {worst:.2f} s, before {worst_0:.2f} s) to "
                        f"the images and readout of one step; stopped {stop:.0f} steps from the clip's step at the "
                        f"press ({stop_0:.0f} before); baseline: the server's own clock")]


def _demo_page(browser, app, hide_canvas: bool = False):
    """A 1600x1000 page of ``app`` showing the demo's ``prompt_train``, its frames all ready:
    (page, its tab)."""
    from browser import open_app, page_client_id, select_option, wait_until

    page = browser.new_page(viewport={"width": 1600, "height": 1000})
    open_app(page, app.url)
    if hide_canvas:
        page.add_style_tag(content="canvas{display:none !important}")
    tab = wait_until(lambda: app.tabs.get(page_client_id(page)), what="the tab")
    key = next(k for k, e in app.catalog.entries.items() if e.tag == "prompt_train")
    select_option(page, "Rollout", key)
    wait_until(lambda: tab.key == key and tab.loaded is not None and tab.loaded.frames.done.is_set(),
               timeout=120, what="the rollout's frames")
    page.wait_for_timeout(2000)
    return page, tab


def bench_keys(tmp: Path, quick: bool) -> list[Figure]:
    """The Chunk slider's thumb stepped with the arrow key in headless Chromium (WebGL in software):
    median time from the key press to the next chunk's imagined frame painted, beside the same
    page with its 3D canvas hidden (what the arm redraw costs a page without a GPU)."""
    sys.path.insert(0, str(REPO / "tests"))
    from browser import launch, skip_reason, slider_thumb, wait_until

    if (reason := skip_reason()) is not None:
        print(f"  keys: skipped ({reason})", file=sys.stderr)
        return []
    from playwright.sync_api import sync_playwright

    from inspector.app import serve

    # in the page: ms from each key press to the first animation frame showing another frame, its
    # image decoded (an <img> whose new source is still loading shows nothing new yet); and to the
    # first animation frame after the 3D view drew again (its draw calls made and the frame that
    # shows them committed): the arms at the new step
    record = """() => { window.__ms = []; window.__arms = []; let t0 = null, t3d = null, before = null, drawn = 0;
        const img = () => document.querySelector("img.inspector-frame[data-kind='imagined']");
        for (const C of [WebGLRenderingContext, WebGL2RenderingContext]) {
          const draw = C.prototype.drawElements;
          C.prototype.drawElements = function(...a) { drawn = performance.now(); return draw.apply(this, a); }; }
        document.addEventListener('keydown', () => { t0 = t3d = performance.now(); before = img()?.getAttribute('data-frame'); }, true);
        const tick = () => { const e = img(), now = performance.now();
                             if (t0 !== null && e && e.getAttribute('data-frame') !== before && e.complete && e.naturalWidth > 0) {
                               window.__ms.push(now - t0); t0 = null; }
                             if (t3d !== null && drawn > t3d + 20 && now > drawn) { window.__arms.push(now - t3d); t3d = null; }
                             requestAnimationFrame(tick); }; tick(); }"""
    presses = 5 if quick else 9
    medians: dict[bool, tuple[float, float]] = {}
    app = serve([DEMO], port=0, block=False)
    try:
        with sync_playwright() as pw:
            browser = launch(pw)
            for hidden in (False, True):
                page, tab = _demo_page(browser, app, hide_canvas=hidden)
                page.evaluate(record)
                thumb = slider_thumb(page, re.compile(r"^Chunk$"))
                thumb.focus()
                to_server = []
                for _ in range(presses):
                    step, painted = tab.step, page.evaluate("() => window.__ms.length")
                    arms = page.evaluate("() => window.__arms.length")
                    t0 = time.monotonic()
                    page.keyboard.press("ArrowRight")
                    wait_until(lambda: tab.step != step, timeout=60, interval=0.005, what="the server's step")
                    to_server.append((time.monotonic() - t0) * 1e3)
                    wait_until(lambda: page.evaluate("() => window.__ms.length") > painted, timeout=60,
                               interval=0.02, what="the next frame painted")
                    if not hidden:
                        wait_until(lambda: page.evaluate("() => window.__arms.length") > arms, timeout=60,
                                   interval=0.02, what="the arms redrawn")
                    page.wait_for_timeout(300)
                arms_ms = page.evaluate("() => window.__arms")
                medians[hidden] = (statistics.median(page.evaluate("() => window.__ms")),
                                   statistics.median(to_server), statistics.median(arms_ms) if arms_ms else None)
                page.close()
            browser.close()
    finally:
        app.stop()
    (painted, server, arms), (painted_hidden, server_hidden, _) = medians[False], medians[True]
    return [Figure("slider_key", painted, "ms", "median < 100 ms", painted < 100, baseline=painted_hidden,
                   note=f"headless Chromium, 1600x1000, demo prompt_train, Chunk thumb, ArrowRight, median of "
                        f"{presses}: key to the next frame painted (image decoded); the 3D arms redrawn after "
                        f"{arms:.0f} ms; at the server after {server:.0f} ms ({server_hidden:.0f} ms with the "
                        f"canvas hidden); baseline: 3D canvas hidden")]


def _browser_cpu_s() -> float:
    """CPU seconds so far of every Chromium process this process started (through Playwright's
    driver, which is not counted): the browser, its GPU process (where software WebGL draws) and
    its renderers."""
    import psutil

    total = 0.0
    for driver in psutil.Process().children():
        for p in _children(driver):
            with contextlib.suppress(psutil.Error):
                times = p.cpu_times()
                total += times.user + times.system
    return total


LOAD_WINDOW_S = 30.0  # a page's first seconds: loaded (15-20 s in software) and idling


def bench_page_load(tmp: Path, quick: bool) -> list[Figure]:
    """What a page drawing WebGL in software (headless Chromium) costs the browser to load the app
    on the demo: CPU seconds of all its processes in the page's first ``LOAD_WINDOW_S``,
    beside the same page when its renderer names a GPU (it then gets the environment map, as every
    page did before pages started plainly lit, and sets it up in software). A window of fixed
    length: a page whose 3D view is on screen never idles (viser draws a frame every second)."""
    sys.path.insert(0, str(REPO / "tests"))
    from browser import GPU_RENDERER_JS, launch, open_app, open_page, skip_reason, wait_until

    if (reason := skip_reason()) is not None:
        print(f"  page_load: skipped ({reason})", file=sys.stderr)
        return []
    from playwright.sync_api import sync_playwright

    from inspector.app import serve

    repeats = 2 if quick else 3
    loads: dict[str, list[float]] = {"software": [], "gpu": []}
    app = serve([DEMO], port=0, block=False)
    try:
        with sync_playwright() as pw:
            browser = launch(pw)
            for _ in range(repeats):
                for kind in ("software", "gpu"):
                    page = open_page(browser, 1600, 1000)
                    if kind == "gpu":
                        page.add_init_script(GPU_RENDERER_JS)
                    cpu0, t0 = _browser_cpu_s(), time.monotonic()
                    open_app(page, app.url)
                    wait_until(lambda: page.evaluate("() => document.documentElement.dataset.inspectorWebgl") == kind,
                               what="the page's renderer check")
                    time.sleep(max(0.0, t0 + LOAD_WINDOW_S - time.monotonic()))
                    loads[kind].append(_browser_cpu_s() - cpu0)
                    page.close()
            browser.close()
    finally:
        app.stop()
    ours, gpu = (statistics.median(loads[kind]) for kind in ("software", "gpu"))
    return [Figure("page_load_cpu", ours, "CPU-s", "< 0.5x baseline", ours < 0.5 * gpu, baseline=gpu,
                   note=f"headless Chromium (WebGL in software), 1600x1000, the demo: CPU of all the browser's "
                        f"processes in a page's first {LOAD_WINDOW_S:.0f} s (loaded, its 3D view drawn), median "
                        f"of {repeats}; baseline: the same page naming a GPU renderer, which gets the "
                        f"environment map (what every page got before)")]


def _labelled_session(tmp: Path, name: str, n: int, labels: bool) -> Path:
    """``n`` single-chunk rollouts with GT joints and no video (what labelling and the outcome
    statistics cost, not decoding), with a label on each when ``labels``."""
    from inspector import SessionWriter
    from inspector.outcomes import store_records

    rng = np.random.default_rng(0)
    root = tmp / name
    with SessionWriter.create(root, model={"name": name}, overwrite=True) as w:
        for i in range(n):
            actions = rng.normal(0, 5, size=(1, 24, 6))
            w.add_rollout(f"r{i:04d}", kind="single_chunk", actions=actions, episode_index=i,
                          gt_actions=actions[0] + rng.normal(0, 1, size=(24, 6)),
                          prompt="Pick the red cube" if i % 2 else "Lift the red cube")
    if labels:
        store_records(root / "outcomes.json", {f"r{i:04d}": {"success": bool(rng.random() < 0.6),
                                                             "progress": float(rng.integers(0, 11) * 10)}
                                               for i in range(n)}, source="label", set_by="benchmark")
    return root


def bench_outcomes(tmp: Path, quick: bool) -> list[Figure]:
    """``report`` and the app's Overview of 1,000 labelled rollouts against the same rollouts
    unlabelled (one run, one cache state); ``compare`` of two labelled sessions (the tests: bootstrap per metric, McNemar);
    and the paired bootstrap's coverage of a known mean, by simulation."""
    from inspector.outcomes import store_records
    from inspector.stats import paired_bootstrap

    n = 300 if quick else 1000
    # report_1000's evaluation (autoregressive, no video), reported before and after labelling
    # every rollout: the same rollouts, each run from a fresh cache
    many = _eval_session(tmp, "many", n, video=False)
    base = run_process(inspector_cmd("report", many, "--json"), env=fresh_cache(tmp))
    rng = np.random.default_rng(0)
    labels = {f"ep000_{i:04d}": {"success": bool(rng.random() < 0.6), "progress": float(rng.integers(0, 11) * 10)}
              for i in range(n)}
    store_records(many / "outcomes.json", labels, source="label", set_by="benchmark")
    try:
        ours = run_process(inspector_cmd("report", many, "--json"), env=fresh_cache(tmp))
    finally:
        (many / "outcomes.json").unlink()
    if len(json.loads(ours.stdout)["aggregate"]["success_by_task"]) != 2:
        raise AssertionError("the labelled report has no success rates")
    figures = [Figure(f"report_{n}_labelled", ours.wall_s, "s", "< 10 s and < 1 GB",
                      ours.wall_s < 10 and ours.peak_mib < 1024, ours.peak_mib, base.wall_s, base.peak_mib,
                      f"report_{n}'s rollouts with a label each; baseline: the same unlabelled, in the same run")]
    # the Overview of the same rollouts, labelled vs not, each in a fresh `inspector serve`
    unlabelled_s, unlabelled_mib = _overview_listed(many, n, labelled=False, env=fresh_cache(tmp))
    store_records(many / "outcomes.json", labels, source="label", set_by="benchmark")
    try:
        overview_s, overview_mib = _overview_listed(many, n, labelled=True, env=fresh_cache(tmp))
    finally:
        (many / "outcomes.json").unlink()
    figures.append(Figure(f"overview_{n}_labelled", overview_s, "s", "< 10 s and < 1 GB (report's)",
                          overview_s < 10 and overview_mib < 1024, overview_mib, unlabelled_s, unlabelled_mib,
                          f"`inspector serve` started to one tab's Overview listing report_{n}'s rollouts with "
                          "metrics, each row's label in its outcome columns and the success rate with its "
                          "interval; peak RSS of the server; cold cache; baseline: the same unlabelled, in "
                          f"the same run, in which report_{n}_labelled took {ours.wall_s:.1f} s (the Overview's "
                          f"rows are report's, computed at nice 10); machine load average "
                          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"))
    labelled = _labelled_session(tmp, "labelled", n, labels=True)
    other = _labelled_session(tmp, "labelled_b", n, labels=True)
    cmp = run_process(inspector_cmd("compare", labelled, other, "--json"), env=fresh_cache(tmp))
    tests = json.loads(cmp.stdout)["tests"]
    plain = run_process(inspector_cmd("report", labelled, "--json"), env=fresh_cache(tmp))
    figures.append(Figure(f"compare_{n}_tests", cmp.wall_s, "s", "<= 2.5x one report",
                          cmp.wall_s <= 2.5 * plain.wall_s and cmp.peak_mib < 1024, cmp.peak_mib,
                          plain.wall_s, plain.peak_mib,
                          note=f"{n} labelled single-chunk pairs, {len(tests)} tests "
                               f"({', '.join(t['metric'] for t in tests)}), 10,000 bootstrap resamples each, "
                               "cold caches; baseline: report of one side (compare reports both)"))
    rng = np.random.default_rng(1)
    sims, pairs = (200, 30) if quick else (1000, 30)
    covered = {"normal": 0, "exponential": 0}
    t0 = time.perf_counter()
    for k in range(sims):
        for dist, (sample, mean) in {"normal": (rng.normal(0.5, 1.0, pairs), 0.5),
                                     "exponential": (rng.exponential(1.0, pairs) - 0.5, 0.5)}.items():
            lo, hi = paired_bootstrap(sample, seed=k).ci
            covered[dist] += lo <= mean <= hi
    per_ci_ms = (time.perf_counter() - t0) / (2 * sims) * 1e3
    coverage = {d: 100 * c / sims for d, c in covered.items()}
    figures.append(Figure("bootstrap_coverage", coverage["normal"], "%", "93-97 % (nominal 95 %)",
                          93 <= coverage["normal"] <= 97,
                          note=f"{sims} simulated evaluations of {pairs} pairs, N(0.5, 1): {coverage['normal']:.1f} %; "
                               f"skewed (exponential): {coverage['exponential']:.1f} %; 10,000 resamples, "
                               f"{per_ci_ms:.1f} ms per interval"))
    return figures


def _overview_listed(session: Path, n: int, labelled: bool, env: dict[str, str]) -> tuple[float, float]:
    """Seconds from starting ``inspector serve session`` until a connected tab's Overview lists all
    ``n`` rows with metrics (``labelled``: each with its label, and the success rate over them),
    and the server's peak RSS [MiB] meanwhile."""
    from inspector.app import HeadlessClient
    from inspector.app._overview_table import MAX_TABLE_ROWS

    def complete(client) -> bool:
        head = client.html_containing("class='ov-head'")
        if f"{n} with metrics" not in head or "computing" in head:
            return False
        if not labelled:
            return True
        table = client.html_containing("<tr data-key=")
        drawn = min(n, MAX_TABLE_ROWS)  # the table draws its first rows; the header counts them all
        return f"over the {n} shown row(s)" in head and table.count("data-col='source'>label") == drawn

    start = time.perf_counter()
    listed: list[float] = []
    with _serve([str(session)], env) as (proc, port):
        def watch() -> None:
            with HeadlessClient(port, observe=True) as client:
                client.wait_until(lambda: complete(client), timeout=900, what=f"the Overview's {n} rows")
            listed.append(time.perf_counter() - start)

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        peak = _sample_peak_rss(proc, lambda: not watcher.is_alive(), 1200) / 2**20
    if not listed:
        raise RuntimeError("the Overview did not list every row")
    return listed[0], peak


def bench_label(tmp: Path, quick: bool) -> list[Figure]:
    """Labelling by keyboard in headless Chromium, the 3D view drawn (in software: no GPU): ``n``
    rollouts of a session written by SessionWriter, each S or F, a progress digit, then N to the
    next unlabelled one. Key to disk: from the press to the rename that put the label in
    ``outcomes.json`` (its ctime: what another process could read from then on), median and p90 of
    every press; and the page time of all ``n``. Baseline: the same with the 3D canvas hidden."""
    sys.path.insert(0, str(REPO / "tests"))
    from browser import launch, skip_reason

    if (reason := skip_reason()) is not None:
        print(f"  label: skipped ({reason})", file=sys.stderr)
        return []
    from playwright.sync_api import sync_playwright

    n = 15 if quick else 50
    load = os.getloadavg()[0]
    with sync_playwright() as pw:
        browser = launch(pw)
        shown = _label_pass(browser, _labelled_session(tmp, "to_label_3d", n, labels=False), n, hide_canvas=False)
        hidden = _label_pass(browser, _labelled_session(tmp, "to_label", n, labels=False), n, hide_canvas=True)
        browser.close()

    def p90(values: list[float]) -> float:
        return float(np.percentile(values, 90))

    median, median_hidden = statistics.median(shown.latencies_ms), statistics.median(hidden.latencies_ms)
    return [Figure("label_key", median, "ms", "median < 300 ms", median < 300, baseline=median_hidden,
                   note=f"headless Chromium 1600x1000, 3D view drawn in software (Light 3D): S/F or a digit to "
                        f"the label renamed into outcomes.json, median of {len(shown.latencies_ms)} presses, p90 "
                        f"{p90(shown.latencies_ms):.0f} ms (canvas hidden: p90 {p90(hidden.latencies_ms):.0f} ms); "
                        f"the server's locked write {statistics.median(shown.writes_ms):.0f} ms of it; baseline: "
                        f"the 3D canvas hidden; load average {load:.1f} on {os.cpu_count()} CPUs"),
            Figure(f"label_{n}_rollouts", shown.page_s, "s", "< 60 s", shown.page_s < 60 and shown.labelled == n,
                   baseline=hidden.page_s,
                   note=f"{n} single-chunk rollouts labelled by keyboard (S/F, a digit, N to the next "
                        f"unlabelled), 3D view drawn, {shown.labelled} labels on disk; N to the next rollout "
                        f"shown: median {statistics.median(shown.next_ms):.0f} ms; baseline: the 3D canvas hidden")]


@dataclass
class _LabelRun:
    latencies_ms: list[float]  # key press to the label renamed into place
    writes_ms: list[float]  # the server's locked read-modify-write
    next_ms: list[float]  # N to the next rollout loaded in the tab
    page_s: float
    labelled: int  # rollouts with a label on disk at the end


def _label_pass(browser, session: Path, n: int, hide_canvas: bool) -> _LabelRun:
    """Label the ``n`` rollouts of ``session`` by keyboard in a new page."""
    from browser import open_app, page_client_id, wait_until

    from inspector.app import serve

    outcomes = session / "outcomes.json"

    def on_disk(tag: str) -> dict:
        try:
            return json.loads(outcomes.read_text())["rollouts"][tag]["label"]
        except (OSError, ValueError, KeyError):
            return {}

    app = serve([session], port=0, block=False)
    run = _LabelRun([], [], [], 0.0, 0)
    try:
        page = browser.new_page(viewport={"width": 1600, "height": 1000})
        open_app(page, app.url)
        if hide_canvas:
            page.add_style_tag(content="canvas{display:none !important}")
        tab = wait_until(lambda: app.tabs.get(page_client_id(page)), what="the tab")
        wait_until(lambda: tab.loaded is not None, timeout=120, what="the first rollout")
        started = time.perf_counter()
        for i in range(n):
            tag = tab.loaded.entry.tag
            for key, field, value in (("s" if i % 3 else "f", "success", i % 3 != 0),
                                      (str(1 + i % 9), "progress", 10.0 * (1 + i % 9))):
                pressed_ns = time.time_ns()
                page.keyboard.press(key)
                wait_until(lambda: on_disk(tag).get(field) == value, timeout=60, interval=0.002, what=f"{key} saved")
                # each press writes once: the file's ctime is the rename that made this label readable
                run.latencies_ms.append((outcomes.stat().st_ctime_ns - pressed_ns) / 1e6)
                if tab.label.last_saved is not None:
                    run.writes_ms.append(tab.label.last_saved[2] * 1e3)
            if i < n - 1:
                before, t0 = tab.key, time.perf_counter()
                page.keyboard.press("n")
                wait_until(lambda: tab.key != before and tab.loaded is not None and tab.loaded.entry.key == tab.key,
                           timeout=60, interval=0.005, what="N")
                run.next_ms.append((time.perf_counter() - t0) * 1e3)
        run.page_s = time.perf_counter() - started
        page.close()
    finally:
        app.stop()
    run.labelled = len(json.loads(outcomes.read_text())["rollouts"])
    return run


@contextlib.contextmanager
def _serve(args: Sequence[str], env: dict[str, str]) -> Iterator[tuple[subprocess.Popen, int]]:
    port = _free_port()
    proc = subprocess.Popen(inspector_cmd("serve", *args, "--port", str(port)), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env={**os.environ, **env})
    try:
        deadline = time.monotonic() + 60
        while True:
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1):
                break
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("inspector serve did not start")
            time.sleep(0.2)
        yield proc, port
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _open_rollouts(port: int, n: int) -> float:
    """Open ``n`` rollouts one after another in one headless tab, each until its frames show."""
    from inspector.app import HeadlessClient

    start = time.perf_counter()
    with HeadlessClient(port, observe=True) as client:
        picker = client.wait_for_control("Rollout", timeout=120)
        options = client.control(picker)["props"]["options"]
        for option in options[:n]:
            client.set_gui_value(picker, option)
            tag = option.split(" / ")[-1]
            client.wait_until(lambda: _shows(client, tag), timeout=120, what=f"{option} to show its frames")
    return time.perf_counter() - start


# The video panel's own element (the page's scripts, sent in the title, name its class too).
VIDEO_PANEL = "<div class='inspector-video'"


def _shows(client, tag: str) -> bool:
    card = client.html_containing("inspector-card'")
    video = client.html_containing(VIDEO_PANEL)
    return f"data-rollout='{tag}'" in card and bool(video) and "loading" not in video and "<img" in video


def bench_serve(tmp: Path, quick: bool) -> list[Figure]:
    """``inspector serve`` as a process: peak RSS while one tab opens 60 rollouts one after another
    (vs the same with a frame cache that never evicts), and with 8 tabs open."""
    from inspector.app import HeadlessClient

    n = 20 if quick else 60
    video = _eval_session(tmp, "video", 60 if quick else 200, video=True)
    figures = []
    peaks = {}
    for label, extra in (("ours", []), ("unbounded", ["--cache-mb", "1000000"])):
        with _serve([str(video), *extra], fresh_cache(tmp)) as (proc, port):
            done = []
            opener = threading.Thread(target=lambda: done.append(_open_rollouts(port, n)), daemon=True)
            opener.start()
            peaks[label] = _sample_peak_rss(proc, lambda: not opener.is_alive(), 1800) / 2**20
            if not done:
                raise RuntimeError("opening rollouts failed")
            peaks[label + "_s"] = done[0]
    figures.append(Figure(f"serve_{n}_opened", peaks["ours"], "MiB", "< 1 GB", peaks["ours"] < 1024,
                          note=f"peak RSS; baseline: a frame cache without a budget; {n} opens took "
                               f"{peaks['ours_s']:.0f} s", baseline=peaks["unbounded"]))

    with _serve([str(DEMO)], fresh_cache(tmp)) as (proc, port):
        clients: list[HeadlessClient] = []
        def connect_all() -> None:
            for _ in range(8):
                c = HeadlessClient(port, observe=True)
                clients.append(c)
                c.wait_until(lambda c=c: "<img" in c.html_containing(VIDEO_PANEL), timeout=180)

        opener = threading.Thread(target=connect_all, daemon=True)
        opener.start()
        peak = _sample_peak_rss(proc, lambda: not opener.is_alive(), 1800) / 2**20
        for c in clients:
            c.close()
    figures.append(Figure("serve_8_tabs", peak, "MiB", "< 1 GB", peak < 1024, note="peak RSS, demo session"))
    return figures


def bench_rank(tmp: Path, quick: bool) -> list[Figure]:
    """Bradley-Terry intervals' coverage on simulated preferences, and ``inspector rank`` as a whole
    process on 5 sessions with 200 votes in their votes.json."""
    from inspector.data.session import SessionWriter
    from inspector.outcomes import OUTCOMES_FILE, store_records
    from inspector.said.votes import Side, new_vote, save_vote
    from inspector.stats.ranking import rank_sessions, simulate_votes

    true = np.array([1.5, 0.75, 0.0, -0.75, -1.5])
    rng = np.random.default_rng(0)
    n_sims = 40 if quick else 400
    covered = 0
    for sim in range(n_sims):
        # drawn from the model itself, which has no ties (a tie is a half win only in the fit)
        fit = rank_sessions(5, *simulate_votes(true, 200, rng), n_bootstrap=1000, seed=sim)
        covered += int(np.sum((fit.low <= true) & (true <= fit.high)))
    coverage = covered / (5 * n_sims)
    roots = []
    for i in range(5):
        with SessionWriter.create(tmp / f"rank_s{i}", model={"name": f"ckpt{i}"}) as w:
            w.add_rollout("r0", kind="single_chunk", actions=np.zeros((1, 9, 6)))
        roots.append((tmp / f"rank_s{i}").resolve())
    first, second, score = simulate_votes(true, 200, rng, tie_probability=0.1)
    for f, s_, sc in zip(first, second, score):
        answer = "a" if sc == 1.0 else "b" if sc == 0.0 else "tie"
        save_vote(new_vote(Side(str(roots[f]), f"s{f}", "r0"), Side(str(roots[s_]), f"s{s_}", "r0"), answer))
    ours = run_process(inspector_cmd("rank", *map(str, roots), "--json"))
    sides = {}
    for side in ("imagined", "real"):  # 8 checkpoints x 5 tasks x 20 rollouts per side, judged in a file
        sides[side] = []
        for c in range(8):
            dest = tmp / f"agree_{side}_{c}"
            records = {}
            with SessionWriter.create(dest, model={"name": f"ckpt{c}"}) as w:
                for task in range(5):
                    for i in range(20):
                        w.add_rollout(f"t{task}_{i:02d}", kind="single_chunk", actions=np.zeros((1, 9, 6)),
                                      prompt=f"task {task}", episode_index=task, start_frame=i)
                        records[f"t{task}_{i:02d}"] = {"success": bool(rng.random() < (c + 1) / 9)}
            store_records(dest / OUTCOMES_FILE, records, source="file", set_by="bench")
            sides[side].append(str(dest))
    from inspector.stats.agreement import Point, agreement, point_statistics

    p = rng.uniform(0.05, 0.95, 30)
    q = np.clip(p + rng.normal(0, 0.12, 30), 0.02, 0.98)
    truth = point_statistics(p, q)
    n_evals = 40 if quick else 200
    held = dict.fromkeys(truth, 0)
    for e in range(n_evals):
        points = [Point(str(i), "t", (rng.random(20) < p[i]).astype(float), (rng.random(20) < q[i]).astype(float))
                  for i in range(30)]
        out = agreement(points, n_bootstrap=1000, seed=e)
        for name, value in truth.items():
            held[name] += out[name]["low"] <= value <= out[name]["high"]
    worst = min(held, key=held.__getitem__)
    agree = run_process(inspector_cmd("agreement", "--imagined", *sides["imagined"], "--real", *sides["real"], "--json"))
    return [Figure("rank_interval_coverage", coverage, "fraction", "0.90 to 0.98 (nominal 0.95)",
                   0.90 <= coverage <= 0.98,
                   note=f"true strengths inside the 95% bootstrap intervals: 5 sessions (strengths -1.5 to 1.5), "
                        f"200 votes drawn from the Bradley-Terry model, {n_sims} simulations"),
            Figure("rank_200_votes", ours.wall_s, "s", "< 5 s and < 500 MB", ours.wall_s < 5 and ours.peak_mib < 500,
                   ours.peak_mib, note="inspector rank on 5 sessions, 200 votes, 2000 bootstrap replicates"),
            Figure("agreement_interval_coverage", held[worst] / n_evals, "fraction", ">= 0.75 (nominal 0.95)",
                   held[worst] / n_evals >= 0.75,
                   note=f"the least of the five statistics ({worst}); each: "
                        + ", ".join(f"{k} {v / n_evals:.2f}" for k, v in held.items())
                        + f"; 30 points, 20 rollouts a side from known probabilities, {n_evals} evaluations"),
            Figure("agreement_1600_rollouts", agree.wall_s, "s", "< 10 s and < 500 MB",
                   agree.wall_s < 10 and agree.peak_mib < 500, agree.peak_mib,
                   note="inspector agreement, 8 checkpoints x 5 tasks x 20 rollouts per side (40 points), "
                        f"2000 bootstrap replicates; machine load average {os.getloadavg()[0]:.1f} on "
                        f"{os.cpu_count()} CPUs")]


# ----------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller counts, fewer repetitions")
    parser.add_argument("--json", type=Path, help="also write the figures as JSON")
    parser.add_argument("--latest", action="store_true",
                        help="merge the figures into benchmarks/latest.json (by name) and rewrite the table in "
                             "benchmarks/README.md")
    parser.add_argument("--only", nargs="*", help="run only these groups: fk report export ray open scrub serve playback keys page_load groot "
                                           "served eval clock outcomes label rank")
    args = parser.parse_args(argv)

    figures: list[Figure] = []
    with tempfile.TemporaryDirectory(prefix="inspector-bench-") as tmp_name:
        tmp = Path(tmp_name)
        os.environ["INSPECTOR_CACHE_DIR"] = str(tmp / "cache-bench")  # never the user's cache
        runs: list[tuple[str, Callable[[], Figure | list[Figure]]]] = [
            ("fk", lambda: bench_fk(args.quick)),
            ("report", lambda: bench_report(tmp, args.quick)),
            ("export", lambda: bench_export(tmp, args.quick)),
            ("ray", lambda: bench_ray(tmp, args.quick)),
            ("open", lambda: bench_open(tmp, args.quick)),
            ("scrub", lambda: bench_scrub(tmp, args.quick)),
            ("serve", lambda: bench_serve(tmp, args.quick)),
            ("playback", lambda: bench_playback(tmp, args.quick)),
            ("keys", lambda: bench_keys(tmp, args.quick)),
            ("page_load", lambda: bench_page_load(tmp, args.quick)),
            ("groot", lambda: bench_groot(tmp, args.quick)),
            ("served", lambda: bench_served(tmp, args.quick)),
            ("eval", lambda: bench_eval(tmp, args.quick)),
            ("clock", lambda: bench_clock(tmp, args.quick)),
            ("rank", lambda: bench_rank(tmp, args.quick)),
            ("outcomes", lambda: bench_outcomes(tmp, args.quick)),
            ("label", lambda: bench_label(tmp, args.quick)),
        ]
        for name, run in runs:
            if args.only and name not in args.only:
                continue
            t = time.perf_counter()
            result = run()
            figures += result if isinstance(result, list) else [result]
            print(f"  measured {name} ({time.perf_counter() - t:.0f} s)", file=sys.stderr)

    machine = f"{os.cpu_count()} CPUs, Python {sys.version.split()[0]}"
    print(f"\nBenchmarks ({time.strftime('%Y-%m-%d')}, {machine}; ratio = baseline / ours)\n")
    rows = [{**asdict(f), "ratio": f.ratio} for f in figures]
    print(table.markdown(rows), end="")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    if args.latest:
        latest = table.merge(table.load(), rows)
        table.LATEST.write_text(json.dumps(latest, indent=2) + "\n")
        table.write(latest)
    return 0


if __name__ == "__main__":
    sys.exit(main())
