"""What a viewer shows: an exported recording, shared as a file on a web server, opened by its URL
in Rerun's web viewer (``rerun --serve-web URL``) in headless Chromium, WebGL in software, and both
arms found on the screenshot."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_export import _gt_path, _slow_prediction

from inspector.analysis.timeline import build_timeline
from inspector.data.session import SessionWriter, open_session
from inspector.export.recording import write_recording

RERUN = Path(sys.executable).parent / "rerun"
ARM_CHAIN = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll")


def _listening_on(port: int) -> bool:
    import socket

    with socket.socket() as s:
        s.settimeout(2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def viewer_recording(tmp_path_factory) -> Path:
    """A rollout with GT joints and no video: in the viewer, the only large yellow and blue areas
    are the two arms (the GT arm is opaque yellow, the prediction translucent blue)."""
    from inspector.data.session import is_session
    from inspector.data.sources import BUNDLED_DEMO

    if os.environ.get("INSPECTOR_DOCS_SCREENSHOT") and is_session(BUNDLED_DEMO):  # docs: the demo's
        tl = build_timeline(open_session(BUNDLED_DEMO).rollouts["limits_wrist"])
        return write_recording(tl, tmp_path_factory.mktemp("rrd") / "limits_wrist.rrd")
    gt = _gt_path(120)
    root = tmp_path_factory.mktemp("viewer") / "session"
    with SessionWriter.create(root, model={"name": "synthetic-wam"}) as w:
        w.add_rollout("reach", kind="autoregressive", actions=_slow_prediction(gt, 8, speed=0.6),
                      prompt="Reach", gt_actions=gt, gt_episode_length=120)
    tl = build_timeline(open_session(root).rollouts["reach"])
    return write_recording(tl, tmp_path_factory.mktemp("rrd") / "reach.rrd")


DOCS_VIEWER = Path(__file__).resolve().parents[1] / "docs" / "rerun_viewer.png"


class _SharedFiles:
    """A folder served over HTTP on loopback, readable from any origin (CORS), as a recording
    shared on a web server is: the web viewer, served from another port, fetches it from there."""

    def __init__(self, folder: Path) -> None:
        import functools
        import threading
        from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

        class Handler(SimpleHTTPRequestHandler):
            def end_headers(self) -> None:
                self.send_header("Access-Control-Allow-Origin", "*")
                super().end_headers()

            def log_message(self, *args) -> None:  # quiet: the test's output is its findings
                pass

        self._server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(folder)))
        self.port = self._server.server_address[1]
        threading.Thread(target=self._server.serve_forever, name="shared-files", daemon=True).start()

    def url(self, name: str) -> str:
        return f"http://127.0.0.1:{self.port}/{name}"

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()


def _rerun_binary() -> Path:
    """The viewer binary itself: the ``rerun`` script only starts it as a child of its own, and
    stopping the script would leave the viewer running."""
    import rerun_cli

    binary = Path(rerun_cli.__file__).parent / "rerun"
    return binary if binary.is_file() else RERUN


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the test process dies, so no viewer outlives it."""
    import ctypes
    import signal

    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def _stop_group(proc: subprocess.Popen) -> None:
    """Stop ``proc`` and whatever it started (it leads its own process group)."""
    import signal

    for sig, wait_s in ((signal.SIGTERM, 10), (signal.SIGKILL, 10)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait_s)
            break
        except subprocess.TimeoutExpired:
            continue


def _first_error_line(log: Path) -> str:
    """The line of a log that says what went wrong (not the tail of a backtrace)."""
    import re

    lines = [re.sub(r"\x1b\[[0-9;]*m", "", line).strip() for line in log.read_text(errors="replace").splitlines()]
    lines = [line for line in lines if line]
    for line in lines:
        if re.search(r"\bERROR\b|\berror\b|panicked|Failed", line):
            return line[:300]
    return lines[-1][:300] if lines else "no output"


