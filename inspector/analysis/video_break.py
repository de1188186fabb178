"""Where the dream breaks: a no-reference degradation curve of imagined video over time.

No GT frame is needed. Each imagined frame gets four numbers (:func:`frame_quality`), measured
at every fourth pixel of every fourth row (:data:`SUBSAMPLE`):

- **sharpness**: variance of the 4-neighbour Laplacian of the luma after a 3x3 box blur (the
  blur keeps pixel noise from passing for detail; a blurrier frame scores lower);
- **noise**: mean squared residual of the luma against its 3x3 box blur (high-frequency energy;
  grain and speckle score higher);
- **flicker**: mean absolute luma change from the previous measured frame (0 for the first);
- **colour**: total-variation distance (0..1) between the frame's colour histogram (4 levels a
  channel, 64 bins) and the clip's first frame's: the share of the picture whose colours moved.

Every third frame is measured (:data:`FRAME_STRIDE`); the others read NaN.

Per chunk, each is the median over the chunk's frames, and the chunk's **degradation** is the
largest of four scores, each 1 as the first chunk and :data:`BREAK_RATIO` (2) where it counts as
degraded:

- blur: ``sharpness_0 / sharpness_k`` (half the sharpness reads 2);
- noise: ``noise_k / noise_0`` (twice the high-frequency energy reads 2);
- colour: ``1 + (colour_k - colour_0) / COLOUR_SHIFT`` (half the picture's colours moved reads
  2). Noise is not detail: a frame turned to fragments and smears of saturated colour can be
  as sharp as the first, or sharper, and its high-frequency energy can fall back to the start's,
  but its colours no longer are the scene's;
- freeze: :data:`FROZEN_SCORE` for a chunk whose frames stand still (median flicker under
  :data:`STILL_FLICKER` grey levels) while the rollout's own arm joints move at least
  :data:`MOVING_DEG` in it; a still video of a still arm is no fault, so without the joints
  stillness decides nothing.

Flicker decides nothing else: the arm's own motion changes frames as much as flicker does. The
video **breaks** at the first chunk from which every later chunk's degradation stays above
:data:`BREAK_RATIO`; the record names the score that put the break chunk over it.
"""

from __future__ import annotations

import warnings
from typing import TypedDict

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

# A chunk counts as degraded when one of its measures is this many times worse than the first
# chunk's: twice the noise energy or half the sharpness.
BREAK_RATIO = 2.0
QUALITY_MEASURES = ("sharpness", "noise", "flicker", "colour")
# The colour distance from the first frame (0..1) that reads BREAK_RATIO: half the picture's
# colours gone elsewhere. The clean demo rollouts' fixed front camera stays under 0.06; their wrist
# camera, which turns with the arm, peaks at 0.48 for a chunk or two and comes back; the real
# DreamZero-SO101 rollouts' views sit at 0.5-0.95 from chunk 8-12 on, to their end.
COLOUR_SHIFT = 0.5
# Frames this close (mean absolute luma change, grey levels) stand still: identical frames decode
# to 0-0.02 apart, while a real imagined view at its most still moves 0.3-0.4.
STILL_FLICKER = 0.1
# ... and a still chunk is frozen only where the rollout's own arm joints travel this far in it [deg]
# (the largest range of one arm joint over the chunk's steps; the demo's joint jitter spans < 1).
MOVING_DEG = 2.0
# A frozen chunk's degradation: stillness has no degree, so a fixed value, twice the break line.
FROZEN_SCORE = 2 * BREAK_RATIO
# The score each column of the per-chunk scores stands for (the record's ``cause``).
CAUSES = ("blur", "noise", "colour", "freeze")


# Every SUBSAMPLE-th pixel of every row and column is measured: the measures compare a clip with
# itself, so the subsampling only has to be the same for every frame, and a 320x176 frame costs
# 44x80 pixels.
SUBSAMPLE = 4
# ... and every FRAME_STRIDE-th frame (three of a chunk's nine): a chunk's median needs no more,
# and the report's 200 rollouts with two views then pay a few seconds for it, not a minute.
FRAME_STRIDE = 3
_BATCH = 16  # frames measured in one vectorised pass; every clip of a task holds up to this many lumas
# at once (32 clips x 64 frames held 40 MB more a worker; 16 gives the same numbers)


