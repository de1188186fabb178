"""``inspector calibrate``: the demo's front camera recovered from noisy clicks with a wild one, and
every bad points file refused in one line.

The clicks are synthesised from the demo's exact camera: the named points of the arm at GT steps
(forward kinematics of the measured joints), projected, then disturbed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from demo_copies import demo_copy

from inspector.analysis.calibrate_command import calibrate, read_points
from inspector.analysis.calibration_solve import CalibrationFailed, solve_fixed_camera
from inspector.data.cameras import CAMERAS_FILE, points_path, read_cameras
from inspector.data.lerobot_dataset import open_dataset
from inspector.data.session import open_session
from inspector.errors import InspectorError
from inspector.robot.camera import named_points
from inspector.units import Units, to_radians

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
NAMES = ("gripper_tip", "gripper_link", "wrist_link", "lower_arm_link", "upper_arm_link")
ALL_NAMES = (*NAMES, "gripper_frame_link", "moving_jaw_so101_v1_link")
WILD = 7  # the index of the wild click


def _clicks(n_frames: int, noise_px: float, seed: int = 5, episode: int = 0, wild: bool = True,
            names: tuple[str, ...] = NAMES):
    """(points (N, 3) [m], exact pixels (N, 2), clicked pixels (N, 2), click dicts) of the front view:
    ``names`` at ``n_frames`` GT steps spread over the episode, ``noise_px`` RMS of noise, and with
    ``wild`` one click (:data:`WILD`) 73 px off."""
    camera = read_cameras(DEMO / CAMERAS_FILE)["front"]
    ep = open_dataset(DEMO / "dataset").episode(episode)
    steps = np.linspace(0, ep.length - 1, n_frames).astype(int)
    at = named_points(to_radians(ep.state[steps], Units("degrees")), names)
    X = np.array([at[name][k] for k in range(len(steps)) for name in names])
    exact, _ = camera.project(X, camera.T_base_camera)
    rng = np.random.default_rng(seed)
    clicked = exact + rng.normal(scale=noise_px / np.sqrt(2), size=exact.shape)
    if wild:
        clicked[WILD] += [70.0, -20.0]
    points = [{"step": int(steps[i // len(names)]), "point": names[i % len(names)],
               "u": float(clicked[i, 0]), "v": float(clicked[i, 1])} for i in range(len(X))]
    return X, exact, clicked, points


@pytest.mark.slow
def test_the_front_camera_is_recovered_from_noisy_clicks_and_a_wild_one():
    """2 px (RMS) of noise on 336 clicks (7 points of the arm in 24 GT frames of each episode), one
    73 px off: the camera within 3 px and 1 cm. (The position is what needs the clicks: the focal
    length and the distance trade off against each other, and 60 clicks leave 1-3 cm; see
    docs/metrics.md#cameras.)"""
    truth = read_cameras(DEMO / CAMERAS_FILE)["front"]
    first = _clicks(24, 2.0, names=ALL_NAMES)
    second = _clicks(24, 2.0, seed=105, episode=1, wild=False, names=ALL_NAMES)
    X, exact, clicked = (np.r_[a, b] for a, b in zip(first[:3], second[:3]))
    result = solve_fixed_camera(X, clicked, truth.width, truth.height)
    assert result.rejected == [WILD] and len(result.used) == len(X) - 1
    assert result.reprojection_error_px <= 3.0
    solved = result.camera
    position_error_m = np.linalg.norm(solved.T_base_camera[:3, 3] - truth.T_base_camera[:3, 3])
    angle_deg = np.degrees(np.arccos(np.clip(solved.T_base_camera[:3, 2] @ truth.T_base_camera[:3, 2], -1, 1)))
    reprojected, _ = solved.project(X, solved.T_base_camera)  # against the exact pixels, not the clicks
    rms_to_exact = float(np.sqrt((np.linalg.norm(reprojected - exact, axis=1) ** 2).mean()))
    print(f"calibrate: {result.reprojection_error_px:.2f} px RMS to the clicks, {rms_to_exact:.2f} px to the "
          f"exact pixels, camera {100 * position_error_m:.2f} cm and {angle_deg:.2f} deg off, focal length "
          f"{solved.K[0, 0]:.1f} px (exact {truth.K[0, 0]:.1f})")
    assert position_error_m <= 0.01 and rms_to_exact <= 3.0 and angle_deg < 1.0


def test_exact_clicks_give_the_exact_camera():
    truth = read_cameras(DEMO / CAMERAS_FILE)["front"]
    X, exact, _, _ = _clicks(8, 0.0, wild=False)
    result = solve_fixed_camera(X, exact, truth.width, truth.height)
    assert result.rejected == [] and result.reprojection_error_px < 1e-3
    assert np.allclose(result.camera.T_base_camera, truth.T_base_camera, atol=1e-5)
    assert np.allclose(result.camera.K, truth.K, atol=1e-3)


def test_too_few_points_determine_no_camera():
    X, exact, _, _ = _clicks(1, 0.0, wild=False)
    with pytest.raises(CalibrationFailed, match="5 points: at least 6"):
        solve_fixed_camera(X, exact, 320, 240)


@pytest.fixture
def session(tmp_path) -> Path:
    return demo_copy(tmp_path, ["prompt_train", "tempo_0.8x"])


def _write(path: Path, doc) -> Path:
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.slow
def test_calibrate_writes_the_view_and_keeps_the_others(session, tmp_path):
    _, _, _, points = _clicks(12, 2.0)
    pfile = _write(tmp_path / "points.json", {"view": "front", "rollout": "prompt_train", "points": points})
    out = subprocess.run([sys.executable, "-m", "inspector", "calibrate", str(session), "--view", "front",
                          "--points", str(pfile), "--json"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert list(result["camera"]) == ["width", "height", "K", "T_base_camera"]
    assert result["points_rejected"] == [WILD] and result["points_used"] == len(points) - 1
    assert 0 < result["reprojection_error_px"] <= 3.0
    cameras = read_cameras(session / CAMERAS_FILE)
    assert set(cameras) == {"front", "wrist"} and cameras["wrist"].parent == "gripper_link"
    assert np.allclose(cameras["front"].T_base_camera, result["camera"]["T_base_camera"])
    assert "inspector calibrate" in cameras["front"].source
    text = subprocess.run([sys.executable, "-m", "inspector", "calibrate", str(session / "rollouts" / "prompt_train"),
                           "--view", "front", "--points", str(pfile)], capture_output=True, text=True, timeout=300)
    assert text.returncode == 0 and "rejected as bad clicks: [7]" in text.stdout and "wrote" in text.stdout


@pytest.mark.slow
def test_a_bad_points_file_is_one_line_and_exit_2(session, tmp_path):
    pfile = _write(tmp_path / "points.json", {"view": "front", "points": []})
    before = (session / CAMERAS_FILE).read_bytes()
    out = subprocess.run([sys.executable, "-m", "inspector", "calibrate", str(session), "--view", "front",
                          "--points", str(pfile)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert out.stderr.startswith(f"error: {pfile}: points: 0 points; at least 6")
    assert (session / CAMERAS_FILE).read_bytes() == before


def _point(**change) -> dict:
    return {"step": 10, "point": "gripper_tip", "u": 100.0, "v": 80.0, **change}


@pytest.mark.parametrize(("doc", "what"), [
    ({"view": "wrist", "points": []}, "view: the file's points are of 'wrist'"),
    ({"points": {}}, "points: expected a list"),
    ({"points": [1]}, "points[0]: expected an object"),
    ({"points": [_point(point="elbow")]}, "points[0].point: unknown point 'elbow'; points: base_link"),
    ({"points": [_point(step=-1)]}, "points[0].step: expected a whole number"),
    ({"points": [_point(step=True)]}, "points[0].step: expected a whole number"),
    ({"points": [_point(step=1.5)]}, "points[0].step: expected a whole number"),
    ({"points": [_point(u="3")]}, "points[0].u: expected a pixel coordinate"),
    ({"points": [_point(v=1e300)]}, "points[0].v: expected a pixel coordinate"),
    ({"points": [_point(v=10**400)]}, "points[0].v: expected a pixel coordinate"),
    ({"points": [_point(w=1)]}, "points[0]: unknown field 'w'"),
    ({"points": [_point(rollout="../x")]}, "points[0].rollout: expected a rollout's tag"),
    ({"points": [], "camera": 1}, "unknown field 'camera'"),
    ([], "expected a JSON object"),
])
def test_bad_points_are_refused_naming_the_field(tmp_path, doc, what):
    pfile = _write(tmp_path / "points.json", doc)
    with pytest.raises(InspectorError) as info:
        read_points(pfile, "front")
    assert info.value.file == str(pfile) and info.value.what.startswith(what), info.value.what


@pytest.mark.parametrize(("content", "what"), [
    (b'{"points": [{"step": 1, "point": "gripper_tip", "u": NaN, "v": 1}]}', "points[0].u: non-finite"),
    (b"[" * 100_000 + b"]" * 100_000, "invalid JSON"),
    (b'{"points": [' + b'{"step": 1, "point": "gripper_tip", "u": 1, "v": 1},' * 10_001 + b"1]}",
     "points: 10,002 points, more than"),
])
def test_hostile_points_files_are_refused(tmp_path, content, what):
    pfile = tmp_path / "points.json"
    pfile.write_bytes(content)
    with pytest.raises(InspectorError) as info:
        read_points(pfile, "front")
    assert what in info.value.what


def test_points_files_that_are_no_files_are_refused_unread(tmp_path):
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    with pytest.raises(InspectorError, match="not a regular file"):
        read_points(fifo, "front")
    big = tmp_path / "big.json"
    with big.open("wb") as fh:
        fh.truncate(64 * 1024 * 1024)
    with pytest.raises(InspectorError, match="bytes"):
        read_points(big, "front")


def test_steps_past_the_episode_and_unnamed_rollouts_are_refused(session, tmp_path):
    _, _, _, points = _clicks(6, 0.0)
    pfile = _write(tmp_path / "points.json", {"points": points})
    with pytest.raises(InspectorError, match="which rollout's GT episode.*prompt_train, tempo_0.8x"):
        calibrate(session, "front", pfile, write=False)
    points[3]["step"] = 100_000
    _write(pfile, {"points": points, "rollout": "prompt_train"})
    with pytest.raises(InspectorError, match=r"points\[3\].step: 100000 is past the GT episode of rollout "
                                             r"'prompt_train' \(steps 0 to \d+\)"):
        calibrate(session, "front", pfile, write=False)
    points[3]["step"] = 0
    points[4]["u"] = 400.0
    _write(pfile, {"points": points, "rollout": "prompt_train"})
    with pytest.raises(InspectorError, match=r"points\[4\]: \(400, .*outside the 320x240 frame"):
        calibrate(session, "front", pfile, write=False)
    _write(pfile, {"points": points, "rollout": "nope"})
    with pytest.raises(InspectorError, match="'nope' is not in the session"):
        calibrate(session, "front", pfile, write=False)
    with pytest.raises(InspectorError, match="no GT frames of view 'top'"):
        calibrate(session, "top", _write(pfile, {"points": points, "rollout": "prompt_train"}), write=False)
    with pytest.raises(InspectorError, match="cameras.wrist: rides on gripper_link; calibrate solves fixed"):
        calibrate(session, "wrist", _write(pfile, {"points": points, "rollout": "prompt_train"}), write=False)


def test_an_error_above_the_limit_is_refused_and_nothing_written(session, tmp_path):
    _, _, _, points = _clicks(8, 6.0, seed=2)
    pfile = _write(tmp_path / "points.json", {"points": points, "rollout": "prompt_train"})
    before = (session / CAMERAS_FILE).read_bytes()
    with pytest.raises(InspectorError, match=r"reprojection error \d+\.\d\d px is above 1 px \(--max-error\)"):
        calibrate(session, "front", pfile, max_error_px=1.0)
    assert (session / CAMERAS_FILE).read_bytes() == before


def test_saved_clicks_are_read_without_points(session):
    _, _, _, points = _clicks(8, 0.0, wild=False)
    saved = points_path(open_session(session, lazy=True), "front")
    saved.parent.mkdir()
    _write(saved, {"view": "front", "rollout": "prompt_train", "points": points})
    result = calibrate(session, "front", write=False)
    assert result["written"] is None and result["reprojection_error_px"] < 0.01
