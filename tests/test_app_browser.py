"""The web app in a real browser: Debian Chromium driven by Playwright.

One app serves a copy of the bundled demo's rollouts (``test_app.make_sessions``), with faults
planted on purpose (``BROKEN``: truncated actions.npy; ``CARRIED_GT``: a truncated GT video). Set
``INSPECTOR_DOCS_SCREENSHOT=1`` to also refresh ``docs/screenshot.png`` (the bundled demo) and,
where the real DreamZero-SO101 outputs are found (``$INSPECTOR_FIXTURES``), ``docs/imported.png``
(those outputs imported).
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import pytest
from browser import (
    ARM_AND_VIDEO_STEP,
    GPU_RENDERER_JS,
    TEST_DPR,
    canvas_is_drawn,
    frame_sources,
    hide_software_webgl_notice,
    open_app,
    open_page,
    page_client_id,
    play_on_one_clock,
    select_option,
    skip_reason,
    slider_thumb,
    wait_until,
)
from conftest import real_fixtures_dir, real_outputs_skip_reason
from test_app import BROKEN, LONG, NOVEL, SINGLE, TRAIN, VIEWS, make_sessions

from inspector.app import serve

_reason = skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.slow] + ([pytest.mark.skip(reason=_reason)] if _reason else [])

DOCS_SCREENSHOT = Path(__file__).resolve().parents[1] / "docs" / "screenshot.png"
DOCS_IMPORTED = DOCS_SCREENSHOT.with_name("imported.png")
SCENE_BOX = (420, 120, 960, 900)  # part of a 1600x1000 page where the 3D canvas shows
# The demo rollout the clock test plays to its end: 25 chunks, a 7.5 s clip at 1x (the page draws
# in software at full CPU for as long as it plays).
PLAYED_TO_THE_END = "phase_lag_wrist"
PAUSE_FRAMES = 4  # animation frames a page may take to answer Pause (see the clock test)


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    _, broken = make_sessions(tmp_path_factory.mktemp("browser"))
    app = serve([broken], port=0, block=False)
    yield app
    app.stop()


def new_page(browser, app, width: int = 1600, height: int = 1000, full_resolution: bool = False,
             draw_3d: bool = True):
    """A fresh page on the app and the server-side TabState it got (the 3D canvas at the tests'
    pixel ratio unless ``full_resolution``: ``browser.TEST_DPR``; never drawn unless ``draw_3d``)."""
    page = open_page(browser, width, height)
    open_app(page, app.url, full_resolution, draw_3d)
    return page, page_tab(page, app)


def page_tab(page, app):
    """The TabState serving the page now (found by the client id the page shows)."""
    tab = wait_until(lambda: app.tabs.get(page_client_id(page)), what="the page's tab on the server")
    wait_until(lambda: tab.loaded is not None or tab.error is not None, what="the first rollout")
    return tab


def wait_for_scene(page, shot: Path | None = None, what: str = "the 3D canvas to be drawn") -> None:
    """Wait until the software renderer has drawn the arms (looks at screenshots; the last one is
    kept as ``shot``)."""
    def drawn() -> bool:
        png = page.screenshot()
        if shot is not None:
            shot.write_bytes(png)
        return canvas_is_drawn(png, SCENE_BOX)
    wait_until(drawn, timeout=60, interval=0.5, what=what)


def key(app, tag: str) -> str:
    return next(k for k, e in app.catalog.entries.items() if e.tag == tag)


def open_in_page(page, tab, app, tag: str) -> None:
    """Pick a rollout in the page's picker and wait for its frames."""
    k = key(app, tag)
    select_option(page, "Rollout", k)
    wait_until(lambda: tab.key == k and tab.loaded is not None, what=f"{tag} to open")
    wait_until(tab.loaded.frames.done.is_set, timeout=60, what="the videos to decode")

    def shown_as_on_server() -> bool:
        # under the tab's lock: ``open`` sets ``loaded`` before it shows the new pairs, and until
        # then the old rollout's pairs would pass for the new one's
        with tab.lock:
            if tab.key != k or tab.loaded is None:
                return False
            expected = {f"{p.view}/imagined" for p in tab.pairs if p.imagined} | {
                f"{p.view}/gt" for p in tab.pairs if p.gt}
        return bool(expected) and set(frame_sources(page)) == expected

    wait_until(shown_as_on_server, timeout=30, what="the page to show the server's frames")