_LUMA_WEIGHTS = (np.float32(0.299), np.float32(0.587), np.float32(0.114))
_N_BINS = 64  # colour histogram bins: 4 levels a channel


def _luma(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    """(H/SUBSAMPLE, W/SUBSAMPLE) luma of an (H, W, 3) frame, every SUBSAMPLE-th pixel."""
    f = rgb[::SUBSAMPLE, ::SUBSAMPLE]
    # a weighted sum straight from the bytes, into one float32 array: no float copy of the three
    # channels first (the same numbers, in under half the time: 56 -> 24 us a 320x176 frame), and
    # not ``f @ weights``, a matrix product over the strided view (1 ms a frame)
    r, g, b = _LUMA_WEIGHTS
    y = f[..., 0] * r
    y += f[..., 1] * g
    y += f[..., 2] * b
    return y


def _colour_bins(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """(H/SUBSAMPLE, W/SUBSAMPLE) colour bin (0..63: 4 levels of red, green, blue) of an (H, W, 3)
    frame, every SUBSAMPLE-th pixel."""
    f = rgb[::SUBSAMPLE, ::SUBSAMPLE]
    # each channel shifted apart, straight from the strided view (12 us a 320x176 frame; shifting
    # the three-channel view first copies it: 68 us)
    bins = f[..., 0] >> 6 << 4
    bins |= f[..., 1] >> 6 << 2
    bins |= f[..., 2] >> 6
    return bins.astype(np.uint8, copy=False)  # uint8 already (numpy's stubs widen shifts to int)


def colour_histograms(bins: npt.NDArray[np.uint8]) -> npt.NDArray[np.float64]:
    """(N, 64) colour histograms (each summing to 1) of (N, h, w) colour bins."""
    n = bins.shape[0]
    offsets = (np.arange(n, dtype=np.int64) * _N_BINS)[:, None, None]
    counts = np.bincount((bins + offsets).ravel(), minlength=n * _N_BINS).reshape(n, _N_BINS)
    return counts / max(1, bins[0].size)


def _box3(y: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """3x3 box mean over the interior of (..., H, W) (the border rows and columns dropped)."""
    rows = y[..., :-2, :] + y[..., 1:-1, :] + y[..., 2:, :]
    return (rows[..., :-2] + rows[..., 1:-1] + rows[..., 2:]) / 9.0


def frame_quality(y: npt.NDArray[np.float32], previous: npt.NDArray[np.float32] | None = None,
                  histograms: npt.NDArray[np.float64] | None = None,
                  reference: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.float64]:
    """(N, 4) sharpness, noise, flicker, colour of (N, h, w) lumas (see the module docstring).

    Args:
        previous: the luma before ``y[0]``, for its flicker (0 without one).
        histograms: (N, 64) the frames' colour histograms (:func:`colour_histograms`).
        reference: (64,) the clip's first frame's; colour is NaN without both.
    """
    n = y.shape[0]
    out = np.full((n, len(QUALITY_MEASURES)), np.nan)
    if histograms is not None and reference is not None:
        out[:, 3] = 0.5 * np.abs(histograms - reference).sum(axis=1)
    if y.shape[1] < 5 or y.shape[2] < 5:
        return out
    smooth = _box3(y)
    lap = (smooth[:, :-2, 1:-1] + smooth[:, 2:, 1:-1] + smooth[:, 1:-1, :-2] + smooth[:, 1:-1, 2:]
           - 4 * smooth[:, 1:-1, 1:-1])
    residual = y[:, 1:-1, 1:-1] - smooth
    out[:, 0] = lap.reshape(n, -1).var(axis=1)
    out[:, 1] = (residual * residual).reshape(n, -1).mean(axis=1)
    before = np.concatenate([y[:1] if previous is None or previous.shape != y.shape[1:] else previous[None], y[:-1]])
    out[:, 2] = np.abs(y - before).reshape(n, -1).mean(axis=1)
    return out


class FrameQuality:
    """The measures of a clip's frames, fed one frame at a time and measured in batches."""

    def __init__(self) -> None:
        self._previous: npt.NDArray[np.float32] | None = None
        self._reference: npt.NDArray[np.float64] | None = None  # the first frame's colour histogram
        self._pending: list[tuple[int, npt.NDArray[np.float32], npt.NDArray[np.uint8]]] = []
        self._values: dict[int, npt.NDArray[np.float64]] = {}

    def add(self, index: int, rgb: npt.NDArray[np.uint8]) -> None:
        """Measure frame ``index`` (if it is one of every :data:`FRAME_STRIDE`)."""
        if index % FRAME_STRIDE:
            return
        y = _luma(rgb)
        if self._pending and self._pending[-1][1].shape != y.shape:
            self._flush()
        self._pending.append((index, y, _colour_bins(rgb)))
        if len(self._pending) >= _BATCH:
            self._flush()

    def _flush(self) -> None:
        if not self._pending:
            return
        stack = np.stack([y for _, y, _ in self._pending])
        histograms = colour_histograms(np.stack([b for _, _, b in self._pending]))
        if self._reference is None:
            self._reference = histograms[0]
        values = frame_quality(stack, self._previous, histograms, self._reference)
        self._values.update({i: v for (i, _, _), v in zip(self._pending, values)})
        self._previous = stack[-1]
        self._pending = []

    def array(self, n_frames: int | None = None) -> Array:
        """(F, 4) the measures by frame index (NaN for a frame not seen)."""
        self._flush()
        n = max(self._values, default=-1) + 1 if n_frames is None else n_frames
        out = np.full((max(n, 0), len(QUALITY_MEASURES)), np.nan)
        for i, v in self._values.items():
            if i < len(out):
                out[i] = v
        return out


def clip_quality(clip) -> Array:
    """(F, 4) the measures of every frame of a :class:`inspector.data.video.VideoClip`."""
    fq = FrameQuality()
    n = 0
    for index, rgb in clip.iter_frames():
        fq.add(index, rgb)
        n = index + 1
    return fq.array(n)


def chunk_arm_travel(arm_deg: npt.ArrayLike, step_chunk: npt.ArrayLike, n_chunks: int) -> Array:
    """(N,) how far the arm moves in each chunk [deg]: the largest range of one arm joint over the
    chunk's steps (NaN for a chunk without steps).

    Args:
        arm_deg: (T, J) the rollout's executed arm joints [deg] (the gripper left out).
        step_chunk: (T,) the chunk of each step.
    """
    q = np.asarray(arm_deg, np.float64).reshape(len(np.asarray(step_chunk)), -1)
    chunk = np.asarray(step_chunk, np.int64)
    out = np.full(max(0, n_chunks), np.nan)
    for k in np.unique(chunk[(chunk >= 0) & (chunk < n_chunks)]):
        rows = q[chunk == k]
        out[k] = float(np.nanmax(rows.max(axis=0) - rows.min(axis=0))) if rows.size else np.nan
    return out


class VideoBreakJson(TypedDict):
    """A view's degradation curve and break chunk, as the report writes it."""

    break_chunk: int | None
    cause: str | None  # which score put the break chunk over the line (:data:`CAUSES`), None without a break
    degradation: list[float | None]  # per chunk, 1 = as the first chunk (the per-chunk measures
    # behind it stay out of report rows: four more lists per view and rollout)


def degradation_scores(quality: npt.ArrayLike, frames_per_chunk: int,
                       arm_travel_deg: npt.ArrayLike | None = None) -> tuple[Array, Array]:
    """Per-chunk measures and the four scores of each chunk (see the module docstring).

    Args:
        quality: (F, 4) sharpness, noise, flicker, colour of each imagined frame (NaN where unknown).
        frames_per_chunk: imagined frames per chunk.
        arm_travel_deg: (N,) the arm's travel in each chunk (:func:`chunk_arm_travel`), or None:
            no freeze is judged without it.

    Returns:
        (per_chunk (N, 4) medians, scores (N, 4) blur, noise, colour, freeze): NaN where a score
        cannot be had (a chunk without frames, no usable first chunk, a chunk that is not frozen).
    """
    m = len(QUALITY_MEASURES)
    q = np.asarray(quality, np.float64).reshape(-1, m)
    fpc = max(1, frames_per_chunk)
    n = -(-len(q) // fpc)
    # chunks as rows of a NaN-padded block, so one nanmedian takes every chunk's medians at once
    padded = np.full((n * fpc, m), np.nan)
    padded[:len(q)] = np.where(np.isfinite(q), q, np.nan)
    if len(q) > 1 and fpc > 1:
        padded[0] = np.nan  # the first frame has no flicker: chunk 0's medians leave it out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN chunk's median is NaN, as meant
        per_chunk = np.nanmedian(padded.reshape(n, fpc, m), axis=1) if n else np.full((0, m), np.nan)
    ref = per_chunk[0] if n else np.full(m, np.nan)
    tiny = 1e-6
    scores = np.full((n, len(CAUSES)), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        scores[:, 0] = ref[0] / np.maximum(per_chunk[:, 0], tiny)
        scores[:, 1] = per_chunk[:, 1] / max(ref[1], tiny)
        scores[:, 2] = 1.0 + np.maximum(per_chunk[:, 3] - ref[3], 0.0) / COLOUR_SHIFT
    if arm_travel_deg is not None:
        travel = np.full(n, np.nan)
        given = np.asarray(arm_travel_deg, np.float64)[:n]
        travel[:len(given)] = given
        with np.errstate(invalid="ignore"):
            frozen = (per_chunk[:, 2] < STILL_FLICKER) & (travel >= MOVING_DEG)
        scores[frozen, 3] = FROZEN_SCORE
    return per_chunk, scores


def degradation(quality: npt.ArrayLike, frames_per_chunk: int,
                arm_travel_deg: npt.ArrayLike | None = None) -> tuple[Array, Array]:
    """Per-chunk measures and degradation from per-frame measures.

    Args: as :func:`degradation_scores`.

    Returns:
        (per_chunk (N, 4) medians, degradation (N,): the largest of each chunk's scores): NaN for
        a chunk without any score.
    """
    per_chunk, scores = degradation_scores(quality, frames_per_chunk, arm_travel_deg)
    return per_chunk, _largest(scores)


def _largest(scores: Array) -> Array:
    usable = np.isfinite(scores)
    return np.where(usable.any(axis=1), np.max(np.where(usable, scores, -np.inf), axis=1), np.nan)


def break_chunk(curve: npt.ArrayLike, ratio: float = BREAK_RATIO) -> int | None:
    """The first chunk from which every later chunk's degradation is above ``ratio`` (chunks
    without a value are skipped), or None when the video holds to its end."""
    d = np.asarray(curve, np.float64)
    known = np.flatnonzero(np.isfinite(d))
    if known.size == 0:
        return None
    good = known[d[known] <= ratio]
    if good.size == 0:
        return int(known[0]) if known[0] > 0 else None  # degraded from the start: no break, it never held
    after = known[known > good[-1]]
    return int(after[0]) if after.size else None


def video_break_record(quality: npt.ArrayLike, frames_per_chunk: int, ratio: float = BREAK_RATIO,
                       arm_travel_deg: npt.ArrayLike | None = None) -> VideoBreakJson:
    """A view's ``video_break`` entry from its per-frame measures (and the arm's travel per chunk,
    for a freeze; see :func:`degradation_scores`)."""
    _, scores = degradation_scores(quality, frames_per_chunk, arm_travel_deg)
    curve = _largest(scores)
    chunk = break_chunk(curve, ratio)
    cause = None
    if chunk is not None:
        at = np.where(np.isfinite(scores[chunk]), scores[chunk], -np.inf)
        cause = CAUSES[int(np.argmax(at))]
    return {"break_chunk": chunk, "cause": cause, "degradation": [_round(v, 3) for v in curve]}


def _round(v: float, digits: int = 4) -> float | None:
    return round(float(v), digits) if np.isfinite(v) else None
