"""Evaluation scale: memory bounded by budgets, not by how many rollouts exist or were opened.

The figures themselves (time, peak RSS at 200 / 1,000 rollouts) are in ``benchmarks/run.py``;
these tests check the mechanisms: the frame cache's budget and eviction, reopening, the decode
bound on huge clips, report workers and the metrics cache giving the same numbers, and the
prompt pairing staying linear.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from demo_copies import demo_copy

from inspector.app._frames import FrameCache
from inspector.data.session import SessionWriter
from inspector.data.video import VideoClip, encode_h264
from inspector.errors import InspectorError
from inspector.report.build import build_report
from inspector.rows.rollout import prompt_pairs
from inspector.rows.tasks import Task, run_task

pytestmark = pytest.mark.slow  # large sessions through the CLI

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "sessions" / "demo"
BEFORE = Path(__file__).resolve().parent / "data" / "report_demo_before_scale.json"


# ----------------------------------------------------------------------------------------------
# Frame cache


def test_frame_cache_evicts_least_recently_used_within_budget():
    cache = FrameCache(budget_bytes=100)
    for i in range(5):
        cache.put(("clip", i), "x" * 30)
    assert cache.bytes <= 100 and len(cache) == 3 and cache.evictions == 2
    assert cache.get(("clip", 0)) is None and cache.get(("clip", 4)) == "x" * 30
    cache.get(("clip", 2))  # used: now the most recent
    cache.put(("clip", 5), "y" * 30)
    assert ("clip", 2) in cache and ("clip", 3) not in cache
    cache.put(("huge",), "z" * 101)  # larger than the whole budget: not kept, nothing evicted for it
    assert ("huge",) not in cache and len(cache) == 3


@pytest.fixture()
def small_budget_app():
    from inspector.app import InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    # one autoregressive demo rollout's frames (two views, imagined + GT) take ~23 MB as JPEG: the
    # budget holds one and a half
    app = InspectorApp(open_sources([DEMO], confine=True), port=0, cache_mb=36,
                       metrics_cache=MetricsCache(enabled=False))
    yield app
    app.stop()


def test_app_memory_follows_the_frame_budget(small_budget_app):
    from inspector.app import HeadlessClient

    app = small_budget_app
    keys = {app.catalog.get(k).tag: k for k in app.catalog.keys()}
    with HeadlessClient(app.port):
        tab = app.wait_for_tabs(1)[0]
        for tag in ("tempo_0.8x", "bias_elbow", "limits_wrist", "prompt_train"):
            assert tab.open(keys[tag])
            assert tab.loaded.frames.decoded.wait(120), tag
            assert app.frame_cache.bytes <= app.frame_cache.budget_bytes
        assert app.frame_cache.evictions > 0  # four rollouts' frames do not fit: the oldest went

        # the last one's frames are the most recently used, GT frames the others cached first
        # included: what the budget leaves beside them can be filled without evicting one
        last = tab.loaded.frames
        prefixes = [p for view in last.views for p in last._keys(view)]
        with app.frame_cache._lock:
            cached = list(app.frame_cache._items.items())
        theirs = sum(len(uri) for key, uri in cached if any(key[:len(p)] == p for p in prefixes))
        spare = app.frame_cache.budget_bytes - theirs
        for i in range(64):
            app.frame_cache.put(("filler", i), "x" * (spare // 64))

        # ... so reopened (here after its built timeline was dropped too, as the catalog does
        # beyond KEEP_LOADED), it needs no decoding at all
        app.catalog._loaded.clear()
        assert tab.open(keys["prompt_train"])
        assert tab.loaded.frames.decoded.is_set()
        tab.set_step(100, force=True)
        assert all(p.imagined and p.gt for p in tab.pairs)

        # an evicted one decodes again in the background and shows its frames
        assert tab.open(keys["tempo_0.8x"])
        assert tab.loaded.frames.decoded.wait(120)
        deadline = time.monotonic() + 60
        while not all(p.imagined and p.gt for p in tab.pairs) and time.monotonic() < deadline:
            time.sleep(0.1)
            tab.set_step(100, force=True)
        assert all(p.imagined and p.gt for p in tab.pairs)
        assert app.frame_cache.bytes <= app.frame_cache.budget_bytes


def test_rollouts_sharing_a_gt_episode_share_its_cached_frames(small_budget_app):
    """bias_elbow and tempo_0.8x both start at frame 0 of demo episode 0: one set of GT JPEGs."""
    app = small_budget_app
    a = app.catalog.load(next(k for k in app.catalog.keys() if k.endswith("bias_elbow")))
    b = app.catalog.load(next(k for k in app.catalog.keys() if k.endswith("tempo_0.8x")))
    assert a.frames._keys("front")[1] == b.frames._keys("front")[1]
    assert a.frames._keys("front")[0] != b.frames._keys("front")[0]


# ----------------------------------------------------------------------------------------------
# Decoding stays within its budget


def _peak_rss_mib(args: list[str], env: dict[str, str]) -> tuple[subprocess.CompletedProcess, float]:
    import psutil

    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    root, peak = psutil.Process(proc.pid), 0
    while proc.poll() is None:
        total = 0
        for p in [root, *root.children(recursive=True)]:
            try:
                total += p.memory_info().rss
            except psutil.Error:
                pass
        peak = max(peak, total)
        time.sleep(0.02)
    out, err = proc.communicate()
    return subprocess.CompletedProcess(args, proc.returncode, out, err), peak / 2**20


def _moving_frames(n: int, width: int, height: int):
    """A bright square moving over a gradient, one frame at a time (never the whole clip)."""
    base = np.zeros((height, width, 3), np.uint8)
    base[..., 0] = np.linspace(0, 255, width, dtype=np.uint8)[None]
    base[..., 2] = 90
    for i in range(n):
        frame = base.copy()
        x = (width - 200) * i // max(n - 1, 1)
        frame[height // 3: height // 3 + 200, x: x + 200] = 250
        yield frame


def _looped(clip: Path, out: Path, times: int) -> None:
    """``clip`` played ``times`` times over, as one MP4: its H.264 packets copied, not encoded
    again (encoding is most of the cost of a large clip; decoding it is what is being tested)."""
    import av

    with av.open(str(clip)) as src, av.open(str(out), "w") as dst:
        video = src.streams.video[0]
        stream = dst.add_stream_from_template(video)
        packets = [(bytes(p), p.pts, p.dts, p.duration, p.is_keyframe) for p in src.demux(video) if p.size]
        span = max(pts + duration for _, pts, _, duration, _ in packets) - min(pts for _, pts, *_ in packets)
        for k in range(times):  # each repeat starts with the clip's own keyframe
            for data, pts, dts, duration, keyframe in packets:
                packet = av.Packet(data)
                packet.pts, packet.dts, packet.duration = pts + k * span, dts + k * span, duration
                packet.is_keyframe = keyframe
                packet.time_base = video.time_base
                packet.stream = stream
                dst.mux(packet)


@pytest.mark.slow
def test_a_huge_clip_is_streamed_not_held(tmp_path):
    """120 frames of 2560x1440 (1.3 GB decoded, 2.6 GB for imagined and GT) as imagined and GT
    video: report and export stay far below one clip's frames, because no clip is ever held whole."""
    import av

    clip = tmp_path / "big.mp4"
    encode_h264(tmp_path / "square.mp4", _moving_frames(20, 2560, 1440), fps=30, preset="ultrafast")
    _looped(tmp_path / "square.mp4", clip, 6)
    with av.open(str(clip)) as container:
        video = container.streams.video[0]
        assert (video.frames, video.width, video.height) == (120, 2560, 1440)
    with SessionWriter.create(tmp_path / "s") as w:
        w.add_rollout("big", kind="autoregressive", actions=np.zeros((23, 24, 6)) + [0, 0, 0, 0, 0, 50],
                      gt_actions=np.zeros((207, 6)) + [0, 0, 0, 0, 0, 50],
                      videos={"front": clip}, gt_videos={"front": clip})
    env = {**os.environ, "INSPECTOR_CACHE_DIR": str(tmp_path / "cache")}
    done, peak = _peak_rss_mib([sys.executable, "-m", "inspector", "report", str(tmp_path / "s"), "--json",
                                "--jobs", "1"], env)
    assert done.returncode == 0, done.stderr
    row = json.loads(done.stdout)["rollouts"][0]
    assert row["video_psnr_db"]["front"] > 60  # the clip against itself
    assert peak < 900, f"report held {peak:.0f} MiB"
    done, peak = _peak_rss_mib([sys.executable, "-m", "inspector", "export", str(tmp_path / "s"), "-o",
                                str(tmp_path / "big.rrd"), "--no-cache"], env)
    assert done.returncode == 0, done.stderr
    assert peak < 900, f"export held {peak:.0f} MiB"


