"""The imagined gripper tracked through its video, against where the predicted joints put it.

A view with a camera knows where the predicted joints put the gripper in each imagined frame (a
point on the arm's surface, projected: :func:`inspector.analysis.camera_measures.gripper_surface`).
Whether the imagined video shows the gripper there is measured by following the gripper through
the video itself and taking the pixel distance between the two tracks, frame by frame
(EWMBench's trajectory consistency compares 2D end-effector tracks the same way, by Hausdorff
distance and DTW).

The tracker is template matching by normalised cross-correlation (numpy, scipy.fft): a square patch
around the point in one frame is looked for within a search window of the next, and the best
match (refined to a sub-pixel peak) is the point's new place. It starts where its caller puts it
(the report and the app: the projected GT ``gripper_link`` origin in the first frame, the model's
first frame being conditioned on the GT one). A match whose correlation falls under
:data:`MIN_CONFIDENCE`, a patch without texture, a peak on the search window's rim (the point moved further than the window reaches) or a point leaving the
image loses the track, for good: the distances stop there, and a lost track is never a small
distance.

Usage::

    tracker = GripperTracker(start_uv, (width, height))
    for rgb in frames:
        tracker.add(rgb)
    track = tracker.result()                  # (F, 2) px, NaN from the frame it was lost
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypedDict

import numpy as np
import numpy.typing as npt
import scipy.fft
from scipy.spatial.distance import cdist, directed_hausdorff

Array = npt.NDArray[np.float64]

MIN_CONFIDENCE = 0.6  # normalised cross-correlation of the best match below which the track is lost
MIN_TEXTURE = 2.0  # grey levels (standard deviation) a patch needs to be matched at all
TEMPLATE_HALF = 0.05  # of the frame's height: a 25x25 patch at 240 rows
SEARCH_RADIUS = 0.04  # of the frame's height: 10 px at 240 rows, around where the point is heading (its
# last motion): the change of motion between frames, not the motion itself, which on the demo's
# rollouts is at most 4.6 px a frame. Its tracks are those of a 14 or 24 px radius, exactly, for
# 7/8 or 1/2 of the cost
SHRINK_FROM_ROWS = 360  # frames this tall are tracked at half size (a quarter of the work)
MAX_TRACK_POINTS = 1000  # Hausdorff and DTW over longer tracks use this many evenly spaced frames


class GripperPixels(TypedDict):
    """One view's ``gripper_px`` (docs/metrics.md): pixel distances between the tracked imagined
    gripper and the projected predicted one, over the frames before the track was lost."""

    median: float | None
    per_chunk: list[float | None]
    lost_from_chunk: int | None
    hausdorff: float | None
    dtw: float | None
    frames_tracked: int
    note: str | None


def _colour(rgb: npt.NDArray[np.uint8], shrink: int) -> npt.NDArray[np.float32]:
    """The (H, W, 3) frame as (3, H, W) float32, each ``shrink`` x ``shrink`` block averaged.
    Colour, not grey: a yellow gripper over a tan table differs more in hue than in brightness.
    Channels first: every sum over them is then a sum of whole planes (a sum over a last axis of
    three cost more than the transforms)."""
    f = np.ascontiguousarray(rgb.transpose(2, 0, 1), dtype=np.float32)
    if shrink == 1:
        return f
    h, w = (f.shape[1] // shrink) * shrink, (f.shape[2] // shrink) * shrink
    return f[:, :h, :w].reshape(-1, h // shrink, shrink, w // shrink, shrink).mean(axis=(2, 4))


class GripperTracker:
    """Follows one point through frames fed one at a time.

    Args:
        start_uv: (2,) the point in the first frame [px].
        size: (width, height) of the frames.
    """

    def __init__(self, start_uv: Sequence[float], size: tuple[int, int]) -> None:
        width, height = size
        # tall frames at half size; smaller ones at full size, where the frame-to-frame drift of a
        # half-size track grew to 15 px on the demo's clean rollout (5 px at full size)
        self._shrink = 2 if height >= SHRINK_FROM_ROWS else 1
        self._size = (width // self._shrink, height // self._shrink)
        self._half = max(4, int(round(TEMPLATE_HALF * self._size[1])))
        self._radius = max(4, int(round(SEARCH_RADIUS * self._size[1])))
        self._uv = (np.asarray(start_uv, np.float64) - (self._shrink - 1) / 2) / self._shrink
        self._velocity = np.zeros(2)  # [px/frame]: the window is centred where the point is heading
        self._track: list[tuple[float, float]] = []
        self._confidence: list[float] = []
        self._template: npt.NDArray[np.float32] | None = None  # the point's patch in the last frame
        self._lost = not bool(np.isfinite(self._uv).all()) or not self._inside(self._uv, self._half)

    @property
    def lost(self) -> bool:
        return self._lost

    def _inside(self, uv: Array, margin: int) -> bool:
        width, height = self._size
        return bool(margin <= uv[0] <= width - 1 - margin and margin <= uv[1] <= height - 1 - margin)

    def add(self, rgb: npt.NDArray[np.uint8]) -> None:
        """Track the point into the next frame (the first frame only records the start)."""
        if self._lost:
            self._track.append((np.nan, np.nan))
            self._confidence.append(np.nan)
            return
        if self._template is not None:
            self._step(rgb)
        if self._lost:
            self._track.append((np.nan, np.nan))
            self._confidence.append(np.nan)
            return
        if self._template is None:
            self._confidence.append(1.0)
        uv = self._uv * self._shrink + (self._shrink - 1) / 2
        self._track.append((float(uv[0]), float(uv[1])))
        # the next frame is searched for this frame's patch around the point (only the patch and
        # the search window are ever converted: a whole frame's conversion cost 3x the match)
        h = self._half
        cu, cv = int(round(self._uv[0])), int(round(self._uv[1]))
        self._template = self._crop(rgb, cv - h, cv + h + 1, cu - h, cu + h + 1)

    def _crop(self, rgb: npt.NDArray[np.uint8], v0: int, v1: int, u0: int, u1: int) -> npt.NDArray[np.float32]:
        """Rows v0:v1, columns u0:u1 of the tracked image (the frame, or its shrunk copy)."""
        s = self._shrink
        return _colour(rgb[v0 * s:v1 * s, u0 * s:u1 * s], s)

    def _step(self, rgb: npt.NDArray[np.uint8]) -> None:
        template = self._template
        assert template is not None
        h, r = self._half, self._radius
        width, height = self._size
        cu, cv = int(round(self._uv[0] + self._velocity[0])), int(round(self._uv[1] + self._velocity[1]))
        v0, v1 = max(0, cv - r - h), min(height, cv + r + h + 1)
        u0, u1 = max(0, cu - r - h), min(width, cu + r + h + 1)
        window = self._crop(rgb, v0, v1, u0, u1) if v1 > v0 and u1 > u0 else np.zeros((3, 0, 0), np.float32)
        t = template - template.mean()
        t_squares = float(np.einsum("cij,cij->", t, t))
        if t_squares < MIN_TEXTURE ** 2 * t.size or window.shape[1] < 2 * h + 1 or window.shape[2] < 2 * h + 1:
            self._lose()
            return
        scores = _ncc_centred(window, t, t_squares)
        iv, iu = divmod(int(scores.argmax()), scores.shape[1])
        best = float(scores[iv, iu])
        on_rim = iv in (0, scores.shape[0] - 1) or iu in (0, scores.shape[1] - 1)
        # a rim that is the image's edge is not the window's: the point may sit there
        rim_is_window = ((iv == 0 and v0 > 0) or (iv == scores.shape[0] - 1 and v1 < height)
                         or (iu == 0 and u0 > 0) or (iu == scores.shape[1] - 1 and u1 < width))
        if not best >= MIN_CONFIDENCE or (on_rim and rim_is_window):
            self._lose(best)
            return
        du, dv = _subpixel(scores, iu, iv)
        uv = np.array([u0 + h + iu + du, v0 + h + iv + dv])
        if not self._inside(uv, h):
            self._lose(best)
            return
        self._velocity = uv - self._uv
        self._uv = uv
        self._confidence.append(best)

    def _lose(self, confidence: float = np.nan) -> None:
        self._lost = True
        self._confidence.append(confidence)

    def result(self) -> Array:
        """(F, 2) the tracked point in each frame fed [px]; NaN from the frame the track was lost."""
        return np.array(self._track, np.float64).reshape(-1, 2)

    def confidence(self) -> Array:
        """(F,) the match's correlation in each frame (1 for the first; NaN after the loss)."""
        return np.array(self._confidence[:len(self._track)], np.float64)


