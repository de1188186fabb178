"""HTML shown in the GUI: rollout card, headline metrics, error card, the video grid.

viser renders HTML (and markdown) as given, so every string that came from a file or a user
(prompts, notes, file paths, error messages) goes through :func:`esc`. These are pure functions of
their inputs, cheap enough to call on every scrub step.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import cast

import numpy as np
import numpy.typing as npt

from ..analysis import metrics
from ..analysis.timeline import ROLLOUT_LABELS, RolloutTimeline
from ..analysis.video_metrics import geometry_note, resizes_whole_frame
from ..data.session import CHAINED_KINDS
from ..errors import InspectorError, one_line
from ..units import JOINT_NAMES
from ._frames import LOADING, READY, FramePair
from ._sanity_card import sanity_rows
from ._video_only import is_video_only, joints_row

CARD = "font-size:0.8rem;line-height:1.35;padding:0.1rem 0.2rem"
GRID = ("display:grid;grid-template-columns:minmax(5.5rem,34%) minmax(0,1fr);column-gap:6px;row-gap:2px;"
        "font-size:0.78rem;overflow-wrap:anywhere")
MUTED = "color:#6b7280"
_SWATCH = "<span style='color:{}'>■</span> {}"
SCENE_LEGEND = " · ".join(_SWATCH.format(c, t) for c, t in (
    ("#9ea3ad", "GT arm"), ("#f76707", "predicted arm"), ("#c92a2a", "chunk's executed steps"),
    ("#fab005", "rest of its horizon"), ("#2b8a3e", "GT path")))
SCENE_LEGEND_NO_GT = " · ".join(_SWATCH.format(c, t) for c, t in (
    ("#f76707", "predicted arm (no GT arm)"), ("#c92a2a", "chunk's executed steps"),
    ("#fab005", "rest of its horizon")))
SCENE_LEGEND_EPISODE = " · ".join(_SWATCH.format(c, t) for c, t in (
    ("#9ea3ad", "measured arm (observation.state)"), ("#f76707", "commanded arm (action)"),
    ("#2b8a3e", "measured path")))


def esc(value: object) -> str:
    return html.escape(str(value), quote=True)


def unit(tl: RolloutTimeline) -> str:
    """Unit of joint-space distances: degrees (arm) or the legacy -100..100 range."""
    return "°" if tl.units.arm == "degrees" else " u"


def _fmt(value: float | np.floating | None, suffix: str = "", digits: int = 1) -> str:
    if value is None or not np.isfinite(value):
        return "—"
    return f"{value:.{digits}f}{suffix}"


def headline_metrics(tl: RolloutTimeline, psnr: dict[str, np.ndarray | None] | None = None,
                     loading_video: bool = False) -> list[tuple[str, str]]:
    """(name, value) rows summarising a rollout, in the units of the data.

    Drift means are over steps inside the real episode; steps past its end are reported apart.
    """
    u = unit(tl)
    rows: list[tuple[str, str]] = []
    if tl.kind == "episode":
        return episode_metrics(tl)
    if not tl.has_joints:  # video only: no joint figure (drift, limit steps) means anything
        rows.append(("joint measures", "not measured: no predicted actions (video only)"))
    elif tl.has_gt_joints:
        inside = ~tl.post_episode if tl.post_episode is not None else np.ones(tl.n_steps, bool)
        ta = tl.time_aligned_drift
        assert ta is not None  # set with the GT joints
        finite_rmse = tl.chunk_rmse[np.isfinite(tl.chunk_rmse)] if tl.chunk_rmse is not None else np.zeros(0)
        rows.append(("chunk RMSE (mean)", _fmt(finite_rmse.mean() if finite_rmse.size else None, u, 2)))
        if inside.any():
            rows.append(("time-aligned drift", f"mean {_fmt(ta[inside].mean(), u)} · final "
                                               f"{_fmt(ta[inside][-1], u)}"))
            assert tl.best_match_drift is not None  # a rollout (not an episode) with GT joints has every alignment
            rows.append(("best-match drift", f"mean {_fmt(tl.best_match_drift[inside].mean(), u)}"))
        if (~inside).any():
            rows.append(("drift past episode end", f"mean {_fmt(ta[~inside].mean(), u)} "
                                                   f"({int((~inside).sum())} steps)"))
        if tl.kind == "autoregressive":  # a single 24-step chunk is too short for a tempo estimate
            rows.append(("tempo (GT time / rollout time)", _fmt(tl.tempo, "×", 2)))
        if tl.ee_error_mm is not None:
            rows.append(("end-effector error", f"mean {_fmt(np.nanmean(tl.ee_error_mm), ' mm', 0)}"))
    else:
        rows.append(("joint drift", "no GT joints (serve with --dataset to compare joints)"))
    if tl.has_joints:
        limits = tl.limit_summary()
        name = f"steps past a joint limit (+{tl.limit_margin_deg:g}° margin)"
        if limits.steps:
            joints = ", ".join(j for j, n in zip(JOINT_NAMES, limits.by_joint) if n)
            rows.append((name, f"{limits.steps} of {tl.n_steps} ({joints})"))
        else:
            rows.append((name, "none"))
    refused = geometry_notes(tl)
    if psnr is not None and tl.video_views():
        means = {v: float(np.nanmean(p)) for v, p in psnr.items()
                 if v not in refused and p is not None and np.isfinite(p).any()}
        if means:  # per view: the front camera's figure is not averaged away by the wrist's
            rows.append(("video PSNR", ", ".join(f"{v} {m:.1f} dB" for v, m in means.items())))
        elif loading_video and len(refused) < len(tl.video_views()):
            rows.append(("video PSNR", "computing…"))
    rows += [(f"video PSNR, {view}", note) for view, note in refused.items()]
    return rows + sanity_rows(tl) + reference_rows(tl.rollout.extra) + fact_rows(tl.rollout.extra)


def geometry_notes(tl: RolloutTimeline) -> dict[str, str]:
    """Per view with GT video whose frames are not compared with the GT's (another geometry, e.g. a
    mosaic of two cameras beside one camera's render): why, as the report row's ``video_psnr_note``."""
    whole_frame = resizes_whole_frame(tl.rollout.extra)
    notes: dict[str, str] = {}
    for view in tl.video_views():
        gt = tl.gt.clips.get(view)
        try:
            note = geometry_note(tl.rollout.video(view), gt, whole_frame) if gt is not None else None
        except InspectorError:  # an unreadable clip says so where its frames would show
            continue
        if note is not None:
            notes[view] = note
    return notes


def fact_rows(extra: object) -> list[tuple[str, str]]:
    """What the source's reader says about the rollout (``extra.facts``: name / text pairs, e.g. a
    neural trajectory's calibration, frame rate, joint ranges and warnings)."""
    facts = extra.get("facts") if isinstance(extra, dict) else None
    if not isinstance(facts, list):
        return []
    return [(str(f[0]), str(f[1])) for f in facts if isinstance(f, list) and len(f) == 2]