def test_whole_clip_decoding_refuses_past_its_budget(tmp_path):
    clip = tmp_path / "c.mp4"
    encode_h264(clip, _moving_frames(20, 320, 240), fps=30, preset="ultrafast")
    assert VideoClip(clip).decode().shape == (20, 240, 320, 3)
    with pytest.raises(InspectorError, match=r"more than 1 MiB decoded at 320x240.*frame by frame") as exc:
        VideoClip(clip).decode(max_bytes=2**20)
    assert exc.value.file == str(clip) and "\n" not in str(exc.value)


def test_frames_at_their_own_size_skip_the_area_filter_with_the_same_pixels(tmp_path):
    """Converting a frame without scaling takes swscale's fast path; the pixels (hence every PSNR)
    are those the area filter gives."""
    import av

    from inspector.data.video import RgbConverter

    clip = tmp_path / "c.mp4"
    encode_h264(clip, _moving_frames(12, 322, 182), fps=30, preset="ultrafast")
    to_rgb = RgbConverter()
    with av.open(str(clip)) as container:
        for frame in container.decode(video=0):
            area = frame.reformat(width=frame.width, height=frame.height, format="rgb24",
                                  interpolation="AREA").to_ndarray()
            assert np.array_equal(to_rgb(frame), area)
            assert np.array_equal(to_rgb(frame, (frame.width, frame.height)), area)
            assert to_rgb(frame, (160, 90)).shape == (90, 160, 3)


