"""Imagined and GT video frames of one rollout, decoded in the background and served as JPEG.

Decoding a 540-frame view (imagined + GT) takes about a second, so a rollout opens at once and its
views arrive as they finish ("loading" until then). Each frame is JPEG-encoded on first display and
kept, so scrubbing back and forth never encodes twice. PSNR per view comes from the shared
timeline (``RolloutTimeline.video_metrics``) once both clips of the view are decoded.
"""

from __future__ import annotations

import base64
import io
import threading
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..timeline import RolloutTimeline

LOADING = "loading"
READY = "ready"
JPEG_QUALITY = 80


@dataclass
class FramePair:
    """What the video panel shows for one view at one step.

    Attributes:
        view: camera name.
        status: ``"loading"``, ``"ready"`` or an error message (one line).
        imagined_index: imagined frame shown (index into the view's clip).
        imagined: JPEG data URI, or None while loading / on error.
        gt: JPEG data URI of the GT frame at the same time, or None (loading, no GT view, or past
            the real episode's end; ``gt_note`` says which).
        gt_note: why there is no GT frame, or "".
        psnr_db: PSNR of this pair [dB], or None (not computed yet or no GT frame).
    """

    view: str
    status: str
    imagined_index: int
    imagined: str | None = None
    gt: str | None = None
    gt_note: str = ""
    psnr_db: float | None = None


class FrameStore:
    """Frames of one rollout's views, shared by every tab that shows the rollout.

    Args:
        timeline: the rollout's shared timeline.
        executor: where decoding runs (a small pool shared by the app).
    """

    def __init__(self, timeline: RolloutTimeline, executor: Executor) -> None:
        self.timeline = timeline
        self.views: list[str] = list(timeline.rollout.views)
        self.status: dict[str, str] = {v: LOADING for v in self.views}  # imagined clips
        self.gt_status: dict[str, str] = {v: LOADING for v in self.views}  # GT clips
        self.psnr: dict[str, npt.NDArray[np.float64] | None] = {v: None for v in self.views}
        self._executor = executor
        self._jpeg: dict[tuple[str, str, int], str] = {}
        self._lock = threading.Lock()
        self._listeners: list[Callable[[], None]] = []
        self._started = False
        self.decoded = threading.Event()  # every clip decoded (or failed): ready to scrub
        self.done = threading.Event()  # ... and every view's PSNR computed

    # -- background work ----------------------------------------------------------------------
    def start(self) -> None:
        """Queue the decodes (idempotent). Listeners hear about every clip and PSNR that finishes.

        Imagined and GT clips are separate jobs, so two workers stay busy to the end (three views
        as three two-clip jobs would leave one worker idle for the last view).
        """
        with self._lock:
            if self._started:
                return
            self._started = True
            self._pending = len(self.views)
            self._halves = {v: 2 for v in self.views}  # clips still decoding per view
            self._clips_left = 2 * len(self.views)
        if not self.views:
            self.decoded.set()
            self.done.set()
            return
        for view in self.views:
            self._executor.submit(self._load_clip, view, False)
            self._executor.submit(self._load_clip, view, True)

    def _load_clip(self, view: str, gt: bool) -> None:
        tl = self.timeline
        if not gt:
            self.status[view] = _attempt(lambda: tl.rollout.video(view).load())
        elif view in tl.gt.views:
            self.gt_status[view] = _attempt(lambda: tl.gt.clips[view].frames)  # decode now, not on a scrub
        else:
            self.gt_status[view] = "no GT video for this view"
        with self._lock:
            self._clips_left -= 1
            if self._clips_left == 0:
                self.decoded.set()
        self._notify()
        with self._lock:
            self._halves[view] -= 1
            if self._halves[view]:
                return  # the view's other clip finishes the view
        if self.status[view] == READY and self.gt_status[view] == READY:
            try:
                self.psnr[view] = tl.video_metrics(view).psnr_db
            except Exception:
                self.psnr[view] = None  # frames still show; only the PSNR is missing
            self._notify()
        with self._lock:
            self._pending -= 1
            finished = self._pending == 0
        if finished:
            self.done.set()
            self._notify()

    def add_listener(self, fn: Callable[[], None]) -> None:
        with self._lock:
            self._listeners.append(fn)

    def remove_listener(self, fn: Callable[[], None]) -> None:
        with self._lock:
            self._listeners = [f for f in self._listeners if f is not fn]

    def _notify(self) -> None:
        with self._lock:
            listeners = list(self._listeners)
        for fn in listeners:
            try:
                fn()
            except Exception:
                pass  # a tab that went away must not break the decoder

    # -- lookups on the scrub path (never decode) ---------------------------------------------
    def pair(self, view: str, step: int) -> FramePair:
        """The imagined frame of ``view`` at ``step`` and the GT frame at the same time."""
        tl = self.timeline
        f = tl.frame_index(step)
        status = self.status.get(view, LOADING)
        out = FramePair(view=view, status=status, imagined_index=f)
        if status != READY:
            return out
        clip = tl.rollout.video(view)
        f = int(min(f, len(clip) - 1))
        out.imagined_index = f
        out.imagined = self._cached(view, "imagined", f, lambda: clip.frames[f])
        if self.gt_status[view] != READY:
            out.gt_note = self.gt_status[view]
            return out
        gt_frame = tl.gt.frame(view, f, step)
        if gt_frame is None:
            out.gt_note = "past the real episode's end"
            return out
        out.gt = self._cached(view, "gt", step, lambda: gt_frame)
        psnr = self.psnr.get(view)
        if psnr is not None and f < len(psnr) and np.isfinite(psnr[f]):
            out.psnr_db = float(psnr[f])
        return out

    def _cached(self, view: str, kind: str, index: int, frame: Callable[[], np.ndarray]) -> str:
        key = (view, kind, index)
        uri = self._jpeg.get(key)
        if uri is None:
            uri = jpeg_data_uri(frame())
            self._jpeg[key] = uri  # a race only encodes the same frame twice
        return uri


def jpeg_data_uri(frame: npt.NDArray[np.uint8], quality: int = JPEG_QUALITY) -> str:
    """(H, W, 3) uint8 RGB -> ``data:image/jpeg;base64,...`` (~0.4 ms for 320x176)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(frame)).save(buf, "JPEG", quality=quality)
    return "data:image/jpeg;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _attempt(load: Callable[[], object]) -> str:
    """Run a decode: READY, or the error as one line (one broken video never stops the others)."""
    try:
        load()
        return READY
    except Exception as exc:
        return _one_line(exc)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__