def test_one_3d_page_scene_keys_notes_and_light_3d(browser, app, tmp_path):
    """The checks that need the 3D view drawn, on one page (a page drawing in software takes
    15-20 s to load): the 60-chunk rollout's frames and scene (:func:`_scene_renders`), the keys
    that step the timeline without turning the view (:func:`_keys_step_the_timeline_not_the_view`),
    then the Notes panel and, last as the page then draws slower, Light 3D unticked by the user
    (:func:`_notes_and_light_3d`)."""
    page, tab = new_page(browser, app)
    # Light 3D first: a page drawing in software keeps it ticked, as every page starts
    assert wait_until(lambda: page.evaluate("() => document.documentElement.dataset.inspectorWebgl")) == "software"
    assert tab.controls.light_3d.value is True
    assert tab.hemisphere_light is not None and tab.hemisphere_light.visible
    open_in_page(page, tab, app, LONG)
    _scene_renders(page, tab, tmp_path)
    _keys_step_the_timeline_not_the_view(page, tab)
    _notes_and_light_3d(page, tab)
    page.close()


def _scene_renders(page, tab, tmp_path) -> None:
    """The 60-chunk rollout in a page: its frames, the 3D scene drawn (the screenshot is kept as
    ``<tmp_path>/app.png``), its prompt and the unit mode."""
    assert set(frame_sources(page)) == {f"{v}/{k}" for v in VIEWS for k in ("imagined", "gt")}
    wait_for_scene(page, tmp_path / "app.png")
    assert page.get_by_text(tab.loaded.timeline.rollout.prompt).first.is_visible()
    assert page.get_by_text("arm degrees, gripper 0..100").first.is_visible()  # unit mode always shown


def _keys_step_the_timeline_not_the_view(page, tab) -> None:
    """viser turns its camera with the arrow keys and W outside text fields; on the Chunk slider
    the arrows step the chunks, and W is the worst-chunk key: neither also moves the view."""
    import numpy as np

    def camera():
        try:
            return np.asarray(tab.client.camera.position, dtype=float)
        except AssertionError:  # not reported by the page yet
            return None

    seen = [None]

    def settled() -> bool:  # the same position 1.5 s apart, a redraw (viser's 1 s heartbeat) between:
        seen.append(camera())  # the view's fit on open, eased out over the frames drawn, is over
        return seen[-2] is not None and bool(np.allclose(seen[-1], seen[-2], atol=1e-6))

    wait_until(settled, interval=1.5, what="the view to settle")
    start = seen[-1]

    def hold(key: str) -> None:  # as a user presses: viser turns the view while a key is down
        page.keyboard.down(key)
        page.wait_for_timeout(300)
        page.keyboard.up(key)

    slider_thumb(page, re.compile(r"^Chunk$")).focus()
    for _ in range(3):
        hold("ArrowRight")
    wait_until(lambda: tab.chunk == 3, what="the arrow keys to step the chunk")
    hold("w")
    worst, n = tab.loaded.timeline.worst_chunk()[0], tab.loaded.timeline.n_chunks - 1
    wait_until(lambda: tab.chunk == worst, what="W to jump to the worst chunk")
    wait_until(lambda: page.evaluate("(t) => document.body.innerText.includes(t)", f"chunk {worst} / {n}"),
               what="the page to show the worst chunk")
    page.wait_for_timeout(1500)  # a turned view is drawn and reported within a heartbeat
    assert np.allclose(camera(), start, atol=1e-4), (start, camera())
    # Where no control claims them, viser's keys still turn the view (and the check above could fail).
    page.locator("body").click(position={"x": 600, "y": 950})
    hold("ArrowLeft")
    wait_until(lambda: not np.allclose(camera(), start, atol=1e-4), what="the arrow key to turn the view")


