"""Other tools' output layouts in a real browser: one app serves a DreamZero-SO101 offline-inference
run and two lerobot-eval output directories (with recordings, and without: video only), as given on
the command line (imported in memory); a page opens one rollout of each and sees its video and the
arm, or, video only, the imagined view beside the simulator's render and no arm."""

from __future__ import annotations

import pytest
from browser import frame_sources, skip_reason
from eval_outputs import write_eval
from offline_runs import write_run
from test_app_browser import new_page, open_in_page, wait_for_scene

from inspector.app import serve

_reason = skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.slow] + ([pytest.mark.skip(reason=_reason)] if _reason else [])


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    root = tmp_path_factory.mktemp("layouts")
    write_run(root / "runs" / "ar3", 3)
    write_eval(root / "eval", {("so101_sim", 0): [True, False]})
    # lerobot-eval's default: no recordings, so video-only episodes
    write_eval(root / "eval_videos", {("pusht", 0): [True]}, record=False, predicted_near_render=True)
    app = serve([root / "runs", root / "eval", root / "eval_videos"], port=0, block=False)
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
        wait_for_scene(page, what=f"{tag}: the 3D canvas to be drawn")
        assert page.get_by_text(words).first.is_visible()
        if tag == "so101_sim_0_ep001":  # its outcome, on the card
            assert page.get_by_text("failure · reward 0 · task so101_sim_0").first.is_visible()
    # a video-only episode: the imagined first view beside the simulator's render, and no arm
    open_in_page(page, tab, app, "pusht_0_ep000")
    assert set(frame_sources(page)) == {"render/imagined", "render/gt", "camera_1/imagined"}
    boxes = {k: page.locator(f"img.inspector-frame[data-view='{k.split('/')[0]}'][data-kind='{k.split('/')[1]}']")
             .bounding_box() for k in ("render/imagined", "render/gt")}
    imagined, gt = boxes["render/imagined"], boxes["render/gt"]
    assert imagined and gt and abs(imagined["y"] - gt["y"]) < 2 and gt["x"] >= imagined["x"] + imagined["width"] - 1
    assert page.get_by_text("none: video only").first.is_visible()
    assert page.get_by_text("success · reward 3 · task pusht_0").first.is_visible()
    assert tab.scene.data is None and not tab.scene.pred_arm.visible and not tab.scene.gt_arm.visible
    page.close()
