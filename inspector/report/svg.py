"""Small line and scatter charts as inline SVG strings: no plotting library, no script, no network.

What the HTML report draws its figures with (and what any page that can hold SVG, such as the
app's HTML panels, can reuse). Colours come from CSS classes (``c0`` .. ``c9``, ``many``,
``mean``, ``post``, ``band``, ``end``), so the page's stylesheet decides them; legends are HTML
(:func:`legend_html`), under the chart rather than over its curves.

    ax = Axes(x_label="step in chunk", y_label="RMSE [deg]", y_min=0)
    ax.band(steps, lo, hi)
    ax.line(steps, mean, cls="mean", label="mean")
    html = ax.svg() + legend_html(ax.legend)

Each ``<svg>`` carries its data-to-pixel mapping (``data-x="x0 x1 px0 px1"``, ``data-y`` alike), so
a test can read a drawn curve back in data units.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from html import escape

import numpy as np

N_COLOURS = 10  # CSS classes c0 .. c9
# Point markers, told apart by shape where colour already names something else.
MARKERS = ("circle", "square", "triangle", "diamond")
CHAR_PX = 6.6  # the width of a tick label's character at the charts' 11 px font (DejaVu Sans, at most about)
_clip_ids = itertools.count()  # clip paths need ids unique in their page


def colour_class(i: int) -> str:
    """The categorical colour class of the i-th series."""
    return f"c{i % N_COLOURS}"


def series_style(i: int) -> tuple[str, str]:
    """(colour class, legend style) of the i-th of many lines: the colours again, dashed, after the
    first :data:`N_COLOURS` (the dash comes from the ``alt`` class), so twenty lines stay apart."""
    if (i // N_COLOURS) % 2:
        return f"{colour_class(i)} alt", "dash"
    return colour_class(i), "line"


def nice_ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """About ``n`` round tick values (1, 2, 5 x 10^k steps) covering [lo, hi]."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return [0.0]
    if hi <= lo:
        hi = lo + (abs(lo) or 1.0)
    raw = (hi - lo) / max(1, n)
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    first = math.floor(lo / step + 1e-9) * step
    ticks, v = [], first
    while v < hi + step * 0.999:
        ticks.append(round(v, 12))
        v += step
    return ticks


def _fmt(v: float) -> str:
    """A tick label: no trailing zeros, thousands as k."""
    if abs(v) >= 10000:
        return f"{v / 1000:g}k"
    return f"{v:.6g}"


def _num(v: float) -> str:
    """A pixel coordinate, one decimal, no trailing '.0'."""
    s = f"{v:.1f}"
    return s[:-2] if s.endswith(".0") else s


@dataclass
class _Series:
    kind: str  # line | band | points | vline
    xs: np.ndarray
    ys: np.ndarray
    cls: str
    key: str | None = None
    title: str | None = None
    hi: np.ndarray | None = None
    label: str | None = None
    decimals: int = 1
    marker: str = "circle"


