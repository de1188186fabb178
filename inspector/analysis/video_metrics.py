"""Imagined vs GT video, compared frame pair by frame pair while both clips stream.

Only the per-frame numbers are kept: a 540-frame view costs two decoders and two frames of
memory, whatever the clips' length or size. Several imagined clips that share one GT clip (rollouts
of the same dataset episode, from the same start frame) are compared in one pass, so the GT
is decoded once for all of them. The GT frame is scaled to each imagined clip's size while
decoding (swscale, area filter), as the metric definition asks. The same pass takes a thumbnail
of every imagined and every GT frame and matches them (:mod:`inspector.analysis.video_action`),
unless asked not to (the app's frame fill, which matches after).

Only frames of one geometry are compared (:func:`geometry_note`): an imagined frame whose
width/height differs from the GT's is not the GT's view scaled (a 256x128 mosaic of two cameras
beside a 256x192 render gives 11-13 dB that mean nothing), so that view gets no PSNR, SSIM or match,
and a one-line note says why. The exception is a source whose model sees each camera's whole frame
resized to its own input size (DreamZero: 640x480 cameras squashed to 320x176), where the GT
resized the same way is what the model was shown.
"""

from __future__ import annotations

import functools
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

import numpy as np
import numpy.typing as npt

from ..data.video import ForwardReader, VideoClip, probe
from ..errors import InspectorError
from . import metrics
from .measures_switch import sanity_measures_on
from .video_action import FrameMatch, FrameMatchJson, Thumbnails, match_frames
from .video_break import QUALITY_MEASURES, FrameQuality

Array = npt.NDArray[np.float64]
Frame = npt.NDArray[np.uint8]


class VideoMetricsRecord(TypedDict):
    """A view's :class:`VideoMetrics` as JSON (the metrics cache keeps it): null for NaN."""

    view: str
    psnr_db: list[float | None]
    ssim: list[float | None] | None
    match: FrameMatchJson | None
    quality: list[list[float | None]] | None
    note: str | None


@dataclass
class VideoMetrics:
    """Imagined vs GT frames of one view at the same times (GT resized to the imagined size).

    Attributes:
        psnr_db: (F,) per imagined frame; NaN where no GT frame exists (past the episode).
        ssim: (F,) likewise, or None when not asked for (it costs ~10x the PSNR).
        match: the GT frame each imagined frame resembles most, or None without a GT clip.
        quality: (F, 4) no-reference sharpness, noise, flicker and colour of each imagined frame
            (:mod:`inspector.analysis.video_break`), or None when not measured.
        note: why the view's frames were not compared with the GT's (every value NaN, no match),
            e.g. ``imagined 256x128 vs GT 256x192: different geometry; not compared``; None
            when they were.
    """

    view: str
    psnr_db: Array
    ssim: Array | None = None
    match: FrameMatch | None = None
    quality: Array | None = None
    note: str | None = None

    @property
    def mean_psnr_db(self) -> float | None:
        v = self.psnr_db[np.isfinite(self.psnr_db)]
        return float(v.mean()) if v.size else None

    def to_json(self) -> VideoMetricsRecord:
        return {"view": self.view, "psnr_db": _floats(self.psnr_db),
                "ssim": None if self.ssim is None else _floats(self.ssim),
                "match": None if self.match is None else self.match.to_json(),
                "quality": None if self.quality is None else [_floats(row) for row in self.quality],
                "note": self.note}

    @classmethod
    def from_json(cls, data: VideoMetricsRecord) -> VideoMetrics:
        ssim, match, quality = data.get("ssim"), data.get("match"), data.get("quality")
        return cls(data["view"], _array(data["psnr_db"]), None if ssim is None else _array(ssim),
                   None if match is None else FrameMatch.from_json(match),
                   None if quality is None else np.array([_array(row) for row in quality]).reshape(-1, len(QUALITY_MEASURES)),
                   data.get("note"))


def _floats(a: Array) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in a]


def _array(values: list) -> Array:
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64)


