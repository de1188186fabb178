"""Video-action agreement: does the imagined video show what the predicted joints say?

Both are put on one ruler, the real (GT) episode:

- the **video's GT time**: each imagined frame is matched to the GT frame of the same camera it
  resembles most. Frames become small grayscale thumbnails, each normalised to zero mean and unit
  length, so a whole clip against the whole GT clip is one matrix product of correlations. The
  match's **confidence** is how much better the best correlation is than the typical one (the
  median over the GT frames): a flat row of scores (a still scene, a frame unlike any GT frame)
  is "no match", never a guess.
- the **joints' GT time**: the GT frame whose pose the predicted step is nearest to (the
  best-match argmin of :mod:`inspector.analysis.metrics`).

**Lag** = the video's GT time - the joints' GT time [s]; positive: the video is ahead of the actions.
Without GT joints the video's GT time still gives the **video's tempo** (its speed against the
real episode), as the joints' best match gives theirs.

A **frozen** video (one that stands still while the joints move) has no lag: each of its frames
matches the one GT frame it shows, so the lag is only the joints' own course mirrored, and its
median can land near 0. It is told by how much of the episode each side covers
(:meth:`VideoAction.spans`): the video's GT time spans less than :data:`FROZEN_SHARE` of what the
joints' GT time spans, and the joints span at least :data:`FROZEN_MIN_SPAN_S`.

Thumbnails are taken while the clips stream for PSNR (:mod:`inspector.analysis.video_metrics`), so
the report's agreement costs no decoding of its own. The app shows a rollout's frames first and
streams the clips once more for the match after, so a rollout can be scrubbed sooner. The match
and the agreement work on every frame of a clip at once: frame by frame, they took 3x and 7x as long.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain
from typing import TypedDict

import numpy as np
import numpy.typing as npt

from . import metrics

Array = npt.NDArray[np.float64]

# Thumbnail grid (rows, columns): fine enough to see where the arm is, coarse enough to ignore the
# blur, noise and small wobble of an imagined frame.
THUMB_SHAPE = (24, 32)
# A match counts when its correlation beats the median one by this much...
MIN_CONFIDENCE = 0.05
# ...and the frames correlate at all (a frame unlike any GT frame still has a best one).
MIN_CORRELATION = 0.5
# GT frames whose correlation is within this fraction of the confidence of the best one tie with it
# (a held pose repeats one picture): the match is the middle of the tied run, as for the joints.
TIE_FRACTION = 0.1
# GT poses this close [data units] to the best match tie with it: the arm holding still, or a pose
# the episode visits twice (the rest pose at its start and end).
JOINT_TIE = 0.25
# |lag| above this [s] means the video and the actions have parted...
SPLIT_LAG_S = 0.5
# ...for good when it stays so in this share of the chunks that follow.
SPLIT_SHARE = 2 / 3
# A video is frozen when its GT time covers less than this share of the GT time the joints cover over
# the same frames (each from its 10th to its 90th percentile: a video that pauses for less than
# four fifths of the rollout still spans its course, and one at a fifth of the joints' tempo or
# more is slow, not frozen)...
FROZEN_SHARE = 0.2
# ...and the joints cover at least this much [s]: over a shorter course (a single chunk, a held
# pose) a still video agrees with the joints.
FROZEN_MIN_SPAN_S = 1.0
# The percentiles a side's span runs between: a few frames matched far off do not widen it.
SPAN_PERCENTILES = (10.0, 90.0)
# A predicted pose farther than this [data units] from every GT pose has no GT time: the joints
# are off the real path (a bias, a limit excursion), and the nearest pose would be a guess.
JOINT_MATCH_MAX = 5.0


def thumbnail(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    """(rows * cols,) grayscale thumbnail of an (H, W, 3) frame, zero mean and unit length
    (all zeros for a frame of one flat colour, which matches nothing).

    Each cell is the mean luma of :data:`CELL_SAMPLES` x :data:`CELL_SAMPLES` pixels spread evenly
    over it: a thumbnail is taken of every frame of both clips, and reading a few pixels costs a
    sixth of averaging all of them (the same matches on the demo and the shift tests).
    """
    return thumbnails(thumbnail_samples(rgb)[None])[0]


def thumbnail_samples(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """The pixels a thumbnail of an (H, W, 3) frame reads, as one row of bytes: a clip's frames
    are sampled as they stream and turned into thumbnails many at a time (:class:`Thumbnails`)."""
    return np.ascontiguousarray(rgb).reshape(-1).take(_sample_bytes(rgb.shape[0], rgb.shape[1]))


def thumbnails(samples: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    """(N, rows * cols) thumbnails of (N, S) rows of :func:`thumbnail_samples`."""
    rows, cols = THUMB_SHAPE
    n = samples.shape[0]
    # the k sample rows of each cell summed (exactly, in integers), then its k columns' RGB weighed
    by_row = samples.reshape(n, rows, CELL_SAMPLES, cols * CELL_SAMPLES * 3)
    cells = by_row[:, :, 0].astype(np.uint16)
    for i in range(1, CELL_SAMPLES):
        cells += by_row[:, :, i]
    v = (cells.reshape(n, rows, cols, CELL_SAMPLES * 3).astype(np.float32) @ _CELL_LUMA).reshape(n, rows * cols)
    v -= v.mean(axis=1, keepdims=True)
    norm = np.sqrt(np.einsum("ij,ij->i", v, v))
    flat = norm <= 1e-3 * np.sqrt(rows * cols)
    v /= np.where(flat, 1.0, norm)[:, None]
    v[flat] = 0.0
    return v


# Pixels read per thumbnail cell along each axis.
CELL_SAMPLES = 2
# Luma weights (ITU-R 601) of one cell row's samples, divided by the samples a cell has: a dot
# product with them is the cell's mean luma.
_CELL_LUMA = (np.tile(np.array([0.299, 0.587, 0.114], np.float32), CELL_SAMPLES) / CELL_SAMPLES**2).astype(np.float32)
_SAMPLE_BYTES: dict[tuple[int, int], npt.NDArray[np.intp]] = {}


def _sample_bytes(height: int, width: int) -> npt.NDArray[np.intp]:
    """Offsets in an (H, W, 3) frame's bytes of the pixels a thumbnail reads, (rows * k, cols * k, 3)
    in order: evenly spaced, centred in their share of the frame (a frame smaller than the grid
    repeats its pixels)."""
    offsets = _SAMPLE_BYTES.get((height, width))
    if offsets is None:
        def centres(n: int, cells: int) -> npt.NDArray[np.intp]:
            m = cells * CELL_SAMPLES
            return np.minimum(((np.arange(m) + 0.5) * n / m).astype(np.intp), n - 1)

        pixel = centres(height, THUMB_SHAPE[0])[:, None] * width + centres(width, THUMB_SHAPE[1])[None, :]
        offsets = _SAMPLE_BYTES[(height, width)] = (pixel[..., None] * 3 + np.arange(3)).reshape(-1)
    return offsets


class Thumbnails:
    """Thumbnails of a clip's frames as they stream: each frame's pixel samples are read as it
    passes (9 KB), and every :data:`BATCH` of them become thumbnails in one numpy pass, a third of
    the cost of one pass a frame; at most a batch of samples is held beside the thumbnails (3 KB a
    frame)."""

    BATCH = 64

    def __init__(self) -> None:
        self.indexes: list[int] = []
        self._done: list[npt.NDArray[np.float32]] = []
        self._pending: list[npt.NDArray[np.uint8]] = []

    def add(self, index: int, rgb: npt.NDArray[np.uint8]) -> None:
        """Take frame ``index``'s thumbnail (indexes increasing)."""
        self.indexes.append(index)
        self._pending.append(thumbnail_samples(rgb))
        if len(self._pending) == self.BATCH:
            self._flush()

    def _flush(self) -> None:
        if self._pending:
            self._done.append(thumbnails(np.stack(self._pending)))
            self._pending = []

    def stacked(self) -> npt.NDArray[np.float32]:
        """(len(indexes), rows * cols) thumbnails, in the order added."""
        self._flush()
        if not self._done:
            return np.zeros((0, THUMB_SHAPE[0] * THUMB_SHAPE[1]), np.float32)
        if len(self._done) > 1:
            self._done = [np.concatenate(self._done)]
        return self._done[0]


