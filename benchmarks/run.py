"""Speed figures of inspector, each with a naive baseline measured in the same run.

    python benchmarks/run.py [--quick] [--json FILE]

Prints a markdown table: figure, ours, naive baseline, ratio (baseline / ours: how many times
faster), target, ok. Absolute times drift on a shared machine; the ratios, measured back to back,
are what to compare between runs. ``--quick`` uses fewer repetitions (under a minute).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO.parent / "shared" / "fixtures" / "dreamzero_so101"
DEMO = REPO / "sessions" / "demo"


@dataclass
class Figure:
    name: str
    ours: float
    baseline: float | None
    ratio: float | None
    target: str
    unit: str
    ok: bool | None


def _best_of(fn: Callable[[], object], repeat: int) -> float:
    """Fastest of ``repeat`` runs [s] (the least disturbed by other work on the machine)."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


# ----------------------------------------------------------------------------------------------


def bench_fk(quick: bool) -> list[Figure]:
    """Batched FK vs a per-frame yourdfpy loop on the same inputs.

    ``fk``: the tool point of 1 M configurations (what every metric uses); ``fk_all_links``: every
    link's full pose (what the app and the export draw).
    """
    from inspector.kinematics import kinematics
    from inspector.robot import GRIPPER_FRAME, load_urdf
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
        Figure("fk", 1.0 / tool, 1.0 / base_tool, base_tool / tool, ">= 1e6 /s and >= 50x",
               "configurations/s", 1.0 / tool >= 1e6 and base_tool / tool >= 50),
        Figure("fk_all_links", 1.0 / all_links, 1.0 / base_all, base_all / all_links, ">= 50x",
               "configurations/s", base_all / all_links >= 50),
    ]


def bench_metrics_1000(quick: bool) -> Figure:
    """All joint-space metrics for 1,000 rollouts (60x24x6 vs a 600-frame GT), batched vs a Python loop."""
    from inspector import metrics
    from inspector.kinematics import kinematics
    from inspector.sweep import sweep_metrics
    from inspector.units import Units, limits_in_units

    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, 600)[:, None]
    gt = np.array([0, -60, 60, 40, 0, 30]) + 30 * np.sin(np.pi * t * rng.uniform(0.5, 1, 6))
    n = 1000
    chunks = gt[np.minimum(np.arange(60)[:, None] * 9 + np.arange(24)[None], 599)][None] \
        + rng.normal(scale=2.0, size=(n, 60, 24, 6)).cumsum(axis=1) * 0.1
    ours = _best_of(lambda: sweep_metrics(chunks, gt), 1)

    fk = kinematics()
    limits = limits_in_units(Units())
    subset = 3 if quick else 5

    def naive() -> None:  # per-timestep Python loop: what a first script would do
        for b in range(subset):
            pred = chunks[b, :, :9].reshape(-1, 6)
            for k, p in enumerate(pred):
                g = gt[min(k, len(gt) - 1)]
                np.linalg.norm(p - g)
                np.linalg.norm(gt - p, axis=1).min()
                fk.gripper_positions(p[None], Units())
                metrics.limit_violations(p, limits)
            metrics.dtw(pred, gt)

    base = _best_of(naive, 1) / subset * n
    return Figure("metrics_1000", ours, base, base / ours, "< 5 s", "s", ours < 5.0)


def _fixture_rollout(tmp: Path):
    """The 60-chunk fixture rollout with three views, imported into a session."""
    from inspector.importers.dreamzero_so101 import import_dreamzero
    from inspector.session import open_session

    dest = tmp / "fixture"
    if not dest.exists():  # both 60-chunk rollouts: the app opens one by default, we time the other
        import_dreamzero(FIXTURES / "train_rollout", dest, log=lambda _: None)
    return dest, open_session(dest).rollouts["ep000_train"]


