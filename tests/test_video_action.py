"""Video-action agreement: the imagined video's GT time against the predicted joints' GT time."""

from __future__ import annotations

import contextlib
import json
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from inspector.analysis import video_action
from inspector.analysis.timeline import build_timeline
from inspector.data.session import SessionWriter, open_session

FPS = 30.0
EXECUTED, HORIZON = 9, 12
N_STEPS = 90  # 10 chunks


def _scene(t: np.ndarray, size=(96, 72)) -> np.ndarray:
    """(len(t), H, W, 3) frames of a lit disc on a fixed textured backdrop, moving along a path
    that never passes the same point twice (a stand-in for the arm)."""
    w, h = size
    rng = np.random.default_rng(5)
    backdrop = (40 + 30 * rng.random((h // 8, w // 8))).repeat(8, 0).repeat(8, 1)
    yy, xx = np.mgrid[0:h, 0:w]
    frames = []
    for ti in t:
        u = ti / 120.0  # 0..1 over the clip
        cx, cy = 12 + 70 * u, 36 + 22 * np.sin(2.5 * np.pi * u)
        disc = np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * 6.0 ** 2))
        gray = backdrop + 200 * disc
        frames.append(np.stack([gray, 0.8 * gray, 0.6 * gray], axis=-1))
    return np.clip(frames, 0, 255).astype(np.uint8)


def _joints(t: np.ndarray) -> np.ndarray:
    """(len(t), 6) GT joints [deg], every time its own pose."""
    u = np.asarray(t, np.float64)[:, None] / 120.0
    return np.hstack([-40 + 80 * u, 10 * np.sin(3 * u), 20 + 30 * u, 5 * np.cos(2 * u), 0 * u, 30 + 0 * u])


def _write(root: Path, shows: np.ndarray, gt_frames: np.ndarray, gt_joints: np.ndarray) -> None:
    """A session with one autoregressive rollout following the GT joints, whose imagined frame f
    shows GT frame ``shows[f]``; GT joints and frames carried with it."""
    n_chunks = N_STEPS // EXECUTED
    steps = np.minimum(np.arange(n_chunks)[:, None] * EXECUTED + np.arange(HORIZON), len(gt_joints) - 1)
    with SessionWriter.create(root) as w:
        w.add_rollout("r", kind="autoregressive", actions=gt_joints[steps], fps=FPS,
                      executed_per_chunk=EXECUTED, frames_per_chunk=EXECUTED,
                      videos={"front": gt_frames[shows]}, gt_actions=gt_joints, gt_videos={"front": gt_frames})


@pytest.mark.parametrize("shift", [6, -4, 0])
@pytest.mark.slow
def test_a_clip_shifted_by_n_frames_reads_n_over_fps(tmp_path: Path, shift: int) -> None:
    n_gt = N_STEPS + 12
    times = np.arange(n_gt, dtype=np.float64)
    gt_frames, gt_joints = _scene(times), _joints(times)
    shows = np.clip(np.arange(N_STEPS) + shift, 0, n_gt - 1)
    _write(tmp_path / "s", shows, gt_frames, gt_joints)

    tl = build_timeline(open_session(tmp_path / "s").rollouts["r"])
    va = tl.video_action("front")
    assert va is not None and va.lag_s is not None
    confident = np.isfinite(va.lag_s)
    assert confident.mean() > 0.9
    inside = confident & (np.arange(N_STEPS) + shift >= 0)  # frames that show a real GT frame
    # every confident frame reads the shift within one frame
    np.testing.assert_allclose(va.lag_s[inside], shift / FPS, atol=1.0 / FPS + 1e-9)
    summary = va.summary()
    assert summary["lag_s_median"] == pytest.approx(shift / FPS, abs=0.5 / FPS)
    assert summary["video_tempo"] == pytest.approx(1.0, abs=0.05)
    # the split: from the first chunk on, when the video runs 0.5 s or more away from the actions
    assert summary["split_chunk"] is None


def test_a_video_far_ahead_splits_from_its_first_chunk(tmp_path: Path) -> None:
    n_gt = N_STEPS + 30
    times = np.arange(n_gt, dtype=np.float64)
    gt_frames, gt_joints = _scene(times), _joints(times)
    _write(tmp_path / "s", np.arange(N_STEPS) + 24, gt_frames, gt_joints)  # 0.8 s ahead
    va = build_timeline(open_session(tmp_path / "s").rollouts["r"]).video_action("front")
    assert va is not None
    assert va.summary()["lag_s_median"] == pytest.approx(0.8, abs=1.0 / FPS)
    assert va.summary()["split_chunk"] == 0


def test_a_still_clip_reads_no_match(tmp_path: Path) -> None:
    still = np.repeat(_scene(np.array([40.0])), N_STEPS, axis=0)
    _write(tmp_path / "s", np.arange(N_STEPS), still, _joints(np.arange(N_STEPS, dtype=np.float64)))
    va = build_timeline(open_session(tmp_path / "s").rollouts["r"]).video_action("front")
    assert va is not None
    summary = va.summary()
    assert summary["matched_fraction"] == 0.0
    assert summary["lag_s_median"] is None and summary["lag_s_abs_mean"] is None
    assert summary["video_tempo"] is None
    assert summary["note"] is not None and summary["note"].startswith("no match")


def test_a_frame_unlike_any_gt_frame_matches_nothing() -> None:
    rng = np.random.default_rng(0)
    gt = np.stack([video_action.thumbnail(f) for f in _scene(np.arange(60.0))])
    noise = np.stack([video_action.thumbnail(rng.integers(0, 255, (72, 96, 3), dtype=np.uint8)) for _ in range(5)])
    flat = np.stack([video_action.thumbnail(np.full((72, 96, 3), 128, np.uint8))])
    match = video_action.match_frames(np.vstack([noise, flat, gt[10:11]]), gt)
    assert not match.matched[:6].any()
    assert match.gt_index[6] == 10


def test_frame_match_round_trips_through_json() -> None:
    gt = np.stack([video_action.thumbnail(f) for f in _scene(np.arange(30.0))])
    match = video_action.match_frames(gt[::3], gt).reindexed(np.arange(30) * 2)
    again = video_action.FrameMatch.from_json(match.to_json())
    np.testing.assert_allclose(again.gt_index, match.gt_index)
    assert again.ties == match.ties
    with pytest.raises(ValueError):
        video_action.FrameMatch.from_json({**match.to_json(), "ties": []})


# ----------------------------------------------------------------------------------------------
# The match and the agreement work on every frame at once; these references read one frame at a
# time, the way the definitions in docs/metrics.md say it.


def _reference_match(imagined: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, list[list[int]]]:
    """(gt_index, ties) frame by frame: the best GT frame, and the runs of GT frames whose score
    is within TIE_FRACTION of the confidence of it (confidence: best - median score)."""
    gt_index, ties = np.full(len(imagined), np.nan), []
    for f, row in enumerate(imagined @ gt.T):
        best, top = int(row.argmax()), row.max()
        confidence = top - np.median(row)
        if confidence < video_action.MIN_CONFIDENCE or top < video_action.MIN_CORRELATION:
            ties.append([])
            continue
        near = [g for g in range(len(gt)) if row[g] >= top - video_action.TIE_FRACTION * confidence]
        runs = [[g, g] for g in near[:1]]
        for g in near[1:]:
            if g == runs[-1][1] + 1:
                runs[-1][1] = g
            else:
                runs.append([g, g])
        gt_index[f] = next((a + b) / 2 for a, b in runs if a <= best <= b)
        ties.append([i for run in runs for i in run])
    return gt_index, ties


def _reference_agreement(match: video_action.FrameMatch, frame_step: np.ndarray, gt_step_of_index: np.ndarray,
                         joints: video_action.JointTimes) -> tuple[np.ndarray, np.ndarray]:
    """(video step, joints step) frame by frame: each side's tied runs by their middles, and the
    pair nearest to each other (the first such in joint-run, then video-run order)."""
    video, joint = np.full(len(frame_step), np.nan), np.full(len(frame_step), np.nan)
    for f, step in enumerate(frame_step):
        if joints.best_drift[step] <= video_action.JOINT_MATCH_MAX:
            joint[f] = joints.best_index[step] - joints.offset
        if not match.matched[f]:
            continue
        video[f] = np.interp(match.gt_index[f], np.arange(len(gt_step_of_index)), gt_step_of_index)
        if np.isnan(joint[f]):
            continue
        video_runs = [(gt_step_of_index[a] + gt_step_of_index[b]) / 2 for a, b in zip(match.ties[f][::2], match.ties[f][1::2])]
        distance = np.linalg.norm(joints.gt - joints.pred[step], axis=1)
        tied = [g for g in range(len(distance)) if distance[g] <= joints.best_drift[step] + video_action.JOINT_TIE]
        joint_runs: list[list[int]] = []
        for g in tied:
            if joint_runs and g == joint_runs[-1][1] + 1:
                joint_runs[-1][1] = g
            else:
                joint_runs.append([g, g])
        pairs = [(abs(v - ((a + b) / 2 - joints.offset)), v, (a + b) / 2 - joints.offset)
                 for a, b in joint_runs for v in video_runs]
        if pairs:
            _, video[f], joint[f] = min(pairs, key=lambda p: p[0])  # min() keeps the first of equals
    return video, joint


def _there_and_back(n: int) -> np.ndarray:
    """(n,) times of an episode that goes out, holds, comes back and holds: most poses and
    pictures occur twice, and the holds tie with themselves."""
    q = n // 4
    return 120 * np.concatenate([np.linspace(0, 1, q), np.ones(q), np.linspace(1, 0, q), np.zeros(n - 3 * q)])


def test_the_match_of_every_frame_at_once_equals_a_frame_by_frame_one() -> None:
    gt_times = _there_and_back(120)
    gt = video_action.thumbnails(np.stack([video_action.thumbnail_samples(f) for f in _scene(gt_times)]))
    rng = np.random.default_rng(3)
    frames = _scene(np.clip(gt_times[::2] + rng.normal(0, 3, 60), 0, 120)).astype(np.int16)
    frames[40:45] = 128  # flat: no match
    noisy = np.clip(frames + rng.integers(-20, 20, frames.shape), 0, 255).astype(np.uint8)
    imagined = np.stack([video_action.thumbnail(f) for f in noisy])

    match = video_action.match_frames(imagined, gt)
    gt_index, ties = _reference_match(imagined, gt)
    np.testing.assert_array_equal(match.gt_index, gt_index)
    assert match.ties == ties
    assert sum(len(t) >= 4 for t in ties) >= 10  # frames tied with both legs of the episode
    assert not match.matched[40:45].any()


def test_the_agreement_of_every_frame_at_once_equals_a_frame_by_frame_one() -> None:
    gt_times = _there_and_back(160)
    gt_joints = _joints(gt_times)
    gt = video_action.thumbnails(np.stack([video_action.thumbnail_samples(f) for f in _scene(gt_times)]))
    rng = np.random.default_rng(4)
    offset, n = 7, 140
    at = np.clip(offset + np.arange(n) + rng.integers(-3, 4, n), 0, len(gt_times) - 1)
    pred = gt_joints[at] + rng.normal(0, 0.05, (n, 6))
    pred[100:110] += 8.0  # off the GT path: no joints' GT time
    distance = np.linalg.norm(gt_joints[None] - pred[:, None], axis=2)
    joints = video_action.JointTimes(pred, gt_joints, offset, distance.argmin(axis=1), distance.min(axis=1))
    imagined = gt[np.clip(at + rng.integers(-5, 6, n), 0, len(gt) - 1)]
    match = video_action.match_frames(imagined, gt)
    frame_step = np.arange(n)
    gt_step_of_index = np.arange(len(gt), dtype=np.float64) - offset

    va = video_action.agreement("front", match, frame_step, 9, FPS, gt_step_of_index, joints)
    video, joint = _reference_agreement(match, frame_step, gt_step_of_index, joints)
    np.testing.assert_array_equal(va.video_gt_s, video / FPS)
    assert va.joints_gt_s is not None
    np.testing.assert_array_equal(va.joints_gt_s, joint / FPS)
    assert np.isnan(va.joints_gt_s[100:110]).all() and np.isfinite(va.video_gt_s[100:110]).any()
    # both sides ambiguous somewhere: the pairing had more than one pair to choose from
    assert sum(len(t) >= 4 for t in match.ties) >= 10


def test_thumbnails_taken_in_batches_equal_thumbnails_taken_one_by_one() -> None:
    rng = np.random.default_rng(6)
    frames = [rng.integers(0, 255, (72, 96, 3), dtype=np.uint8) for _ in range(10)] + [np.full((72, 96, 3), 9, np.uint8)]
    taken = video_action.Thumbnails()
    taken.BATCH = 4  # three batches and a rest
    for i, f in enumerate(frames):
        taken.add(2 * i, f)
    assert taken.indexes == list(range(0, 22, 2))
    one_by_one = np.stack([video_action.thumbnail(f) for f in frames])
    np.testing.assert_array_equal(taken.stacked(), one_by_one)
    np.testing.assert_allclose(np.linalg.norm(one_by_one[:-1], axis=1), 1.0, rtol=1e-5)
    assert not one_by_one[-1].any()  # one flat colour: all zeros, which matches nothing


@pytest.mark.slow
def test_the_recording_holds_both_gt_times_the_lag_and_the_split(tmp_path: Path) -> None:
    from test_export import Recording, rrd_verify

    from inspector.export import layout as L
    from inspector.export.recording import write_recording

    n_gt = N_STEPS + 30
    times = np.arange(n_gt, dtype=np.float64)
    _write(tmp_path / "s", np.arange(N_STEPS) + 24, _scene(times), _joints(times))
    tl = build_timeline(open_session(tmp_path / "s").rollouts["r"])
    path = write_recording(tl, tmp_path / "r.rrd")
    rrd_verify(path)
    rec = Recording(path)
    va = tl.video_action("front")
    assert va is not None and va.lag_s is not None and va.joints_gt_s is not None
    frames, lag = rec.scalars(L.lag_path("front"), order_by=L.FRAME)
    np.testing.assert_allclose(lag, va.lag_s[frames])
    assert len(lag) == np.isfinite(va.lag_s).sum() > 0
    _, video = rec.scalars(L.gt_time_path("front", "video"), order_by=L.FRAME)
    _, joints = rec.scalars(L.gt_time_path("front", "joints"), order_by=L.FRAME)
    np.testing.assert_allclose(video, va.video_gt_s[np.isfinite(va.video_gt_s)])
    np.testing.assert_allclose(joints, va.joints_gt_s[np.isfinite(va.joints_gt_s)])
    split_frames, _ = rec.scalars(L.gt_time_path("front", "split"), order_by=L.FRAME)
    assert list(split_frames) == [0]  # 0.8 s ahead from the start: parted from chunk 0


@contextlib.contextmanager
def _opened_in_app(session: Path, tag: str = "r") -> Iterator[tuple[Any, Any]]:
    """(app, tab): ``session`` served, its rollout ``tag`` open in a tab with its video metrics done."""
    from test_app import connect, key

    from inspector.app import serve

    app = serve([session], port=0, block=False)
    try:
        client, tab = connect(app)
        with client:
            assert tab.open(key(app, tag))
            assert tab.loaded.frames.done.wait(120)
            yield app, tab
    finally:
        app.stop()


def _wait_for_agreements(tab: Any, views: tuple[str, ...]) -> None:
    """Until the tab's plots have the agreement of ``views`` (they follow the frames' callback)."""
    import time

    deadline = time.monotonic() + 60
    while not all(v in tab.plots.agreements for v in views):
        assert time.monotonic() < deadline, "no agreement after the video metrics"
        time.sleep(0.05)


@pytest.mark.slow
def test_the_app_plots_both_gt_times_marks_the_split_and_reads_the_lag(tmp_path: Path) -> None:
    import re
    import time

    n_gt = N_STEPS + 30
    times = np.arange(n_gt, dtype=np.float64)
    _write(tmp_path / "s", np.arange(N_STEPS) + 24, _scene(times), _joints(times))  # 0.8 s ahead
    with _opened_in_app(tmp_path / "s") as (_, tab):
        deadline = time.monotonic() + 60

        def plotted() -> list[str]:
            plot = tab.plots.agreement_plot
            return [] if plot is None else [s["label"] for s in plot.handle.series]

        # the plot is redrawn after the frames' callback has the view's agreement: wait for the lines
        while "front" not in tab.plots.agreements or "video's GT time, front" not in plotted():
            assert time.monotonic() < deadline, f"no agreement plotted after the video metrics: {plotted()}"
            time.sleep(0.05)
        labels = plotted()
        assert "video's GT time, front" in labels and "joints' GT time" in labels
        assert "front: video and actions part (chunk 0)" in labels
        tab.set_step(40, force=True)
        read = re.search(r"lag front ([+-][\d.]+) s", tab.controls.readout.content)
        assert read is not None and float(read.group(1)) == pytest.approx(0.8, abs=1.0 / FPS)


@pytest.mark.slow
def test_a_frame_match_that_fails_in_the_app_is_named_on_the_plot(tmp_path: Path, monkeypatch) -> None:
    import time

    from test_app import key

    from inspector.analysis.timeline import RolloutTimeline
    from inspector.errors import InspectorError

    times = np.arange(N_STEPS + 30, dtype=np.float64)
    _write(tmp_path / "s", np.arange(N_STEPS), _scene(times), _joints(times))

    def broken(self, view: str, with_ssim: bool = False):
        raise InspectorError(tmp_path / "gt_front.mp4", "frame 77 cannot be decoded")

    monkeypatch.setattr(RolloutTimeline, "video_metrics", broken)  # the fill streams the clips itself
    with _opened_in_app(tmp_path / "s") as (app, tab):
        assert tab.loaded.frames.psnr["front"] is not None  # the frames and the PSNR stand
        plot = tab.plots.agreement_plot
        assert plot is not None
        deadline = time.monotonic() + 60
        while "no frame match" not in plot.handle.title:  # the plots follow the frames' callback
            assert time.monotonic() < deadline, f"the plot does not say the match failed: {plot.handle.title!r}"
            time.sleep(0.05)
        assert "front: no frame match (" in plot.handle.title and "frame 77 cannot be decoded" in plot.handle.title
        tab.open(key(app, "r"))  # built again: it still says so
        assert "frame 77 cannot be decoded" in tab.plots.agreement_plot.handle.title


def test_the_app_shows_frames_before_matching_them_and_matches_only_what_a_tab_shows(tmp_path: Path) -> None:
    """The app's frames come first and the frame match after (the same numbers the report
    computes), and only for a rollout a tab shows."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from inspector.analysis.video_metrics import compare_clips
    from inspector.app._frames import READY, FrameCache, FrameStore

    n_gt = N_STEPS + 30
    times = np.arange(n_gt, dtype=np.float64)
    _write(tmp_path / "s", np.arange(N_STEPS) + 24, _scene(times), _joints(times))
    tl = build_timeline(open_session(tmp_path / "s").rollouts["r"])
    gate = threading.Event()
    stored: list = []

    class GatedMatcher(ThreadPoolExecutor):
        """Runs matches only once the test opens the gate, counting what it was given."""

        submitted: list = []

        def submit(self, fn, /, *args, **kwargs):  # type: ignore[override]
            self.submitted.append(args)
            return super().submit(lambda: (gate.wait(60), fn(*args, **kwargs)))

    decoder, matcher = ThreadPoolExecutor(2), GatedMatcher(1)
    try:
        store = FrameStore(tl, decoder, FrameCache(), stored.append, matcher)
        store.start()
        assert store.decoded.wait(60)
        assert store.status["front"] == READY and store.pair("front", 40).imagined is not None
        assert store.psnr["front"] is not None  # PSNR comes with the frames
        assert not store.done.is_set() and "front" not in tl.known_video_metrics()
        assert matcher.submitted == []  # no tab shows the rollout: nothing to match yet

        changed = threading.Event()
        store.add_listener(changed.set)  # a tab opens it
        assert matcher.submitted == [("front",)]
        assert not store.done.wait(0.5)  # held at the gate: the frames do not wait for it
        gate.set()
        assert store.done.wait(60) and changed.is_set()
        vm = tl.known_video_metrics()["front"]
        assert vm.match is not None and [v.view for v in stored] == ["front"]
        # what the app keeps (and stores in the metrics cache) is what the report computes
        fresh = compare_clips("front", [tl.rollout.video("front")], tl.gt.clips["front"],
                              tl.gt_index_of_frame("front"))[0]
        assert vm.to_json() == fresh.to_json() == stored[0].to_json()
        assert tl.video_action("front").summary()["lag_s_median"] == pytest.approx(0.8, abs=1.0 / FPS)
    finally:
        gate.set()
        decoder.shutdown()
        matcher.shutdown()


def test_the_overview_table_has_a_median_lag_column() -> None:
    from inspector.app._overview_rows import OverviewRow
    from inspector.app._overview_table import Query, select_rows, table_html

    summary = {"tag": "r", "session": "s", "kind": "autoregressive", "prompt": "pick", "episode_index": 0,
               "start_frame": 0, "rmse_deg": None, "per_step_mse": None, "chunk_joints": None, "n_chunks": 3,
               "steps_per_chunk": 9, "episode_length": None, "time_aligned_drift": None, "best_match_drift": None,
               "tempo": None, "ee_error_mm": None, "post_episode_chunks": 0, "limit_violations": {"steps": 0},
               "video_psnr_db": {"front": 18.0},
               "video_action": {"front": {"lag_s_median": 0.8, "lag_s_abs_mean": 0.8, "matched_fraction": 1.0,
                                          "split_chunk": 0, "video_tempo": 1.0, "note": None}}}
    rows = [OverviewRow("s / r", "s", "r", "autoregressive", "pick", Path("/nowhere"), summary, None)]
    html = table_html(rows, select_rows(rows, Query(), {}), {})
    assert ">lag front<" in html and ">+0.80<" in html


@pytest.mark.slow
def test_gt_thumbnails_kept_from_an_earlier_window_match_as_a_fresh_read(monkeypatch, tmp_path: Path) -> None:
    """Single chunks of one episode start at different GT frames; the thumbnails of the episode
    read for the earliest serve the later ones (the tail of its window) with the same match."""
    import os
    import shutil

    from inspector.analysis import video_metrics
    from inspector.demo.generate import DEMO_DIR

    if not (DEMO_DIR / "session.json").is_file():
        pytest.skip("sessions/demo not built (inspector demo --rebuild)")
    shutil.copytree(DEMO_DIR, tmp_path / "demo")
    session = open_session(tmp_path / "demo")

    def metrics(tag: str) -> video_metrics.VideoMetrics:
        return build_timeline(session.rollouts[tag]).video_metrics("front")

    kept = video_metrics.GtThumbnailCache()
    served: list[bool] = []
    get = kept.get
    monkeypatch.setattr(kept, "get", lambda reader: served.append(get(reader) is not None) or get(reader))
    monkeypatch.setattr(video_metrics, "GT_THUMBNAILS", video_metrics.GtThumbnailCache())
    fresh = metrics("single_f076")
    monkeypatch.setattr(video_metrics, "GT_THUMBNAILS", kept)
    assert metrics("single_f000").to_json()["match"] is not None and served == [False]
    again = metrics("single_f076")
    assert served == [False, True]  # the tail of frame 0's window: nothing decoded past the pairing
    assert again.to_json() == fresh.to_json()
    assert fresh.match is not None and fresh.match.matched.any()

    gt_clip = build_timeline(session.rollouts["single_f076"]).gt.clips["front"].path
    os.utime(gt_clip, ns=(0, 0))  # the GT video rewritten: what was kept is not its thumbnails
    assert metrics("single_f076").to_json() == fresh.to_json() and served[-1] is False


# ----------------------------------------------------------------------------------------------
# A frozen video: it stands still while the joints move, so its lag is no lag.


# The demo rollouts the frozen-video tests look at: prompt_train (whose joints and moving video the
# planted rollouts start from: the negative control nearest to them), bias_elbow (joints off the GT
# path) and single_f384 (no frame matches). That no rollout of the whole demo is frozen is checked
# on the demo's own report (tests/test_sanity.py).
FROZEN_DEMO_TAGS = ("prompt_train", "bias_elbow", "single_f384")
# Frames of the frozen video's noise and wobble (degrade()'s wobble, round(2 sin(i / 7)) pixels,
# repeats after about 44 frames): two wobbles, 3 s at 30 fps.
FROZEN_CYCLE = 88


@pytest.fixture(scope="module")
def demo_frozen(tmp_path_factory) -> Path:
    """A copy of the demo session (its GT dataset and :data:`FROZEN_DEMO_TAGS`) with two more
    rollouts of prompt_train's joints: ``frozen``, its imagined video frozen on its mid-episode
    frame (with the demo's noise and wobble of an imagined frame over it), and ``paused``, its
    video held for 5 s mid-way."""
    import shutil

    from inspector.data.video import VideoClip, encode_h264
    from inspector.demo.generate import DEMO_DIR, degrade

    if not (DEMO_DIR / "session.json").is_file():
        pytest.skip("sessions/demo not built (inspector demo --rebuild)")
    root = tmp_path_factory.mktemp("frozen") / "demo"
    shutil.copytree(DEMO_DIR, root, ignore=lambda folder, names: [
        n for n in names if Path(folder) == DEMO_DIR / "rollouts" and n not in FROZEN_DEMO_TAGS])
    rollouts, rng = root / "rollouts", np.random.default_rng(0)
    for tag in ("frozen", "paused"):
        shutil.copytree(rollouts / "prompt_train", rollouts / tag)
        for clip in sorted((rollouts / tag / "video").glob("*.mp4")):
            frames = np.stack([rgb for _, rgb in VideoClip(clip).iter_frames()])
            mid = len(frames) // 2
            if tag == "frozen":  # a cycle of the wobble, degraded once and played over and over:
                # degrade() is most of this fixture's time, and each frame still differs from the next
                cycle = degrade(np.repeat(frames[mid][None], FROZEN_CYCLE, axis=0), rng)
                frames = cycle[np.arange(len(frames)) % FROZEN_CYCLE]
            else:
                frames[mid:mid + 150] = frames[mid]
            encode_h264(clip, frames, 30.0, preset="ultrafast")  # a fifth of medium's time, and no smoother
    assert sorted(p.name for p in rollouts.iterdir()) == sorted([*FROZEN_DEMO_TAGS, "frozen", "paused"])
    return root


@pytest.fixture(scope="module")
def frozen_report(demo_frozen: Path, tmp_path_factory) -> tuple[dict, str]:
    """(the JSON report, its HTML page) of ``demo_frozen``, computed once for the tests that read it."""
    page = tmp_path_factory.mktemp("frozen-report") / "report.html"
    out = _report([demo_frozen], "--json", "--html", str(page))
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout), page.read_text()


def _report(paths: list[Path], *flags: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "inspector", "report", *map(str, paths), "--no-cache", "--jobs", "1", *flags],
                          capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_a_frozen_video_is_called_frozen_and_has_no_lag(frozen_report: tuple[dict, str]) -> None:
    report, page = frozen_report
    rows = {r["tag"]: r for r in report["rollouts"]}
    assert set(rows) == {*FROZEN_DEMO_TAGS, "frozen", "paused"}
    for view in ("front", "wrist"):
        frozen = rows["frozen"]["video_action"][view]
        assert frozen["matched_fraction"] > 0.9  # every frame matches the one it shows...
        assert frozen["frozen"] is True  # ...but the video stands still while the joints move
        assert frozen["lag_s_median"] is None and frozen["lag_s_abs_mean"] is None and frozen["split_chunk"] is None
        assert frozen["note"].startswith("frozen:")
        # a video that pauses for 5 s of 15 still follows its joints
        paused = rows["paused"]["video_action"][view]
        assert paused["frozen"] is False and abs(paused["lag_s_median"]) < 0.15
        for tag, row in rows.items():
            if tag != "frozen":  # nor is any other (single chunks: too short to tell)
                assert row["video_action"][view]["frozen"] is not True, (tag, view)
    # the page's lag cells say so, not a number
    row = re.search(r'<tr data-key="\d+"><td class=t>frozen</td>((?:(?!</tr>).)*)</tr>', page, re.S)
    assert row is not None and row.group(1).count(">frozen</td>") == 2, "the frozen rollout's lag cells"


@pytest.mark.slow
def test_the_text_report_and_the_overview_say_frozen_and_no_match(frozen_report: tuple[dict, str]) -> None:
    from inspector.app._overview_rows import OverviewRow
    from inspector.app._overview_table import Query, select_rows, table_html
    from inspector.report.build import format_report

    lines: dict[str, str] = {}
    text = format_report(frozen_report[0])  # what report prints without --json
    for line in text.splitlines():  # each rollout's first line: the drift table's (the sanity table follows)
        if line.strip():
            lines.setdefault(line.split()[0], line)
    assert lines["frozen"].count(" frozen") == 2  # the two lag columns
    assert lines["single_f384"].count("no match") == 2  # no frame of either view matches

    def row(tag: str, entry: dict[str, Any]) -> OverviewRow:
        summary = {"tag": tag, "session": "s", "kind": "autoregressive", "prompt": "pick", "episode_index": 0,
                   "start_frame": 0, "rmse_deg": None, "per_step_mse": None, "chunk_joints": None, "n_chunks": 3,
                   "steps_per_chunk": 9, "episode_length": None, "time_aligned_drift": None, "best_match_drift": None,
                   "tempo": None, "ee_error_mm": None, "post_episode_chunks": 0, "limit_violations": {"steps": 0},
                   "video_psnr_db": {"front": 18.0}, "video_action": {"front": entry}}
        return OverviewRow(f"s / {tag}", "s", tag, "autoregressive", "pick", Path("/nowhere"), summary, None)

    frozen = {"lag_s_median": None, "lag_s_abs_mean": None, "matched_fraction": 1.0, "split_chunk": None,
              "video_tempo": 0.0, "frozen": True, "note": "frozen: the video stands still"}
    unmatched = {"lag_s_median": None, "lag_s_abs_mean": None, "matched_fraction": 0.0, "split_chunk": None,
                 "video_tempo": None, "frozen": None, "note": "no match: no imagined frame resembles one GT frame"}
    rows = [row("a", frozen), row("b", unmatched)]
    html = table_html(rows, select_rows(rows, Query(), {}), {})
    assert ">frozen<" in html and ">no match<" in html


@pytest.mark.slow
def test_the_recording_says_the_video_is_frozen_and_logs_no_lag(demo_frozen: Path, tmp_path: Path) -> None:
    from test_export import Recording, rrd_verify

    from inspector.export import layout as L
    from inspector.export.recording import write_recording

    tl = build_timeline(open_session(demo_frozen).rollouts["frozen"])
    path = write_recording(tl, tmp_path / "frozen.rrd")
    rrd_verify(path)
    rec = Recording(path)
    text = rec.static(L.DESCRIPTION, "TextDocument:text")[0][0]
    assert "| median video-action lag, front (video - joints GT time) | frozen: " in text
    for view in ("front", "wrist"):
        assert len(rec.scalars(L.lag_path(view), order_by=L.FRAME)[0]) == 0  # no lag drawn
        assert len(rec.scalars(L.gt_time_path(view, "video"), order_by=L.FRAME)[0]) > 400  # the still video's GT time
    _, events = rec.temporal(L.EVENTS, "TextLog:text")
    assert any(e[0].startswith("front: frozen: the video stands still") for e in events)


@pytest.mark.slow
def test_frames_without_a_lag_read_no_match_in_the_recording(tmp_path: Path) -> None:
    """bias_elbow's joints leave the GT path (more than JOINT_MATCH_MAX from every GT pose): its
    frames there have no lag; the recording marks them "no match" instead of leaving a gap."""
    from test_export import Recording

    from inspector.demo.generate import DEMO_DIR
    from inspector.export import layout as L
    from inspector.export.recording import write_recording

    if not (DEMO_DIR / "session.json").is_file():
        pytest.skip("sessions/demo not built (inspector demo --rebuild)")
    tl = build_timeline(open_session(DEMO_DIR).rollouts["bias_elbow"])
    va = tl.video_action("front")
    assert va is not None and va.lag_s is not None
    rec = Recording(write_recording(tl, tmp_path / "bias.rrd"))
    frames, _ = rec.scalars(L.gt_time_path("front", "no_match"), order_by=L.FRAME)
    np.testing.assert_array_equal(frames, np.flatnonzero(~np.isfinite(va.lag_s)))
    assert len(frames) > 100
    assert "front: no match (no lag)" in rec.static(L.gt_time_path("front", "no_match"), "SeriesPoints:names")[0]
    assert "nan" not in rec.static(L.DESCRIPTION, "TextDocument:text")[0][0]


@pytest.mark.slow
def test_the_app_reads_frozen_and_no_match_never_nan(demo_frozen: Path) -> None:
    from test_app import key

    with _opened_in_app(demo_frozen, "bias_elbow") as (app, tab):
        _wait_for_agreements(tab, ("front", "wrist"))
        # chunk 21: the elbow's bias has taken the joints off the GT path
        tab.set_step(21 * 9, force=True)
        readout = tab.controls.readout.content
        assert "nan" not in readout and "front: no match" in readout, readout
        assert "front: no match at " in tab.plots.agreement_plot.handle.title
        tab.open(key(app, "frozen"))
        assert tab.loaded.frames.done.wait(120)
        _wait_for_agreements(tab, ("front", "wrist"))
        tab.set_step(40, force=True)
        readout = tab.controls.readout.content
        assert "front: video frozen" in readout and "wrist: video frozen" in readout, readout
        assert not re.search(r"lag (front|wrist)", readout)
        assert "front: video frozen, no lag" in tab.plots.agreement_plot.handle.title