def _ncc(window: npt.NDArray[np.float32], template: npt.NDArray[np.float32]) -> Array:
    """Normalised cross-correlation of ``template`` at every place it fits in ``window`` (both
    (channels, rows, columns)): -1 where a patch or the template has no spread."""
    t = template - template.mean()
    return _ncc_centred(window, t, float(np.einsum("cij,cij->", t, t)))


def _ncc_centred(window: npt.NDArray[np.float32], t: npt.NDArray[np.float32], t_squares: float) -> Array:
    """:func:`_ncc` of a template already less its mean, ``t``, whose squares sum to ``t_squares``."""
    th, tw = t.shape[1:]
    c, wh, ww = window.shape
    n = t.size
    # the template sums to zero, so a patch's mean drops out of the product; the products at every
    # place at once by FFT (30x a sliding window's): the window's and the flipped template's
    # channels in one forward transform, summed before the one inverse (sizes of small primes
    # only: a 73-pixel window, 73 being prime, took 4x as long)
    shape = (_fast_size(wh), _fast_size(ww))
    both = np.zeros((2 * c, *shape), np.float32)
    both[:c, :wh, :ww] = window
    both[c:, :th, :tw] = t[:, ::-1, ::-1]
    spectra = scipy.fft.rfft2(both)
    num = scipy.fft.irfft2((spectra[:c] * spectra[c:]).sum(axis=0), s=shape)[th - 1:wh, tw - 1:ww]
    # each patch's sum and sum of squares from running sums over the window (box filters)
    total, squares = _box(np.stack((window.sum(axis=0), np.einsum("cij,cij->ij", window, window))), th, tw)
    den = np.sqrt(np.maximum(squares - total * total / n, 0.0) * t_squares)
    return np.divide(num, den, out=np.full(num.shape, -1.0), where=den > 0)