def _notes_and_light_3d(page, tab) -> None:
    """The panel's controls, the 60-chunk rollout open.

    Light 3D: headless Chromium draws WebGL in software (SwiftShader): "Light 3D" stays ticked, as
    every page starts, and the page never gets an environment map; a user who unticks it keeps it so.

    Notes: each field carries the id its label points to (viser's text inputs have none of their
    own), and keeps it while typed into and after its folder is closed and opened again; typing
    into them and saving writes the session's annotations.json."""
    import json

    assert tab.controls.light_3d.value is True and tab.hemisphere_light.visible
    label = page.locator("label", has_text=re.compile(r"^Light 3D$")).first
    box = page.locator(f"[id='{label.get_attribute('for')}']")
    assert box.is_checked()
    folder = page.get_by_text("Notes", exact=True).first
    folder.click()
    for name in ("Rollout note", "Chunk note", "Flag rollout"):
        label = page.locator("label", has_text=re.compile(f"^{name}$")).first
        label.wait_for(state="visible")
        target = label.get_attribute("for")
        field = page.locator(f"[id='{target}']")
        wait_until(lambda: field.count() == 1, what=f"the field {name!r} labels")
        assert field.evaluate("el => el.tagName") == "INPUT"
    note = page.get_by_label("Rollout note", exact=True)
    note.fill("typed")
    assert note.input_value() == "typed"
    folder.click()  # closed and open again: the fields are rendered anew
    folder.click()
    wait_until(lambda: page.get_by_label("Chunk note", exact=True).count() == 1,
               what="the chunk note's label to find its field again")
    assert page.get_by_label("Rollout note", exact=True).count() == 1
    chunk = str(tab.chunk)  # the chunk the keys left the page at
    page.get_by_label("Rollout note", exact=True).fill("grasp slips at chunk 12")  # fields found by label
    page.get_by_label("Chunk note", exact=True).fill("cube out of view")
    page.get_by_role("button", name="Save notes").click()
    annotations = tab.loaded.entry.session.root / "annotations.json"

    def saved() -> dict | None:  # the rollout's note and then the chunk's are written
        try:
            entry = json.loads(annotations.read_text())["rollouts"][LONG]
        except (OSError, ValueError, KeyError):
            return None
        return entry if chunk in entry.get("chunks", {}) else None
    note = wait_until(saved, what="annotations.json to be written")
    assert note["note"] == "grasp slips at chunk 12" and note["chunks"][chunk]["note"] == "cube out of view"
    # last, as the rest of the page then draws slower: the user unticks Light 3D and it stays so
    box.click()  # the user unticks it
    wait_until(lambda: tab.controls.light_3d.value is False, what="Light 3D unticked on the server")
    wait_until(lambda: not tab.hemisphere_light.visible, what="the plain light to go")
    page.wait_for_timeout(2000)  # the page's script looks every 0.5 s; it ticks once per connection
    assert tab.controls.light_3d.value is False and not box.is_checked()


def test_one_page_broken_and_single_chunk_rollouts_sliders_keys_and_compare(browser, app):
    """The checks of the panels that need no 3D view, on one page (each page costs a load): a
    broken rollout's card and a single-chunk one's step slider, then the 60-chunk rollout's Chunk
    slider, Play and the step keys, then Compare."""
    page, tab = new_page(browser, app, draw_3d=False)
    _broken_rollout_shows_error_card_and_a_single_chunk_the_step_slider_only(page, tab, app)
    _chunk_slider_play_button_and_step_keys(page, tab, app)
    _compare_shows_the_second_rollouts_video(page, tab, app)
    page.close()