@dataclass
class Axes:
    """One chart: add series, then :meth:`svg`. Ranges fit the data (``x_min`` etc. pin them).

    Args:
        x_label, y_label: axis titles (units in brackets).
        width, height: the SVG's size in its own pixels (it scales with the page).
        x_min, x_max, y_min, y_max: fixed range ends (None: from the data).
        x_ticks: (x, name) of each tick of a categorical axis (a session at each rank), in place of
            numbered ticks; names too long to sit side by side are drawn slanted.
    """

    x_label: str = ""
    y_label: str = ""
    width: int = 520
    height: int = 300
    x_min: float | None = None
    x_max: float | None = None
    y_min: float | None = None
    y_max: float | None = None
    x_ticks: list[tuple[float, str]] | None = None
    # (cls, label, style, key) of the series given a label: drawn by :func:`legend_html`
    legend: list[tuple[str, str, str, str | None]] = field(default_factory=list)
    _series: list[_Series] = field(default_factory=list)

    margin_left = 52
    margin_right = 12
    margin_top = 10
    margin_bottom = 40

    # -- adding ------------------------------------------------------------------------------
    def line(self, xs: Sequence[float] | np.ndarray, ys: Sequence[float | None], cls: str, key: str | None = None,
             title: str | None = None, label: str | None = None, style: str = "line", decimals: int = 1) -> None:
        """A polyline; missing (None / NaN) values break it. ``key`` becomes ``data-key`` (the
        page links a curve to its table row), ``title`` a hover tooltip, ``label`` a legend entry,
        ``decimals`` the pixel precision (0 for the faint background of many curves)."""
        self._series.append(_Series("line", _arr(xs), _arr(ys), cls, key, title, decimals=decimals))
        if label:
            self.legend.append((cls, label, style, key))

    def band(self, xs: Sequence[float] | np.ndarray, lo: Sequence[float], hi: Sequence[float], cls: str = "band",
             label: str | None = None) -> None:
        """A filled area between ``lo`` and ``hi``."""
        self._series.append(_Series("band", _arr(xs), _arr(lo), cls, hi=_arr(hi)))
        if label:
            self.legend.append((cls, label, "band", None))

    def points(self, xs: Sequence[float], ys: Sequence[float], cls: str, titles: Sequence[str] | None = None,
               keys: Sequence[str] | None = None, label: str | None = None, marker: str = "circle") -> None:
        """Dots, each with an optional hover title and ``data-key``; ``marker`` is one of
        :data:`MARKERS` (its legend swatch too)."""
        xs_a, ys_a = _arr(xs), _arr(ys)
        for i in range(len(xs_a)):
            self._series.append(_Series("points", xs_a[i:i + 1], ys_a[i:i + 1], cls,
                                        None if keys is None else keys[i],
                                        None if titles is None else titles[i], marker=marker))
        if label:
            self.legend.append((cls, label, "dot" if marker == "circle" else marker, None))

    def vline(self, x: float, cls: str = "end", label: str | None = None) -> None:
        """A vertical marker across the plot, with a label at its top."""
        self._series.append(_Series("vline", _arr([x]), _arr([np.nan]), cls, label=label))

    # -- drawing -----------------------------------------------------------------------------
    def _ranges(self) -> tuple[tuple[float, float], tuple[float, float]]:
        xs = [s.xs for s in self._series]
        ys = [s.ys for s in self._series if s.kind != "vline"] + [s.hi for s in self._series if s.hi is not None]
        x_lo, x_hi = _finite_range(xs, self.x_min, self.x_max)
        y_lo, y_hi = _finite_range(ys, self.y_min, self.y_max)
        if self.y_max is None:
            ticks = nice_ticks(y_lo, y_hi)
            y_hi = max(y_hi, ticks[-1])
            if self.y_min is None:
                y_lo = min(y_lo, ticks[0])
        return (x_lo, x_hi), (y_lo, y_hi)

    def svg(self) -> str:
        """The chart as one ``<svg>`` element."""
        (x0, x1), (y0, y1) = self._ranges()
        slant = self._tick_slant(x1 - x0)
        bottom = self.margin_bottom + (_slanted_height(self.x_ticks or []) if slant else 0)
        px0, px1 = self._slanted_left(x0, x1) if slant else self.margin_left, self.width - self.margin_right
        py0, py1 = self.height - bottom, self.margin_top  # y grows downwards

        def X(v: np.ndarray) -> np.ndarray:
            return px0 + (v - x0) / (x1 - x0) * (px1 - px0)

        def Y(v: np.ndarray) -> np.ndarray:
            return py0 + (v - y0) / (y1 - y0) * (py1 - py0)

        out = [f'<svg class="chart" viewBox="0 0 {self.width} {self.height}" role="img" '
               f'data-x="{x0:.9g} {x1:.9g} {px0} {px1}" data-y="{y0:.9g} {y1:.9g} {py0} {py1}">']
        out.append(self._axes_svg(X, Y, (x0, x1), (y0, y1), (px0, px1), (py0, py1), slant))
        clip = f"clip{next(_clip_ids)}"
        pad = 6  # dots and thick lines at the range's ends stay whole
        out.append(f'<clipPath id="{clip}"><rect x="{px0 - pad}" y="{py1 - pad}" width="{px1 - px0 + 2 * pad}" '
                   f'height="{py0 - py1 + 2 * pad}"/></clipPath><g clip-path="url(#{clip})">')
        label_rows = _label_rows([float(X(s.xs)[0]) for s in self._series if s.kind == "vline" and s.label])
        for s in self._series:
            row = next(label_rows) if s.kind == "vline" and s.label else 0
            out.append(_draw(s, X, Y, (py0, py1), label_dy=12 * row))
        out.append("</g></svg>")
        return "".join(out)

    def _tick_slant(self, x_span: float) -> bool:
        """Whether the named ticks are too long to sit side by side (then they are drawn slanted)."""
        if not self.x_ticks or len(self.x_ticks) < 2:
            return False
        xs = sorted(x for x, _ in self.x_ticks)
        gap_px = min(b - a for a, b in zip(xs, xs[1:])) / x_span * (self.width - self.margin_left - self.margin_right)
        return max(len(name) for _, name in self.x_ticks) * CHAR_PX > gap_px - 8

    def _slanted_left(self, x0: float, x1: float) -> float:
        """The plot's left edge [px] that leaves the first slanted name room to the left of its tick."""
        assert self.x_ticks
        first = min(self.x_ticks)
        need = len(first[1]) * CHAR_PX * math.cos(math.radians(35)) + 4
        f = (first[0] - x0) / (x1 - x0)  # where the first tick sits along the plot
        right = self.width - self.margin_right
        return max(self.margin_left, math.ceil((need - f * right) / (1 - f)))

    def _x_ticks_svg(self, X, xr: tuple[float, float], py0: float, slant: bool) -> list[str]:
        parts = []
        if self.x_ticks is None:
            ticks = [(t, _fmt(t)) for t in nice_ticks(*xr, n=6) if xr[0] - 1e-9 <= t <= xr[1] + 1e-9]
        else:
            ticks = [(t, name) for t, name in self.x_ticks]
        for t, name in ticks:
            x = _num(float(X(np.float64(t))))
            text = (f'<text x="{x}" y="{py0 + 15}" text-anchor="middle">{escape(name)}</text>' if not slant else
                    f'<text x="{x}" y="{py0 + 12}" text-anchor="end" transform="rotate(-35 {x} {py0 + 12})">'
                    f"{escape(name)}</text>")
            parts.append(f'<line class="tick" x1="{x}" x2="{x}" y1="{py0}" y2="{py0 + 4}"/>{text}')
        return parts

    def _axes_svg(self, X, Y, xr: tuple[float, float], yr: tuple[float, float], pxr, pyr, slant: bool = False) -> str:
        (px0, px1), (py0, py1) = pxr, pyr
        parts = ['<g class="axes">']
        for t in nice_ticks(*yr):
            if yr[0] - 1e-9 <= t <= yr[1] + 1e-9:
                y = _num(float(Y(np.float64(t))))
                parts.append(f'<line class="grid" x1="{px0}" x2="{px1}" y1="{y}" y2="{y}"/>'
                             f'<text x="{px0 - 5}" y="{y}" dy="0.32em" text-anchor="end">{_fmt(t)}</text>')
        parts += self._x_ticks_svg(X, xr, py0, slant)
        parts.append(f'<path class="frame" d="M{px0},{py1}V{py0}H{px1}"/>')
        parts.append(f'<text class="label" x="{(px0 + px1) / 2:g}" y="{self.height - 6}" '
                     f'text-anchor="middle">{escape(self.x_label)}</text>')
        parts.append(f'<text class="label" transform="rotate(-90)" x="{-(py0 + py1) / 2:g}" y="13" '
                     f'text-anchor="middle">{escape(self.y_label)}</text>')
        parts.append("</g>")
        return "".join(parts)


