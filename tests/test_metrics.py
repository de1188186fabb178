"""Metrics against known answers: the seed report's metas and synthetic paths with planted faults."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from inspector.analysis import metrics
from inspector.analysis.timeline import build_timeline
from inspector.data.session import SessionWriter, open_session
from inspector.robot.kinematics import kinematics
from inspector.units import Units


def _smooth_path(n: int, seed: int = 0) -> np.ndarray:
    """(n, 6) a smooth, non-repeating joint path in degrees / gripper 0..100."""
    t = np.linspace(0, 1, n)[:, None]
    rng = np.random.default_rng(seed)
    amp = rng.uniform(20, 40, 6)
    return np.array([0, -60, 60, 40, 0, 30]) + amp * np.sin(np.pi * t * rng.uniform(0.6, 0.9, 6) + rng.uniform(0, 0.5, 6))


def _timeline(tmp_path, pred_executed: np.ndarray, gt: np.ndarray, horizon: int = 24, executed: int = 9):
    n_chunks = len(pred_executed) // executed
    chunks = np.zeros((n_chunks, horizon, 6))
    for k in range(n_chunks):
        idx = np.minimum(k * executed + np.arange(horizon), len(pred_executed) - 1)
        chunks[k] = pred_executed[idx]
    with SessionWriter.create(tmp_path / "s") as w:
        w.add_rollout("r", kind="autoregressive", actions=chunks, gt_actions=gt, executed_per_chunk=executed)
    return build_timeline(open_session(tmp_path / "s").rollouts["r"])


def test_reference_chunk_metrics_reproduce_the_metas_exactly(imported_session):
    s = open_session(imported_session)
    checked = 0
    for tag in ["f000", "f084", "f169", "train_ep0"]:
        r = s.rollouts[tag]
        ref = r.extra["reference_metrics"]
        ce = build_timeline(r).chunk_errors
        assert ce.rmse == pytest.approx(ref["action_rmse_deg"], abs=1e-6)
        np.testing.assert_allclose(ce.per_joint_rmse, ref["per_joint_rmse"], atol=1e-6)
        np.testing.assert_allclose(ce.per_step_mse, ref["per_step_mse"], atol=1e-6)
        checked += 1
    assert checked == 4


def test_video_psnr_front_f084_matches_meta(imported_session):
    r = open_session(imported_session).rollouts["f084"]
    psnr = build_timeline(r).video_metrics("front").mean_psnr_db
    assert psnr == pytest.approx(r.extra["reference_metrics"]["video_psnr_db"], abs=0.3)


@pytest.mark.slow
def test_frames_shown_while_comparing_do_not_change_the_psnr(imported_session):
    """The app compares a view while it caches the frames it shows (``on_imagined``/``on_gt``),
    reusing the GT frame scaled for display: the PSNR is the one computed without them, and
    each GT frame shown is the clip's frame scaled to the imagined size."""
    from inspector.analysis.video_metrics import compare_clips, resizes_whole_frame

    tl = build_timeline(open_session(imported_session).rollouts["ep000_train"])
    imagined, gt = tl.rollout.video("front"), tl.gt.clips["front"]
    size = imagined.info().width, imagined.info().height
    assert (gt.info().width, gt.info().height) != size  # the GT is scaled: the costly path
    whole_frame = resizes_whole_frame(tl.rollout.extra)  # 640x480 squashed to 320x176, as the model saw it
    assert whole_frame
    shown_gt: dict[int, np.ndarray] = {}
    with_frames = compare_clips("front", [imagined], gt, tl.gt_index_of_frame("front"),
                                on_imagined=lambda b, f, rgb: None,
                                on_gt=lambda i, rgb: shown_gt.setdefault(i, rgb.copy()), whole_frame=whole_frame)[0]
    alone = compare_clips("front", [imagined], gt, tl.gt_index_of_frame("front"), whole_frame=whole_frame)[0]
    np.testing.assert_array_equal(with_frames.psnr_db, alone.psnr_db)
    assert np.isfinite(alone.psnr_db).sum() > 100
    for i, rgb in gt.iter_frames(size):
        if i in (0, 150, len(shown_gt) - 1):
            np.testing.assert_array_equal(shown_gt[i], rgb)