def _broken_rollout_shows_error_card_and_a_single_chunk_the_step_slider_only(page, tab, app) -> None:
    """A rollout that fails to load shows its error card and the others still open; a single-chunk
    sample (one chunk) then shows no chunk slider and no prev/next/worst buttons."""
    select_option(page, "Rollout", key(app, BROKEN) + " ⚠")
    card = page.locator(".inspector-error-card")
    card.wait_for(state="visible", timeout=20_000)
    assert "actions.npy" in card.inner_text()
    assert tab.loaded is None and tab.error is not None
    open_in_page(page, tab, app, SINGLE)
    assert page.locator(".inspector-error-card").count() == 0 or not card.is_visible()
    assert tab.loaded.timeline.n_chunks == 1
    chunk_slider = page.locator("label", has_text=re.compile(r"^Chunk$")).first
    wait_until(lambda: not chunk_slider.is_visible(), what="the chunk slider to hide")
    assert page.locator("label", has_text=re.compile(r"^Step$")).first.is_visible()  # not "Step in chunk"
    assert not page.get_by_role("button", name="worst").is_visible()
    thumb = slider_thumb(page, re.compile(r"^Step$"))
    thumb.focus()
    page.keyboard.press("ArrowRight")
    wait_until(lambda: tab.step == 1, what="the step slider to move the tab")
    open_in_page(page, tab, app, LONG)  # and back for a chunked rollout
    wait_until(chunk_slider.is_visible, what="the chunk slider to come back")


def _chunk_slider_play_button_and_step_keys(page, tab, app) -> None:
    """The Chunk slider moves the server's tab and the video (keys and a mouse drag); Play, Pause,
    and the L and PageDown keys step the timeline."""
    open_in_page(page, tab, app, LONG)
    before = frame_sources(page)
    thumb = slider_thumb(page, re.compile(r"^Chunk$"))
    thumb.focus()
    for _ in range(3):
        page.keyboard.press("ArrowRight")
    wait_until(lambda: tab.chunk == 3, what="the tab to reach chunk 3")
    assert tab.step == 27
    wait_until(lambda: frame_sources(page)["front/imagined"] != before["front/imagined"],
               what="the imagined frame to change")
    # Dragging with the mouse works too.
    box = thumb.bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    page.mouse.move(box["x"] + 120, box["y"] + box["height"] / 2, steps=8)
    page.mouse.up()
    wait_until(lambda: tab.chunk > 10, what="the drag to move the chunk")
    # Play and Pause from the start, then the step keys (one page for the slider and the buttons).
    tab.set_step(0)
    page.get_by_role("button", name="Play").click()
    wait_until(lambda: tab.playing and tab.step > 5, what="playback to advance")
    page.get_by_role("button", name="Pause").click()
    wait_until(lambda: not tab.playing, what="playback to pause")
    stopped = tab.step
    page.wait_for_timeout(500)
    assert tab.step == stopped
    page.locator("body").click(position={"x": 600, "y": 950})  # focus the page, not a control
    page.keyboard.press("l")  # next step
    wait_until(lambda: tab.step == stopped + 1, what="the L key to step forward")
    page.keyboard.press("PageDown")  # next chunk
    wait_until(lambda: tab.step == stopped + 1 + tab.loaded.timeline.steps_per_chunk, what="PageDown")


def _compare_shows_the_second_rollouts_video(page, tab, app) -> None:
    """Training vs novel prompt: the compared rollout's imagined frames show beside the first's,
    for every view, in the page."""
    open_in_page(page, tab, app, TRAIN)
    page.get_by_text("Compare", exact=True).first.click()  # the folder starts closed
    select_option(page, "Compare with", key(app, NOVEL))
    wait_until(lambda: tab.compare is not None and tab.compare.frames.done.is_set(), timeout=90,
               what="the compared rollout to load")
    tab.set_chunk(1, 4)  # where the novel prompt veers off: the two prompts' videos differ
    views = set(VIEWS)

    def compared_in_page() -> bool:
        shown = frame_sources(page)
        return {k.split("/")[0] for k in shown if k.endswith("/compare")} == views
    wait_until(compared_in_page, timeout=60, what="the compared rollout's frames in every view")
    shown = frame_sources(page)
    assert all(shown[f"{v}/compare"] != shown[f"{v}/imagined"] for v in views)


