"""uPlot charts over rollout time with chunk boundaries, the episode's end and a moving cursor.

uPlot draws every series of a chart against one shared x array and cannot be given a vertical line
directly, so markers are extra x samples: a vertical line at ``x`` is two samples ``(x, lo)`` and
``(x, hi)`` of a series that is NaN everywhere else (uPlot draws nothing for NaN), and the data
series take interpolated values at those samples so their lines pass through unbroken. Chunk
boundaries are one "comb" series (short ticks along the bottom). The cursor is re-inserted on each
scrub: the only per-step cost is a few ``np.insert`` calls and one prop update.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

TICK_COLOR = "#9aa0a6"
END_COLOR = "#d62728"
CURSOR_COLOR = "#111111"
MARK_COLOR = "#495057"


Mark = tuple[float, str] | tuple[float, str, str]  # (x, label[, color]) of a vertical line


@dataclass
class Line:
    """One data series. ``y``: (n,) values at the chart's x samples (NaN = no value)."""

    label: str
    y: Array
    color: str
    width: float = 1.5
    dash: tuple[float, ...] | None = None


def y_range(lines: Sequence[Line], floor: float | None = None, pad: float = 0.06) -> tuple[float, float]:
    """(lo, hi) covering every finite value with a margin; ``floor`` pins the bottom (e.g. 0)."""
    vals = np.concatenate([np.asarray(line.y, np.float64).ravel() for line in lines]) if lines else np.zeros(0)
    vals = vals[np.isfinite(vals)]
    if vals.size == 0:
        return (0.0 if floor is None else floor), 1.0
    lo, hi = float(vals.min()), float(vals.max())
    if floor is not None:
        lo = min(lo, floor)
    span = hi - lo if hi > lo else max(1.0, abs(hi))
    return (lo if floor is not None and lo == floor else lo - pad * span), hi + pad * span