def test_mosaic_sample_front_psnr_and_the_sources_figure(imported_session):
    """``demo/train_ep0``: ``gt_future.mp4`` is the front camera alone, so the front view has GT
    (PSNR ~18 dB, not the 4.5-10 dB of a GT cut as a mosaic) and top / gripper have none. The
    meta's ``video_psnr_db`` (~4.8 dB, the whole mosaic against the front view) is shown as the
    source's figure with its note, on the app's card and in the recording's description."""
    from inspector.app._cards import headline_metrics
    from inspector.export.description import describe

    r = open_session(imported_session).rollouts["train_ep0"]
    tl = build_timeline(r)
    assert tl.gt.views == ["front"]
    front = tl.video_metrics("front").mean_psnr_db
    assert 17.0 < front < 19.0, front
    source = r.extra["reference_metrics"]["video_psnr_db"]
    assert source == pytest.approx(4.81, abs=0.01)
    note = r.extra["reference_notes"]["video_psnr_db"]
    assert "mosaic" in note and "front camera alone" in note and "\n" not in note
    rows = dict(headline_metrics(tl))
    assert "video_psnr_db" not in rows["reported by the evaluation"]  # not among the plain figures
    assert rows["source's video_psnr_db"] == f"{source:.2f}: {note}"
    text = describe(tl, {"front": front, "top": None, "gripper": None})
    assert f"| video_psnr_db (as reported by the source) | 4.8 ({note}) |" in text
    assert "| mean video PSNR, front | " + f"{front:.1f} dB |" in text
    # a sample with per-view GT files has no such note: its meta compared one view with its GT
    assert "reference_notes" not in open_session(imported_session).rollouts["f084"].extra


def test_raw_60_chunk_rollouts_leave_the_joint_limits(imported_session):
    s = open_session(imported_session)
    for tag in ["ep000_train", "ep000_novel"]:
        tl = build_timeline(s.rollouts[tag])
        by_joint = tl.limit_violation.sum(axis=0)
        assert by_joint.sum() > 0
        assert by_joint[5] > 0  # the gripper goes far below 0 (about -115)
        assert tl.pred.min() < -100 and not tl.has_gt_joints


def test_tempo_mismatch_is_speed_not_path(tmp_path):
    gt = _smooth_path(600)
    t = np.arange(540)
    slow = np.stack([np.interp(0.8 * t, np.arange(600), gt[:, j]) for j in range(6)], axis=1)
    tl = _timeline(tmp_path, slow, gt)
    assert tl.best_match_drift.mean() < 0.5
    assert tl.time_aligned_drift.mean() > 10 * tl.best_match_drift.mean()
    assert tl.tempo == pytest.approx(0.8, abs=0.05)
    assert tl.speed_mismatch.mean() > tl.path_error.mean()


def test_constant_bias_gives_both_drifts_about_b(tmp_path):
    gt = _smooth_path(600)
    biased = gt[:540].copy()
    biased[:, 2] += 5.0
    tl = _timeline(tmp_path, biased, gt)
    assert np.median(tl.time_aligned_drift) == pytest.approx(5.0, abs=1e-6)
    assert np.median(tl.best_match_drift) == pytest.approx(5.0, abs=0.5)
    assert tl.tempo == pytest.approx(1.0, abs=0.05)


def test_reverse_order_is_penalised_by_dtw_not_best_match():
    gt = _smooth_path(300)
    forward_drift, forward_cost = metrics.dtw(gt, gt)
    reverse = gt[::-1]
    bm, _ = metrics.best_match(reverse, gt)
    reverse_drift, reverse_cost = metrics.dtw(reverse, gt)
    assert bm.max() < 1e-9  # every pose is on the path
    assert forward_cost < 1e-9 and reverse_cost > 10.0
    assert reverse_drift.mean() > 10.0


