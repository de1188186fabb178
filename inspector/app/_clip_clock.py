"""One clock for playback: the arms, readout and plot cursors follow the clip the page plays.

A playback clip (see ``._playback_clip``) starts in the page a second or more after the server
swaps it in (the page parses a few MB of video, then the browser decodes its first frames), and it
runs on the browser's media clock from then on. A server stepping the arms on its own clock from
Play ran that far ahead of the video beside them for the whole playback. So the page tells the
server where its clip is: a script reads the playing ``<video>``'s ``currentTime`` ten times a
second and writes it, with the clip's id, into a text field kept out of sight ("Clip clock"), whose
value viser sends to the server like any control's. The server holds the step it swapped the clip
in at until the clip plays, then steps to where the clip is (between reports, ahead at the clip's
rate). A page that never reports (a client without the script, a browser that does not play the
clip) keeps the server's own clock, as does a page whose clip falls silent.

The field sits in the right panel: viser sends each panel's control values through one sender that
keeps only the latest message of any 50 ms, so the script also stays quiet for a moment after the
user touches anything, and never stands in for a change the user made there.
"""

from __future__ import annotations

import json
import math
import statistics
import time
from collections import deque
from dataclasses import dataclass

from ._page_script import page_script_html

CLIP_CLOCK_LABEL = "Clip clock"
# A page that has not said its new clip plays after this long never will (autoplay refused, say),
# and one silent this long is gone: the server's own clock runs on from where playback is.
SILENT_AFTER_S = 4.0
# A step behind the one shown by more than this is taken (the page's clip restarted, or the server
# ran on its own clock meanwhile); a smaller one is jitter in the reports, and the arms never step back.
BACK_STEPS = 5
# The page shows a step some time after the server sends it (a 3D frame in software WebGL takes
# 0.1-0.5 s, more on a loaded machine, and the readout and arms land together after one): the
# server sends the step the clip will be at by then. The page reports the step its readout shows;
# how long ago the server sent that step is the lag, and the lead is the median of the last
# LAG_REPORTS lags (measured, not corrected in a loop: a lead never changes the lag it is measured
# by), at most MAX_LEAD_S. With a GPU it stays near the websocket's few ms.
LAG_REPORTS = 8
MAX_LEAD_S = 3.0
# Off: the server's clock only, as before (the benchmark's baseline).
ENABLED = True

# The page's side. Reports are JSON: {"clip": id, "t": currentTime [s], "playing": bool,
# "ended": bool, "shown": the readout's step, "n": a counter (a value that changes is sent)};
# {"clip": null} once per connection says the page keeps this clock.
_CLIP_CLOCK_JS = r"""
const LABEL = __LABEL__;
const setValue = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, 'value').set;
let userAt = -1e9, sentAt = -1e9, n = 0, client = null, last = '';
for (const type of ['pointerdown', 'keydown', 'input', 'change', 'wheel']) {
  document.addEventListener(type, (e) => { if (e.isTrusted) userAt = performance.now(); }, true);
}
const field = () => {
  const label = [...document.querySelectorAll('label')].find((l) => l.textContent.trim() === LABEL);
  let row = label && label.parentElement;
  while (row && !row.querySelector('input')) row = row.parentElement;
  if (!row) return null;
  const box = row.parentElement || row;
  if (box.style.display !== 'none') box.style.display = 'none';
  return row.querySelector('input');
};
const report = () => {
  const input = field();
  const now = performance.now();
  if (!input || now - userAt < 200 || now - sentAt < 90) return;
  const id = document.querySelector('[data-inspector-client]')?.dataset.inspectorClient;
  const grid = document.querySelector('.inspector-video[data-clip-id]');
  const video = grid && grid.querySelector('video.inspector-frame');
  let state;
  if (video) {
    const playing = !video.paused && !video.seeking && video.readyState >= 3;
    const shown = document.querySelector('.inspector-readout[data-step]');
    state = {clip: +grid.dataset.clipId, t: video.currentTime, playing: playing, ended: video.ended,
             shown: shown ? +shown.dataset.step : null};
  } else if (id !== client) {
    state = {clip: null};
  } else return;
  const key = JSON.stringify(state);
  if (key === last && !(state.playing)) return;
  last = key;
  client = id;
  state.n = ++n;
  sentAt = now;
  setValue.call(input, JSON.stringify(state));
  input.dispatchEvent(new Event('input', {bubbles: true}));
};
setInterval(report, 100);
document.addEventListener('playing', report, true);
""".replace("__LABEL__", json.dumps(CLIP_CLOCK_LABEL))

CLIP_CLOCK_HTML = page_script_html("clip_clock", _CLIP_CLOCK_JS)