class CursorPlot:
    """A uPlot line chart over time [s] with markers and a cursor at the current time.

    Args:
        gui: the client's GuiApi (inside the container the chart belongs to).
        title: chart title (say the unit).
        x: (n,) sample times [s], ascending.
        lines: data series.
        ticks: x of chunk boundaries (short ticks along the bottom).
        end: x of the real episode's end (a dashed red line), or None.
        marks: further vertical lines, ``(x, label)`` (dashed, dark) or ``(x, label, color)``
            each; marks of one label and color are one series (one legend entry).
        floor: pin the y axis bottom (0 for errors).
        height: chart height [px].
    """

    def __init__(self, gui, title: str, x: npt.ArrayLike, lines: Sequence[Line], *,
                 ticks: npt.ArrayLike = (), end: float | None = None, floor: float | None = None,
                 height: int = 220, visible: bool = True, marks: Sequence[Mark] = ()) -> None:
        self._ticks = np.asarray(ticks, np.float64)
        self._end = end
        self._marks = list(marks)
        self._floor = floor
        self._cursor_x: float | None = None
        self._build(np.asarray(x, np.float64), list(lines))
        self.handle = gui.add_uplot(
            self._data_with_cursor(), self._series_options(), title=title,
            scales={"x": {"time": False, "range": self._x_range}, "y": {"range": self._y_range}},
            legend={"show": True, "live": False}, height=height, visible=visible,
            padding=(10, 16, 0, 0),  # room for the top y tick label
        )

    @property
    def lines(self) -> list[Line]:
        """The data series shown."""
        return list(self._lines)

    @property
    def visible(self) -> bool:
        return bool(self.handle.visible)

    @visible.setter
    def visible(self, value: bool) -> None:
        self.handle.visible = value

    def set_lines(self, lines: Sequence[Line], x: npt.ArrayLike | None = None, title: str | None = None,
                  marks: Sequence[Mark] | None = None) -> None:
        """Replace the data series (e.g. another joint picked); markers (unless ``marks`` replaces
        the further ones) and cursor stay."""
        if marks is not None:
            self._marks = list(marks)
        self._build(self._x if x is None else np.asarray(x, np.float64), list(lines))
        self.handle.series = self._series_options()
        self.handle.scales = {"x": {"time": False, "range": self._x_range}, "y": {"range": self._y_range}}
        if title is not None:
            self.handle.title = title
        self.handle.data = self._data_with_cursor()

    def set_cursor(self, x: float) -> None:
        """Move the cursor line to time ``x`` [s] (the per-scrub update)."""
        if self._cursor_x == x:
            return
        self._cursor_x = float(x)
        self.handle.data = self._data_with_cursor()

    # -- data assembly ------------------------------------------------------------------------
    def _build(self, x: Array, lines: list[Line]) -> None:
        """Merge data samples with the static marker samples, sorted by x."""
        self._x, self._lines = x, lines
        lo, hi = y_range(lines, floor=self._floor)
        self._y_range = (lo, hi)
        x0 = float(x[0]) if len(x) else 0.0
        x1 = max(float(x[-1]) if len(x) else 0.0, self._end or 0.0)
        self._x_range = (x0, x1 if x1 > x0 else x0 + 1.0)
        # Marker samples: chunk ticks (lo, tick top, lo per boundary) and the episode-end line.
        tick_top = lo + 0.07 * (hi - lo)
        groups = [(np.repeat(self._ticks, 3), np.tile([lo, tick_top, lo], len(self._ticks)),
                   _series("chunks", TICK_COLOR, 1.0))]
        if self._end is not None:
            groups.append((np.array([self._end, self._end]), np.array([lo, hi]),
                           _series("episode end", END_COLOR, 1.5, (6, 4))))
        by_series: dict[tuple[str, str], list[float]] = {}
        for mark in self._marks:
            by_series.setdefault((mark[1], mark[2] if len(mark) > 2 else MARK_COLOR), []).append(float(mark[0]))
        for (label, color), xs in by_series.items():
            # (x, lo), (x, hi), (x, NaN) per mark: the NaN keeps uPlot from joining one mark to the next
            groups.append((np.repeat(xs, 3), np.tile([lo, hi, np.nan], len(xs)), _series(label, color, 1.5, (3, 3))))
        all_x = np.concatenate([x, *[g[0] for g in groups]])
        order = np.argsort(all_x, kind="stable")  # equal x keep their order: a tick reads lo, hi, lo
        self._X = all_x[order]
        extra_x = np.concatenate([g[0] for g in groups])
        self._data = [np.concatenate([line.y, _interp(extra_x, x, line.y)])[order] for line in lines]
        self._markers = []
        offset = len(x)
        for gx, gy, options in groups:
            arr = np.full(len(all_x), np.nan)
            arr[offset:offset + len(gx)] = gy
            offset += len(gx)
            self._markers.append((arr[order], options))

    def _data_with_cursor(self) -> tuple[Array, ...]:
        x = self._cursor_x
        if x is None:
            x = float(self._X[0]) if len(self._X) else 0.0
        i = int(np.searchsorted(self._X, x, side="right"))
        lo, hi = self._y_range
        here = np.array([x, x])
        out = [np.insert(self._X, i, here)]
        out += [np.insert(d, i, _interp(here, self._x, line.y)) for d, line in zip(self._data, self._lines)]
        out += [np.insert(arr, i, [np.nan, np.nan]) for arr, _ in self._markers]
        out.append(np.insert(np.full(len(self._X), np.nan), i, [lo, hi]))
        return tuple(out)

    def _series_options(self) -> tuple[dict, ...]:
        return (
            {"label": "t [s]"},
            *[_series(s.label, s.color, s.width, s.dash) for s in self._lines],
            *[options for _, options in self._markers],
            _series("now", CURSOR_COLOR, 1.5),
        )


def _series(label: str, color: str, width: float, dash: tuple[float, ...] | None = None) -> dict:
    """uPlot options of a line series without point markers."""
    opt: dict = {"label": label, "stroke": color, "width": width, "points": {"show": False}}
    if dash:
        opt["dash"] = list(dash)
    return opt


def _interp(xq: Array, x: Array, y: Array) -> Array:
    """Values of the polyline (x, y) at ``xq``; NaN where ``y`` is NaN nearby or x is empty."""
    if len(xq) == 0:
        return np.zeros(0)
    if len(x) == 0:
        return np.full(len(xq), np.nan)
    return np.interp(xq, x, np.asarray(y, np.float64))
