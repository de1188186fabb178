"""What the cameras cost: the report's camera measures, the app's overlay and the gripper track.

    python benchmarks/camera_measures.py [-n 200] [--reps 2] [--jobs 2]

1. ``inspector report --json`` of ``n`` rollouts with video (``eval_session.py``'s session: the
   demo's episode 0, two 540-frame views) with and without the demo's ``cameras.json`` copied in,
   alternating, each run with a fresh metrics cache: the same code, so the difference is what the
   arm-masked PSNR and the gripper track cost (a session without cameras computes neither). CPU
   seconds of the process tree (``wait4``) and wall seconds, median of ``--reps``.
2. The app: the overlay of one view at one step (two silhouettes and two PNGs), median over 60
   steps of the demo's ``video_ahead_1s``; the tracker per frame over its front video; opening
   the demo's 60-chunk rollout in a fresh app (until every frame is decoded: the gripper is
   tracked on the way) and a server-side scrub step, without cameras, with them, and with the
   overlay on.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
DEMO = REPO / "sessions" / "demo"


def report_run(session: Path, cache: Path, jobs: int) -> tuple[float, float]:
    """(CPU seconds of the process tree, wall seconds) of one cold ``inspector report --json``."""
    shutil.rmtree(cache, ignore_errors=True)
    env = {**os.environ, "INSPECTOR_CACHE_DIR": str(cache)}
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "inspector", "report", str(session), "--json", "-j", str(jobs)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"report exited {status}: {proc.stderr.read().decode()[-2000:] if proc.stderr else ''}")
    return usage.ru_utime + usage.ru_stime, wall


def app_costs() -> tuple[float, float]:
    """(ms a view's overlay at a step, ms a tracked frame) on the demo."""
    import numpy as np

    from inspector.analysis.gripper_track import GripperTracker
    from inspector.analysis.timeline import build_timeline
    from inspector.app._overlay import ArmOverlay
    from inspector.data.session import load_session_rollout, open_session

    tl = build_timeline(load_session_rollout(open_session(DEMO, lazy=True), "video_ahead_1s"))
    overlay = ArmOverlay.of(tl)
    assert overlay is not None
    overlay.uris("front", 0, 0, (320, 240))  # the meshes, once per process
    times = []
    for step in np.linspace(1, tl.n_steps - 1, 60).astype(int):
        t0 = time.perf_counter()
        overlay.uris("front", int(step), tl.frame_index(int(step)), (320, 240))
        times.append(time.perf_counter() - t0)
    frames = [rgb for _, rgb in tl.rollout.video("front").iter_frames()]
    tracker = GripperTracker((150.0, 110.0), (320, 240))
    t0 = time.perf_counter()
    for rgb in frames:
        tracker.add(rgb)
    return statistics.median(times) * 1e3, (time.perf_counter() - t0) / len(frames) * 1e3


def app_open_and_scrub(tmp: Path, reps: int) -> dict[str, tuple[float, float]]:
    """Per setting (a demo copy without cameras; with them, overlay off; with them, overlay on):
    (seconds until the 60-chunk rollout's frames are all decoded in a fresh app, best of ``reps``;
    the median server-side scrub step [ms] over 60 steps)."""
    import numpy as np
    from run import _free_port

    from inspector.app import HeadlessClient, InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    out = {}
    for name, cameras, overlay in (("without cameras", False, False), ("cameras, overlay off", True, False),
                                   ("cameras, overlay on", True, True)):
        session = tmp / "demo"
        shutil.rmtree(session, ignore_errors=True)
        shutil.copytree(DEMO, session)
        if not cameras:
            (session / "cameras.json").unlink()
        opened, scrub = [], []
        for _ in range(reps):
            app = InspectorApp(open_sources([session]), port=_free_port(), metrics_cache=MetricsCache(enabled=False))
            try:
                with HeadlessClient(app.port):
                    tab = app.wait_for_tabs(1)[0]
                    key = next(k for k in app.catalog.keys() if k.endswith("overrun_60chunks"))
                    if tab.loaded is not None:
                        tab.loaded.frames.done.wait(timeout=120)
                    tab.video.overlay.value = overlay
                    start = time.perf_counter()
                    tab.open(key)
                    tab.loaded.frames.decoded.wait(timeout=300)
                    opened.append(time.perf_counter() - start)
                    tab.loaded.frames.done.wait(timeout=300)
                    for step in np.random.default_rng(0).integers(0, tab.loaded.timeline.n_steps, 60):
                        t0 = time.perf_counter()
                        tab.set_step(int(step))
                        scrub.append(time.perf_counter() - t0)
            finally:
                app.stop()
        out[name] = (min(opened), statistics.median(scrub) * 1e3)
        print(f"  app, {name}: open {out[name][0]:.2f} s, scrub step {out[name][1]:.1f} ms", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=200)
    parser.add_argument("--reps", type=int, default=2)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--skip-report", action="store_true")
    args = parser.parse_args(argv)
    overlay_ms, track_ms = app_costs()
    print(f"app: overlay of a view at a step {overlay_ms:.1f} ms (median of 60); tracker {track_ms:.2f} ms a frame")
    with tempfile.TemporaryDirectory(prefix="inspector-cameras-app-") as tmp:
        app_open_and_scrub(Path(tmp), args.reps)
    if args.skip_report:
        return 0
    from eval_session import make_eval_session

    with tempfile.TemporaryDirectory(prefix="inspector-cameras-bench-") as tmp:
        session = make_eval_session(Path(tmp) / "video", args.n, video=True)
        cameras = session / "cameras.json"
        runs: dict[str, list[tuple[float, float]]] = {"without cameras": [], "with cameras": []}
        for rep in range(args.reps):
            for name in (("without cameras", "with cameras") if rep % 2 == 0 else ("with cameras", "without cameras")):
                if name == "with cameras":
                    shutil.copyfile(DEMO / "cameras.json", cameras)
                else:
                    cameras.unlink(missing_ok=True)
                runs[name].append(report_run(session, Path(tmp) / "cache", args.jobs))
                print(f"  {name}: {runs[name][-1][0]:.1f} CPU-s, {runs[name][-1][1]:.1f} s", flush=True)
        cpu = {k: statistics.median(c for c, _ in v) for k, v in runs.items()}
        wall = {k: statistics.median(w for _, w in v) for k, v in runs.items()}
        print(f"report of {args.n} rollouts with video (-j {args.jobs}): without cameras {cpu['without cameras']:.1f} "
              f"CPU-s / {wall['without cameras']:.1f} s; with {cpu['with cameras']:.1f} CPU-s / "
              f"{wall['with cameras']:.1f} s; with/without CPU {cpu['with cameras'] / cpu['without cameras']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