@dataclass(frozen=True)
class ClipTime:
    """One report of the page's clip: its time ``t_s`` on the clip's own clock [s] at
    ``received`` (``time.monotonic()``), and whether it was playing or had ended."""

    clip: int
    t_s: float
    playing: bool
    ended: bool
    received: float
    shown: int | None = None  # the step the page's readout showed at the same moment


def parse_report(text: str, received: float) -> ClipTime | None | bool:
    """A report from the page: its ClipTime, True for the page's hello (``{"clip": null}``), or
    None for anything else (the field is the page's to write: never trusted)."""
    try:
        data = json.loads(text)
    except ValueError:
        return None
    if not isinstance(data, dict):
        return None
    clip = data.get("clip")
    if clip is None:
        return True
    t = data.get("t")
    if (not isinstance(clip, int) or isinstance(clip, bool) or not isinstance(t, (int, float))
            or isinstance(t, bool) or not math.isfinite(t) or t < 0):
        return None
    shown = data.get("shown")
    shown = shown if isinstance(shown, int) and not isinstance(shown, bool) else None
    return ClipTime(clip, float(t), data.get("playing") is True, data.get("ended") is True, received, shown)


class ClipClock:
    """Where the page's playing clip is, from its reports (see the module docstring).

    :meth:`shown` starts following a clip swapped in; :meth:`step` says which step playback is at
    by that clip, or None where the server's own clock is to run.
    """

    def __init__(self) -> None:
        self.page_reports = False  # the page said it keeps this clock
        self._clip: int | None = None
        self._start = self._end = self._held = 0
        self._fps = 0.0
        self._shown_at = 0.0
        self._last: ClipTime | None = None
        self.lead_s = 0.0  # how far ahead of the clip the server sends the step (see LAG_REPORTS)
        self._sent: dict[int, float] = {}  # step -> when the play loop sent it, for this clip
        self._lags: deque[float] = deque(maxlen=LAG_REPORTS)  # the page's lag outlives a clip

    def shown(self, clip: int, start: int, end: int, fps: float, step: int, now: float | None = None) -> None:
        """Clip ``clip`` (steps ``start``..``end`` - 1 at ``fps`` frames/s) went to the page,
        to start at ``step``."""
        self._clip, self._start, self._end, self._fps, self._held = clip, start, end, fps, step
        self._shown_at = time.monotonic() if now is None else now
        self._last = None
        self._sent = {}

    def sent(self, step: int, now: float) -> None:
        """The play loop sent ``step`` to the page at ``now`` (``time.monotonic()``)."""
        if self._clip is not None:
            self._sent[step] = now

    def stop(self) -> None:
        """No clip plays (paused, images back)."""
        self._clip, self._last = None, None

    def report(self, text: str, received: float | None = None) -> bool:
        """Take the page's report; True when it is about the clip being followed."""
        got = parse_report(text, time.monotonic() if received is None else received)
        if got is None:
            return False
        self.page_reports = True
        if got is True or got.clip != self._clip:  # type: ignore[union-attr]
            return False
        assert isinstance(got, ClipTime)
        self._last = got
        sent = self._sent.get(got.shown) if got.playing and got.shown is not None else None
        if sent is not None:
            self._lags.append(got.received - sent)
            self.lead_s = min(max(statistics.median(self._lags), 0.0), MAX_LEAD_S)
        return True

    def step(self, now: float | None = None, lead: bool = True) -> int | None:
        """The step the page's clip shows at ``now`` (``time.monotonic()``; ``lead``: plus the
        page's display lag), the step to hold at while it starts, or None: the server's clock runs
        (no clip, a page that does not report, or one silent for SILENT_AFTER_S)."""
        if self._clip is None or not self.page_reports or not ENABLED:
            return None
        now = time.monotonic() if now is None else now
        last = self._last
        if last is None:  # swapped in, not playing yet in the page
            return self._held if now - self._shown_at < SILENT_AFTER_S else None
        if now - last.received > SILENT_AFTER_S:
            return None
        if last.ended:
            return self._end
        # A playing clip plays on while the page is too busy to say so (its video is decoded and
        # presented off the page's main thread): ahead at the clip's rate since the last report.
        ahead = now - last.received + (self.lead_s if lead else 0.0) if last.playing else 0.0
        step = self._start + math.floor((last.t_s + ahead) * self._fps + 1e-3)
        return max(self._start, min(step, self._end))

    @staticmethod
    def follow(current: int, clip_step: int) -> int:
        """The step to show: the clip's, except a few steps back (report jitter: hold instead)."""
        return clip_step if clip_step >= current or clip_step < current - BACK_STEPS else current
