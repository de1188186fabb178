"""Where the dream breaks: a no-reference degradation curve of imagined video over time.

No GT frame is needed. Each imagined frame gets three numbers (:func:`frame_quality`), measured
on its luma at every fourth pixel of every fourth row (:data:`SUBSAMPLE`):

- **sharpness**: variance of the 4-neighbour Laplacian of the frame after a 3x3 box blur (the
  blur keeps pixel noise from passing for detail; a blurrier frame scores lower);
- **noise**: mean squared residual of the frame against its 3x3 box blur (high-frequency energy;
  grain and speckle score higher);
- **flicker**: mean absolute luma change from the previous measured frame (0 for the first).

Every third frame is measured (:data:`FRAME_STRIDE`); the others read NaN.

Per chunk, each is the median over the chunk's frames, and the chunk's **degradation** is the
larger of ``sharpness_0 / sharpness_k`` and ``noise_k / noise_0`` (the first chunk's values as
reference: 1 = as good as the start). Flicker is reported beside them but decides nothing: the arm's
own motion changes frames as much as flicker does, and a first chunk at rest would make every later
move look degraded. The video **breaks** at the first chunk from which every later chunk's
degradation stays above :data:`BREAK_RATIO`.
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
QUALITY_MEASURES = ("sharpness", "noise", "flicker")


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


def _box3(y: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """3x3 box mean over the interior of (..., H, W) (the border rows and columns dropped)."""
    rows = y[..., :-2, :] + y[..., 1:-1, :] + y[..., 2:, :]
    return (rows[..., :-2] + rows[..., 1:-1] + rows[..., 2:]) / 9.0


def frame_quality(y: npt.NDArray[np.float32], previous: npt.NDArray[np.float32] | None = None
                  ) -> npt.NDArray[np.float64]:
    """(N, 3) sharpness, noise, flicker of (N, h, w) lumas (see the module docstring); frame 0's
    flicker is against ``previous`` (0 without one)."""
    n = y.shape[0]
    if y.shape[1] < 5 or y.shape[2] < 5:
        return np.full((n, 3), np.nan)
    smooth = _box3(y)
    lap = (smooth[:, :-2, 1:-1] + smooth[:, 2:, 1:-1] + smooth[:, 1:-1, :-2] + smooth[:, 1:-1, 2:]
           - 4 * smooth[:, 1:-1, 1:-1])
    residual = y[:, 1:-1, 1:-1] - smooth
    out = np.empty((n, 3))
    out[:, 0] = lap.reshape(n, -1).var(axis=1)
    out[:, 1] = (residual * residual).reshape(n, -1).mean(axis=1)
    before = np.concatenate([y[:1] if previous is None or previous.shape != y.shape[1:] else previous[None], y[:-1]])
    out[:, 2] = np.abs(y - before).reshape(n, -1).mean(axis=1)
    return out


class FrameQuality:
    """The measures of a clip's frames, fed one frame at a time and measured in batches."""

    def __init__(self) -> None:
        self._previous: npt.NDArray[np.float32] | None = None
        self._pending: list[tuple[int, npt.NDArray[np.float32]]] = []
        self._values: dict[int, npt.NDArray[np.float64]] = {}

    def add(self, index: int, rgb: npt.NDArray[np.uint8]) -> None:
        """Measure frame ``index`` (if it is one of every :data:`FRAME_STRIDE`)."""
        if index % FRAME_STRIDE:
            return
        y = _luma(rgb)
        if self._pending and self._pending[-1][1].shape != y.shape:
            self._flush()
        self._pending.append((index, y))
        if len(self._pending) >= _BATCH:
            self._flush()

    def _flush(self) -> None:
        if not self._pending:
            return
        stack = np.stack([y for _, y in self._pending])
        values = frame_quality(stack, self._previous)
        self._values.update({i: v for (i, _), v in zip(self._pending, values)})
        self._previous = stack[-1]
        self._pending = []

    def array(self, n_frames: int | None = None) -> Array:
        """(F, 3) the measures by frame index (NaN for a frame not seen)."""
        self._flush()
        n = max(self._values, default=-1) + 1 if n_frames is None else n_frames
        out = np.full((max(n, 0), 3), np.nan)
        for i, v in self._values.items():
            if i < len(out):
                out[i] = v
        return out


def clip_quality(clip) -> Array:
    """(F, 3) the measures of every frame of a :class:`inspector.data.video.VideoClip`."""
    fq = FrameQuality()
    n = 0
    for index, rgb in clip.iter_frames():
        fq.add(index, rgb)
        n = index + 1
    return fq.array(n)


class VideoBreakJson(TypedDict):
    """A view's degradation curve and break chunk, as the report writes it."""

    break_chunk: int | None
    degradation: list[float | None]  # per chunk, 1 = as the first chunk (the per-chunk measures
    # behind it stay out of report rows: three more lists per view and rollout)


def degradation(quality: npt.ArrayLike, frames_per_chunk: int) -> tuple[Array, Array]:
    """Per-chunk measures and degradation from per-frame measures.

    Args:
        quality: (F, 3) sharpness, noise, flicker of each imagined frame (NaN where unknown).
        frames_per_chunk: imagined frames per chunk.

    Returns:
        (per_chunk (N, 3) medians, degradation (N,)): NaN for a chunk without frames, and
        all NaN when the first chunk has no usable reference.
    """
    q = np.asarray(quality, np.float64).reshape(-1, 3)
    fpc = max(1, frames_per_chunk)
    n = -(-len(q) // fpc)
    # chunks as rows of a NaN-padded block, so one nanmedian takes every chunk's medians at once
    padded = np.full((n * fpc, 3), np.nan)
    padded[:len(q)] = np.where(np.isfinite(q), q, np.nan)
    if len(q) > 1 and fpc > 1:
        padded[0] = np.nan  # the first frame has no flicker: chunk 0's medians leave it out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN chunk's median is NaN, as meant
        per_chunk = np.nanmedian(padded.reshape(n, fpc, 3), axis=1) if n else np.full((0, 3), np.nan)
    ref = per_chunk[0] if n else np.full(3, np.nan)
    tiny = 1e-6
    with np.errstate(invalid="ignore", divide="ignore"):
        ratios = np.stack([ref[0] / np.maximum(per_chunk[:, 0], tiny), per_chunk[:, 1] / max(ref[1], tiny)], axis=1)
    usable = np.isfinite(ratios)
    worst = np.where(usable.any(axis=1), np.nanmax(np.where(usable, ratios, -np.inf), axis=1), np.nan)
    return per_chunk, worst


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


def video_break_record(quality: npt.ArrayLike, frames_per_chunk: int, ratio: float = BREAK_RATIO) -> VideoBreakJson:
    """A view's ``video_break`` entry from its per-frame measures."""
    _, curve = degradation(quality, frames_per_chunk)
    return {"break_chunk": break_chunk(curve, ratio), "degradation": [_round(v, 3) for v in curve]}


def _round(v: float, digits: int = 4) -> float | None:
    return round(float(v), digits) if np.isfinite(v) else None
