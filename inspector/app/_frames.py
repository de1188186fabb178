"""Video frames for the browser: decoded in the background, kept only as the JPEGs it is sent.

One :class:`FrameCache` serves the whole server: JPEG data URIs at display size under a byte
budget (``inspector serve --cache-mb``), least recently used evicted first, across rollouts and
tabs. No decoded frame outlives the moment it is encoded, so memory follows the budget, not the
number of rollouts ever opened.

A rollout's :class:`FrameStore` fills the cache one view at a time: a worker streams the
imagined clip and its GT clip together (:func:`inspector.analysis.video_metrics.compare_clips`),
JPEG-encodes every frame as it passes and computes the view's PSNR on the way, so one decode
serves both. Reopening a recently seen rollout finds its frames in the cache; frames evicted
since are decoded again in the background. The scrub path only looks frames up.

The frame match of video-action agreement comes after: on the way it would delay the moment the
rollout can be scrubbed (see the ``open`` note in benchmarks/README.md), so once every view's frames are in, one worker
computes each view's video metrics as the report does (:meth:`RolloutTimeline.video_metrics`)
and the agreement plot fills in. A rollout no tab shows any more is not matched until one does.
"""

from __future__ import annotations

import base64
import itertools
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from ..analysis.timeline import RolloutTimeline
from ..analysis.video_metrics import compare_clips, resizes_whole_frame
from ..data.video import fit_size
from ..errors import InspectorError
from . import DEFAULT_FRAME_CACHE_MB
from ._listeners import Listeners, Notifying
from ._overlay import ArmOverlay

LOADING = "loading"
READY = "ready"
JPEG_QUALITY = 80
# The widest frame the video panel shows [px]; larger clips are scaled down before encoding.
DISPLAY_MAX_WIDTH = 640