# Frames the page's playing clip of the front view has presented (None until one plays).
CLIP_FRAMES_PRESENTED = """() => {
    const v = document.querySelector("video.inspector-frame[data-view='front'][data-kind='imagined']");
    if (!v || v.paused || v.currentTime === 0) return null;
    const q = v.getVideoPlaybackQuality(); return q.totalVideoFrames - q.droppedVideoFrames; }"""


CLIP_TIME_SHOWN = """() => {
    const g = document.querySelector('.inspector-video');
    const v = g.querySelector("video.inspector-frame[data-view='front'][data-kind='imagined']");
    return {caption: g.querySelector('.inspector-time').textContent, t: v.currentTime,
            first: +g.dataset.clipFirst}; }"""


def test_playback_is_a_video_the_browser_presents_at_the_rollout_rate(browser, demo_app):
    """Playing the demo, every panel becomes a clip the browser plays by itself: it presents
    frames at the clip's rate, where stepping images manages under one a second here (WebGL in
    software). Pause brings back the images of the step playback stopped at."""
    demo = demo_app
    page, tab = new_page(browser, demo, draw_3d=False)
    open_in_page(page, tab, demo, "prompt_train")
    tab.speed = 0.5  # 15 frames/s and a 29 s clip: time to start on a busy machine
    tab.play()
    first = wait_until(lambda: page.evaluate(CLIP_FRAMES_PRESENTED), timeout=120, interval=0.05,
                       what="the playback clip to play in the page")
    start = time.monotonic()
    page.wait_for_timeout(4000)
    presented = (page.evaluate(CLIP_FRAMES_PRESENTED) or first) - first
    rate = presented / (time.monotonic() - start)
    assert rate >= 10, f"the clip presented {rate:.1f} frames/s (15 expected)"
    kinds = page.evaluate("() => [...document.querySelectorAll('video.inspector-frame')]"
                          ".map(v => v.dataset.view + '/' + v.dataset.kind).sort()")
    assert kinds == sorted(f"{p.view}/{k}" for p in tab.pairs for k in ("imagined", "gt"))
    # The time under the frames is the step the clip shows, not the step it started from. The
    # page writes it on the video's timeupdate events, which wait behind whatever the page's
    # main thread is doing (a software-WebGL frame takes 1-2 s here): look until one look finds
    # it caught up; a time line that stands still never does, as the clip plays on.
    seen = []

    def caught_up():
        shown = page.evaluate(CLIP_TIME_SHOWN)
        seen.append(shown)
        match = re.fullmatch(r"t = (\d+\.\d\d) s · step (\d+) · playing", shown["caption"])
        assert match, shown["caption"]
        assert float(match[1]) == pytest.approx(int(match[2]) / 30, abs=0.006), shown
        clip_step = shown["first"] + shown["t"] * 15  # the clip's step by its own clock, 15 frames/s
        return abs(int(match[2]) - clip_step) <= 8 and int(match[2]) > shown["first"]

    try:
        wait_until(caught_up, timeout=20, interval=0.2, what="the time line to follow the clip")
    except AssertionError as exc:
        raise AssertionError(f"{exc}; the last looks: {seen[-3:]}") from None
    tab.pause()
    wait_until(lambda: not page.evaluate("() => !!document.querySelector('video')")
               and frame_sources(page).get("front/imagined") == tab.pairs[0].imagined,
               timeout=120, what="the paused step's images")
    page.close()