@pytest.mark.slow
def test_frames_past_8k_are_refused_in_one_line(tmp_path):
    clip = tmp_path / "huge.mp4"
    encode_h264(clip, _moving_frames(1, 8192, 4352), fps=30, preset="ultrafast")
    with SessionWriter.create(tmp_path / "s") as w:
        w.add_rollout("ok", kind="single_chunk", actions=np.zeros((1, 24, 6)), gt_actions=np.zeros((24, 6)))
        w.add_rollout("huge", kind="single_chunk", actions=np.zeros((1, 24, 6)), gt_actions=np.zeros((24, 6)),
                      videos={"front": clip}, gt_videos={"front": clip})
    report = build_report([str(tmp_path / "s")], jobs=1, use_cache=False)
    assert [r["tag"] for r in report["rollouts"]] == ["ok"]
    error = report["errors"]["s/huge"]
    assert "8192x4352" in error and "pixel limit" in error and "huge/video/front.mp4" in error
    assert "\n" not in error


# ----------------------------------------------------------------------------------------------
# report: the same numbers however it runs


def _close(a, b, path: str, rel: float) -> None:
    if isinstance(a, dict):
        assert set(a) <= set(b) | {"worst_chunk", "start_frame", "n_chunks"}, path
        for k in a:
            if k in b:
                _close(a[k], b[k], f"{path}.{k}", rel)
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{i}]", rel)
    elif isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, rel=rel, abs=1e-9), path
    else:
        assert a == b, path