class FrameMatchJson(TypedDict):
    """A :class:`FrameMatch` as the metrics cache stores it (None: no match, or no GT frame)."""

    gt_index: list[float | None]
    confidence: list[float | None]
    ties: list[list[int]]


@dataclass
class FrameMatch:
    """The GT frame each imagined frame of one view resembles most.

    Attributes:
        gt_index: (F,) index in the view's GT clip (the middle of the tied run holding the best
            frame, so it may end in .5); NaN where the match is not confident (see
            :attr:`matched`) or there is no GT frame.
        confidence: (F,) best correlation minus the median one; NaN where there is no GT frame.
        ties: per frame, the runs of GT indexes that tie with the best match, flattened
            ``[first, last, first, last, ...]`` (empty where not matched): a held pose, or a
            scene the episode shows twice, is equally well any of them.
    """

    gt_index: Array
    confidence: Array
    ties: list[list[int]]

    @property
    def matched(self) -> npt.NDArray[np.bool_]:
        return np.isfinite(self.gt_index)

    def to_json(self) -> FrameMatchJson:
        return {"gt_index": _floats(self.gt_index, 1), "confidence": _floats(self.confidence, 4),
                "ties": self.ties}

    @classmethod
    def from_json(cls, data: FrameMatchJson) -> FrameMatch:
        gt_index, confidence = _array(data["gt_index"]), _array(data["confidence"])
        ties = [[int(i) for i in runs] for runs in data["ties"]]
        if not (gt_index.shape == confidence.shape and len(ties) == gt_index.size
                and all(len(runs) % 2 == 0 for runs in ties)):
            raise ValueError("frame match: gt_index, confidence and ties do not describe the same frames")
        return cls(gt_index, confidence, ties)

    def reindexed(self, index_of_position: npt.ArrayLike) -> FrameMatch:
        """The same match with GT positions (0, 1, ... among the frames read) turned into clip
        indexes (a clip's numbering may have gaps)."""
        index = np.asarray(index_of_position, np.float64)
        if index.size == 0 or np.array_equal(index, np.arange(index.size)):
            return self  # no gaps: positions are indexes
        gt_index = self.gt_index.copy()
        ok = self.matched
        gt_index[ok] = np.interp(gt_index[ok], np.arange(index.size), index)
        ties = [[int(index[i]) for i in runs] for runs in self.ties]
        return FrameMatch(gt_index, self.confidence, ties)


