"""HTML shown in the GUI: rollout card, headline metrics, error card, the video grid.

viser renders HTML (and markdown) as given, so every string that came from a file or a user
(prompts, notes, file paths, error messages) goes through :func:`esc`. These are pure functions of
their inputs, cheap enough to call on every scrub step.
"""

from __future__ import annotations

import html
from collections.abc import Sequence

import numpy as np

from ..errors import InspectorError, one_line
from ..timeline import RolloutTimeline
from ._frames import LOADING, FramePair

CARD = "font-size:0.8rem;line-height:1.35;padding:0.1rem 0.2rem"
TABLE = "border-collapse:collapse;width:100%;font-size:0.78rem"
TD = "padding:1px 4px;vertical-align:top"
MUTED = "color:#6b7280"
_SWATCH = "<span style='color:{}'>■</span> {}"
SCENE_LEGEND = " · ".join(_SWATCH.format(c, t) for c, t in (
    ("#9ea3ad", "GT arm"), ("#f76707", "predicted arm"), ("#c92a2a", "chunk's executed steps"),
    ("#fab005", "rest of its horizon"), ("#2b8a3e", "GT path")))
SCENE_LEGEND_NO_GT = " · ".join(_SWATCH.format(c, t) for c, t in (
    ("#f76707", "predicted arm (no GT arm)"), ("#c92a2a", "chunk's executed steps"),
    ("#fab005", "rest of its horizon")))


def esc(value: object) -> str:
    return html.escape(str(value), quote=True)


def unit(tl: RolloutTimeline) -> str:
    """Unit of joint-space distances: degrees (arm) or the legacy -100..100 range."""
    return "°" if tl.units.arm == "degrees" else " u"


def _fmt(value: float | None, suffix: str = "", digits: int = 1) -> str:
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
    if tl.has_gt_joints:
        inside = ~tl.post_episode if tl.post_episode is not None else np.ones(tl.n_steps, bool)
        ta = tl.time_aligned_drift
        finite_rmse = tl.chunk_rmse[np.isfinite(tl.chunk_rmse)] if tl.chunk_rmse is not None else np.zeros(0)
        rows.append(("chunk RMSE (mean)", _fmt(finite_rmse.mean() if finite_rmse.size else None, u, 2)))
        if inside.any():
            rows.append(("time-aligned drift", f"mean {_fmt(ta[inside].mean(), u)} · final "
                                               f"{_fmt(ta[inside][-1], u)}"))
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
    viol = tl.limit_violation
    if viol.any():
        from ..units import JOINT_NAMES

        joints = ", ".join(j for j, v in zip(JOINT_NAMES, viol.any(axis=0)) if v)
        rows.append(("joint-limit violations", f"{int(viol.any(axis=1).sum())} of {tl.n_steps} steps ({joints})"))
    else:
        rows.append(("joint-limit violations", "none"))
    if psnr is not None and tl.video_views():
        means = {v: float(np.nanmean(p)) for v, p in psnr.items() if p is not None and np.isfinite(p).any()}
        if means:
            overall = float(np.mean(list(means.values())))
            per = ", ".join(f"{v} {m:.1f}" for v, m in means.items())
            rows.append(("video PSNR", f"{overall:.1f} dB ({per})"))
        elif loading_video:
            rows.append(("video PSNR", "computing…"))
    return rows + reference_rows(tl.rollout.extra)


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


def rollout_card(tl: RolloutTimeline, metrics: Sequence[tuple[str, str]], gt_note: str) -> str:
    """Prompt, model, kind, units, GT source and headline metrics of the open rollout."""
    r = tl.rollout
    session = r.session
    model = session.model if session is not None else {}
    model_text = " · ".join(str(model[k]) for k in ("name", "checkpoint") if model.get(k)) or "—"
    kind = f"{r.kind} · {r.n_chunks} chunk{'s' if r.n_chunks != 1 else ''} × {r.horizon} steps"
    if r.kind == "autoregressive":
        kind += f" ({r.executed_per_chunk} executed each)"
    rows = [
        ("prompt", f"<b>{esc(r.prompt or '—')}</b>"),
        ("model", esc(model_text)),
        ("kind", esc(kind)),
        ("units", esc(tl.units.label())),
        ("ground truth", esc(tl.gt.source) + (f"<br><span style='{MUTED}'>{esc(gt_note)}</span>" if gt_note else "")),
    ]
    rows.append(("3D scene", SCENE_LEGEND if tl.has_gt_joints else SCENE_LEGEND_NO_GT))
    rows += [(esc(k), esc(v)) for k, v in metrics]
    body = "".join(f"<tr><td style='{TD};{MUTED};white-space:nowrap'>{k}</td><td style='{TD}'>{v}</td></tr>"
                   for k, v in rows)
    return f"<div style='{CARD}'><table style='{TABLE}'>{body}</table></div>"


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


def video_grid(pairs: Sequence[FramePair], step: int, t_s: float) -> str:
    """One column per view: the imagined frame above the GT frame at the same time, with their PSNR."""
    if not pairs:
        return f"<div style='{CARD};{MUTED}'>This rollout has no imagined video.</div>"
    img = "width:100%;display:block;border-radius:3px;background:#222"
    box = ("width:100%;aspect-ratio:320/176;display:flex;align-items:center;justify-content:center;"
           "background:#e9ecef;color:#6b7280;font-size:0.7rem;border-radius:3px;text-align:center")
    cap = "font-size:0.66rem;text-align:center;margin-bottom:3px"
    cols = []
    for p in pairs:
        psnr = f"PSNR {p.psnr_db:.1f} dB" if p.psnr_db is not None else "PSNR —"
        if p.status == LOADING:
            top = bottom = f"<div style='{box}'>loading…</div>"
        elif p.imagined is None:
            top = f"<div style='{box};color:#c92a2a'>{esc(p.status)}</div>"
            bottom = f"<div style='{box}'>—</div>"
        else:
            top = (f"<img class='inspector-frame' data-view='{esc(p.view)}' data-kind='imagined' "
                   f"data-frame='{p.imagined_index}' src='{p.imagined}' style='{img}'>")
            bottom = (f"<img class='inspector-frame' data-view='{esc(p.view)}' data-kind='gt' "
                      f"data-step='{step}' src='{p.gt}' style='{img}'>" if p.gt is not None
                      else f"<div style='{box}'>loading…</div>" if p.gt_note == LOADING
                      else f"<div style='{box}'>no GT frame<br>({esc(p.gt_note)})</div>")
        cols.append(
            "<div style='min-width:0'>"
            f"<div style='display:flex;justify-content:space-between;font-size:0.72rem'>"
            f"<b>{esc(p.view)}</b><span>{psnr}</span></div>"
            f"{top}<div style='{cap};color:#e8590c'>imagined · frame {p.imagined_index}</div>"
            f"{bottom}<div style='{cap};color:#2b8a3e'>ground truth · same time</div></div>"
        )
    grid = f"display:grid;grid-template-columns:repeat({len(cols)},minmax(0,1fr));gap:6px"
    return (f"<div class='inspector-video' data-step='{step}' style='font-family:sans-serif'>"
            f"<div style='{grid}'>{''.join(cols)}</div>"
            f"<div style='font-size:0.7rem;color:#6b7280;margin-top:2px'>t = {t_s:.2f} s · step {step}</div></div>")