@functools.lru_cache(maxsize=256)
def _fast_size(n: int) -> int:
    """The smallest m >= n with no prime factor above 5 (what FFTs are quick at)."""
    m = n
    while True:
        k = m
        for p in (2, 3, 5):
            while k % p == 0:
                k //= p
        if k == 1:
            return m
        m += 1


def _box(a: npt.NDArray[np.float32], th: int, tw: int) -> Array:
    """Sums of every th x tw block of each plane of a (P, H, W) array (valid places only), as
    two products with bands of ones (in float64: the squares' sums lose the variance to
    rounding in float32; a quarter of the time of running sums over these small planes)."""
    return _band(a.shape[1], th) @ a.astype(np.float64) @ _band(a.shape[2], tw).T


@functools.lru_cache(maxsize=64)
def _band(n: int, k: int) -> Array:
    """(n - k + 1, n): row i has ones over columns i..i+k-1 (a sum of k neighbours, valid places)."""
    i, j = np.arange(n - k + 1)[:, None], np.arange(n)[None, :]
    band = ((j >= i) & (j < i + k)).astype(np.float64)
    band.flags.writeable = False
    return band


def _subpixel(scores: Array, iu: int, iv: int) -> tuple[float, float]:
    """The peak's offset from (iu, iv) by a parabola through it and its neighbours, each axis."""
    def offset(before: float, at: float, after: float) -> float:
        curve = before - 2 * at + after
        return float(np.clip(0.5 * (before - after) / curve, -0.5, 0.5)) if curve < 0 else 0.0
    du = offset(scores[iv, iu - 1], scores[iv, iu], scores[iv, iu + 1]) if 0 < iu < scores.shape[1] - 1 else 0.0
    dv = offset(scores[iv - 1, iu], scores[iv, iu], scores[iv + 1, iu]) if 0 < iv < scores.shape[0] - 1 else 0.0
    return du, dv


# ---------------------------------------------------------------------------------------------
# Comparing the tracks


def hausdorff(a: npt.ArrayLike, b: npt.ArrayLike) -> float:
    """Symmetric Hausdorff distance between two (N, 2) and (M, 2) point sets [px]."""
    pa, pb = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(max(directed_hausdorff(pa, pb)[0], directed_hausdorff(pb, pa)[0]))