@pytest.fixture(scope="module")
def demo_reports(tmp_path_factory) -> dict[str, dict]:
    """The demo's report (at the margin of the all-in-memory version, 0) two ways: computed by two
    workers, filling a metrics cache, and read from that cache in this process. (How rollouts are
    cut into tasks never shows in a row: ``test_a_rollouts_numbers_do_not_depend_on_its_batch``.)"""
    cache = str(tmp_path_factory.mktemp("demo-cache"))
    return {"two": build_report([str(DEMO)], jobs=2, cache_dir=cache, limit_margin_deg=0.0),
            "cached": build_report([str(DEMO)], jobs=1, cache_dir=cache, limit_margin_deg=0.0)}


def test_report_gives_the_numbers_it_gave_before_streaming(demo_reports):
    """The demo's report as the previous, all-in-memory version computed it (margin 0 there)."""
    before = json.loads(BEFORE.read_text())
    now = demo_reports["two"]
    old_rows = {r["tag"]: r for r in before["rollouts"]}
    # the rollouts the demo had then (video_ahead_1s came later), in the same order
    assert [r["tag"] for r in now["rollouts"] if r["tag"] in old_rows] == list(old_rows)
    # The single chunks were rendered again since (9 frames, as their frames_per_chunk says, which
    # moved the noise draws of all but the first): the demo's own tests check them, not this.
    for row in (r for r in now["rollouts"] if r["tag"] in old_rows and not r["tag"].startswith("single_f")):
        old = old_rows[row["tag"]]
        for key in ("rmse_deg", "per_joint_rmse", "per_step_mse", "time_aligned_drift", "best_match_drift",
                    "video_psnr_db", "post_episode_chunks"):
            _close(row[key], old[key], f"{row['tag']}.{key}", rel=1e-12)
        # A step at a pose the episode holds at two times (the rest pose at its start and end) now
        # matches the hold nearest in time; a KD-tree matched whichever it found first. The tempo
        # fit moved by 0.002 at most (test_metrics checks the rule).
        _close(row["tempo"], old["tempo"], f"{row['tag']}.tempo", rel=0.0025)
        # FK is now exact to 1e-15 m (it was 5e-7 m off through a float32 URDF parse). DTW is left
        # out: its alignment is open at the end since (a rollout is not charged for the part of
        # the episode it never reaches), and test_metrics checks it against the textbook's.
        _close(row["ee_error_mm"], old["ee_error_mm"], f"{row['tag']}.ee_error_mm", rel=1e-6)
        assert row["limit_violations"]["count"] == old["limit_violations"]["count"]
        assert row["limit_violations"]["by_joint"] == old["limit_violations"]["by_joint"]


def test_report_is_the_same_from_the_cache(demo_reports):
    assert demo_reports["cached"]["rollouts"] and demo_reports["two"] == demo_reports["cached"]


def test_a_rollouts_numbers_do_not_depend_on_its_batch():
    """Bit for bit: how rollouts are cut into tasks (``--jobs``, ``--ray``) never shows in a row."""
    from inspector.analysis.timeline import build_timelines
    from inspector.data.ground_truth import resolve_ground_truth
    from inspector.data.session import open_session

    session = open_session(DEMO)
    rollouts = [session.rollouts[t] for t in ("bias_elbow", "limits_wrist", "prompt_novel", "prompt_train")]
    gt = resolve_ground_truth(rollouts[0])
    together = build_timelines(rollouts, gt)
    for i, rollout in enumerate(rollouts):
        alone = build_timelines([rollout], gt)[0]
        for name in ("time_aligned_drift", "best_match_drift", "dtw_drift", "ee_error_mm", "chunk_rmse"):
            assert np.array_equal(getattr(alone, name), getattr(together[i], name), equal_nan=True), name
        for name in ("rmse", "per_step_mse", "per_joint_rmse"):
            assert np.array_equal(getattr(alone.chunk_errors, name), getattr(together[i].chunk_errors, name)), name


