"""The report page's overlay frames: the arms drawn into each view at a rollout's worst chunk."""

from __future__ import annotations

import base64
import io
import re
import shutil
from pathlib import Path

import numpy as np
from PIL import Image

from inspector.report.overlay_frames import PRED_RGB, overlay_section

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"


def _row(tag: str, chunk: int) -> dict:
    return {"tag": tag, "session": "demo", "worst_chunk": {"chunk": chunk, "by": "chunk RMSE"},
            "time_aligned_drift": None}


def test_each_view_with_a_camera_shows_both_frames_with_the_arms_drawn():
    html = overlay_section({"rollouts": [_row("video_ahead_1s", 12)]}, [str(DEMO / "rollouts" / "video_ahead_1s")])
    uris = re.findall(r"src='data:image/jpeg;base64,([^']+)'", html)
    assert len(uris) == 4  # front and wrist, imagined and GT
    assert sum(len(u) for u in uris) < 40_000  # the page stays small
    for uri in uris:
        rgb = np.asarray(Image.open(io.BytesIO(base64.b64decode(uri))).convert("RGB")).astype(int)
        assert rgb.shape[1] == 128
        assert (np.abs(rgb - PRED_RGB).sum(axis=2) < 60).sum() > 20  # the predicted arm's outline
    assert "video_ahead_1s" in html and "chunk 12" in html


def test_a_session_without_cameras_adds_no_section(tmp_path):
    session = tmp_path / "demo"
    shutil.copytree(DEMO, session, ignore=shutil.ignore_patterns("cameras.json"))
    assert overlay_section({"rollouts": [_row("prompt_train", 3)]}, [str(session)]) == ""
    assert overlay_section({"rollouts": [_row("prompt_train", 3)]}, []) == ""
