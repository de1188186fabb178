"""Other tools' output layouts in a real browser: one app serves a DreamZero-SO101 offline-inference
run and a lerobot-eval output directory, as given on the command line (imported in memory); a page
opens one rollout of each and sees its video and the arm."""

from __future__ import annotations

import pytest
from browser import canvas_is_drawn, frame_sources, skip_reason
from eval_outputs import write_eval
from offline_runs import write_run
from test_app_browser import SCENE_BOX, new_page, open_in_page

from inspector.app import serve

_reason = skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.slow] + ([pytest.mark.skip(reason=_reason)] if _reason else [])


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    root = tmp_path_factory.mktemp("layouts")
    write_run(root / "runs" / "ar3", 3)
    write_eval(root / "eval", {("so101_sim", 0): [True, False]})
    app = serve([root / "runs", root / "eval"], port=0, block=False)
    yield app
    app.stop()


def test_a_rollout_of_each_layout_shows_its_video_and_the_arm(browser, app):
    """The page starts on the first rollout (the offline run): open the lerobot-eval episode, then
    come back to the run, so each one is opened from the picker."""
    page, tab = new_page(browser, app)
    for tag, frames, words in (
            ("so101_sim_0_ep001", {"predicted/imagined", "render/gt", "top/gt"}, "executed (state)"),
            ("ar3", {f"{v}/imagined" for v in ("front", "top", "gripper")}, "Pick the red cube")):
        open_in_page(page, tab, app, tag)
        assert set(frame_sources(page)) == frames
        assert all(src.startswith("data:image/") for src in frame_sources(page).values())
        page.wait_for_timeout(1500)  # let the software renderer draw the arm
        assert canvas_is_drawn(page.screenshot(), SCENE_BOX), f"{tag}: the 3D canvas is blank"
        assert page.get_by_text(words).first.is_visible()
        if tag == "so101_sim_0_ep001":  # its outcome, on the card
            assert page.get_by_text("failure · reward 0 · task so101_sim_0").first.is_visible()
    page.close()