@pytest.mark.parametrize("by", ["search", "tree"])
@pytest.mark.parametrize("seed", range(40))
def test_nearest_poses_is_the_exhaustive_search(seed, by, monkeypatch):
    """Distances exactly as ``sqrt(sum((p - g)^2))`` gives them for the nearest GT pose, as a
    KD-tree answers them; the index: the nearest pose, and among poses tied at that distance
    (held and revisited poses, whole-degree values) the one nearest in time to ``near``. By the
    search (small blocks, so that it runs over several) and by the tree that large batches use."""
    from scipy.spatial import cKDTree

    monkeypatch.setattr(metrics, "KDTREE_PAIRS", 0 if by == "tree" else 1 << 62)
    rng = np.random.default_rng(seed)
    g = rng.normal(scale=rng.choice([1.0, 50.0, 1e6]), size=(int(rng.integers(1, 300)), 6))
    if seed % 3 == 0:  # holds: every pose ten times, and the first ones again at the end
        g = np.concatenate([np.repeat(g[:max(1, len(g) // 10)], 10, axis=0), g[:3]])
    if seed % 4 == 0:
        g = np.round(g)
    n = int(rng.integers(1, 400))
    p = np.concatenate([g[rng.integers(0, len(g), n // 2)], rng.normal(scale=50, size=(n - n // 2, 6))])
    if seed % 5 == 0:
        p = np.round(p)
    near = rng.integers(0, len(g), len(p))
    old_block, metrics.NEAREST_BLOCK = metrics.NEAREST_BLOCK, 64 * len(g)
    try:
        dist, index = metrics.nearest_poses(p, g, near)
    finally:
        metrics.NEAREST_BLOCK = old_block
    squared = np.square(p[:, None, :] - g[None, :, :]).sum(axis=-1)  # (N, G), exactly as the function sums
    assert np.array_equal(dist, np.sqrt(squared.min(axis=1)))
    assert np.array_equal(dist, cKDTree(g).query(p, k=1)[0])
    for row, (i, tied) in enumerate(zip(index, squared == squared.min(axis=1, keepdims=True))):
        candidates = np.flatnonzero(tied)
        assert i == candidates[np.argmin(np.abs(candidates - near[row]))]


def test_a_pose_the_episode_holds_at_its_start_and_end_matches_the_one_nearest_in_time():
    """The rest pose at the start and at the end of an episode: the rollout's first steps at rest
    match the start's hold, its last steps the end's (each by its middle)."""
    rest, path = np.array([0.0, -90, 90, 60, 0, 5]), _smooth_path(200)
    gt = np.concatenate([np.repeat(rest[None], 20, axis=0), path, np.repeat(rest[None], 20, axis=0)])
    pred = gt + 0.5  # the same course, a little off: the two holds are equally near
    drift, index = metrics.best_match(pred, gt)
    assert np.all(drift <= np.sqrt(6 * 0.25) + 1e-12)  # (on the path, a neighbouring frame may be nearer)
    assert list(index[:20]) == [9] * 20 and list(index[-20:]) == [229] * 20
    assert metrics.tempo(index) == pytest.approx(1.0, abs=0.05)  # (the holds count by their middles)
    # a rollout that starts 100 frames into the episode: "in time" counts from there
    _, late = metrics.best_match(pred[-20:], gt, offset=len(gt) - 20)
    assert list(late) == [229] * 20


def _reference_dtw(pred, gt):
    """Textbook open-end DTW with a Python double loop: total cost, path length, per-sample mean
    cost. The path starts at both starts and ends at the cheapest cell of the last row."""
    T, G = len(pred), len(gt)
    c = np.linalg.norm(pred[:, None] - gt[None], axis=-1)
    D = np.full((T + 1, G + 1), np.inf)
    D[0, 0] = 0
    for i in range(1, T + 1):
        for j in range(1, G + 1):
            D[i, j] = c[i - 1, j - 1] + min(D[i - 1, j - 1], D[i - 1, j], D[i, j - 1])
    end = 1 + int(np.argmin(D[T, 1:]))
    i, j, cells = T, end, []
    while (i, j) != (0, 0):
        cells.append((i - 1, j - 1))
        steps = {(i - 1, j - 1): D[i - 1, j - 1], (i - 1, j): D[i - 1, j], (i, j - 1): D[i, j - 1]}
        i, j = min(steps, key=steps.get)
    drift = np.zeros(T)
    count = np.zeros(T)
    for a, b in cells:
        drift[a] += c[a, b]
        count[a] += 1
    return D[T, end], len(cells), drift / count


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dtw_matches_textbook_dynamic_programming(seed):
    rng = np.random.default_rng(seed)
    pred = rng.normal(size=(25, 6)).cumsum(axis=0)
    gt = rng.normal(size=(31, 6)).cumsum(axis=0)
    total, length, drift = _reference_dtw(pred, gt)
    ours_drift, ours_cost = metrics.dtw(pred, gt)
    assert ours_cost == pytest.approx(total / length, rel=1e-5)
    np.testing.assert_allclose(ours_drift, drift, rtol=1e-5)


@pytest.mark.parametrize("T, G", [(1, 1), (1, 9), (9, 1), (2, 9), (9, 2)])
def test_dtw_paths_along_the_tables_edges_match_the_textbook(T, G):
    """One-step predictions or one-frame episodes: the path runs along the table's first row or
    column, where only one move stays inside it."""
    rng = np.random.default_rng(T * 10 + G)
    pred, gt = rng.normal(size=(T, 6)).cumsum(axis=0), rng.normal(size=(G, 6)).cumsum(axis=0)
    total, length, drift = _reference_dtw(pred, gt)
    ours_drift, ours_cost = metrics.dtw(pred, gt)
    assert ours_cost == pytest.approx(total / length, rel=1e-5)
    np.testing.assert_allclose(ours_drift, drift, rtol=1e-5)


def test_dtw_charges_a_prediction_that_covers_part_of_the_episode_nothing_for_the_rest():
    """A slow rollout (or a single chunk) follows the first part of the GT path exactly: its
    alignment ends where it ends, not at the episode's last frame."""
    gt = _smooth_path(300)
    for part in (gt[:240], gt[:24]):
        drift, cost = metrics.dtw(part, gt)
        assert drift.max() < 1e-6 and cost < 1e-6
    slow = gt[np.minimum(np.arange(300) * 0.8, 299).astype(int)]  # 0.8x: 240 frames of the path
    drift, _ = metrics.dtw(slow, gt)
    assert drift.max() < 1e-6  # anchored at both ends, its last step took on the last 60 frames


def test_dtw_batched_equals_single():
    gt = _smooth_path(80)
    preds = np.stack([gt + 1.0, gt[::-1], gt * 1.1])
    d_batch, c_batch = metrics.dtw(preds, gt)
    for i in range(3):
        d, c = metrics.dtw(preds[i], gt)
        np.testing.assert_allclose(d_batch[i], d)
        assert c_batch[i] == pytest.approx(c)


def test_ee_error_of_pure_wrist_roll_offset_is_what_fk_predicts(tmp_path):
    gt = _smooth_path(600)
    pred = gt[:540].copy()
    pred[:, 4] += 20.0
    tl = _timeline(tmp_path, pred, gt)
    fk = kinematics()
    expected = np.linalg.norm(fk.gripper_positions(pred, Units()) - fk.gripper_positions(gt[:540], Units()), axis=1) * 1000
    np.testing.assert_allclose(tl.ee_error_mm, expected, atol=1e-9)
    assert 0 < tl.ee_error_mm.max() < 20  # the tool point sits close to the roll axis


def test_post_episode_samples_are_marked(tmp_path):
    gt = _smooth_path(300)
    pred = np.concatenate([gt, np.repeat(gt[-1:], 240, axis=0)])
    tl = _timeline(tmp_path, pred, gt)
    assert tl.post_episode.sum() == 240 and tl.episode_end_step == 300
    assert tl.time_aligned_drift[300:].max() < 1e-9  # clamped to the last GT frame


def test_prompt_divergence_finds_the_collapse():
    base = _smooth_path(540)
    other = base.copy()
    other[:18] += 15.0  # apart for two chunks of 9 steps, then the same path
    _, per_chunk, collapse = metrics.prompt_divergence(base, other, 9)
    assert per_chunk[:2].min() > 10 and per_chunk[2:].max() == 0 and collapse == 2


def test_limit_violations_per_joint():
    limits = np.array([[-10, 10]] * 6, dtype=float)
    v = np.zeros((4, 6))
    v[1, 5] = -115
    v[2, 1] = 11
    assert metrics.limit_violations(v, limits).sum(axis=0).tolist() == [0, 1, 0, 0, 0, 1]


def test_psnr_and_ssim_identical_and_noisy():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 255, size=(3, 40, 50, 3), dtype=np.uint8)
    assert metrics.ssim(a, a) == pytest.approx([1, 1, 1])
    noisy = np.clip(a.astype(int) + rng.normal(0, 10, a.shape), 0, 255).astype(np.uint8)
    p = metrics.psnr(a, noisy)
    assert np.all((p > 25) & (p < 30))
    noisier = np.clip(a.astype(int) + rng.normal(0, 60, a.shape), 0, 255).astype(np.uint8)
    s_low, s_high = metrics.ssim(a, noisy), metrics.ssim(a, noisier)
    assert np.all(s_low < 1.0) and np.all(s_high < s_low - 0.1)


def test_aggregate():
    agg = metrics.aggregate([3.0, 1.0, 2.0, np.nan])
    assert agg == {"n": 3, "mean": 2.0, "median": 2.0, "best": 1.0, "worst": 3.0}


@pytest.mark.slow
def test_report_json_on_fixtures(dreamzero_dir):
    out = subprocess.run([sys.executable, "-m", "inspector", "report", str(dreamzero_dir), "--json"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    rows = {r["tag"]: r for r in report["rollouts"]}
    assert rows["f084"]["rmse_deg"] == pytest.approx(1.5735122747236143, abs=1e-6)
    assert rows["ep000_train"]["time_aligned_drift"] is None  # no GT joints stored with it
    assert rows["ep000_train"]["limit_violations"]["count"] > 0
    assert rows["ep000_train"]["post_episode_chunks"] == 23  # 540 steps on a 328-frame episode
    assert set(rows["ep000_train"]["video_psnr_db"]) == {"front", "gripper", "top"}
    assert report["aggregate"]["n"] == 6 and report["aggregate"]["best_rmse_deg"] == pytest.approx(0.5694685, abs=1e-6)
    for key in ["tag", "kind", "prompt", "episode_index", "rmse_deg", "per_joint_rmse", "per_step_mse",
                "time_aligned_drift", "best_match_drift", "dtw_drift", "tempo", "ee_error_mm",
                "limit_violations", "video_psnr_db", "post_episode_chunks"]:
        assert key in rows["f084"]


def test_sweep_equals_per_rollout_timelines(tmp_path):
    from inspector.analysis.sweep import sweep_metrics

    gt = _smooth_path(400)
    t = np.arange(360)
    preds = [np.stack([np.interp(s * t, np.arange(400), gt[:, j]) for j in range(6)], axis=1) for s in (0.8, 1.0, 1.1)]
    preds[1] = preds[1] + np.array([0, 0, 3.0, 0, 0, 0])
    timelines = [_timeline(tmp_path / str(i), p, gt) for i, p in enumerate(preds)]
    sweep = sweep_metrics(np.stack([tl.chunks for tl in timelines]), gt)
    for i, tl in enumerate(timelines):
        np.testing.assert_allclose(sweep.time_aligned_drift[i], tl.time_aligned_drift)
        np.testing.assert_allclose(sweep.best_match_drift[i], tl.best_match_drift)
        np.testing.assert_allclose(sweep.dtw_drift[i], tl.dtw_drift, rtol=1e-6)
        np.testing.assert_allclose(sweep.ee_error_mm[i], tl.ee_error_mm, atol=1e-3)  # float32 FK in sweeps
        np.testing.assert_allclose(sweep.chunk_rmse[i], tl.chunk_rmse)
        assert sweep.tempo[i] == pytest.approx(tl.tempo)
        assert sweep.rmse[i] == pytest.approx(tl.chunk_errors.rmse)
        assert sweep.limit_violations[i].tolist() == tl.limit_violation.sum(axis=0).tolist()