# How far the width/height ratios of an imagined and a GT frame may differ and still be one
# geometry (the GT scaled uniformly): an odd side padded to even by the encoder moves it by ~1%.
SAME_ASPECT_TOLERANCE = 0.03
# Sources whose model sees each camera's whole frame resized to its own input size, whatever the
# camera's aspect (DreamZero's transform: the 640x480 front camera becomes 320x176; the GT frame
# squashed so matches the seed's own GT file at 35 dB, a 176-row crop of it at 14-16 dB). Their
# GT resized the same way is what the model was shown, so it is compared. ``inspector eval``'s
# rollouts (``extra.eval``) are a served DreamZero checkpoint's.
WHOLE_FRAME_FORMATS = frozenset({"dreamzero_so101", "dreamzero-offline", "dreamzero-served"})


def resizes_whole_frame(extra: Mapping[str, object]) -> bool:
    """Whether a rollout (by its ``extra``) comes from a model that resizes each camera's whole
    frame to its own input size (see :data:`WHOLE_FRAME_FORMATS`)."""
    source = extra.get("source")
    return "eval" in extra or isinstance(source, dict) and source.get("format") in WHOLE_FRAME_FORMATS


def geometry_note(imagined: VideoClip, gt: VideoClip, whole_frame: bool = False) -> str | None:
    """Why the frames of ``imagined`` are not compared with those of ``gt``, or None when they are:
    same size, or the same width/height within :data:`SAME_ASPECT_TOLERANCE` (GT scaled uniformly),
    or any size where ``whole_frame`` (the model resizes each camera's whole frame).

    Raises:
        InspectorError: a clip that is not a readable video (naming it).
    """
    (iw, ih), (gw, gh) = _frame_size(imagined.path), _frame_size(gt.path)
    if (iw, ih) == (gw, gh) or whole_frame:
        return None
    if min(iw, ih, gw, gh) > 0 and abs((iw / ih) / (gw / gh) - 1) <= SAME_ASPECT_TOLERANCE:
        return None
    return f"imagined {iw}x{ih} vs GT {gw}x{gh}: different geometry; not compared"


def _frame_size(path: Path) -> tuple[int, int]:
    """(width, height) of a video file, read once per version of the file."""
    try:
        st = path.stat()
    except OSError:  # not there: probe says so, naming it
        info = probe(path)
        return info.width, info.height
    return _probed_size(str(path), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=256)
def _probed_size(path: str, mtime_ns: int, size: int) -> tuple[int, int]:
    info = probe(path)
    return info.width, info.height