def _arm_pixels(png: bytes) -> tuple[int, int, tuple[float, float]]:
    """(GT-yellow pixels, prediction-blue pixels near them, where the yellow is) in a screenshot.

    Yellow: the hue of the GT arm (``GT_RGBA``, shaded), saturated. Blue: the translucent
    prediction over a light background (hue ~215 deg, weakly saturated), counted only inside the
    box around the yellow pixels widened by half, i.e. in the 3D view, not in the side panels.
    Where: the yellow pixels' centre as fractions of the page's width and height.
    """
    import io

    from PIL import Image

    hsv = np.asarray(Image.open(io.BytesIO(png)).convert("HSV")).astype(int)
    h, s, v = hsv[..., 0] * 360 // 255, hsv[..., 1], hsv[..., 2]
    yellow = (h >= 33) & (h <= 50) & (s > 140) & (v > 90)
    if yellow.sum() == 0:
        return 0, 0, (float("nan"), float("nan"))
    ys, xs = np.nonzero(yellow)
    y0, y1, x0, x1 = ys.min(), ys.max(), xs.min(), xs.max()
    dy, dx = (y1 - y0) // 2, (x1 - x0) // 2
    box = (slice(max(0, y0 - dy), y1 + dy + 1), slice(max(0, x0 - dx), x1 + dx + 1))
    blue = (h[box] >= 195) & (h[box] <= 235) & (s[box] > 40) & (v[box] > 120)
    return int(yellow.sum()), int(blue.sum()), (xs.mean() / h.shape[1], ys.mean() / h.shape[0])


@pytest.mark.slow
@pytest.mark.browser
def test_web_viewer_draws_both_arms(viewer_recording, tmp_path, playwright):
    """Share an exported recording as a file on a web server and open it by its URL in Rerun's web
    viewer (``rerun --serve-web URL``, loopback only) in Debian Chromium, WebGL2 rendered by
    SwiftShader, and look at the 3D view: the opaque yellow
    GT arm and the translucent blue prediction must both be drawn (an arm whose URDF root is not
    tied to the view's frame leaves the view empty), in the top-left of the page where the
    recording's own layout puts the 3D view (a viewer that ignores it lays views out by
    heuristics, with side panels open). The last screenshot is kept as ``<tmp_path>/viewer.png``."""
    import urllib.parse
    import urllib.request

    from browser import PAGE_TIMEOUT_S, SWIFTSHADER_ARGS, launch, wait_until

    # By URL, not ``rerun --serve-web FILE``: that serves the file over gRPC, which (rerun 0.41)
    # keeps a core busy for as long as it runs, a third of what this test would cost.
    shared = _SharedFiles(viewer_recording.parent)
    rrd_url = shared.url(viewer_recording.name)
    web_port = _free_port()
    log = tmp_path / "rerun.log"
    with open(log, "wb") as out:
        viewer = subprocess.Popen(
            [str(_rerun_binary()), rrd_url, "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(web_port)],
            stdout=out, stderr=subprocess.STDOUT, preexec_fn=_die_with_parent, start_new_session=True)
    try:
        def web_viewer_answers() -> bool:
            if viewer.poll() is not None:
                pytest.skip(f"rerun --serve-web exited ({viewer.returncode}): {_first_error_line(log)}")
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=5) as response:
                    return response.status == 200
            except OSError:
                return False

        wait_until(web_viewer_answers, timeout=120, interval=0.5, what="rerun's web viewer to answer")
        browser = launch(playwright, SWIFTSHADER_ARGS)  # its own: WebGL2 needs SwiftShader
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            if not page.evaluate("() => !!document.createElement('canvas').getContext('webgl2')"):
                pytest.skip("Chromium has no WebGL2, even with SwiftShader (--use-angle=swiftshader)")
            page.goto(f"http://127.0.0.1:{web_port}/?url={urllib.parse.quote(rrd_url, safe='')}")
            page.wait_for_selector("canvas", timeout=PAGE_TIMEOUT_S * 1000)
            shot = tmp_path / "viewer.png"
            found: tuple = (0, 0, None)

            def both_arms_drawn() -> bool:
                nonlocal found
                # Software WebGL on a busy machine: one frame may take many seconds.
                png = page.screenshot(timeout=180_000)
                shot.write_bytes(png)
                found = _arm_pixels(png)
                return found[0] > 1500 and found[1] > 800

            try:
                wait_until(both_arms_drawn, timeout=420, interval=2.0, what="both arms in the 3D view")
            except AssertionError as exc:
                raise AssertionError(f"{exc}; last (yellow, blue, centre): {found}; see {shot}") from None
            yellow, blue, (x, y) = found
            assert x < 0.5 and y < 0.5, f"the arms are not in the layout's 3D view (top left): {found}, see {shot}"
            if os.environ.get("INSPECTOR_DOCS_SCREENSHOT"):
                page.wait_for_timeout(5000)  # the video panels, decoded after the arms
                DOCS_VIEWER.parent.mkdir(exist_ok=True)
                DOCS_VIEWER.write_bytes(page.screenshot(timeout=180_000))
        finally:
            browser.close()
    finally:
        _stop_group(viewer)
        shared.close()
    assert not _listening_on(web_port), "the viewer outlived the test"