@contextlib.contextmanager
def _app_tab(tmp: Path) -> Iterator[tuple[object, object]]:
    """The app serving the fixture session, with one headless tab connected: yields (tab, rollout key)."""
    from inspector.app import HeadlessClient, InspectorApp
    from inspector.sources import open_sources

    session_dir, _ = _fixture_rollout(tmp)
    app = InspectorApp(open_sources([session_dir]), port=_free_port())
    try:
        with HeadlessClient(app.port):
            tab = app.wait_for_tabs(1)[0]
            key = next(k for k in app.catalog.keys() if k.endswith("ep000_train"))
            # a new tab opens the default rollout (ep000_novel) at once: let it settle first,
            # so the figure times opening a rollout that nothing has touched yet
            assert tab.key != key
            deadline = time.time() + 60
            while tab.loaded is None and tab.error is None and time.time() < deadline:
                time.sleep(0.05)
            if tab.loaded is not None:
                tab.loaded.frames.done.wait(timeout=60)
            yield tab, key
    finally:
        app.stop()


def bench_open(tmp: Path, quick: bool) -> Figure:
    """A 60-chunk rollout with its GT and three views ready to scrub, through the app's own path."""
    from inspector.timeline import build_timeline

    _, rollout = _fixture_rollout(tmp)

    def open_untouched() -> float:
        with _app_tab(tmp) as (tab, key):  # a fresh app: nothing of that rollout loaded yet
            start = time.perf_counter()
            tab.open(key)
            tab.loaded.frames.decoded.wait(timeout=60)  # every frame of every view on hand
            return time.perf_counter() - start

    ours = min(open_untouched() for _ in range(1 if quick else 3))

    def naive() -> None:  # one thread, full-size GT decoded then resized in numpy
        from inspector.metrics import resize_frames
        from inspector.session import load_rollout
        from inspector.video import decode

        r = load_rollout(rollout.root)
        build_timeline(r)
        for view in r.views:
            pred, _ = decode(r.video_path(view))
            gt_frames, _ = decode(r.video_path(view, gt=True))
            resize_frames(gt_frames, *pred.shape[1:3])

    base = _best_of(naive, 1)
    return Figure("open", ours, base, base / ours, "< 1.5 s", "s", ours < 1.5)


def bench_scrub(tmp: Path, quick: bool) -> Figure:
    """One scrub step server-side (FK, both arms, video frames, plot cursor): median of 200."""
    _, rollout = _fixture_rollout(tmp)
    with _app_tab(tmp) as (tab, key):
        tab.open(key)
        tab.loaded.frames.done.wait(timeout=60)
        rng = np.random.default_rng(0)
        steps = rng.integers(0, tab.loaded.timeline.n_steps, size=60 if quick else 200)
        times = []
        for s in steps:
            t = time.perf_counter()
            tab.set_step(int(s))
            times.append(time.perf_counter() - t)
        ours = float(np.median(times))

    # baseline: the same frames decoded from the file on every step (seek + decode)
    import av

    def decode_at(path: Path, index: int) -> None:
        with av.open(str(path)) as c:
            stream = c.streams.video[0]
            c.seek(int(index / 30.0 / stream.time_base), stream=stream, backward=True)
            for frame in c.decode(stream):
                if frame.pts * stream.time_base >= index / 30.0 - 1e-3:
                    frame.to_ndarray(format="rgb24")
                    break

    clips = [rollout.video_path(v) for v in rollout.views] + [rollout.video_path(v, gt=True) for v in rollout.gt_views]
    base_times = []
    for s in steps[:20]:
        t = time.perf_counter()
        for path in clips:
            decode_at(path, int(s))
        base_times.append(time.perf_counter() - t)
    base = float(np.median(base_times))
    return Figure("scrub", ours * 1e3, base * 1e3, base / ours, "median < 15 ms", "ms", ours < 0.015)


