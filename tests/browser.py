"""Helpers for driving the app in Debian Chromium through Playwright (never a downloaded browser)."""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Sequence
from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]
# Rerun's web viewer needs WebGL2: SwiftShader renders it on the CPU when there is no GPU.
SWIFTSHADER_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
SCENE_TIMEOUT_S = 60.0
# The first page of a browser compiles its WebGL shaders in software, on a machine that may be
# busy with other work: allow for it (a deadline, not a wait).
PAGE_TIMEOUT_S = 120.0


def skip_reason() -> str | None:
    """Why the browser tests cannot run here, or None."""
    if not CHROMIUM.is_file() and shutil.which("chromium") is None:
        return "Debian chromium not installed (apt-get install -y chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright Python package is not installed"
    return None


def launch(playwright, extra_args: Sequence[str] = ()):
    """Launch the system Chromium headless (``extra_args``, e.g. :data:`SWIFTSHADER_ARGS`)."""
    exe = str(CHROMIUM) if CHROMIUM.is_file() else shutil.which("chromium")
    return playwright.chromium.launch(executable_path=exe, args=[*CHROMIUM_ARGS, *extra_args], headless=True)


def open_page(browser, width: int, height: int):
    """A new page whose actions (click, fill, wait_for_selector) may take up to
    :data:`PAGE_TIMEOUT_S`: Playwright's default 30 s is too short when several software-rendered
    pages share a busy 2-core machine."""
    page = browser.new_page(viewport={"width": width, "height": height})
    page.set_default_timeout(PAGE_TIMEOUT_S * 1000)
    return page


def wait_until(condition: Callable[[], object], timeout: float = SCENE_TIMEOUT_S, interval: float = 0.1,
               what: str = "condition") -> object:
    """Poll ``condition`` until it is truthy; raise AssertionError after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(interval)


# The pixel ratio the app's 3D canvas is drawn at in tests (viser's ``fixedDpr`` URL setting):
# SwiftShader's time goes on pixels, and a page busy drawing a frame answers no input; at a
# quarter of the pixels every step, click and key of a test is answered sooner. Tests about the
# picture itself open the page at the full ratio (``full_resolution``).
TEST_DPR = os.environ.get("INSPECTOR_TEST_DPR", "0.5")


def app_url(url: str, full_resolution: bool = False) -> str:
    """``url`` with the tests' canvas pixel ratio (unless ``full_resolution``)."""
    if full_resolution or not TEST_DPR:
        return url
    return f"{url}{'&' if '?' in url else '?'}fixedDpr={TEST_DPR}"


# Tests that do not look at the 3D view move it off-screen (``draw_3d=False``): viser draws no
# frame of a canvas out of view (an IntersectionObserver), while a SwiftShader frame of the two arms
# takes ~0.5 s of a core, and viser draws one every second even when nothing moves. Nothing else
# moves: a transform leaves the page's layout as it was.
SCENE_OFF_SCREEN_JS = """
setInterval(() => {
  let e = window.__viserMutable && window.__viserMutable.canvas;
  while (e && !(e.style.position === 'relative' && e.style.zIndex === '0')) e = e.parentElement;
  if (e && e.style.transform === '') e.style.transform = 'translateX(-100000px)';
}, 100);"""


# Makes a page's WebGL renderer query (WEBGL_debug_renderer_info's UNMASKED_RENDERER_WEBGL, 0x9246)
# name a GPU, as a page with one does (an init script): the app then gives it the environment map.
GPU_RENDERER_JS = """
for (const C of [WebGLRenderingContext, WebGL2RenderingContext]) {
  const get = C.prototype.getParameter;
  C.prototype.getParameter = function (p) {
    return p === 0x9246 ? 'ANGLE (NVIDIA, NVIDIA GeForce RTX 4090 Direct3D11 vs_5_0 ps_5_0, D3D11)' : get.call(this, p);
  };
}"""


def open_app(page, url: str, full_resolution: bool = False, draw_3d: bool = True) -> None:
    """Load the app and wait until its controls and first video frames are there (the 3D view
    off-screen, never drawn, unless ``draw_3d``)."""
    if not draw_3d:
        page.add_init_script(SCENE_OFF_SCREEN_JS)
    page.goto(app_url(url, full_resolution))
    page.wait_for_selector("text=SO-101 rollout inspector", timeout=PAGE_TIMEOUT_S * 1000)
    page.wait_for_selector("canvas", timeout=PAGE_TIMEOUT_S * 1000)


def hide_software_webgl_notice(page) -> None:
    """viser warns that headless Chromium renders WebGL in software; hide it for screenshots."""
    page.add_style_tag(content="#webgl-software-rendering{display:none !important}")


def slider_thumb(page, label):
    """The thumb of the viser slider labelled ``label`` (text or regex; found via its <label for=...>)."""
    target = page.locator("label", has_text=label).first.get_attribute("for")
    return page.locator(f"[id='{target}'] [role=slider]").first


def page_client_id(page) -> int | None:
    """The viser client id of the page's current connection (a reconnect gets a new one)."""
    value = page.evaluate("() => document.querySelector('[data-inspector-client]')?.dataset.inspectorClient")
    return None if value is None else int(value)


def frame_sources(page) -> dict[str, str]:
    """``{"<view>/<kind>": src}`` of the frames the video panel shows now."""
    return page.evaluate(
        "() => Object.fromEntries([...document.querySelectorAll('img.inspector-frame')]"
        ".map(e => [e.dataset.view + '/' + e.dataset.kind, e.getAttribute('src')]))")