def reference_rows(extra: object) -> list[tuple[str, str]]:
    """The source's own metrics (``extra.reference_metrics``), never mixed with ours: one row of
    plain figures, and one row per figure that comes with a note on what it measured."""
    extra = extra if isinstance(extra, dict) else {}
    ref, notes = extra.get("reference_metrics"), extra.get("reference_notes")
    if not isinstance(ref, dict):
        return []
    notes = {k: v for k, v in notes.items() if isinstance(v, str)} if isinstance(notes, dict) else {}
    numbers = {k: float(v) for k, v in ref.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    plain = [f"{k} {v:.2f}" for k, v in numbers.items() if k not in notes][:4]
    rows = [("reported by the evaluation", ", ".join(plain))] if plain else []
    rows += [(f"source's {k}", f"{numbers[k]:.2f}: {note}") for k, note in notes.items() if k in numbers]
    return rows


def episode_metrics(tl: RolloutTimeline) -> list[tuple[str, str]]:
    """(name, value) rows summarising a dataset episode: how well the follower tracked its command."""
    u = unit(tl)
    err = tl.time_aligned_drift
    # an episode's timeline always has GT joints (the measured arm)
    assert err is not None and tl.gt_aligned is not None
    rows = [("tracking error |commanded − measured|", f"mean {_fmt(err.mean(), u)} · max {_fmt(err.max(), u)}")]
    if tl.chunk_errors is not None:
        per_joint = tl.chunk_errors.per_joint_rmse
        worst = int(np.argmax(per_joint))
        rows.append(("worst-tracked joint (RMSE)", f"{JOINT_NAMES[worst]} {_fmt(per_joint[worst], u, 2)}"))
    if tl.ee_error_mm is not None:
        rows.append(("end-effector tracking error", f"mean {_fmt(tl.ee_error_mm.mean(), ' mm', 1)} · "
                                                     f"max {_fmt(tl.ee_error_mm.max(), ' mm', 1)}"))

    margin = f"(+{tl.limit_margin_deg:g}° margin)"
    measured_excess = metrics.limit_excess(tl.gt_aligned, tl.limits)
    for name, flags in (("commanded", tl.limit_violation), ("measured", measured_excess > tl.limit_margin)):
        steps = int(flags.any(axis=1).sum())
        joints = ", ".join(j for j, v in zip(JOINT_NAMES, cast(npt.NDArray[np.bool_], flags.any(axis=0))) if v)
        rows.append((f"{name} steps past a joint limit {margin}",
                     f"{steps} of {tl.n_steps} ({joints})" if steps else "none"))
    return rows


def rollout_card(tl: RolloutTimeline, metrics: Sequence[tuple[str, str]], gt_note: str) -> str:
    """Prompt, model, kind, units, GT source and headline metrics of the open rollout."""
    r = tl.rollout
    if r.kind == "episode":
        return episode_card(tl, metrics)
    session = r.session
    model = session.model if session is not None else {}
    model_text = " · ".join(str(model[k]) for k in ("name", "checkpoint") if model.get(k)) or "—"
    kind = f"{r.kind} · {r.n_chunks} chunk{'s' if r.n_chunks != 1 else ''} × {r.horizon} steps"
    if r.kind in CHAINED_KINDS:
        kind += f" ({r.executed_per_chunk} executed each)"
    rows = [
        ("prompt", f"<b>{esc(r.prompt or '—')}</b>"),
        ("model", esc(model_text)),
        ("kind", esc(kind)),
        ("units", esc(tl.units.label())),
        ("ground truth", esc(tl.gt.source) + (f"<br><span style='{MUTED}'>{esc(gt_note)}</span>" if gt_note else "")),
    ]
    outcome = r.extra.get("outcome")
    if isinstance(outcome, dict) and outcome.get("success") is not None:  # a simulated evaluation's verdict
        reward = outcome.get("sum_reward")
        rows.append(("outcome", esc(f"{'success' if outcome['success'] else 'failure'} · reward "
                                    f"{'—' if reward is None else format(reward, '.3g')} · task {outcome.get('task')}")))
    rows.append(joints_row(tl) if is_video_only(tl) else ("3D scene", _scene_legend(tl)))
    rows += [(esc(k), esc(v)) for k, v in metrics]
    return _card_table(r.tag, rows)


def _scene_legend(tl: RolloutTimeline) -> str:
    if not tl.has_gt_joints:
        return SCENE_LEGEND_NO_GT
    if tl.labels == ROLLOUT_LABELS:
        return SCENE_LEGEND
    # the importer named the two arms (e.g. commanded / executed)
    return " · ".join(_SWATCH.format(c, esc(t)) for c, t in (
        ("#9ea3ad", f"{tl.labels.gt} arm"), ("#f76707", f"{tl.labels.pred} arm"), ("#2b8a3e", f"{tl.labels.gt} path")))


def episode_card(tl: RolloutTimeline, metrics: Sequence[tuple[str, str]]) -> str:
    """Task, dataset, length, units and tracking metrics of an open dataset episode."""
    r = tl.rollout
    rows = [
        ("task", f"<b>{esc(r.prompt or '—')}</b>"),
        ("dataset", esc(f"{r.extra.get('dataset_name', '')} · episode {r.episode_index}")),
        ("length", esc(f"{tl.n_steps} frames · {tl.n_steps / tl.fps:.1f} s at {tl.fps:g} fps")),
        ("units", esc(tl.units.label() + (f" ({r.extra['units_reason']})" if r.extra.get("units_reason") else ""))),
        ("3D scene", SCENE_LEGEND_EPISODE),
        *[(esc(k), esc(v)) for k, v in metrics],
    ]
    return _card_table(r.tag, rows)


def _card_table(tag: str, rows: Sequence[tuple[str, str]]) -> str:
    """Name / value rows in two columns that wrap (long paths and prompts never run off the panel)."""
    body = "".join(f"<div style='{MUTED}'>{k}</div><div>{v}</div>" for k, v in rows)
    return (f"<div class='inspector-card' data-rollout='{esc(tag)}' style='{CARD}'>"
            f"<div style='{GRID}'>{body}</div></div>")


def error_card(title: str, error: BaseException) -> str:
    """A red card naming the file at fault and what is wrong with it."""
    if isinstance(error, InspectorError):
        file, what = one_line(error.file), error.what
    else:
        file, what = "", f"{type(error).__name__}: {error}"
    file_row = f"<div><b>file</b> <code style='word-break:break-all'>{esc(file)}</code></div>" if file else ""
    return (
        "<div class='inspector-error-card' style='border:1px solid #e03131;background:#fff5f5;"
        "border-radius:6px;padding:6px 8px;font-size:0.8rem;color:#7d1a1a'>"
        f"<div style='font-weight:600;margin-bottom:2px'>⚠ {esc(title)}</div>{file_row}"
        f"<div><b>problem</b> {esc(what)}</div>"
        "<div style='color:#6b7280;margin-top:2px'>Other rollouts still work: pick one above.</div></div>"
    )


def video_grid(pairs: Sequence[FramePair], step: int, t_s: float,
               compare: dict[str, FramePair] | None = None, compare_tag: str | None = None,
               large: bool = False, clips: dict[tuple[str, str], str] | None = None,
               clip_clock: tuple[int, int, float, float] | None = None, clip_id: int | None = None) -> str:
    """One row per view: the imagined frame beside the GT frame at the same time (and the compared
    rollout's imagined frame), with the PSNR of each pair; ``large`` stacks one view's frames.

    ``clips`` maps (view, kind) to a playback clip's video URI: that cell plays it instead of
    showing the step's frame (kind ``imagined``, ``gt`` or ``compare``). ``clip_clock`` (the clips'
    first and end step, their frames/s, the rollout's steps/s) lets the time line under the frames
    follow the playing clip in the page rather than stand at the step it started from;
    ``clip_id`` names the clips, so the page's reports of where they are say which (see ._clip_clock).
    """
    if not pairs:
        return f"<div style='{CARD};{MUTED}'>No video for this rollout.</div>"
    compare = compare or {}
    clips = clips or {}
    rows = []
    # rows of frames: one per view, or the one view's frames stacked
    n_rows = (2 + (pairs[0].view in compare)) if large else len(pairs)
    frame_height = frame_height_css(n_rows)
    for p in pairs:
        cells = []
        if p.has_imagined:
            caption = "imagined · playing" if (p.view, "imagined") in clips else f"imagined · frame {p.imagined_index}"
            cells.append(_frame_cell(p.view, "imagined", p.imagined, p.status, caption, "#e8590c",
                                     f"data-frame='{p.imagined_index}'", clips.get((p.view, "imagined")), frame_height,
                                     p.imagined_overlay))
            gt_status = p.status if p.status != READY else (LOADING if p.gt_note == LOADING else
                                                             f"no GT frame ({p.gt_note})")
            gt_caption = "ground truth · same time"
        else:  # a camera with real frames only (a dataset episode's cameras)
            gt_status = p.status if p.status != READY else (p.gt_note or LOADING)
            gt_caption = f"camera · frame {p.gt_index}" if p.gt_index is not None else "camera"
        cells.append(_frame_cell(p.view, "gt", p.gt, gt_status, gt_caption, "#2b8a3e", f"data-step='{step}'",
                                 clips.get((p.view, "gt")), frame_height, p.gt_overlay))
        c = compare.get(p.view)
        if c is not None:
            psnr_c = f" · PSNR {c.psnr_db:.1f} dB" if c.psnr_db is not None else ""
            cells.append(_frame_cell(p.view, "compare", c.imagined, c.status,
                                     f"{compare_tag or 'compared'} · imagined{psnr_c}", "#1c7ed6",
                                     f"data-frame='{c.imagined_index}'", clips.get((p.view, "compare")), frame_height))
        if clips:  # the frame changes faster than the server says: its PSNR is shown when paused
            psnr = "PSNR on pause" if p.psnr_db is not None else ""
        else:
            psnr = f"PSNR {p.psnr_db:.1f} dB" if p.psnr_db is not None else ("PSNR —" if p.has_imagined else "")
        columns = 1 if large else len(cells)
        grid = f"display:grid;grid-template-columns:repeat({columns},minmax(0,1fr));gap:4px"
        rows.append(f"<div style='margin-bottom:6px'><div style='display:flex;justify-content:space-between;"
                    f"font-size:0.72rem'><b>{esc(p.view)}</b><span>{psnr}</span></div>"
                    f"<div style='{grid}'>{''.join(cells)}</div></div>")
    clock = ""
    if clips and clip_clock is not None:
        first, end, clip_fps, steps_per_s = clip_clock
        clock = (f" data-clip-first='{first}' data-clip-end='{end}' data-clip-fps='{clip_fps:.6g}'"
                 f" data-steps-per-s='{steps_per_s:.6g}'")
        if clip_id is not None:
            clock += f" data-clip-id='{int(clip_id)}'"
    return (f"<div class='inspector-video' data-step='{step}'{clock} style='font-family:sans-serif'>{''.join(rows)}"
            f"<div class='inspector-time' style='font-size:0.7rem;color:#6b7280'>t = {t_s:.2f} s · step {step}</div></div>")


# The page's side of ``clip_clock``: the step a playing clip shows, written under the frames as the
# clip's time advances (every panel's clip runs the same clock; whichever reports last writes).
_FOLLOW_CLIP_CLOCK = (
    "const g=this.closest('.inspector-video'),d=g&&g.dataset;if(!d||!d.clipFps)return;"
    "const s=Math.min(+d.clipEnd-1,+d.clipFirst+Math.floor(this.currentTime*d.clipFps+1e-3));"
    "g.querySelector('.inspector-time').textContent='t = '+(s/d.stepsPerS).toFixed(2)+' s \u00b7 step '+s+' \u00b7 playing'")


# The frames take at most this share of the window's height, all rows together [vh]: at 900 px
# the drift plot under them stays in view (two views' frames took 540 px, leaving ~200 px of plot).
FRAMES_SHARE_VH = 39
FRAME_ROW_CHROME_PX = 30  # a row's view name, caption and gap


def frame_height_css(n_rows: int) -> str:
    """The CSS max-height of one frame when ``n_rows`` rows of frames share the window."""
    return f"calc({FRAMES_SHARE_VH / max(n_rows, 1):.4g}vh - {FRAME_ROW_CHROME_PX}px)"


def _frame_cell(view: str, kind: str, src: str | None, status: str, caption: str, colour: str, data: str,
                clip: str | None = None, max_height: str = "none", overlay: str | None = None) -> str:
    """One frame with its caption, a playing clip, or a grey box saying why there is none; the
    frame keeps its aspect within ``max_height`` (centred in its cell, the margins left clear).
    ``overlay``: a transparent image of the frame's size laid over it (the arms, see ._overlay):
    the same box and the same ``object-fit`` put it on the frame's pixels."""
    fit = f"width:100%;max-height:{max_height};object-fit:contain;display:block;border-radius:3px"
    if clip is not None:  # muted: browsers autoplay only muted media; canplay: autoplay may not start
        body = (f"<video class='inspector-frame' data-view='{esc(view)}' data-kind='{kind}' src='{clip}' "
                "autoplay muted playsinline disablepictureinpicture oncanplay='this.play()' "
                f"ontimeupdate=\"{_FOLLOW_CLIP_CLOCK}\" "
                f"style='{fit}'></video>")
    elif src is not None:
        body = (f"<img class='inspector-frame' data-view='{esc(view)}' data-kind='{kind}' {data} src='{src}' "
                f"style='{fit}'>")
        if overlay is not None:
            body = (f"<div style='position:relative'>{body}<img class='inspector-overlay' data-view='{esc(view)}' "
                    f"data-kind='{kind}' src='{overlay}' style='position:absolute;inset:0;width:100%;height:100%;"
                    "object-fit:contain;pointer-events:none'></div>")
    else:
        error = status != LOADING and not status.startswith("no GT frame")
        body = (f"<div style='width:100%;aspect-ratio:320/176;max-height:{max_height};display:flex;align-items:center;"
                f"justify-content:center;background:#e9ecef;color:{'#c92a2a' if error else '#6b7280'};"
                f"font-size:0.7rem;border-radius:3px;text-align:center;padding:2px'>"
                f"{'loading…' if status == LOADING else esc(status)}</div>")
    return (f"<div style='min-width:0'>{body}"
            f"<div style='font-size:0.66rem;text-align:center;color:{colour}'>{esc(caption)}</div></div>")