def _floats(a: Array, digits: int) -> list[float | None]:
    return [round(float(v), digits) if np.isfinite(v) else None for v in a]


def _array(values: list[float | None]) -> Array:
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64).reshape(-1)


def match_frames(imagined: npt.NDArray[np.float32], gt: npt.NDArray[np.float32]) -> FrameMatch:
    """Match every imagined thumbnail to the GT thumbnails, all pairs at once.

    Args:
        imagined: (F, D) thumbnails (:func:`thumbnail`).
        gt: (G, D) thumbnails of the GT clip, in clip order.
    """
    n = imagined.shape[0]
    if gt.shape[0] == 0 or n == 0:
        return FrameMatch(np.full(n, np.nan), np.full(n, np.nan), [[] for _ in range(n)])
    scores = imagined @ gt.T  # (F, G) correlations
    best = scores.argmax(axis=1)
    top = scores[np.arange(n), best]
    confidence = (top - _row_medians(scores)).astype(np.float64)
    ok = (confidence >= MIN_CONFIDENCE) & (top >= MIN_CORRELATION)
    # the runs of GT frames tied with the best one, of every matched frame at once
    near = scores >= (top - TIE_FRACTION * confidence)[:, None]
    near[~ok] = False
    run_row, first, last = _runs(near)
    holding = (first <= best[run_row]) & (best[run_row] <= last)
    gt_index = np.full(n, np.nan)
    gt_index[run_row[holding]] = (first[holding] + last[holding]) / 2.0
    flat_runs = np.stack([first, last], axis=1).reshape(-1).tolist()
    bounds = np.concatenate([[0], np.cumsum(2 * np.bincount(run_row, minlength=n))]).tolist()
    ties = [flat_runs[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    return FrameMatch(gt_index, confidence, ties)


def _row_medians(a: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """``np.median(a, axis=1)`` of a finite array, by sorting: 8x quicker here (numpy's median
    partitions at two places, one to look for NaN, which costs more than a sort of 500 values)."""
    ordered = np.sort(a, axis=1)
    half = a.shape[1] // 2
    return ordered[:, half] if a.shape[1] % 2 else (ordered[:, half - 1] + ordered[:, half]) / np.float32(2)


class ViewAgreementJson(TypedDict):
    """One view's entry of a report row's ``video_action``."""

    lag_s_median: float | None
    lag_s_abs_mean: float | None
    matched_fraction: float
    split_chunk: int | None
    video_tempo: float | None
    frozen: bool | None
    note: str | None


@dataclass
class VideoAction:
    """One view's agreement over the rollout, per imagined frame.

    Attributes:
        view: the camera.
        frame_step: (F,) the executed step each imagined frame shows.
        frame_chunk: (F,) its chunk.
        video_gt_s: (F,) the video's GT time [s since the start frame]; NaN: no match.
        confidence: (F,) the match's confidence (NaN: no GT frame).
        joints_gt_s: (F,) the joints' GT time at the frame's step [s], or None without GT joints.
        fps: steps per second.
        video_match_s: (F,) the video's GT time of the match itself [s] (before a tied match is
            paired with the joints' time nearest to it), or None: as ``video_gt_s``.
    """

    view: str
    frame_step: npt.NDArray[np.int64]
    frame_chunk: npt.NDArray[np.int64]
    video_gt_s: Array
    confidence: Array
    joints_gt_s: Array | None
    fps: float
    video_match_s: Array | None = None

    @property
    def lag_s(self) -> Array | None:
        """(F,) video GT time - joints GT time [s]; NaN where the frame has no match (the video's,
        or the joints' off the GT path)."""
        return None if self.joints_gt_s is None else self.video_gt_s - self.joints_gt_s

    def spans(self) -> tuple[float, float] | None:
        """(video, joints): how much of the episode [s] each side's GT time covers over the frames
        whose lag is measured, from its 10th to its 90th percentile; None without two such frames.

        The video's side is its match itself: a still frame that ties with two times of the
        episode (the rest pose at its start and end) stays at one of them, where pairing it with
        the joints would follow them from one to the other."""
        lag = self.lag_s
        if lag is None or self.joints_gt_s is None:
            return None
        both = np.isfinite(lag)
        if both.sum() < 2:
            return None
        video = self.video_gt_s if self.video_match_s is None else self.video_match_s
        return _span(video[both]), _span(self.joints_gt_s[both])

    def frozen(self) -> bool | None:
        """Whether the video stands still while the joints move: its GT time covers less than
        :data:`FROZEN_SHARE` of the joints' and theirs at least :data:`FROZEN_MIN_SPAN_S` (None: no
        lag measured, see :meth:`spans`). A frozen video's lag is no lag: each frame's is only the
        joints' distance from the one time the video shows."""
        spans = self.spans()
        if spans is None:
            return None
        video, joints = spans
        return bool(joints >= FROZEN_MIN_SPAN_S and video < FROZEN_SHARE * joints)

    @property
    def matched_fraction(self) -> float:
        return float(np.isfinite(self.video_gt_s).mean()) if self.video_gt_s.size else 0.0

    def split_chunk(self) -> int | None:
        """The first chunk from which on |lag| (the median of each chunk's matched frames) stays
        above :data:`SPLIT_LAG_S`: it is above there and in at least :data:`SPLIT_SHARE` of the
        measured chunks after it (a held pose, where no shift can show, does not end it; chunks
        without a matched frame are not measured)."""
        lag = self.lag_s
        if lag is None:
            return None
        above = []
        for chunk in np.unique(self.frame_chunk):
            values = np.abs(lag[(self.frame_chunk == chunk) & np.isfinite(lag)])
            if values.size:
                above.append((int(chunk), bool(np.median(values) > SPLIT_LAG_S)))
        flags = np.array([a for _, a in above], dtype=np.float64)
        # share of measured chunks above, from each chunk to the end
        share = np.cumsum(flags[::-1])[::-1] / np.arange(len(flags), 0, -1) if len(flags) else flags
        for (chunk, is_above), s in zip(above, share):
            if is_above and s >= SPLIT_SHARE:
                return chunk
        return None

    def video_tempo(self) -> float | None:
        """Slope of the video's GT time against rollout time (1: the real episode's speed)."""
        ok = np.isfinite(self.video_gt_s)
        if ok.sum() < 2 or np.unique(self.frame_step[ok]).size < 2:
            return None
        n_steps = int(self.frame_step.max()) + 1
        index = np.zeros(n_steps)
        valid = np.zeros(n_steps, bool)
        index[self.frame_step[ok]] = self.video_gt_s[ok] * self.fps  # GT time in steps
        valid[self.frame_step[ok]] = True
        value = float(metrics.tempo(index, valid))
        return value if np.isfinite(value) else None

    def summary(self) -> ViewAgreementJson:
        """The view's ``video_action`` entry of a report row (a null says why in ``note``)."""
        lag = self.lag_s
        matched = lag[np.isfinite(lag)] if lag is not None else np.empty(0)
        frozen = self.frozen()
        note = None
        if not np.isfinite(self.video_gt_s).any():
            note = "no match: no imagined frame resembles one GT frame more than the others"
        elif lag is None:
            note = "no GT joints: lag not measured"
        elif not matched.size:
            note = f"no lag: the predicted joints are more than {JOINT_MATCH_MAX:g} from every GT pose where the video matched"
        elif frozen:
            note = frozen_note(self)
            matched = np.empty(0)  # a frozen video's lag is no lag
        return {
            "lag_s_median": round(float(np.median(matched)), 4) if matched.size else None,
            "lag_s_abs_mean": round(float(np.abs(matched).mean()), 4) if matched.size else None,
            "matched_fraction": round(self.matched_fraction, 4),
            "split_chunk": None if frozen else self.split_chunk(),
            "video_tempo": _rounded(self.video_tempo()),
            "frozen": frozen,
            "note": note,
        }


# What a lag reads where there is none to read: a frame (or every frame of a view) without a match
# on one side, and a frozen video.
NO_MATCH = "no match"
FROZEN = "frozen"


def median_lag_label(entry: ViewAgreementJson | None, fmt: str = "+.2f", missing: str = "-") -> str:
    """A view's median lag as a table cell: the number, or why there is none (:data:`FROZEN`,
    :data:`NO_MATCH` where no frame has a match on both sides, ``missing`` otherwise: no GT
    joints, not measured)."""
    if entry is None:
        return missing
    if entry.get("frozen"):
        return FROZEN
    lag = entry.get("lag_s_median")
    if lag is not None:
        return format(lag, fmt)
    note = entry.get("note") or ""
    return NO_MATCH if note.startswith(("no match", "no lag")) else missing


def frozen_note(va: VideoAction) -> str:
    """Why ``va``'s video is frozen, in one line (the note of its report entry)."""
    spans = va.spans()
    assert spans is not None
    return (f"frozen: the video stands still (its GT time spans {spans[0]:.2f} s) while the joints "
            f"move (theirs {spans[1]:.2f} s): no lag")


def _span(values: Array) -> float:
    """How far ``values`` spread: their 10th to 90th percentile (:data:`SPAN_PERCENTILES`)."""
    lo, hi = np.percentile(values, SPAN_PERCENTILES)
    return float(hi - lo)


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


@dataclass
class JointTimes:
    """Where the predicted joints are on the GT episode (from the timeline's best match).

    Attributes:
        pred: (T, 6) executed predicted joints.
        gt: (G, 6) GT joints.
        offset: index in ``gt`` of rollout step 0.
        best_index: (T,) the best-match argmin (index in ``gt``).
        best_drift: (T,) its distance.
    """

    pred: Array
    gt: Array
    offset: int
    best_index: npt.NDArray[np.int64]
    best_drift: Array

    def tied_runs(self, steps: npt.NDArray[np.intp]) -> tuple[npt.NDArray[np.intp], Array]:
        """For each of ``steps``, the middles of the runs of GT steps (since the start frame) whose
        pose is as near to the step's as the best match: one per time the episode holds that pose.

        Returns:
            (which of ``steps`` each run is for, its middle), ordered by step, then by time.
        """
        rows, middles = [], []
        for start in range(0, len(steps), self.BLOCK):
            block = steps[start:start + self.BLOCK]
            distance = np.linalg.norm(self.gt[None] - self.pred[block][:, None], axis=2)  # (b, G)
            row, first, last = _runs(distance <= (self.best_drift[block] + JOINT_TIE)[:, None])
            rows.append(row + start)
            middles.append((first + last) / 2.0 - self.offset)
        if not rows:
            return np.empty(0, np.intp), np.empty(0)
        return np.concatenate(rows), np.concatenate(middles)

    # Steps whose distances to every GT pose are computed at once ((BLOCK, G, 6) floats).
    BLOCK = 64


def _runs(mask: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The runs of True in each row of an (N, M) mask, as (row, first, last) arrays in row order."""
    padded = np.zeros((mask.shape[0], mask.shape[1] + 2), bool)
    padded[:, 1:-1] = mask
    # where a row switches: each padded row starts and ends False, so its edges pair up
    row, edge = np.nonzero(padded[:, 1:] != padded[:, :-1])
    return row[0::2], edge[0::2], edge[1::2] - 1


def _nearest_pairs(a_row: npt.NDArray[np.intp], a: Array, b_row: npt.NDArray[np.intp], b: Array, n: int
                   ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """For each of ``n`` rows with values on both sides, the pair of its values (one of ``a``, one
    of ``b``, each tagged with its row) nearest to each other: the first in (``b``, ``a``) order
    where several are as near.

    Returns:
        (row, index in ``a``, index in ``b``) of each row that has a pair.
    """
    count_a, count_b = np.bincount(a_row, minlength=n), np.bincount(b_row, minlength=n)
    pairs = count_a * count_b
    if not pairs.any():
        return (np.empty(0, np.intp),) * 3
    pair_row = np.repeat(np.arange(n), pairs)
    within = np.arange(pair_row.size) - np.repeat(np.cumsum(pairs) - pairs, pairs)
    at_a = (np.cumsum(count_a) - count_a)[pair_row] + within % count_a[pair_row]
    at_b = (np.cumsum(count_b) - count_b)[pair_row] + within // count_a[pair_row]
    gap = np.abs(a[at_a] - b[at_b])
    has = np.flatnonzero(pairs)
    nearest = np.repeat(np.minimum.reduceat(gap, (np.cumsum(pairs) - pairs)[has]), pairs[has])
    hit = np.flatnonzero(gap == nearest)
    first = hit[np.r_[True, pair_row[hit][1:] != pair_row[hit][:-1]]]
    return pair_row[first], at_a[first], at_b[first]


def agreement(view: str, match: FrameMatch, frame_step: npt.NDArray[np.int64], steps_per_chunk: int,
              fps: float, gt_step_of_index: Array, joints: JointTimes | None) -> VideoAction:
    """One view's agreement from its frame match and the joints' best match.

    Where either side is ambiguous (its best match ties with GT frames at other times: a pose or a
    scene the episode shows twice), each tied run counts by its middle and the two GT times are
    the runs' nearest to each other, so an ambiguity never reads as a lag.

    Args:
        view: the camera.
        match: the view's frame match.
        frame_step: (F,) the executed step each imagined frame shows.
        steps_per_chunk: steps each chunk covers.
        fps: steps per second.
        gt_step_of_index: (G,) the rollout step (since the start frame) each GT clip frame shows.
        joints: where the predicted joints are on the episode, or None without GT joints.
    """
    n = match.gt_index.size
    video_step = np.full(n, np.nan)
    joints_step = None if joints is None else (joints.best_index[np.minimum(frame_step, len(joints.best_index) - 1)]
                                               - joints.offset).astype(np.float64)
    steps_of = np.asarray(gt_step_of_index, np.float64)
    matched = np.flatnonzero(match.matched) if steps_of.size else np.empty(0, np.intp)
    video_step[matched] = np.interp(match.gt_index[matched], np.arange(steps_of.size), steps_of)
    video_match = video_step.copy()  # the match itself, before a tie is paired with the joints
    if joints is not None and joints_step is not None:
        off_path = joints.best_drift[np.minimum(frame_step, len(joints.best_drift) - 1)] > JOINT_MATCH_MAX
        joints_step[off_path] = np.nan
        both = matched[np.isfinite(joints_step[matched])]
        # one time per tied run on each side (its middle), and the pair of them nearest to each other
        video_row, video_middle = _video_runs(match, both, steps_of)
        joints_row, joints_middle = joints.tied_runs(np.minimum(frame_step[both], len(joints.pred) - 1))
        row, at_video, at_joints = _nearest_pairs(video_row, video_middle, joints_row, joints_middle, both.size)
        video_step[both[row]] = video_middle[at_video]
        joints_step[both[row]] = joints_middle[at_joints]
    return VideoAction(view, frame_step, frame_step // max(1, steps_per_chunk), video_step / fps,
                       match.confidence, None if joints_step is None else joints_step / fps, fps,
                       video_match / fps)


def _video_runs(match: FrameMatch, frames: npt.NDArray[np.intp], steps_of: Array
                ) -> tuple[npt.NDArray[np.intp], Array]:
    """(which of ``frames`` each run is for, its middle in steps) of the runs of GT frames tied
    with each frame's best match."""
    counts = np.array([len(match.ties[f]) // 2 for f in frames], np.intp)
    flat = np.fromiter(chain.from_iterable(match.ties[f] for f in frames), np.intp, count=2 * int(counts.sum()))
    runs = steps_of[np.clip(flat.reshape(-1, 2), 0, steps_of.size - 1)]  # (r, 2) in steps
    return np.repeat(np.arange(frames.size), counts), runs.mean(axis=1)
