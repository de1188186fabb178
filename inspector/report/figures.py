"""The aggregate figures of an evaluation, from ``inspector report`` rows alone.

They reproduce the DreamZero-SO101 report's figures from raw outputs:

- **per-step RMSE over the horizon** across single-chunk samples (each sample, mean, min..max);
- **RMSE against position in the episode** (start frame / episode length) of single-chunk samples;
- **per-joint predicted vs GT** of single-chunk samples over the horizon;
- **time-aligned drift per chunk** of every autoregressive rollout on one plot, each episode's end
  marked, **best-match drift** beside it;
- **video-action lag** of every rollout and view (does the imagined video show what its joints say?).

Each figure (:data:`FIGURES`) has a data function (plain numbers, what a test or another view
checks) and a function drawing it as inline SVG (:mod:`inspector.report.svg`), which any page that
holds HTML can show. Rows are identified by their index in the list given (``key``), which the
HTML report uses to link a curve to its table row.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..data.session import CHAINED_KINDS
from ..units import JOINT_NAMES
from .svg import N_COLOURS, Axes, colour_class, nice_ticks

Row = dict[str, Any]
# Series drawn in their own colour, with a legend; more are drawn alike, with their mean.
MAX_LEGEND = N_COLOURS
# Single-chunk samples in the joint overlay (each in its own colour).
MAX_OVERLAY_SAMPLES = N_COLOURS
# Episode ends labelled in a drift plot (more are drawn unlabelled).
MAX_END_LABELS = 6


@dataclass
class Panel:
    """One chart of a figure: its SVG and a heading."""

    svg: str
    title: str = ""


@dataclass
class Figure:
    """One figure of the report.

    Attributes:
        key: a short identifier (the HTML element's id).
        title: the figure's heading.
        caption: what is drawn, with definitions and units.
        panels: its charts (several for small multiples), none when there is nothing to draw.
        legend: entries shared by its panels (see :func:`inspector.report.svg.legend_html`).
        note: why nothing is drawn, or what was left out.
    """

    key: str
    title: str
    caption: str
    panels: list[Panel] = field(default_factory=list)
    legend: list[tuple[str, str, str, str | None]] = field(default_factory=list)
    note: str | None = None


def _single_chunk(rows: Sequence[Row]) -> list[tuple[int, Row]]:
    return [(i, r) for i, r in enumerate(rows) if r["kind"] == "single_chunk"]


def _label(r: Row, sessions: int) -> str:
    return f"{r['session']}/{r['tag']}" if sessions > 1 and r.get("session") else r["tag"]


def _n_sessions(rows: Sequence[Row]) -> int:
    return len({r.get("session") for r in rows})


# ----------------------------------------------------------------------------------------------
# Per-step RMSE over the horizon


def per_step_rmse(rows: Sequence[Row]) -> dict[str, Any] | None:
    """Per-step RMSE of each single-chunk sample with GT joints (``sqrt(per_step_mse)``: RMSE over
    the joints at each step of the horizon), their mean and min..max over samples.

    Samples of the most common horizon are used (others are counted in ``n_other_horizon``).

    Returns:
        None without samples, else ``keys`` (row indexes), ``per_sample`` (n, H), ``mean``,
        ``min``, ``max`` (H,) [data units], ``n_other_horizon``.
    """
    samples = [(i, r) for i, r in _single_chunk(rows) if r.get("per_step_mse")]
    if not samples:
        return None
    horizon = Counter(len(r["per_step_mse"]) for _, r in samples).most_common(1)[0][0]
    used = [(i, r) for i, r in samples if len(r["per_step_mse"]) == horizon]
    per_sample = np.sqrt(np.array([r["per_step_mse"] for _, r in used], dtype=np.float64))
    return {"keys": [i for i, _ in used], "per_sample": per_sample, "mean": per_sample.mean(axis=0),
            "min": per_sample.min(axis=0), "max": per_sample.max(axis=0),
            "n_other_horizon": len(samples) - len(used)}


def _draw_per_step_rmse(fig: Figure, rows: Sequence[Row], data: dict[str, Any]) -> None:
    per_sample = data["per_sample"]
    steps = np.arange(per_sample.shape[1])
    ax = Axes(x_label="step in chunk", y_label="RMSE [deg]", y_min=0, x_min=0, x_max=float(steps[-1]))
    n, sessions = len(data["keys"]), _n_sessions(rows)
    ax.band(steps, data["min"], data["max"], label="min..max")
    if n > MAX_LEGEND:
        ax.legend.append(("many", "each sample", "line", None))
    for j, (key, y) in enumerate(zip(data["keys"], per_sample)):
        r = rows[key]
        few = n <= MAX_LEGEND
        ax.line(steps, y, colour_class(j) if few else "many", key=str(key),
                title=f"{_label(r, sessions)} (RMSE {r['rmse_deg']:.3f})",
                label=_label(r, sessions) if few and n > 1 else None, decimals=1 if few else 0)
    ax.line(steps, data["mean"], "mean", label=f"mean of {n}")
    fig.panels.append(Panel(ax.svg()))
    fig.legend = ax.legend
    if data["n_other_horizon"]:
        fig.note = f"{data['n_other_horizon']} sample(s) with another horizon left out"


# ----------------------------------------------------------------------------------------------
# Video-action lag across rollouts


def video_action_lags(rows: Sequence[Row]) -> dict[str, Any] | None:
    """Median lag (video GT time - joints GT time) of every rollout and view that has one.

    Returns:
        None when no rollout has a lag, else ``views``, ``frozen`` (the rollouts and views whose
        video is frozen: no lag) and, per view, ``keys`` (row indexes) and ``lag`` (s).
    """
    by_view: dict[str, tuple[list[int], list[float]]] = defaultdict(lambda: ([], []))
    frozen = []
    for i, r in enumerate(rows):
        for view, entry in sorted((r.get("video_action") or {}).items()):
            if entry is not None and entry.get("frozen"):
                frozen.append(f"{r['tag']} {view}")
            if entry is not None and entry.get("lag_s_median") is not None:
                by_view[view][0].append(i)
                by_view[view][1].append(entry["lag_s_median"])
    if not by_view:
        return None
    return {"views": sorted(by_view), "frozen": frozen,
            **{view: {"keys": keys, "lag": np.array(lags, dtype=np.float64)} for view, (keys, lags) in by_view.items()}}


def _draw_video_action_lags(fig: Figure, rows: Sequence[Row], data: dict[str, Any]) -> None:
    from ..analysis.video_action import SPLIT_LAG_S

    n = len(rows)
    lags = np.concatenate([data[v]["lag"] for v in data["views"]])
    reach = max(2 * SPLIT_LAG_S, float(np.abs(lags).max()) * 1.1)
    ax = Axes(x_label="rollout (table order)", y_label="median lag, video - joints [s]", x_min=0,
              x_max=max(1.0, n - 1.0), y_min=-reach, y_max=reach)
    ax.band([0, max(1.0, n - 1.0)], [-SPLIT_LAG_S, -SPLIT_LAG_S], [SPLIT_LAG_S, SPLIT_LAG_S],
            label=f"|lag| <= {SPLIT_LAG_S:g} s")
    sessions = _n_sessions(rows)
    for v_i, view in enumerate(data["views"]):
        keys = data[view]["keys"]
        titles = []
        for k in keys:
            entry = rows[k]["video_action"][view]
            split = "" if entry.get("split_chunk") is None else f", parts from chunk {entry['split_chunk']}"
            titles.append(f"{_label(rows[k], sessions)} {view}: median lag {entry['lag_s_median']:+.2f} s, "
                          f"mean |lag| {entry['lag_s_abs_mean']:.2f} s, "
                          f"{100 * entry['matched_fraction']:.0f}% of frames matched{split}")
        ax.points(keys, data[view]["lag"], colour_class(v_i), titles=titles, keys=[str(k) for k in keys],
                  label=view)
    fig.panels.append(Panel(ax.svg()))
    fig.legend = ax.legend
    if data["frozen"]:
        fig.note = f"frozen video (no lag), left out: {', '.join(data['frozen'])}"


# ----------------------------------------------------------------------------------------------
# RMSE against position in the episode


def rmse_by_position(rows: Sequence[Row]) -> dict[str, Any] | None:
    """Chunk RMSE of each single-chunk sample against where it starts in its episode.

    Returns:
        None without samples, else ``keys``, ``x``, ``rmse``, and ``relative``: True when x is the
        start frame / episode length (every sample's length known), False when x is the start
        frame.
    """
    samples = [(i, r) for i, r in _single_chunk(rows) if r.get("rmse_deg") is not None]
    if not samples:
        return None
    relative = all(r.get("episode_length") for _, r in samples)
    x = [r["start_frame"] / r["episode_length"] if relative else r["start_frame"] for _, r in samples]
    return {"keys": [i for i, _ in samples], "x": np.array(x, dtype=np.float64),
            "rmse": np.array([r["rmse_deg"] for _, r in samples], dtype=np.float64), "relative": relative}


def _draw_rmse_by_position(fig: Figure, rows: Sequence[Row], data: dict[str, Any]) -> None:
    sessions = sorted({str(rows[k].get("session")) for k in data["keys"]})
    rel = data["relative"]
    ax = Axes(x_label="start frame / episode length" if rel else "start frame", y_label="chunk RMSE [deg]",
              y_min=0, x_min=0, x_max=1.0 if rel else nice_ticks(0.0, float(data["x"].max()))[-1])
    for s_i, session in enumerate(sessions):
        idx = [j for j, k in enumerate(data["keys"]) if str(rows[k].get("session")) == session]
        titles = []
        for j in idx:
            r = rows[data["keys"][j]]
            where = f"frame {r['start_frame']}" + (f" of {r['episode_length']}" if r.get("episode_length") else "")
            titles.append(f"{_label(r, len(sessions))}: RMSE {r['rmse_deg']:.3f} at {where}")
        ax.points(data["x"][idx], data["rmse"][idx], colour_class(s_i), titles=titles,
                  keys=[str(data["keys"][j]) for j in idx], label=f"{session} (a dot per sample)")
    fig.panels.append(Panel(ax.svg()))
    fig.legend = ax.legend
    if not rel:
        fig.note = "episode lengths unknown for some samples: x is the start frame"


# ----------------------------------------------------------------------------------------------
# Per-joint predicted vs GT


def joint_overlay(rows: Sequence[Row]) -> dict[str, Any] | None:
    """Predicted and GT joints of single-chunk samples over their horizon, for the overlay.

    At most :data:`MAX_OVERLAY_SAMPLES` samples (evenly spread over the rows), so each keeps its
    own colour.

    Returns:
        None without samples, else ``keys``, ``pred`` and ``gt`` (n, H, 6) [data units; GT NaN
        where unknown], ``n_total`` samples.
    """
    samples = [(i, r) for i, r in _single_chunk(rows) if r.get("chunk_joints")]
    if not samples:
        return None
    horizon = Counter(len(r["chunk_joints"]["pred"]) for _, r in samples).most_common(1)[0][0]
    samples = [(i, r) for i, r in samples if len(r["chunk_joints"]["pred"]) == horizon]
    n_total = len(samples)
    if n_total > MAX_OVERLAY_SAMPLES:
        samples = [samples[int(j)] for j in np.linspace(0, n_total - 1, MAX_OVERLAY_SAMPLES).round()]
    pred = np.array([r["chunk_joints"]["pred"] for _, r in samples], dtype=np.float64)
    gt = np.full_like(pred, np.nan)
    for j, (_, r) in enumerate(samples):
        if r["chunk_joints"]["gt"] is not None:
            gt[j] = [[np.nan] * pred.shape[2] if q is None else q for q in r["chunk_joints"]["gt"]]
    return {"keys": [i for i, _ in samples], "pred": pred, "gt": gt, "n_total": n_total}


def _draw_joint_overlay(fig: Figure, rows: Sequence[Row], data: dict[str, Any]) -> None:
    sessions = _n_sessions(rows)
    steps = np.arange(data["pred"].shape[1])
    for joint, name in enumerate(JOINT_NAMES):
        unit = "[0..100]" if name == "gripper" else "[deg]"
        ax = Axes(x_label="step in chunk", y_label=f"{name} {unit}", width=360, height=240,
                  x_min=0, x_max=float(steps[-1]))
        for j, key in enumerate(data["keys"]):
            r = rows[key]
            cls = colour_class(j)
            where = f"{_label(r, sessions)}, frame {r['start_frame']}"
            ax.line(steps, data["gt"][j, :, joint], f"{cls} gt", key=str(key), title=f"{where}: GT")
            ax.line(steps, data["pred"][j, :, joint], cls, key=str(key), title=f"{where}: predicted",
                    label=_label(r, sessions))
        fig.panels.append(Panel(ax.svg(), name))
        if joint == 0:
            fig.legend = ax.legend + [("c7 gt", "GT", "dash", None)]
    if data["n_total"] > len(data["keys"]):
        fig.note = f"{len(data['keys'])} of {data['n_total']} samples shown, evenly spread over the table's order"


# ----------------------------------------------------------------------------------------------
# Drift per chunk of autoregressive rollouts


def drift_curves(rows: Sequence[Row], metric: str = "time_aligned_drift") -> dict[str, Any] | None:
    """Per-chunk ``metric`` (``time_aligned_drift``, ``best_match_drift``, ``dtw_drift``) of every
    autoregressive rollout with GT joints, and where each episode ends.

    Chunk k's value (the mean over its executed steps) sits at x = k + 0.5 chunks executed; an
    episode's end at x = (episode length - start frame) / steps per chunk.

    Returns:
        None without such rollouts, else ``keys``, ``x`` and ``y`` (lists of (n_chunks,) arrays),
        ``inside`` (chunks before the episode's end, per rollout), ``ends`` ({x: [label, ...]}),
        ``mean`` (max n_chunks,) over rollouts, [data units].
    """
    used = [(i, r) for i, r in enumerate(rows)
            if r["kind"] in CHAINED_KINDS and r.get(metric) and r[metric].get("per_chunk")]
    if not used:
        return None
    xs, ys, inside = [], [], []
    ends: dict[float, list[str]] = defaultdict(list)
    for _, r in used:
        y = np.array(r[metric]["per_chunk"], dtype=np.float64)
        xs.append(np.arange(len(y)) + 0.5)
        ys.append(y)
        post = r.get("post_episode_chunks") or 0
        inside.append(len(y) - post)
        if r.get("episode_length") and r.get("steps_per_chunk"):
            end = (r["episode_length"] - r["start_frame"]) / r["steps_per_chunk"]
            if end > 0:
                label = "end ep " + ("?" if r["episode_index"] is None else str(r["episode_index"]))
                if label not in ends[round(end, 3)]:
                    ends[round(end, 3)].append(label)
    longest = max(len(y) for y in ys)
    padded = np.full((len(ys), longest), np.nan)
    for j, y in enumerate(ys):
        padded[j, :len(y)] = y
    return {"keys": [i for i, _ in used], "x": xs, "y": ys, "inside": inside, "ends": dict(ends),
            "mean": np.nanmean(padded, axis=0)}


def _drift_panel(rows: Sequence[Row], data: dict[str, Any], name: str) -> tuple[Panel, list]:
    """The panel of one drift metric and its legend entries."""
    n, sessions = len(data["keys"]), _n_sessions(rows)
    ax = Axes(x_label="chunks executed", y_label=f"{name} drift [deg]", y_min=0, x_min=0)
    labelled = len(data["ends"]) <= MAX_END_LABELS
    for x, labels in sorted(data["ends"].items()):
        ax.vline(x, "end", label=", ".join(labels[:2]) + (" ..." if len(labels) > 2 else "") if labelled else None)
    for j, (key, x, y, k_in) in enumerate(zip(data["keys"], data["x"], data["y"], data["inside"])):
        r = rows[key]
        few = n <= MAX_LEGEND
        cls, decimals = (colour_class(j), 1) if few else ("many", 0)
        title = _label(r, sessions)
        # in-episode solid; post-episode (GT held at its last frame) dashed, joined to it
        ax.line(x[:k_in], y[:k_in], cls, key=str(key), title=title, label=title if few else None, decimals=decimals)
        if k_in < len(y):
            start = max(0, k_in - 1)
            ax.line(x[start:], y[start:], f"{cls} post", key=str(key), decimals=decimals)
    if n > MAX_LEGEND:
        ax.legend.append(("many", "each rollout", "line", None))
        ax.line(np.arange(len(data["mean"])) + 0.5, data["mean"], "mean", label=f"mean of {n}")
    if data["ends"]:
        ax.legend.append(("end", "episode end", "dash", None))
    if any(k < len(y) for k, y in zip(data["inside"], data["y"])):
        ax.legend.append(("c7 post", "post-episode", "dash", None))
    return Panel(ax.svg(), name), ax.legend


def _drift_data(rows: Sequence[Row]) -> tuple[dict[str, Any], dict[str, Any]] | None:
    """Time-aligned and best-match :func:`drift_curves` (None without GT joints)."""
    time_aligned, best = drift_curves(rows, "time_aligned_drift"), drift_curves(rows, "best_match_drift")
    return None if time_aligned is None or best is None else (time_aligned, best)


def _no_drift(rows: Sequence[Row]) -> str:
    n_auto = sum(r["kind"] == "autoregressive" for r in rows)
    if not n_auto:
        return "no autoregressive rollouts"
    return f"{n_auto} autoregressive rollout(s), none with GT joints (give the GT dataset with --dataset to measure drift)"


def _draw_drift(fig: Figure, rows: Sequence[Row], data: tuple[dict[str, Any], dict[str, Any]]) -> None:
    panel, fig.legend = _drift_panel(rows, data[0], "time-aligned")
    fig.panels.append(panel)
    fig.panels.append(_drift_panel(rows, data[1], "best-match")[0])


# ----------------------------------------------------------------------------------------------
# All of them


@dataclass(frozen=True)
class _Spec:
    """A figure: what it is, its data function (None: nothing to draw), how it draws, and what
    it says when there is nothing to draw."""

    key: str
    title: str
    caption: str
    data: Callable[[Sequence[Row]], Any]
    draw: Callable[[Figure, Sequence[Row], Any], None]
    empty: Callable[[Sequence[Row]], str]


def _say(text: str) -> Callable[[Sequence[Row]], str]:
    return lambda rows: text


FIGURES = [
    _Spec("per-step-rmse", "Per-step RMSE over the horizon",
          "RMSE over the 6 joints at each step of the predicted chunk (sqrt of per-step MSE), for every "
          "single-chunk sample: each sample, their mean, and min..max over samples.",
          per_step_rmse, _draw_per_step_rmse, _say("no single-chunk samples with GT joints")),
    _Spec("rmse-by-position", "RMSE against position in the episode",
          "Chunk RMSE of every single-chunk sample against its start frame / episode length (the start "
          "frame itself when an episode's length is unknown); colour: session.",
          rmse_by_position, _draw_rmse_by_position, _say("no single-chunk samples with GT joints")),
    _Spec("joint-overlay", "Per-joint predicted vs GT",
          "Each single-chunk sample's predicted joints (solid) and GT (dashed, same colour) over the "
          "predicted horizon, one panel per joint.",
          joint_overlay, _draw_joint_overlay, _say("no single-chunk samples")),
    _Spec("drift", "Drift per chunk of autoregressive rollouts",
          "Time-aligned drift d(pred(t), gt(t)) and, beside it, best-match drift min_j d(pred(t), gt_j) "
          "(speed-invariant), averaged over each chunk's executed steps [data units]. Vertical lines: "
          "each episode's end; dashed: post-episode chunks (compared with the episode's last frame).",
          _drift_data, _draw_drift, _no_drift),
    _Spec("video-action", "Video-action lag across rollouts",
          "Does the imagined video show what the predicted joints say? Each imagined frame is matched to the "
          "GT frame of its camera it resembles most; its GT time minus the GT time the predicted joints "
          "match is the lag (positive: the video runs ahead of the actions). Each dot: a rollout's median "
          "lag over its matched frames, colour: camera; shaded: within 0.5 s.",
          video_action_lags, _draw_video_action_lags,
          _say("no rollout with GT video, GT joints and a confident frame match")),
]


def report_figures(rows: Sequence[Row]) -> list[Figure]:
    """Every aggregate figure of a report's rows, in reading order (see :data:`FIGURES`)."""
    figures = []
    for spec in FIGURES:
        fig = Figure(spec.key, spec.title, spec.caption)
        data = spec.data(rows)
        if data is None:
            fig.note = spec.empty(rows)
        else:
            spec.draw(fig, rows, data)
        figures.append(fig)
    return figures