def compare_clips(view: str, imagined: Sequence[VideoClip], gt: VideoClip | None,
                  gt_index_of: Callable[[int], int], with_ssim: bool = False,
                  on_imagined: Callable[[int, int, Frame], None] | None = None,
                  on_gt: Callable[[int, Frame], None] | None = None, match: bool = True,
                  whole_frame: bool | Sequence[bool] = False,
                  on_pair: Callable[[int, int, Frame, Frame | None], None] | None = None) -> list[VideoMetrics]:
    """PSNR (and SSIM) of each imagined clip against the GT frames paired with its frames, and
    the GT frame each imagined frame resembles most (every GT frame of the clip is a candidate).
    A clip whose frames' geometry differs from the GT's (:func:`geometry_note`) gets neither: its
    values are NaN, its ``note`` says why.

    Args:
        view: the camera name (for the result).
        imagined: clips that share ``gt`` and its pairing (same start frame and timing).
        gt: the GT clip, or None (every value NaN; ``on_imagined`` still sees every frame).
        gt_index_of: ``gt_index_of(f)`` -> GT clip index paired with imagined frame ``f``, -1 for
            none; non-decreasing in ``f``.
        with_ssim: also compute SSIM.
        on_imagined: called as ``on_imagined(clip_number, f, rgb)`` for every imagined frame.
        on_gt: called as ``on_gt(index, rgb)`` for every GT frame of the clip, paired or not
            (at the first imagined clip's size).
        match: also match the frames (False: ``match`` is None, and no thumbnail is taken; the
            app shows frames first and matches them after, so a rollout can be scrubbed sooner).
        whole_frame: per clip (or one for all), whether its model resizes each camera's whole frame
            (:func:`resizes_whole_frame`): then GT frames of another width/height are compared.
        on_pair: called as ``on_pair(clip_number, f, rgb, gt_rgb)`` for every imagined frame, with
            the GT frame compared with it (at its size), or None where none is (the camera
            measures, :mod:`inspector.analysis.camera_measures`).

    Raises:
        InspectorError: a clip cannot be decoded (naming it).
    """
    streams = [_Stream(clip) for clip in imagined]
    whole = [whole_frame] * len(imagined) if isinstance(whole_frame, bool) else list(whole_frame)
    notes = [geometry_note(clip, gt, w) if gt is not None else None for clip, w in zip(imagined, whole)]
    gt_thumbs = Thumbnails()
    thumbs = [Thumbnails() for _ in streams]
    quality = [FrameQuality() if sanity_measures_on() else None for _ in streams]
    known_gt: list[GtThumbnails | None] = []  # the clip's thumbnails from an earlier call, once looked up

    def gt_known() -> GtThumbnails | None:
        if not known_gt and gt_stream is not None:
            known_gt.append(GT_THUMBNAILS.get(gt_stream))
        return known_gt[0] if known_gt else None

    def gt_seen(index: int, rgb: Frame) -> None:
        if match and gt_known() is None:
            gt_thumbs.add(index, rgb)
        if on_gt is not None:
            on_gt(index, rgb)

    gt_stream = ForwardReader(gt, gt_seen if match or on_gt is not None else None) if gt is not None else None
    psnr: list[list[float]] = [[] for _ in streams]
    ssim: list[list[float]] = [[] for _ in streams]
    f = 0
    while True:
        live = [s for s in streams if s.peek() is not None]
        if not live:
            break
        f = min(s.peek()[0] for s in live)  # type: ignore[index]
        target = gt_index_of(f)
        for b, s in enumerate(streams):
            item = s.peek()
            if item is None or item[0] != f:
                continue
            s.advance()
            rgb = item[1]
            if on_imagined is not None:
                on_imagined(b, f, rgb)
            if (fq := quality[b]) is not None:
                fq.add(f, rgb)
            # a clip not compared still reads its GT frames where they are shown (the app's)
            wanted = target >= 0 and (notes[b] is None or on_gt is not None)
            gt_rgb = gt_stream.frame_at(target, rgb.shape[1::-1]) if gt_stream is not None and wanted else None
            if notes[b] is not None:
                gt_rgb = None
            if on_pair is not None:
                on_pair(b, f, rgb, gt_rgb)
            _set(psnr[b], f, np.nan if gt_rgb is None else float(metrics.psnr(rgb[None], gt_rgb[None])[0]))
            if with_ssim:
                _set(ssim[b], f, np.nan if gt_rgb is None else float(metrics.ssim(rgb[None], gt_rgb[None])[0]))
            if gt_stream is not None and match and notes[b] is None:
                # after the PSNR, which has just read the whole frame: its samples are in the CPU's
                # cache now (twice as quick to gather as from the frame as it was decoded, ahead)
                thumbs[b].add(f, rgb)
    matchable = gt_stream is not None and match and any(n is None for n in notes)
    candidates = gt_known() if matchable else None
    if gt_stream is not None and (on_gt is not None or (matchable and candidates is None)):
        try:
            gt_stream.drain()  # every GT frame is a candidate match (and is shown), paired or not
        except InspectorError:
            # past the frames PSNR pairs with, the GT clip cannot be decoded: the PSNR stands, and
            # with candidates missing, a match would be a guess, so there is none
            matchable = False
        if matchable and candidates is None:
            candidates = GT_THUMBNAILS.put(gt_stream, gt_thumbs)
    matches = [_match(t, candidates) if matchable and candidates is not None and note is None else None
               for t, note in zip(thumbs, notes)]
    return [VideoMetrics(view, np.array(p, dtype=np.float64), np.array(q, dtype=np.float64) if with_ssim else None, m,
                         None if fq is None else fq.array(len(p)), note)
            for p, q, m, fq, note in zip(psnr, ssim, matches, quality, notes)]


