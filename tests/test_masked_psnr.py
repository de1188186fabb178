"""PSNR inside and outside the projected GT arm, on the demo's frames and cameras."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from inspector.analysis import metrics
from inspector.analysis.camera_measures import project_gripper, scaled_camera
from inspector.analysis.masked_psnr import MaskedPsnrAccumulator, split_squared_error
from inspector.data.cameras import CAMERAS_FILE, read_cameras
from inspector.data.lerobot_dataset import open_dataset
from inspector.data.session import load_session_rollout, open_session
from inspector.robot.silhouette import arm_masks, arm_mesh
from inspector.units import Units, to_radians

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"


@pytest.fixture(scope="module")
def frame_pairs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three imagined frames of prompt_train's front view, their GT frames and the GT arm's masks."""
    cameras = read_cameras(DEMO / CAMERAS_FILE)
    episode = open_dataset(DEMO / "dataset").episode(0)
    steps = [0, 60, 120]
    gt = {i: rgb for i, rgb in episode.video("front").iter_frames() if i in steps}
    session = open_session(DEMO, lazy=True)
    imagined = {i: rgb for i, rgb in load_session_rollout(session, "prompt_train").video("front").iter_frames()
                if i in steps}
    mesh = arm_mesh()
    assert mesh is not None
    masks = arm_masks(mesh, cameras["front"], to_radians(episode.state[steps], Units("degrees")))
    return np.stack([imagined[i] for i in steps]), np.stack([gt[i] for i in steps]), masks


def test_the_split_is_the_psnr_of_each_side_s_own_pixels(frame_pairs):
    imagined, gt, masks = frame_pairs
    acc = MaskedPsnrAccumulator()
    arm, scene = [], []
    for a, b, m in zip(imagined, gt, masks):
        assert 200 < m.sum() < m.size // 2  # the arm is in view, not all of it
        acc.add(a, b, m)
        err = (a.astype(float) - b.astype(float)) ** 2
        arm.append(10 * np.log10(255 ** 2 / err[m].mean()))
        scene.append(10 * np.log10(255 ** 2 / err[~m].mean()))
    record = acc.result()
    assert record["arm"] == pytest.approx(np.mean(arm), abs=1e-3)
    assert record["scene"] == pytest.approx(np.mean(scene), abs=1e-3)
    assert record["frames"] == 3 and record["note"] is None


def test_the_two_sides_add_up_to_the_whole_frame(frame_pairs):
    imagined, gt, masks = frame_pairs
    for a, b, m in zip(imagined, gt, masks):
        se_in, n_in, se_out, n_out = split_squared_error(a, b, m)
        whole = 10 * np.log10(255 ** 2 / ((se_in + se_out) / (n_in + n_out)))
        assert whole == pytest.approx(metrics.psnr(a[None], b[None])[0], abs=1e-9)


def test_an_empty_mask_gives_no_arm_psnr_and_says_why(frame_pairs):
    imagined, gt, masks = frame_pairs
    acc = MaskedPsnrAccumulator()
    acc.add(imagined[0], gt[0], np.zeros_like(masks[0]))
    record = acc.result()
    assert record["arm"] is None and record["scene"] is not None
    assert "covers no pixel" in record["note"]


def test_a_camera_scaled_to_a_frame_draws_what_the_silhouette_draws_at_that_size():
    camera = read_cameras(DEMO / CAMERAS_FILE)["front"]
    mesh = arm_mesh()
    assert mesh is not None
    q = to_radians(open_dataset(DEMO / "dataset").episode(0).state[[30, 90]], Units("degrees"))
    size = (160, 88)  # a squashed frame: another aspect, as DreamZero's
    np.testing.assert_array_equal(arm_masks(mesh, scaled_camera(camera, size), q), arm_masks(mesh, camera, q, size))
    full, small = project_gripper(camera, q), project_gripper(scaled_camera(camera, size), q)
    np.testing.assert_allclose((small + 0.5) * [camera.width / size[0], camera.height / size[1]] - 0.5, full,
                               atol=1e-9)


@pytest.mark.parametrize("tag, frames", [("single_f000", 9), ("phase_lag_wrist", 57), ("prompt_train", 56)])
def test_a_short_clip_is_measured_on_every_frame_a_long_one_on_32_to_63(tag, frames):
    """Frames whose GT episode frame is a multiple of a power of two: 32-63 of a long clip, each
    GT frame once, and the same GT frames for every rollout of an episode (their masks shared)."""
    from inspector.analysis.camera_measures import MASKED_FRAMES, ViewCameraPass
    from inspector.analysis.timeline import build_timeline

    tl = build_timeline(load_session_rollout(open_session(DEMO, lazy=True), tag))
    measures = ViewCameraPass(tl, "front", read_cameras(DEMO / CAMERAS_FILE)["front"])
    clip = [rgb for _, rgb in tl.rollout.video("front").iter_frames()]
    for f, rgb in enumerate(clip):
        measures.add(f, rgb, rgb)  # its own GT: only which frames are measured matters here
    assert measures.masked_psnr()["frames"] == frames
    assert frames == len(clip) or MASKED_FRAMES <= frames < 2 * MASKED_FRAMES
    measured = {tl.rollout.start_frame + measures._step(f) for f in range(len(clip))} & \
        set(range(0, 10**6, measures._masked_every))
    assert len(measured) == frames