def dtw_distance(a: npt.ArrayLike, b: npt.ArrayLike) -> float:
    """Dynamic time warping of two 2D tracks, (N, 2) and (M, 2): the least total Euclidean cost of
    a monotone alignment of both whole tracks, divided by max(N, M) [px per frame].

    Each row of the cost table is one vectorised pass: within a row,
    ``D[i, j] = min(m[j], D[i, j-1] + c[i, j])`` (``m`` from the row above) unrolls to
    ``C[j] + min over k <= j of (m[k] - C[k])``, with ``C`` the running sum of the row's costs.
    """
    pa, pb = np.asarray(a, np.float64), np.asarray(b, np.float64)
    cost = cdist(pa, pb)
    running = np.cumsum(cost, axis=1)  # every row's C at once
    row = running[0].copy()
    m = np.empty_like(row)
    for i in range(1, len(pa)):
        m[0] = row[0]
        np.minimum(row[1:], row[:-1], out=m[1:])
        m += cost[i]
        m -= running[i]
        row = np.minimum.accumulate(m)
        row += running[i]
    return float(row[-1] / max(len(pa), len(pb)))


@dataclass(frozen=True)
class TrackComparison:
    """Per-frame distances between the tracked and the projected gripper [px] (NaN once lost)."""

    distance: Array
    lost_from_frame: int | None


def compare_tracks(tracked: npt.ArrayLike, projected: npt.ArrayLike) -> TrackComparison:
    """Distances between (F, 2) tracked and (F, 2) projected points, frame by frame.

    A frame where the track is lost (NaN) and every later one has no distance; a frame whose
    projected point is missing (behind the camera) has none either, without ending the track.
    """
    t, p = np.asarray(tracked, np.float64), np.asarray(projected, np.float64)
    lost = ~np.isfinite(t).all(axis=1)
    first_lost = int(np.argmax(lost)) if lost.any() else None
    d = np.sqrt(((t - p) ** 2).sum(axis=1))
    if first_lost is not None:
        d[first_lost:] = np.nan
    return TrackComparison(d, first_lost)


def gripper_pixels(tracked: npt.ArrayLike, projected: npt.ArrayLike, frame_chunk: npt.ArrayLike,
                   n_chunks: int) -> GripperPixels:
    """The ``gripper_px`` record of one view.

    Args:
        tracked: (F, 2) the tracked imagined gripper [px], NaN from the frame it was lost.
        projected: (F, 2) the predicted joints' projected gripper tip in the same frames [px].
        frame_chunk: (F,) the chunk each frame belongs to.
        n_chunks: chunks in the rollout.
    """
    t, p = np.asarray(tracked, np.float64), np.asarray(projected, np.float64)
    chunk = np.asarray(frame_chunk, np.int64)
    cmp = compare_tracks(t, p)
    lost_chunk = None if cmp.lost_from_frame is None else int(chunk[cmp.lost_from_frame])
    per_chunk: list[float | None] = []
    for c in range(n_chunks):
        v = cmp.distance[(chunk == c) & np.isfinite(cmp.distance)]
        per_chunk.append(None if not v.size or (lost_chunk is not None and c >= lost_chunk)
                         else round(float(np.median(v)), 3))
    good = np.isfinite(cmp.distance)
    note = None
    if not good.any():
        note = ("the gripper could not be tracked from the first frame" if cmp.lost_from_frame == 0
                else "no frame with both a tracked and a projected gripper")
        return {"median": None, "per_chunk": per_chunk, "lost_from_chunk": lost_chunk, "hausdorff": None,
                "dtw": None, "frames_tracked": 0, "note": note}
    idx = np.flatnonzero(good)
    if len(idx) > MAX_TRACK_POINTS:
        idx = idx[np.linspace(0, len(idx) - 1, MAX_TRACK_POINTS).round().astype(np.int64)]
    return {"median": round(float(np.median(cmp.distance[good])), 3), "per_chunk": per_chunk,
            "lost_from_chunk": lost_chunk, "hausdorff": round(hausdorff(t[idx], p[idx]), 3),
            "dtw": round(dtw_distance(t[idx], p[idx]), 3), "frames_tracked": int(good.sum()), "note": note}


__all__ = ["GripperPixels", "GripperTracker", "MIN_CONFIDENCE", "TrackComparison", "compare_tracks", "dtw_distance",
           "gripper_pixels", "hausdorff"]