def select_option(page, label: str, option: str) -> None:
    """Pick ``option`` in the viser dropdown labelled ``label``."""
    page.get_by_label(label, exact=True).click()
    page.get_by_role("option", name=option, exact=True).click()


def canvas_is_drawn(png: bytes, box: tuple[int, int, int, int]) -> bool:
    """True when the screenshot region ``box`` (x0, y0, x1, y1) is not a flat colour."""
    import io

    import numpy as np
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))[box[1]:box[3], box[0]:box[2]]
    return bool(img.reshape(-1, 3).std(axis=0).max() > 8.0)


# In one look: the step the readout over the arms says and the step the playing clip shows (its
# currentTime on the clip's own clock), and what the page's last 3D frames took.
ARM_AND_VIDEO_STEP = """() => {
    const r = document.querySelector('.inspector-readout'), g = document.querySelector('.inspector-video');
    const m = r && r.textContent.match(/step (\\d+)/);
    const v = g && g.querySelector("video.inspector-frame[data-kind='imagined']");
    const playing = !!(v && !v.paused && v.currentTime > 0 && g.dataset.clipFps);
    return {arm: m ? +m[1] : null, images: !v, grid: g ? +g.dataset.step : null,
            video: playing ? +g.dataset.clipFirst + v.currentTime * +g.dataset.clipFps : null}; }"""
# ms between the page's animation frames (a frame of the 3D view each, while the arms move)
FRAME_TIMES = """() => { window.__frames = []; let p = performance.now();
    const f = (n) => { window.__frames.push(n - p); p = n; requestAnimationFrame(f); }; requestAnimationFrame(f); }"""
# ms from the user's press (the event's own time stamp, taken as the input arrived) to the first
# animation frame showing images again whose step the readout says too, and how many animation
# frames began in between (the first being the one the press waited for)
PAUSE_ANSWER = """() => { window.__answer = null; window.__pressed = null; let frames = 0;
    document.addEventListener('pointerdown', (e) => { window.__pressed = e.timeStamp; window.__answer = null; frames = 0; }, true);
    const tick = () => {
      if (window.__pressed !== null && window.__answer === null) {
        frames += 1;
        const r = document.querySelector('.inspector-readout'), g = document.querySelector('.inspector-video');
        const m = r && r.textContent.match(/step (\\d+)/);
        if (g && !g.querySelector('video') && m && +m[1] === +g.dataset.step)
          window.__answer = {ms: performance.now() - window.__pressed, step: +m[1], frames: frames};
      }
      requestAnimationFrame(tick); }; tick(); }"""


def play_on_one_clock(page, tab, presses: int = 1) -> dict:
    """Measure a page's playback clock (the app's tab ``tab`` at step 0 with the rollout open, its
    clips cached): Play pressed in the page and played to the end, looking at the readout's and
    the clip's steps together every ~50 ms; then ``presses`` times, Play from the start and Pause
    pressed (as a user clicks: at the button's place) once the clip has played 2 s.

    Returns ``{"gaps": |readout step - clip step| per look with the clip playing, "frame_s": the
    time between the page's animation frames during playback, as a look at a random moment finds
    it (:func:`time_weighted_median`) [s], "pauses": [{"s": press
    to answered [s], "frames": the animation frames that began meanwhile, the one that showed the
    answer included, "step": where it stopped, "clip_step": the clip's step at the press}]}``.
    """
    fps = tab.loaded.timeline.fps
    page.get_by_role("button", name="Play").click()
    wait_until(lambda: tab.playing, what="playback to start")
    page.evaluate(FRAME_TIMES)
    looks = []
    while tab.playing:  # to the rollout's end
        looks.append(page.evaluate(ARM_AND_VIDEO_STEP))
        time.sleep(0.05)
    gaps = [abs(look["arm"] - look["video"]) for look in looks if look["video"] is not None and look["arm"] is not None]
    frame_s = time_weighted_median(page.evaluate("() => window.__frames.splice(0)")) / 1e3
    page.evaluate(PAUSE_ANSWER)
    pauses = []
    for _ in range(presses):
        tab.set_step(0)
        wait_until(lambda: page.evaluate(ARM_AND_VIDEO_STEP)["grid"] == 0, what="the first step's images")
        page.get_by_role("button", name="Play").click()
        box = page.get_by_role("button", name="Pause").bounding_box()
        wait_until(lambda: (page.evaluate(ARM_AND_VIDEO_STEP)["video"] or 0) > 2 * fps, timeout=60, interval=0.05,
                   what="the clip to play for 2 s")
        clip_step = page.evaluate(ARM_AND_VIDEO_STEP)["video"]
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        answer = wait_until(lambda: page.evaluate("() => window.__answer"), timeout=60, interval=0.05,
                            what="Pause to bring back the images and the readout of one step")
        wait_until(lambda: not tab.playing, what="the tab to pause")
        pauses.append({"s": answer["ms"] / 1e3, "frames": answer["frames"], "step": answer["step"],
                       "clip_step": clip_step, "tab_step": tab.step})
    return {"gaps": gaps, "frame_s": frame_s, "pauses": pauses}


def time_weighted_median(durations: Sequence[float]) -> float:
    """The duration half of the time is spent in intervals at least as long as: what a look at a
    random moment finds (a page that stalls for a second now and then spends much of its time in
    those seconds, which the plain median of its frame times hides)."""
    ordered = sorted(durations)
    total, seen = sum(ordered), 0.0
    for d in ordered:
        seen += d
        if seen >= total / 2:
            return d
    return 0.0