def test_metrics_cache_hits_and_invalidates(tmp_path):
    session = demo_copy(tmp_path, ("bias_elbow", "tempo_0.8x"))
    task = Task(str(session), ("bias_elbow", "tempo_0.8x"), None, 2.0, str(tmp_path / "cache"))
    first = run_task(task)
    assert [o.cached for o in first] == [False, False]
    assert [o.cached for o in run_task(task)] == [True, True]
    # a changed rollout file is computed again; the other still comes from the cache
    actions = session / "rollouts" / "tempo_0.8x" / "actions.npy"
    a = np.load(actions)
    np.save(actions, a + 1.0)
    again = {o.tag: o for o in run_task(task)}
    assert again["bias_elbow"].cached and not again["tempo_0.8x"].cached
    assert again["tempo_0.8x"].row["time_aligned_drift"] != first[1].row["time_aligned_drift"]
    # a different joint-limit margin is another entry
    other = Task(str(session), ("bias_elbow",), None, 5.0, str(tmp_path / "cache"))
    assert not run_task(other)[0].cached


def test_a_broken_rollout_in_a_batch_fails_alone(tmp_path):
    # all four share GT episode 0 from frame 0, hence one batch
    session = demo_copy(tmp_path, ("bias_elbow", "tempo_0.8x", "limits_wrist", "prompt_train"))
    video = session / "rollouts" / "bias_elbow" / "video" / "wrist.mp4"
    video.write_bytes(video.read_bytes()[:5000])  # truncated: undecodable after a few frames
    report = build_report([str(session)], jobs=1, use_cache=False)
    assert "bias_elbow" not in [r["tag"] for r in report["rollouts"]]
    assert "wrist.mp4" in report["errors"]["demo/bias_elbow"]
    assert {"tempo_0.8x", "limits_wrist", "prompt_train"} <= {r["tag"] for r in report["rollouts"]}


# ----------------------------------------------------------------------------------------------
# Prompt pairs


def test_prompt_pairs_are_matched_by_tag_and_linear_in_count():
    entries = [((s, i), ("s", 0, 0), f"ep{i:05d}_train", "Pick the red cube") for s in ("a",) for i in range(5000)]
    entries += [(("b", i), ("s", 0, 0), f"ep{i:05d}_novel", "Pick the blue cube") for i in range(5000)]
    entries += [(("c", 0), ("s", 0, 0), "prompt_novel", "Pick the green cube")]
    start = time.perf_counter()
    pairs = prompt_pairs(entries)
    assert time.perf_counter() - start < 5  # all-against-all would be 25 M comparisons
    by_tag = {(a, b) for a, b in pairs}
    assert (("b", 7), ("a", 7)) in by_tag  # ep00007_novel with ep00007_train
    assert len(pairs) == 5000 + 2  # each novel with its train; green (alone) with one of each
    # a different start frame never pairs
    assert prompt_pairs([(1, ("s", 0, 0), "x_train", "A"), (2, ("s", 0, 10), "x_novel", "B")]) == []


def test_ctrl_c_stops_a_report_and_its_workers_at_once(tmp_path):
    """Ctrl-C (SIGINT to the terminal's process group) while the workers compute: exit 130 with no
    worker traceback, without waiting for the tasks under way or the ones queued to a worker."""
    import signal

    import psutil

    proc = subprocess.Popen([sys.executable, "-m", "inspector", "report", str(DEMO), "--json", "--jobs", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "INSPECTOR_CACHE_DIR": str(tmp_path / "cache")})
    try:
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline:  # until both workers compute
            workers = [p for p in psutil.Process(proc.pid).children() if "spawn_main" in " ".join(p.cmdline())]
            if len(workers) == 2 and all(w.cpu_times().user > 1.0 for w in workers):
                break
            time.sleep(0.1)
        assert proc.poll() is None, "the report ended before its workers computed"
        os.killpg(proc.pid, signal.SIGINT)
        stopped = time.monotonic()
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130 and out == "", err
    assert "Traceback" not in err, err
    assert time.monotonic() - stopped < 60
