"""The imagined gripper tracked through its video against the projected predicted gripper: the
tracker, the track comparisons (against scipy and a plain DTW), and the demo's planted fault
(``video_ahead_1s``) against its clean twin (``prompt_train``) in ``report --json``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import directed_hausdorff

from inspector.analysis.gripper_track import (
    MIN_CONFIDENCE,
    GripperTracker,
    _ncc,
    compare_tracks,
    dtw_distance,
    gripper_pixels,
    hausdorff,
)
from inspector.data.lerobot_dataset import open_dataset

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"


def _plain_dtw(a: np.ndarray, b: np.ndarray) -> float:
    D = np.full((len(a) + 1, len(b) + 1), np.inf)
    D[0, 0] = 0.0
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            D[i, j] = np.linalg.norm(a[i - 1] - b[j - 1]) + min(D[i - 1, j], D[i, j - 1], D[i - 1, j - 1])
    return float(D[-1, -1] / max(len(a), len(b)))


@pytest.mark.parametrize("seed", range(4))
def test_track_distances_match_scipy_and_a_plain_dtw(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(int(rng.integers(3, 40)), 2)) * 20
    b = rng.normal(size=(int(rng.integers(3, 40)), 2)) * 20
    assert hausdorff(a, b) == pytest.approx(max(directed_hausdorff(a, b)[0], directed_hausdorff(b, a)[0]))
    assert dtw_distance(a, b) == pytest.approx(_plain_dtw(a, b))


def test_normalised_cross_correlation_is_the_pearson_correlation_of_each_patch():
    rng = np.random.default_rng(1)
    window = (rng.random((30, 34, 3)) * 255).astype(np.float32)
    template = window[9:18, 12:21].copy()
    scores = _ncc(window.transpose(2, 0, 1), template.transpose(2, 0, 1))  # channels first
    for i, j in [(0, 0), (9, 12), (21, 25), (4, 17)]:
        patch = window[i:i + 9, j:j + 9].ravel()
        assert scores[i, j] == pytest.approx(np.corrcoef(patch, template.ravel())[0, 1], abs=1e-5)
    assert np.unravel_index(scores.argmax(), scores.shape) == (9, 12)


def _gt_frames(n: int) -> np.ndarray:
    clip = open_dataset(DEMO / "dataset").episode(0).video("front")
    frames = []
    for _, rgb in clip.iter_frames():
        frames.append(rgb)
        if len(frames) == n:
            break
    return np.stack(frames)


def test_a_track_is_lost_for_good_where_the_frames_stop_matching():
    frames = _gt_frames(20)
    noise = np.random.default_rng(0).integers(0, 256, frames[10:].shape, dtype=np.uint8)
    frames[10:] = noise  # from frame 10 the scene is gone: nothing there matches the gripper
    tracker = GripperTracker((160.0, 120.0), (frames.shape[2], frames.shape[1]))
    for rgb in frames:
        tracker.add(rgb)
    track, confidence = tracker.result(), tracker.confidence()
    assert np.isfinite(track[:10]).all() and np.isnan(track[10:]).all()
    assert (confidence[1:10] >= MIN_CONFIDENCE).all()
    # the projected point sits right on the lost track's last place: still no small distance
    projected = np.nan_to_num(track, nan=0.0)
    projected[10:] = track[9]
    record = gripper_pixels(track, projected, np.arange(20) // 5, 4)
    assert record["lost_from_chunk"] == 2
    assert record["per_chunk"][:2] == [0.0, 0.0] and record["per_chunk"][2:] == [None, None]
    assert record["frames_tracked"] == 10
    assert np.isnan(compare_tracks(track, projected).distance[10:]).all()


def test_a_still_scene_is_tracked_in_place():
    frames = np.repeat(_gt_frames(1), 8, axis=0)
    tracker = GripperTracker((150.0, 110.0), (frames.shape[2], frames.shape[1]))
    for rgb in frames:
        tracker.add(rgb)
    np.testing.assert_allclose(tracker.result(), np.tile([150.0, 110.0], (8, 1)), atol=0.51)


def test_a_start_outside_the_image_is_lost_from_the_first_frame():
    frames = _gt_frames(3)
    tracker = GripperTracker((-40.0, 110.0), (frames.shape[2], frames.shape[1]))
    for rgb in frames:
        tracker.add(rgb)
    record = gripper_pixels(tracker.result(), np.zeros((3, 2)), np.zeros(3, np.int64), 1)
    assert record["median"] is None and record["lost_from_chunk"] == 0 and record["note"]


@pytest.fixture(scope="module")
def demo_rows(tmp_path_factory) -> dict[str, dict]:
    rollouts = [str(DEMO / "rollouts" / tag) for tag in ("prompt_train", "video_ahead_1s")]
    env = {**os.environ, "INSPECTOR_CACHE_DIR": str(tmp_path_factory.mktemp("cache"))}
    done = subprocess.run([sys.executable, "-m", "inspector", "report", *rollouts, "--json", "--no-cache", "-j", "1"],
                          capture_output=True, text=True, env=env, timeout=600, check=True)

    def strict(name: str) -> None:
        raise ValueError(f"{name} in strict JSON")
    return {r["tag"]: r for r in json.loads(done.stdout, parse_constant=strict)["rollouts"]}


@pytest.mark.slow
def test_a_video_ahead_of_its_joints_puts_its_gripper_far_from_theirs(demo_rows):
    clean, ahead = demo_rows["prompt_train"]["gripper_px"]["front"], demo_rows["video_ahead_1s"]["gripper_px"]["front"]
    print(f"front gripper_px median: prompt_train {clean['median']} px, video_ahead_1s {ahead['median']} px; "
          f"dtw {clean['dtw']} / {ahead['dtw']}")
    assert clean["lost_from_chunk"] is None and ahead["lost_from_chunk"] is None
    assert clean["median"] < 8.0  # the clean video's gripper is where its joints put it
    assert ahead["median"] > 3 * clean["median"]
    assert ahead["dtw"] > 1.5 * clean["dtw"]
    assert len(clean["per_chunk"]) == demo_rows["prompt_train"]["n_chunks"]
    # the first chunk, before the video has run ahead far, is close in both
    assert ahead["per_chunk"][0] < 5.0


@pytest.mark.slow
def test_the_wrist_camera_says_why_it_has_no_gripper_track(demo_rows):
    wrist = demo_rows["prompt_train"]["gripper_px"]["wrist"]
    assert wrist["median"] is None and "rides on gripper_link" in wrist["note"]


@pytest.mark.slow
def test_report_rows_split_the_psnr_between_arm_and_scene(demo_rows):
    for row in demo_rows.values():
        for view in ("front", "wrist"):
            masked = row["video_psnr_masked"][view]
            assert masked["frames"] > 0 and masked["note"] is None
            assert 5 < masked["arm"] < 60 and 5 < masked["scene"] < 60
    # the video ahead of its joints errs in the arm more than the clean one does
    assert demo_rows["video_ahead_1s"]["video_psnr_masked"]["front"]["arm"] < \
        demo_rows["prompt_train"]["video_psnr_masked"]["front"]["arm"]