def test_screenshot(browser, app, tmp_path):
    """Screenshots of the app (the 3D scene drawn): its 60-chunk rollout; with
    INSPECTOR_DOCS_SCREENSHOT=1 also the bundled demo, refreshing docs/screenshot.png, and the real
    DreamZero-SO101 outputs imported, where found, refreshing docs/imported.png."""
    from inspector.data.session import is_session
    from inspector.data.sources import BUNDLED_DEMO

    shots: list[tuple[object, str | None, Path | None]] = []
    if os.environ.get("INSPECTOR_DOCS_SCREENSHOT") and is_session(BUNDLED_DEMO):
        demo = serve([BUNDLED_DEMO], port=0, block=False)
        shots.append((demo, None, DOCS_SCREENSHOT))
    if os.environ.get("INSPECTOR_DOCS_SCREENSHOT") and real_outputs_skip_reason() is None:
        from inspector.data.importers.dreamzero_so101 import import_dreamzero

        imported = import_dreamzero(real_fixtures_dir() / "dreamzero_so101", tmp_path / "dz", log=lambda _: None)
        shots.append((serve([imported], port=0, block=False), "ep000_train", DOCS_IMPORTED))
    if not shots:
        pytest.skip("refreshes docs/ only with INSPECTOR_DOCS_SCREENSHOT=1 (the app's own screenshot: "
                    "test_one_3d_page_scene_keys_notes_and_light_3d)")
    try:
        for shot_app, tag, docs_path in shots:
            page, tab = new_page(browser, shot_app, full_resolution=True)  # the picture is the point
            hide_software_webgl_notice(page)
            # The richest view: an autoregressive rollout with GT joints if there is one.
            open_in_page(page, tab, shot_app, tag or _pick_rollout(shot_app))
            tl = tab.loaded.timeline
            tab.set_chunk(min(tl.worst_chunk()[0], tl.n_chunks - 1) if tl.kind == "autoregressive" else 0, 4)
            wait_until(lambda: tab.loaded.frames.done.is_set(), timeout=60, what="PSNR")
            page.wait_for_timeout(2500)
            out = tmp_path / (docs_path.name if docs_path is not None else "app.png")
            page.screenshot(path=str(out))
            assert canvas_is_drawn(out.read_bytes(), SCENE_BOX)
            if docs_path is not None:
                docs_path.parent.mkdir(exist_ok=True)
                docs_path.write_bytes(out.read_bytes())
            page.close()
    finally:
        for shot_app, _, _ in shots:
            shot_app.stop()


def _pick_rollout(app) -> str:
    entries = [e for e in app.catalog.entries.values() if e.error is None]
    if any(e.tag == "limits_wrist" for e in entries):  # the demo's most telling rollout
        return "limits_wrist"
    for want_ar, want_gt in ((True, True), (False, True), (True, False)):
        for e in entries:
            r = e.rollout
            has_gt = r.gt_actions is not None or e.session.dataset_root is not None
            if (r.kind == "autoregressive") == want_ar and has_gt == want_gt:
                return e.tag
    return entries[0].tag


def test_a_page_with_a_gpu_unticks_light_3d_even_before_the_tab_was_wired(browser, app, monkeypatch):
    """Every page starts plainly lit (Light 3D ticked, no environment map to set up); a page whose
    WebGL renderer is a GPU unticks it and gets the environment map. On a slow start the page's GUI
    (and its script) can untick it before the server has wired the box's callback: the tab applies
    the box's value once wired. The GPU is the page's answer to the renderer query (Chromium here
    draws in software)."""
    import inspector.app._state as state

    class SlowScene(state.TabScene):
        def __init__(self, *args, **kwargs):
            time.sleep(6)  # the panel is already in the page; its script unticks the box meanwhile
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(state, "TabScene", SlowScene)
    page = open_page(browser, 1600, 1000)
    page.add_init_script(GPU_RENDERER_JS)
    # the page looks at its WebGL renderer on a canvas of its own: the 3D view need not be drawn
    open_app(page, app.url, draw_3d=False)
    tab = page_tab(page, app)
    assert wait_until(lambda: page.evaluate("() => document.documentElement.dataset.inspectorWebgl")) == "gpu"
    wait_until(lambda: tab.controls.light_3d.value is False and tab.hemisphere_light is not None
               and not tab.hemisphere_light.visible, what="the page's scene to get its environment map")
    page.close()