def legend_html(entries: Sequence[tuple[str, str, str, str | None]]) -> str:
    """An HTML legend (drawn under a chart, never over its curves) of (cls, label, style, key)
    entries; style is ``line``, ``dash``, ``band`` or ``dot``; ``key`` links an entry to its curves."""
    if not entries:
        return ""
    parts = ['<div class="legend">']
    for cls, label, style, key in entries:
        if style == "band":
            swatch = f'<rect class="{cls}" x="1" y="1" width="20" height="10"/>'
        elif style == "dot":
            swatch = f'<circle class="pt {cls}" cx="11" cy="6" r="4"/>'
        elif style in MARKERS:
            swatch = _marker(style, 11, 6, cls, "", "")
        else:
            dash = ' stroke-dasharray="4 3"' if style == "dash" else ""
            swatch = f'<path class="ln {cls}" d="M1,6h20"{dash}/>'
        data_key = f' data-key="{escape(key)}"' if key is not None else ""
        parts.append(f'<span class="entry"{data_key}><svg width="22" height="12">{swatch}</svg>{escape(label)}</span>')
    parts.append("</div>")
    return "".join(parts)


def _slanted_height(ticks: Sequence[tuple[float, str]]) -> float:
    """The height [px] that tick names slanted at 35 degrees take below the axis, beyond a straight one's."""
    return max(len(name) for _, name in ticks) * CHAR_PX * math.sin(math.radians(35)) - 6