def _match(imagined: Thumbnails, gt: GtThumbnails) -> FrameMatch:
    """The frame match of one imagined clip's thumbnails against the GT's."""
    read = imagined.stacked()
    frames = np.zeros((imagined.indexes[-1] + 1 if imagined.indexes else 0, read.shape[1]), np.float32)
    frames[imagined.indexes] = read  # a gap in the clip's numbering is all zeros: it matches nothing
    # positions among the GT frames read -> indexes in the clip (its numbering may have gaps)
    return match_frames(frames, gt.thumbnails).reindexed(gt.indexes)


@dataclass(frozen=True)
class GtThumbnails:
    """Thumbnails of every frame of a GT clip, at one size: the candidates of a frame match."""

    indexes: list[int]
    thumbnails: npt.NDArray[np.float32]


class GtThumbnailCache:
    """The GT thumbnails of the clips matched lately in this process, by file version, window end
    and size. Rollouts of one episode from different start frames (single chunks) share no pass
    over their GT clip, yet each is matched against every GT frame from its start on: reading the
    rest of the clip again for each cost the demo's report 9% more CPU. A window that
    starts later than one kept is its tail. ~1.4 MB an entry (445 frames).
    """

    def __init__(self, entries: int = 8) -> None:
        self._entries = entries
        self._items: OrderedDict[tuple, _KeptThumbnails] = OrderedDict()
        self._lock = threading.Lock()

    @staticmethod
    def _place(reader: ForwardReader) -> tuple[tuple, int] | None:
        """(the key of the reader's file version, window end and size; the file's frame number at
        which its window starts), or None where the window does not start on one of the file's
        frames (then frames of two windows need not have the same numbers)."""
        clip = reader.clip
        try:
            stat = clip.path.stat()
            fps = probe(clip.path).fps
        except (OSError, InspectorError):
            return None
        first = (clip.start_s or 0.0) * fps
        if not fps > 0 or abs(first - round(first)) > 1e-3:
            return None
        return (str(clip.path), stat.st_mtime_ns, stat.st_size, clip.end_s, reader.first_size), int(round(first))

    def get(self, reader: ForwardReader) -> GtThumbnails | None:
        """The thumbnails of ``reader``'s clip at the size it reads at, if known."""
        place = self._place(reader)
        if place is None:
            return None
        key, first = place
        with self._lock:
            kept = self._items.get(key)
            if kept is None or kept.first > first:
                return None
            self._items.move_to_end(key)
        tail = kept.numbers >= first
        return GtThumbnails((kept.numbers[tail] - first).tolist(), kept.thumbnails[tail])

    def put(self, reader: ForwardReader, thumbs: Thumbnails) -> GtThumbnails:
        """Keep the thumbnails of every frame of ``reader``'s clip (read to its end)."""
        entry = GtThumbnails(list(thumbs.indexes), thumbs.stacked())
        place = self._place(reader)
        if place is not None:
            key, first = place
            with self._lock:
                kept = self._items.get(key)
                if kept is None or kept.first > first:  # the longer window serves both
                    self._items[key] = _KeptThumbnails(first, np.asarray(entry.indexes, np.int64) + first,
                                                       entry.thumbnails)
                self._items.move_to_end(key)
                while len(self._items) > self._entries:
                    self._items.popitem(last=False)
        return entry


@dataclass(frozen=True)
class _KeptThumbnails:
    """A window's GT thumbnails, numbered by frame of the file."""

    first: int
    numbers: npt.NDArray[np.int64]
    thumbnails: npt.NDArray[np.float32]


GT_THUMBNAILS = GtThumbnailCache()


def _set(values: list, index: int, value) -> None:
    """values[index] = value, padding a gap in the clip's numbering with NaN."""
    values.extend([np.nan] * (index + 1 - len(values)))
    values[index] = value


class _Stream:
    """An imagined clip decoded at its own size, one frame of lookahead."""

    def __init__(self, clip: VideoClip) -> None:
        self._frames: Iterator[tuple[int, Frame]] = clip.iter_frames()
        self._next: tuple[int, Frame] | None = None
        self._done = False

    def peek(self) -> tuple[int, Frame] | None:
        if self._next is None and not self._done:
            self._next = next(self._frames, None)
            self._done = self._next is None
        return self._next

    def advance(self) -> None:
        self._next = None