def bench_export(tmp: Path, quick: bool) -> list[Figure]:
    """The 60-chunk rollout with three views to .rrd, vs one rr.log per frame with images."""
    import rerun as rr

    from inspector.export import write_recording
    from inspector.timeline import build_timeline

    from inspector.session import load_rollout

    _, rollout = _fixture_rollout(tmp)
    out = tmp / "export.rrd"

    def ours_once() -> None:
        # read from disk each time: nothing decoded or cached beforehand, as in `inspector export`
        write_recording(build_timeline(load_rollout(rollout.root)), out)

    ours = _best_of(ours_once, 1 if quick else 2)
    size_mb = out.stat().st_size / 1e6

    # Naive: decode the same clips, then one rr.log per frame with the imagined and GT images.
    # Logging is timed on the first 60 frames and scaled to the clip lengths.
    fresh = load_rollout(rollout.root)
    t = time.perf_counter()
    clips = {(v, gt): fresh.video(v, gt=gt).frames for v in fresh.views for gt in (False, True)}
    decode_s = time.perf_counter() - t
    n = 60

    def naive() -> None:
        rec = rr.RecordingStream("naive")
        rec.save(str(tmp / "naive.rrd"))
        for f in range(n):
            rec.set_time("frame", sequence=f)
            for (view, gt), frames in clips.items():
                rec.log(f"video/{view}/{'gt' if gt else 'imagined'}", rr.Image(frames[f]))
        rec.flush()
        rec.disconnect()

    total_frames = sum(len(frames) for frames in clips.values())
    per_frame_sets = total_frames / (n * len(clips))
    base = decode_s + _best_of(naive, 1) * per_frame_sets
    naive_mb = (tmp / "naive.rrd").stat().st_size / 1e6 * per_frame_sets
    return [Figure("export", ours, base, base / ours, "< 3 s", "s", ours < 3.0),
            Figure("export_size", size_mb, naive_mb, naive_mb / size_mb, "< 10 MB", "MB", size_mb < 10.0)]


def bench_memory(tmp: Path, quick: bool) -> Figure:
    """Peak RSS of ``inspector serve`` on the demo with one client that opens a rollout."""
    port = _free_port()
    target = [str(DEMO)] if DEMO.exists() else [str(_fixture_rollout(tmp)[0])]
    proc = subprocess.Popen([sys.executable, "-m", "inspector", "serve", *target, "--port", str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        from inspector.app import HeadlessClient

        _wait_port(port, 60)
        with HeadlessClient(port):
            time.sleep(8 if quick else 15)  # the tab opens the default rollout and decodes its video
        peak_kb = _peak_rss_kb(proc.pid)
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    return Figure("memory", peak_kb / 1024, None, None, "report only", "MiB peak RSS", None)


# ----------------------------------------------------------------------------------------------


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_port(port: int, timeout: float) -> None:
    import socket

    deadline = time.time() + timeout
    while time.time() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1):
                return
        except OSError:
            time.sleep(0.2)
    raise TimeoutError(f"server on port {port} did not start")


def _peak_rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return 0


def _fmt(value: float | None, unit: str) -> str:
    if value is None:
        return "-"
    if unit == "configurations/s":
        return f"{value / 1e6:.2f} M/s" if value >= 1e5 else f"{value / 1e3:.1f} k/s"
    return f"{value:.3g} {unit}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (under a minute)")
    parser.add_argument("--json", type=Path, help="also write the figures as JSON")
    parser.add_argument("--only", nargs="*", help="run only these figures")
    args = parser.parse_args(argv)

    figures: list[Figure] = []
    with tempfile.TemporaryDirectory(prefix="inspector-bench-") as tmp_name:
        tmp = Path(tmp_name)
        runs: list[tuple[str, Callable[[], Figure | list[Figure]]]] = [
            ("fk", lambda: bench_fk(args.quick)),
            ("metrics_1000", lambda: bench_metrics_1000(args.quick)),
            ("open", lambda: bench_open(tmp, args.quick)),
            ("scrub", lambda: bench_scrub(tmp, args.quick)),
            ("export", lambda: bench_export(tmp, args.quick)),
            ("memory", lambda: bench_memory(tmp, args.quick)),
        ]
        for name, run in runs:
            if args.only and name not in args.only:
                continue
            result = run()
            figures += result if isinstance(result, list) else [result]
            print(f"  measured {name}", file=sys.stderr)

    machine = f"{os.cpu_count()} CPUs, Python {sys.version.split()[0]}"
    print(f"\nBenchmarks ({time.strftime('%Y-%m-%d')}, {machine}; ratio = baseline / ours)\n")
    print("| figure | ours | naive baseline | ratio | target | ok |")
    print("|---|---|---|---|---|---|")
    for f in figures:
        ratio = "-" if f.ratio is None else f"{f.ratio:.1f}x"
        ok = "-" if f.ok is None else ("yes" if f.ok else "**no**")
        print(f"| {f.name} | {_fmt(f.ours, f.unit)} | {_fmt(f.baseline, f.unit)} | {ratio} | {f.target} | {ok} |")
    if args.json:
        args.json.write_text(json.dumps([asdict(f) for f in figures], indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
