"""The arms drawn into the frames in a Rerun recording: each view with a camera is a Pinhole in
the 3D scene, posed as the camera model poses it, its videos referenced under it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rerun as rr

from inspector.analysis.timeline import build_timeline
from inspector.data.cameras import CAMERAS_FILE, read_cameras
from inspector.data.session import load_session_rollout, open_session
from inspector.export import layout as L
from inspector.export.cameras import camera_path, camera_video_path
from inspector.export.recording import write_recording
from inspector.robot.kinematics import kinematics
from inspector.units import to_radians

pytestmark = pytest.mark.slow  # a recording written and checked with rerun rrd verify

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
RERUN = Path(sys.executable).parent / "rerun"


def test_each_view_with_a_camera_is_a_pinhole_with_its_videos_under_it(tmp_path):
    session = open_session(DEMO, lazy=True)
    tl = build_timeline(load_session_rollout(session, "prompt_train"))
    path = write_recording(tl, tmp_path / "prompt_train.rrd")
    done = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr

    chunks: dict[str, list] = {}
    for chunk in rr.chunk.RrdReader(path).stream().to_chunks():
        chunks.setdefault(chunk.entity_path, []).append((chunk.is_static, chunk.to_record_batch()))

    def column(entity: str, component: str, static: bool) -> list:
        return [v for s, rb in chunks.get(f"/{entity}", []) if s == static and component in rb.schema.names
                for v in rb.column(component).to_pylist()]

    cameras = read_cameras(DEMO / CAMERAS_FILE)
    for view, camera in cameras.items():
        K = np.array(column(camera_path(view), "Pinhole:image_from_camera", True)[-1]).reshape(3, 3).T
        np.testing.assert_allclose(K, camera.K, rtol=1e-6)  # rerun keeps the matrix column-major
        assert np.ravel(column(camera_path(view), "Pinhole:resolution", True)[-1]).tolist() == [camera.width,
                                                                                               camera.height]
        for source in ("imagined", "gt"):
            refs = column(camera_video_path(view, source), "VideoFrameReference:video_reference", True)
            assert np.ravel(refs).tolist() == [L.video_path(view, source)]
            own = column(L.video_path(view, source), "VideoFrameReference:timestamp", False)
            under = column(camera_video_path(view, source), "VideoFrameReference:timestamp", False)
            assert len(under) == len(own) > 0
    front = cameras["front"]
    t = np.ravel(column(camera_path("front"), "Transform3D:translation", True)[-1])
    np.testing.assert_allclose(t, front.T_base_camera[:3, 3], atol=1e-6)
    # the wrist camera rides on the gripper: a pose a step, where the predicted arm puts it
    wrist = cameras["wrist"]
    moving = column(camera_path("wrist"), "Transform3D:translation", False)
    assert len(moving) == tl.n_steps
    q = to_radians(tl.pred, tl.units)
    expected = wrist.poses(kinematics().link_poses(q, links=(wrist.parent,)), len(q))[:, :3, 3]
    np.testing.assert_allclose(np.sort(np.array(moving).reshape(-1, 3), axis=0), np.sort(expected, axis=0), atol=1e-5)


def test_a_raw_directory_s_sidecars_reach_the_export_workers(dz_layout, tmp_path):
    """``export --jobs 2`` of a raw directory: each worker reads its sidecars (the temporary
    import holds neither), so the view with a camera is a Pinhole in every recording, and a
    rollout labelled in the outcomes sidecar carries its outcome."""
    import shutil

    from inspector.data.cameras import sidecar_path, write_camera
    from inspector.export.outcomes import OUTCOME
    from inspector.said.outcome_store import sidecar_path as outcomes_sidecar
    from inspector.said.outcome_store import update_outcome

    raw = tmp_path / "dreamzero_so101"
    shutil.copytree(dz_layout, raw)
    write_camera(sidecar_path(raw), "front", read_cameras(DEMO / CAMERAS_FILE)["front"])
    update_outcome(outcomes_sidecar(raw), "f000", {"success": True, "progress": 100})
    out = tmp_path / "rrd"
    done = subprocess.run([sys.executable, "-m", "inspector", "export", str(raw), "-o", str(out), "--jobs", "2",
                           "--no-cache"], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    files = sorted(out.glob("*.rrd"))
    assert len(files) >= 2
    for path in files:
        entities = {chunk.entity_path for chunk in rr.chunk.RrdReader(path).stream().to_chunks()}
        assert f"/{camera_path('front')}" in entities, path.name
        assert not any(e.startswith(f"/{camera_path('top')}") for e in entities)
        assert (f"/{OUTCOME}" in entities) == (path.stem == "f000"), path.name