def _marker(shape: str, cx: float, cy: float, cls: str, key: str, title: str, r: float = 4) -> str:
    """A point's marker: a circle, square, triangle or diamond of about the same area, centred on (cx, cy)."""
    attrs = f'class="pt {cls}"{key}'
    if shape == "square":
        s = r * 0.89
        return f'<rect {attrs} x="{_num(cx - s)}" y="{_num(cy - s)}" width="{_num(2 * s)}" height="{_num(2 * s)}">{title}</rect>'
    if shape in ("triangle", "diamond"):
        s = r * 1.25
        corners = ([(cx, cy - s), (cx + s, cy + s * 0.8), (cx - s, cy + s * 0.8)] if shape == "triangle" else
                   [(cx, cy - s), (cx + s, cy), (cx, cy + s), (cx - s, cy)])
        d = "M" + "L".join(f"{_num(a)},{_num(b)}" for a, b in corners) + "Z"
        return f'<path {attrs} d="{d}">{title}</path>'
    return f'<circle {attrs} cx="{_num(cx)}" cy="{_num(cy)}" r="{_num(r)}">{title}</circle>'


def _label_rows(xs_px: list[float], min_gap_px: float = 60.0):
    """Text row (0, 1, 2) of each vertical marker's label, in the markers' order, so labels of
    markers closer than ``min_gap_px`` stack instead of overlapping."""
    rows: list[int] = []
    for i, x in enumerate(xs_px):
        near = [rows[j] for j in range(i) if abs(xs_px[j] - x) < min_gap_px]
        rows.append(next(r for r in range(len(near) + 1) if r not in near) % 3)
    return iter(rows)


def _arr(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64)


def _finite_range(arrays: list[np.ndarray], lo_fixed: float | None, hi_fixed: float | None) -> tuple[float, float]:
    finite = [a[np.isfinite(a)] for a in arrays]
    finite = [a for a in finite if a.size]
    lo = min((float(a.min()) for a in finite), default=0.0)
    hi = max((float(a.max()) for a in finite), default=1.0)
    lo = lo if lo_fixed is None else lo_fixed
    hi = hi if hi_fixed is None else hi_fixed
    if hi <= lo:
        hi = lo + (abs(lo) * 0.1 or 1.0)
    return lo, hi


def _segments(x: np.ndarray, y: np.ndarray, decimals: int = 1) -> list[str]:
    """Path pieces ``Mx,y l dx,dy dx,dy ...`` of the finite runs of (x, y) [px]: each point is
    rounded to ``decimals`` and the steps taken between rounded points (no drift accumulates);
    relative steps keep a thousand curves small."""
    ok = np.isfinite(x) & np.isfinite(y)
    scale = 10 ** decimals
    xi, yi = np.round(np.where(ok, x, 0) * scale).astype(np.int64), np.round(np.where(ok, y, 0) * scale).astype(np.int64)

    def num(v: int) -> str:
        return str(v) if decimals == 0 else _num(v / scale)

    pieces, start = [], None
    for i in range(len(x) + 1):
        if i < len(x) and ok[i]:
            start = i if start is None else start
            continue
        if start is not None:
            steps = " ".join(f"{num(int(xi[j] - xi[j - 1]))},{num(int(yi[j] - yi[j - 1]))}" for j in range(start + 1, i))
            pieces.append(f"M{num(int(xi[start]))},{num(int(yi[start]))}" + (f"l{steps}" if steps else ""))
            start = None
    return pieces


def _draw(s: _Series, X, Y, pyr, label_dy: float = 0) -> str:
    key = f' data-key="{escape(s.key)}"' if s.key is not None else ""
    title = f"<title>{escape(s.title)}</title>" if s.title else ""
    if s.kind == "line":
        d = "".join(_segments(X(s.xs), Y(s.ys), s.decimals))
        return f'<path class="ln {s.cls}"{key} d="{d}">{title}</path>' if d else ""
    if s.kind == "band":
        assert s.hi is not None  # band() always sets hi
        ok = np.isfinite(s.xs) & np.isfinite(s.ys) & np.isfinite(s.hi)
        x, lo, hi = X(s.xs[ok]), Y(s.ys[ok]), Y(s.hi[ok])
        if not len(x):
            return ""
        pts = [f"{_num(float(a))},{_num(float(b))}" for a, b in zip(np.r_[x, x[::-1]], np.r_[hi, lo[::-1]])]
        return f'<path class="{s.cls}" d="M{"L".join(pts)}Z"/>'
    if s.kind == "points":
        if not (np.isfinite(s.xs[0]) and np.isfinite(s.ys[0])):
            return ""
        return _marker(s.marker, float(X(s.xs)[0]), float(Y(s.ys)[0]), s.cls, key, title)
    x = _num(float(X(s.xs)[0]))
    label = (f'<text class="vlabel" x="{x}" y="{_num(pyr[1] + 2 + label_dy)}" dx="3" dy="0.8em">{escape(s.label)}</text>'
             if s.label else "")
    return f'<path class="{s.cls}" d="M{x},{pyr[0]}V{pyr[1]}"/>{label}'