def test_the_camera_is_fitted_to_the_canvas_the_page_has(browser, app):
    """The panels dock after the page first reports its canvas: the view is fitted again to the
    canvas it ends up with (before, a wide first canvas left the arms filling a narrow one), and
    again on a resize, but a camera the user has moved stays where the user put it."""
    import numpy as np

    # The canvas's shape is the point, not its pixels: drawn at the tests' pixel ratio (a quarter
    # of the pixels to draw in software), its width in pixels scales with the ratio.
    page, tab = new_page(browser, app)
    open_in_page(page, tab, app, LONG)
    camera = tab.client.camera
    narrow = 400 * float(TEST_DPR or 1)  # [px] the canvas beside the docked panels of a 1200 px page is narrower

    def fitted_to_canvas() -> bool:
        aspect = camera.image_width / camera.image_height
        return tab.scene.framed_aspect is not None and abs(tab.scene.framed_aspect - aspect) < 0.02 * aspect

    wait_until(fitted_to_canvas, what="the view fitted to the docked canvas")
    page.set_viewport_size({"width": 1200, "height": 1000})
    wait_until(lambda: camera.image_width < narrow and fitted_to_canvas(), what="the view fitted after a resize")
    moved = tuple(np.asarray(camera.position) + [0.3, 0.0, 0.1])  # as if the user orbited away
    camera.position = moved
    wait_until(lambda: np.allclose(camera.position, moved, atol=1e-4), what="the page to take the camera")
    page.set_viewport_size({"width": 1600, "height": 1000})
    wait_until(lambda: camera.image_width > narrow, what="the canvas to grow back")
    page.wait_for_timeout(2000)
    np.testing.assert_allclose(camera.position, moved, atol=1e-4)
    page.close()


def test_arms_readout_and_video_play_on_one_clock(browser, demo_app):
    """The demo at 1x with its clip playing: the step over the arms is the step of the video beside
    them (median gap at most 3 steps), from the clip's first frame to the end; Pause is answered
    within 1 s, the arms and the images on the step the clip had reached.

    The arms move only when the page draws a 3D frame (in software WebGL here, 0.1-0.3 s on a
    quiet machine, a second and more now and then on a loaded one), so between frames the readout
    stands while the video moves on: the bounds take the larger of the spec and what the page's
    own frames allow (a frame as a look at a random moment finds it; for the gap one frame's
    steps: the readout stands for up to a frame, and the lead is measured over frames whose
    length changes; for Pause, the frames an answer takes at the least). The server's own clock,
    the clock before, ran 20-160 steps ahead for the whole playback."""
    import statistics

    # The demo served for the run: its catalog and Overview rows are made by now (a fresh server
    # would make them while the clock is measured), and no other test's page is open in it (tests
    # that drive a browser run one after another).
    demo = demo_app
    page, tab = new_page(browser, demo)
    open_in_page(page, tab, demo, PLAYED_TO_THE_END)
    fps = tab.loaded.timeline.fps
    wait_until(lambda: tab.controls.light_3d.value is True, what="the page to tick Light 3D")
    tab.play()  # encode the clips once: the measured Play finds them cached
    wait_until(lambda: tab._clip is not None, timeout=180, what="the playback clips")
    tab.pause()
    tab.set_step(0)
    wait_until(lambda: page.evaluate(ARM_AND_VIDEO_STEP)["images"], timeout=60, what="the images back")

    measured = play_on_one_clock(page, tab)
    gaps, frame_s, (pause,) = measured["gaps"], measured["frame_s"], measured["pauses"]
    assert len(gaps) >= 5, f"the clip played in only {len(gaps)} looks"
    gap_bound = max(3.0, frame_s * fps)
    assert statistics.median(gaps) <= gap_bound, (
        f"median gap {statistics.median(gaps):.1f} steps (bound {gap_bound:.1f}; a 3D frame every "
        f"{frame_s * 1e3:.0f} ms); gaps: {[round(g) for g in gaps]}")
    # Pause within 1 s, or, on a page whose frames are too slow for that, within the frames an
    # answer takes at the least: the frame the press waits for, the one the server's answer
    # arrives in and the one that shows it, and one for the server on a loaded machine (a
    # software-WebGL frame takes 0.3-0.7 s under load: 3-4 frames, 0.8-1.9 s, in 20 presses)
    assert pause["s"] <= 1.0 or pause["frames"] <= PAUSE_FRAMES, (
        f"Pause answered after {pause['s']:.2f} s and {pause['frames']} animation frames "
        f"(bound 1 s, or {PAUSE_FRAMES} frames)")
    assert pause["tab_step"] == pause["step"]  # the arms are where the images are
    # it stopped where the clip was, give or take what the clip played while the press travelled
    # (a page too busy to pass the press on is as late with its last report of the clip)
    assert abs(pause["step"] - pause["clip_step"]) <= fps * pause["s"] + 3, pause
    page.close()