class FrameCache:
    """JPEG data URIs by key, least recently used evicted beyond ``budget_bytes``. Thread-safe.

    Attributes:
        hits, misses, evictions: counters (for tests and the benchmark).
    """

    def __init__(self, budget_bytes: int = DEFAULT_FRAME_CACHE_MB * 2**20) -> None:
        self.budget_bytes = int(budget_bytes)
        self._items: OrderedDict[Hashable, str] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        self.hits = self.misses = self.evictions = 0

    @property
    def bytes(self) -> int:
        """What the cached URIs take [bytes]."""
        return self._bytes

    def __len__(self) -> int:
        return len(self._items)

    def get(self, key: Hashable) -> str | None:
        with self._lock:
            uri = self._items.get(key)
            if uri is None:
                self.misses += 1
                return None
            self._items.move_to_end(key)
            self.hits += 1
            return uri

    def __contains__(self, key: Hashable) -> bool:
        with self._lock:
            return key in self._items

    def touch(self, key: Hashable) -> bool:
        """Mark ``key`` as just used, if it is cached (without counting a hit): a frame a fill
        passes belongs to the rollout being opened, so it must not be the next one evicted."""
        with self._lock:
            if key not in self._items:
                return False
            self._items.move_to_end(key)
            return True

    def put(self, key: Hashable, uri: str) -> None:
        """Keep ``uri``; an entry larger than the whole budget is not kept at all."""
        size = len(uri)
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self._bytes -= len(old)
            if size > self.budget_bytes:
                return
            self._items[key] = uri
            self._bytes += size
            while self._bytes > self.budget_bytes:
                _, evicted = self._items.popitem(last=False)
                self._bytes -= len(evicted)
                self.evictions += 1


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
        has_imagined: False for a view with GT frames only (a dataset camera).
        gt_index: the GT frame shown, for a view with GT frames only.
        imagined_overlay, gt_overlay: the arms drawn over each frame (PNG data URIs, see
            :mod:`._overlay`), or None (not asked for, or the view has no camera).
    """

    view: str
    status: str
    imagined_index: int
    imagined: str | None = None
    gt: str | None = None
    gt_note: str = ""
    psnr_db: float | None = None
    has_imagined: bool = True
    gt_index: int | None = None
    imagined_overlay: str | None = None
    gt_overlay: str | None = None


_STORE_TOKENS = itertools.count()


class FrameStore(Notifying):
    """Frames of one rollout's views, shared by every tab that shows the rollout.

    A view has an imagined clip, a GT clip, or both; a dataset episode's cameras (and a dataset
    camera the model does not imagine) have only GT frames.

    Args:
        timeline: the rollout's shared timeline.
        executor: where decoding runs (a small pool shared by the app).
        cache: the server's frame cache.
        on_video_metrics: called with each view's :class:`~inspector.analysis.video_metrics.VideoMetrics`
            once computed (the app stores them in the metrics cache).
        matcher: where the frame matches run (default: ``executor``); one worker keeps them from
            holding up other rollouts' frames.
    """

    def __init__(self, timeline: RolloutTimeline, executor: Executor, cache: FrameCache,
                 on_video_metrics: Callable[[Any], None] | None = None,
                 matcher: Executor | None = None) -> None:
        self.timeline = timeline
        imagined = list(timeline.rollout.views)
        self.views: list[str] = imagined + [v for v in timeline.gt.views if v not in imagined]
        self.imagined_views = set(imagined)
        self.status: dict[str, str] = {v: LOADING for v in self.views}  # the view's frames
        self.gt_status: dict[str, str] = {v: (LOADING if v in timeline.gt.clips else "no GT video for this view")
                                          for v in self.views}
        known = timeline.known_video_metrics()
        self.psnr: dict[str, npt.NDArray[np.float64] | None] = {
            v: known[v].psnr_db if v in known else None for v in self.views}
        self._executor = executor
        self._matcher = matcher if matcher is not None else executor
        self._cache = cache
        self._on_video_metrics = on_video_metrics
        self._lock = threading.Lock()
        self._listeners = Listeners()
        self._filling: set[str] = set()
        self._framed: set[str] = set()  # views whose frames are all in the cache
        self._finished: set[str] = set()  # ... and whose video metrics are known (or failed, or has none)
        self._unmatched: set[str] = set()  # framed, with PSNR, the frame match still to compute
        self._matching: set[str] = set()  # ... being computed now
        self.match_errors: dict[str, str] = {}  # views whose frame match failed: why, in one line
        self._sizes: dict[str, tuple[int, int]] = {}
        self.decoded = threading.Event()  # every view's frames are in the cache: ready to scrub
        self.done = threading.Event()  # ... and every view's PSNR and frame match are known (or failed)
        self.token = next(_STORE_TOKENS)  # names this store's entries in the cache (playback clips)
        self._started = False
        try:  # the arms drawn into the frames of views with a camera; a bad camera never stops the frames
            self.overlay: ArmOverlay | None = ArmOverlay.of(timeline)
        except Exception:
            self.overlay = None

    @property
    def started(self) -> bool:
        """:meth:`start` was called (the views are decoding, or done)."""
        return self._started

    @property
    def cache(self) -> FrameCache:
        """The server's frame cache this store fills (playback clips are kept there too)."""
        return self._cache

    def _compared(self, view: str) -> bool:
        """The view has both imagined and GT frames: its fill computes PSNR."""
        return view in self.imagined_views and view in self.timeline.gt.clips

    # -- background work ----------------------------------------------------------------------
    def start(self) -> None:
        """Fill the cache with every view's frames. A view whose frames are still cached is ready
        at once (a recently seen rollout reopens instantly); its video metrics are computed if
        not known yet. Later calls do nothing."""
        with self._lock:
            if self._started:
                return
            self._started = True
        known = self.timeline.known_video_metrics()
        for view in self.views:
            if self._frames_cached(view):
                self.status[view] = READY
                if view in self.timeline.gt.clips:
                    self.gt_status[view] = READY
                if self._compared(view) and view not in known:
                    with self._lock:
                        self._unmatched.add(view)  # the match computes the PSNR too
                self._view_framed(view)
                if view not in self._unmatched:
                    self._view_finished(view)
                continue
            self._fill(view)
        if not self.views:
            self.decoded.set()
            self.done.set()

    def _frames_cached(self, view: str) -> bool:
        """The view's first and last frames are in the cache (the least recently used go first,
        so the rest are too, or come back on a miss)."""
        tl = self.timeline
        try:
            size = self.display_size(view)
            imagined_key, gt_key = self._keys(view)
            wanted = []
            if view in self.imagined_views:
                n = len(tl.rollout.video(view))
                wanted += [(*imagined_key, 0, size), (*imagined_key, n - 1, size)]
            if view in tl.gt.clips:
                wanted += [(*gt_key, 0, size), (*gt_key, tl.gt.frames_in_clip(view) - 1, size)]
        except Exception:
            return False
        return all(k in self._cache for k in wanted)

    def _fill(self, view: str) -> None:
        with self._lock:
            if view in self._filling:
                return
            self._filling.add(view)
        self._executor.submit(self._fill_view, view)

    def _fill_view(self, view: str) -> None:
        """Stream the view's clips into the cache, computing PSNR on the way where it has both."""
        tl = self.timeline
        gt_clip = tl.gt.clips.get(view)
        imagined_key, gt_key = self._keys(view)
        imagined_clips = [tl.rollout.video(view)] if view in self.imagined_views else []

        # the imagined gripper is tracked on the way (a view with a fixed camera)
        track = self.overlay.tracker_feed(view) if self.overlay is not None and imagined_clips else None

        def imagined(_: int, f: int, rgb: npt.NDArray[np.uint8]) -> None:
            self._store(view, (*imagined_key, f), rgb)
            if track is not None:
                track(f, rgb)

        def gt_frame(i: int, rgb: npt.NDArray[np.uint8]) -> None:
            self._store(view, (*gt_key, i), rgb)

        def run(with_gt: bool):
            results = compare_clips(view, imagined_clips, gt_clip if with_gt else None,
                                    tl.gt_index_of_frame(view) if with_gt else (lambda f: -1),
                                    on_imagined=imagined, on_gt=gt_frame if with_gt else None, match=False,
                                    whole_frame=resizes_whole_frame(tl.rollout.extra))
            return results[0] if results else None

        try:
            vm = run(with_gt=gt_clip is not None)
            self.status[view] = READY
            if gt_clip is not None:
                self.gt_status[view] = READY
            if vm is not None and self._compared(view):
                self.psnr[view] = vm.psnr_db
                if view not in tl.known_video_metrics():
                    with self._lock:
                        self._unmatched.add(view)
        except InspectorError as exc:
            if gt_clip is not None and exc.file == str(gt_clip.path) and imagined_clips:
                # a broken GT clip: the imagined frames still show, without their GT
                self.gt_status[view] = _one_line(exc)
                try:
                    run(with_gt=False)
                    self.status[view] = READY
                except Exception as again:
                    self.status[view] = _one_line(again)
            else:
                self.status[view] = _one_line(exc)
        except Exception as exc:  # one broken video never stops the others
            self.status[view] = _one_line(exc)
        with self._lock:
            self._filling.discard(view)
            unmatched = view in self._unmatched
        self._view_framed(view)
        if unmatched:
            self._notify()  # its frames and PSNR show now; the match follows
        else:
            self._view_finished(view)

    # -- the frame match, once every view's frames are in -----------------------------------
    def add_listener(self, fn: Callable[[], None]) -> None:
        super().add_listener(fn)
        self._match_unmatched()  # a tab shows the rollout again: finish what was left

    def _match_unmatched(self) -> None:
        """Queue the frame match of each view that waits for one, once every view's frames are in
        (they come first) and while a tab shows the rollout."""
        if not self.decoded.is_set() or not self._listeners:
            return
        with self._lock:
            todo = sorted(self._unmatched - self._matching)
            self._matching.update(todo)
        for view in todo:
            try:
                self._matcher.submit(self._match_view, view)
            except RuntimeError:  # the server is stopping: nothing more runs
                return

    def _match_view(self, view: str) -> None:
        """The view's video metrics as the report computes them (PSNR and the frame match)."""
        if not self._listeners:  # no tab shows the rollout any more: left for when one does
            with self._lock:
                self._matching.discard(view)
            return
        try:
            vm = self.timeline.video_metrics(view)
            self.psnr[view] = vm.psnr_db
            if self._on_video_metrics is not None:
                self._on_video_metrics(vm)
        except Exception as exc:  # the frames and the PSNR stand; the agreement plot says why it lacks this view
            self.match_errors[view] = _one_line(exc)
        with self._lock:
            self._matching.discard(view)
            self._unmatched.discard(view)
        self._view_finished(view)

    def _view_framed(self, view: str) -> None:
        with self._lock:
            self._framed.add(view)
            if len(self._framed) == len(self.views):
                self.decoded.set()
        self._match_unmatched()

    def _view_finished(self, view: str) -> None:
        with self._lock:
            self._finished.add(view)
            if len(self._finished) == len(self.views):
                self.done.set()
        self._notify()

    def gripper_distance(self) -> dict[str, npt.NDArray[np.float64]]:
        """Per view whose frames are decoded and whose gripper was tracked on the way: the (T,)
        pixel distance between the tracked and the projected predicted gripper per step."""
        if self.overlay is None:
            return {}
        with self._lock:
            framed = sorted(self._framed)
        out = {}
        for view in framed:
            series = self.overlay.distance_series(view)
            if series is not None:
                out[view] = series
        return out

    def _keys(self, view: str) -> tuple[tuple, tuple]:
        """Cache key prefixes of the view's imagined and GT clips (a GT clip shared by rollouts of
        the same episode and start frame is cached once for all of them)."""
        tl = self.timeline
        gt = tl.gt.clips.get(view)
        imagined = tl.rollout.video(view).key if view in self.imagined_views else (view,)
        return ("imagined", *imagined), ("gt", *(gt.key if gt is not None else (view,)))

    def display_size(self, view: str) -> tuple[int, int]:
        """(width, height) the view's frames are shown at: the imagined clip's (else the GT
        clip's), at most :data:`DISPLAY_MAX_WIDTH` wide; GT frames are shown at the same size."""
        size = self._sizes.get(view)
        if size is None:
            tl = self.timeline
            clip = tl.rollout.video(view) if view in self.imagined_views else tl.gt.clips[view]
            info = clip.info()
            size = self._sizes[view] = fit_size(info.width, info.height, DISPLAY_MAX_WIDTH)
        return size

    def _store(self, view: str, key: tuple, rgb: npt.NDArray[np.uint8]) -> None:
        size = self.display_size(view)
        full_key = (*key, size)
        # a GT frame another rollout of the same episode cached is kept, and now counts as this
        # rollout's: left at its old place it went first, and the rollout reopened half-cached
        if not self._cache.touch(full_key):
            self._cache.put(full_key, jpeg_data_uri(rgb, size))

    # -- lookups on the scrub path (never decode) ---------------------------------------------
    def pair(self, view: str, step: int, overlay: bool = False) -> FramePair:
        """The imagined frame of ``view`` at ``step`` and the GT frame at the same time (a view
        without imagined video has only the GT frame); ``overlay``: with the arms drawn over them."""
        out = self._pair(view, step)
        if overlay and self.overlay is not None and out.status == READY:
            try:
                drawn = self.overlay.uris(view, step, out.imagined_index, self.display_size(view))
            except Exception:  # the frames stand without it
                drawn = None
            if drawn is not None:
                out.imagined_overlay = drawn[0] if out.imagined is not None else None
                out.gt_overlay = drawn[1] if out.gt is not None else None
        return out

    def _pair(self, view: str, step: int) -> FramePair:
        tl = self.timeline
        f = tl.frame_index(step)
        out = FramePair(view=view, status=self.status.get(view, LOADING), imagined_index=f,
                        has_imagined=view in self.imagined_views)
        if out.status not in (LOADING, READY):
            return out  # the view's clip is broken: its error is the status
        try:
            size = self.display_size(view)
        except Exception as exc:
            out.status = _one_line(exc)
            return out
        imagined_key, gt_key = self._keys(view)
        if out.has_imagined:
            out.imagined = self._cache.get((*imagined_key, f, size))
            if out.imagined is None:
                out.status = LOADING
                self._fill(view)  # evicted since (or still on its way): decode again in the background
                return out
            out.status = READY
        if self.gt_status[view] not in (LOADING, READY):
            out.gt_note = self.gt_status[view]
            return out
        try:
            gt_index = tl.gt.display_index(view, f, step)
        except Exception as exc:  # an unreadable GT clip: its fill reports it too
            out.gt_note = _one_line(exc)
            return out
        if gt_index is None:
            out.gt_note = "past the real episode's end"
        else:
            out.gt, out.gt_index = self._cache.get((*gt_key, gt_index, size)), gt_index
            if out.gt is None:
                out.gt_note = LOADING
                self._fill(view)
        if not out.has_imagined:  # a camera alone: ready when its frame is
            out.status = LOADING if out.gt_note == LOADING else READY
        psnr = self.psnr.get(view)
        if out.gt is not None and psnr is not None and f < len(psnr) and np.isfinite(psnr[f]):
            out.psnr_db = float(psnr[f])
        return out


def jpeg_data_uri(frame: npt.NDArray[np.uint8], size: tuple[int, int] | None = None,
                  quality: int = JPEG_QUALITY) -> str:
    """(H, W, 3) uint8 RGB -> ``data:image/jpeg;base64,...``, scaled to ``size`` (width, height).

    simplejpeg (libjpeg-turbo, straight from the array) takes half the time of PIL's encoder.
    """
    import simplejpeg

    if size is not None and (frame.shape[1], frame.shape[0]) != tuple(size):
        from PIL import Image

        frame = np.asarray(Image.fromarray(np.ascontiguousarray(frame)).resize(
            cast(tuple[int, int], tuple(size)), Image.Resampling.BILINEAR, reducing_gap=2.0))
    data = simplejpeg.encode_jpeg(np.ascontiguousarray(frame), quality=quality, colorspace="RGB")
    return "data:image/jpeg;base64," + base64.b64encode(data).decode("ascii")


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__
