"""The arms drawn into the frames, in a real browser: the bundled demo (exact cameras) served, the
overlay toggled on for the rollout whose video runs ahead of its joints, its overlay images
laid over each frame, and the imagined gripper's distance plotted under the drift plot."""

from __future__ import annotations

import base64
import io
import os
from pathlib import Path

import numpy as np
import pytest
from browser import open_app, open_page, select_option, skip_reason, wait_until
from PIL import Image

from inspector.app._overlay import PRED_RGB

_reason = skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.slow] + ([pytest.mark.skip(reason=_reason)] if _reason else [])

TAG = "video_ahead_1s"
SHOT_DIR = os.environ.get("INSPECTOR_TEST_SHOTS")  # where to keep the screenshot (else the test's tmp dir)


def _overlays(page) -> dict[str, str]:
    return page.evaluate(
        "() => Object.fromEntries([...document.querySelectorAll('img.inspector-overlay')]"
        ".map(e => [e.dataset.view + '/' + e.dataset.kind, e.getAttribute('src')]))")


def _decoded(uri: str) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))).convert("RGBA"))


def test_the_arms_are_drawn_into_every_frame_with_a_camera(browser, demo_app, tmp_path):
    page = open_page(browser, 1600, 1000)
    open_app(page, demo_app.url, draw_3d=False)
    from browser import page_client_id

    tab = wait_until(lambda: demo_app.tabs.get(page_client_id(page)), what="the page's tab")
    key = next(k for k, e in demo_app.catalog.entries.items() if e.tag == TAG)
    select_option(page, "Rollout", key)
    wait_until(lambda: tab.key == key and tab.loaded is not None, what=f"{TAG} to open")
    wait_until(tab.loaded.frames.decoded.is_set, timeout=120, what="the frames to decode")
    assert tab.video.overlay.visible  # the demo has a camera per view
    assert not _overlays(page)  # off until asked for
    tab.set_chunk(12, 4)
    page.get_by_label("Arms in frames", exact=True).check()
    shown = wait_until(lambda: len(_overlays(page)) == 4 and _overlays(page), timeout=60,
                       what="an overlay over each of the four frames")
    assert isinstance(shown, dict) and set(shown) == {"front/imagined", "front/gt", "wrist/imagined", "wrist/gt"}
    for where, uri in shown.items():
        rgba = _decoded(uri)
        orange = (np.abs(rgba[..., :3].astype(int) - PRED_RGB).sum(axis=2) < 10) & (rgba[..., 3] > 0)
        assert orange.sum() > 50, f"no predicted arm drawn over {where}"
        assert (rgba[..., 3] == 0).mean() > 0.3, f"the overlay over {where} hides the frame"
    # the overlay sits on the frame: the same box in the page
    boxes = page.evaluate(
        "() => [...document.querySelectorAll('img.inspector-overlay')].map(o => {"
        "const f = o.parentElement.querySelector('img.inspector-frame').getBoundingClientRect();"
        "const b = o.getBoundingClientRect(); return [b.x - f.x, b.y - f.y, b.width - f.width, b.height - f.height]})")
    assert all(abs(v) < 1 for box in boxes for v in box)
    # the imagined gripper's distance to where the joints put it, under the drift plot
    wait_until(lambda: tab.plots.gripper_plot is not None, timeout=60, what="the gripper distance plot")
    series = tab.loaded.frames.gripper_distance()["front"]
    assert np.nanmedian(series) > 10  # this video runs 1 s ahead of its joints
    shot = Path(SHOT_DIR) if SHOT_DIR else tmp_path
    shot.mkdir(parents=True, exist_ok=True)
    page.mouse.move(700, 500)  # the toggle's hint off the frames
    page.wait_for_timeout(500)
    page.screenshot(path=str(shot / "overlay.png"))
    page.get_by_label("Arms in frames", exact=True).uncheck()
    wait_until(lambda: not _overlays(page), timeout=30, what="the overlay to go")
    page.close()