def test_labels_made_by_keyboard_are_in_report_from_another_process(browser, app):
    """S / F / digits / T label the open rollout at once, N opens the next unlabelled one; a
    report run as its own process reads the three labels."""
    import json
    import subprocess
    import sys

    page, tab = new_page(browser, app, draw_3d=False)
    session_root = next(e.session.root for e in app.catalog.entries.values() if e.session is not None)
    outcomes = session_root / "outcomes.json"
    outcomes.unlink(missing_ok=True)  # a clean slate (a rerun finds the last try's labels)

    def label_on_disk(tag: str) -> dict:
        try:
            return json.loads(outcomes.read_text())["rollouts"][tag]["label"]
        except (OSError, ValueError, KeyError):
            return {}

    def press(key_name: str, tag: str, field: str, value) -> None:
        page.keyboard.press(key_name)
        wait_until(lambda: label_on_disk(tag).get(field) == value, timeout=30,
                   what=f"{key_name} to save {field}={value!r} for {tag}")

    def next_loaded(previous: str | None) -> str:
        """Press N until a rollout that loads is open (a planted broken one is passed over)."""
        while True:
            page.keyboard.press("n")
            wait_until(lambda: tab.key != previous and (tab.loaded is not None or tab.error is not None),
                       what="N to open the next unlabelled rollout")
            if tab.loaded is not None and tab.loaded.entry.tag != previous:
                return tab.loaded.entry.tag
            previous = tab.key

    wait_until(lambda: tab.loaded is not None, what="the first rollout")
    labelled = {}
    first = tab.loaded.entry.tag
    press("s", first, "success", True)
    press("7", first, "progress", 70.0)
    labelled[first] = (True, 70.0, None)
    second = next_loaded(tab.key)
    press("f", second, "success", False)
    press("3", second, "progress", 30.0)
    press("t", second, "failure", "missed_grasp")  # the first tag of the taxonomy
    labelled[second] = (False, 30.0, "missed_grasp")
    third = next_loaded(tab.key)
    press("s", third, "success", True)
    press("0", third, "progress", 100.0)
    labelled[third] = (True, 100.0, None)
    assert len(labelled) == 3
    wait_until(lambda: re.search(r"\b3 of \d+ labelled", page.locator(".inspector-label-queue").first.inner_text()),
               what="the label queue to count three")
    page.close()
    done = subprocess.run([sys.executable, "-m", "inspector", "report", "--json", "-j", "1",
                           *(session_root / "rollouts" / t for t in labelled)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    rows = {r["tag"]: r["task_outcome"] for r in json.loads(done.stdout)["rollouts"]}
    assert {t: (o["success"], o["progress"], o["failure"]) for t, o in rows.items()} == labelled
    assert {o["source"] for o in rows.values()} == {"label"}
