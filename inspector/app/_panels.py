"""The GUI of one tab: the left control panel, and the right panel (video above plots).

These classes only create and hold handles (and turn a timeline into plot series); what happens
when a control changes is wired in :mod:`._state`. Layout: the control panel docks left, the
video and plots dock right; the 3D scene fills the middle.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..analysis.metrics import prompt_divergence
from ..analysis.timeline import RolloutTimeline
from ..analysis.video_action import FROZEN, NO_MATCH, VideoAction
from ..units import JOINT_NAMES
from ._cards import unit
from ._clip_clock import CLIP_CLOCK_HTML, CLIP_CLOCK_LABEL
from ._keys import KEYS_HTML, TIMELINE_KEYS_HINT
from ._label_ids import LABEL_IDS_HTML
from ._light_3d import LIGHT_3D_HINT, LIGHT_3D_HTML, LIGHT_3D_LABEL
from ._page_chrome import WEBGL_NOTICE_HTML, page_title_html
from ._plots import CursorPlot, Line, Mark
from ._video_only import is_video_only, panel_note

SPEEDS = ("0.25x", "0.5x", "1x", "2x", "4x")
# The docked panels' widths; the 3D scene fills the rest [px].
LEFT_PANEL_PX, RIGHT_PANEL_PX = 350, 640
NO_COMPARE = "— none —"
PRED_HEX, GT_HEX, CMP_HEX = "#f08c00", "#2b8a3e", "#1c7ed6"
BM_HEX, DTW_HEX, LIMIT_HEX = "#7048e8", "#868e96", "#e03131"
JOINT_HEX = ("#1c7ed6", "#2b8a3e", "#f08c00", "#ae3ec9", "#0ca678", "#e03131")


PICKER_LABEL = "Rollout"
PAGE_TITLE_HTML = page_title_html(PICKER_LABEL)  # the app and what is open


class ControlPanel:
    """Left panel: overview button, picker, rollout card, timeline controls, compare, notes, export."""

    def __init__(self, gui, keys: Sequence[str], error_keys: set[str], client_id: int = 0) -> None:
        # Picker labels mark rollouts that failed to load; they map back to catalog keys only.
        self.option_to_key = {(f"{k} ⚠" if k in error_keys else k): k for k in keys}
        self.key_to_option = {v: k for k, v in self.option_to_key.items()}
        options = list(self.option_to_key) or ["(no rollouts)"]
        # data-inspector-client lets a test find the server-side tab of a page.
        gui.add_html(f"<div data-inspector-client='{int(client_id)}' style='font-weight:600;"
                     f"font-size:0.95rem;padding:0 0.2rem'>SO-101 rollout inspector{LABEL_IDS_HTML}{LIGHT_3D_HTML}{KEYS_HTML}"
                     f"{CLIP_CLOCK_HTML}{PAGE_TITLE_HTML}{WEBGL_NOTICE_HTML}</div>")
        # the whole evaluation in one table (see ._overview, which wires it)
        self.show_overview = gui.add_button("Overview", icon="table", hint="Every served rollout in one table")
        self.picker = gui.add_dropdown(PICKER_LABEL, options, initial_value=options[0])
        self.error = gui.add_html("", visible=False)
        self.card = gui.add_html("")
        with gui.add_folder("Timeline") as self.timeline_folder:
            # no hints on controls that are dragged: a tooltip would sit over the thumb and labels
            self.chunk = gui.add_slider("Chunk", 0, 1, 1, 0)
            self.step_in_chunk = gui.add_slider("Step in chunk", 0, 1, 1, 0)
            self.readout = gui.add_html("")
            self.play = gui.add_button("Play", icon="player-play")
            self.speed = gui.add_dropdown("Speed", SPEEDS, initial_value="1x")
            self.nav = gui.add_button_group("Go to chunk", ("◀ prev", "next ▶", "worst"))
            gui.add_html(f"<div style='font-size:0.7rem;color:#6b7280;padding:0 0.2rem'>{TIMELINE_KEYS_HINT}</div>")
        with gui.add_folder("Compare", expand_by_default=False):
            self.compare = gui.add_dropdown("Compare with", [NO_COMPARE, *keys], initial_value=NO_COMPARE)
            self.compare_info = gui.add_html("")
        with gui.add_folder("Notes", expand_by_default=False):
            # Single-line fields fit the panel; ._label_ids ties their labels to them.
            self.flag_rollout = gui.add_checkbox("Flag rollout", False)
            self.note_rollout = gui.add_text("Rollout note", "")
            self.flag_chunk = gui.add_checkbox("Flag this chunk", False)
            self.note_chunk = gui.add_text("Chunk note", "")
            self.save_notes = gui.add_button("Save notes", icon="device-floppy")
            self.notes_info = gui.add_html("")
        self.export = gui.add_button("Export .rrd", icon="download",
                                     hint="Download a Rerun recording of this rollout")
        # outside any folder: the page's script finds it only while it is shown; ticked until the
        # page finds a GPU (see ._light_3d)
        self.light_3d = gui.add_checkbox(LIGHT_3D_LABEL, True, hint=LIGHT_3D_HINT)

    def key_of(self, option: str) -> str | None:
        return self.option_to_key.get(option)


ALL_VIEWS = "all views"

OVERLAY_LABEL = "Arms in frames"
OVERLAY_HINT = ("Draw the predicted arm (orange) and the GT arm (grey) into the frames of each view with a "
                "camera (cameras.json), with the tracked imagined gripper (cyan) and where the predicted joints "
                "put it (orange ring). Shown on paused frames.")


class VideoPanel:
    """Per camera view, the imagined frame beside the GT frame at the same time (and the compared
    rollout's imagined frame); the selector shows one view large."""

    def __init__(self, gui) -> None:
        self.view = gui.add_dropdown("Video", (ALL_VIEWS,), initial_value=ALL_VIEWS)
        # the predicted (orange) and GT (grey) arms drawn into the frames of views with a camera
        self.overlay = gui.add_checkbox(OVERLAY_LABEL, False, hint=OVERLAY_HINT, visible=False)
        self.html = gui.add_html("<div>loading…</div>")
        # The page's script writes where its playback clip is here, and hides it (see ._clip_clock).
        self.clock = gui.add_text(CLIP_CLOCK_LABEL, "")

    def set_views(self, views: Sequence[str]) -> None:
        options = (ALL_VIEWS, *views) if len(views) > 1 else (ALL_VIEWS,)
        if tuple(self.view.options) != options:
            self.view.options = options
        if self.view.value not in options:
            self.view.value = ALL_VIEWS
        self.view.visible = len(views) > 1

    def set_overlay_available(self, available: bool) -> None:
        """Offer the overlay toggle only where a view has a camera."""
        if self.overlay.visible != available:
            self.overlay.visible = available

    @property
    def selected(self) -> str | None:
        """The view shown large, or None for all of them."""
        return None if self.view.value == ALL_VIEWS else self.view.value


class PlotPanel:
    """Plots under the video (tabs: drift, joints, end effector & video), rebuilt per rollout."""

    def __init__(self, gui) -> None:
        self._gui = gui
        tabs = gui.add_tab_group()
        self.tab_drift = tabs.add_tab("Drift", icon="chart-line")
        self.tab_joints = tabs.add_tab("Joints", icon="adjustments")
        self.tab_ee = tabs.add_tab("EE & video", icon="chart-dots")
        with self.tab_joints:
            self.joint = gui.add_dropdown("Joint", JOINT_NAMES, initial_value="shoulder_lift", order=0)
        self.plots: list[CursorPlot] = []
        self._handles: list = []
        self.joint_plot: CursorPlot | None = None
        self.drift_plot: CursorPlot | None = None  # drift (or limits, without GT joints), with the sanity marks
        self._sanity: tuple[tuple[int, str, str], ...] = ()
        self.psnr_plot: CursorPlot | None = None
        self.agreement_plot: CursorPlot | None = None
        # each view's video-action agreement, once its video metrics are known
        self.agreements: dict[str, VideoAction] = {}
        self._frozen: dict[str, bool | None] = {}  # VideoAction.frozen() of each of agreements, once asked
        self._match_errors: tuple[tuple[str, str], ...] = ()  # (view, why) of the failed frame matches shown
        self._tl: RolloutTimeline | None = None
        self._cmp: RolloutTimeline | None = None
        self._psnr_views: tuple[str, ...] = ()
        self.gripper_plot: CursorPlot | None = None  # the imagined gripper vs the predicted joints [px]
        self._gripper_views: tuple[str, ...] = ()

    def clear(self) -> None:
        for h in self._handles:
            h.remove()
        for p in self.plots:
            p.handle.remove()
        self._handles, self.plots = [], []
        self.joint_plot = self.psnr_plot = self.agreement_plot = self.drift_plot = self.gripper_plot = None
        self.agreements, self._match_errors, self._frozen = {}, (), {}
        self._gripper_views = ()
        self._tl = None

    def build(self, tl: RolloutTimeline, compare: RolloutTimeline | None,
              psnr: dict[str, np.ndarray | None], match_errors: dict[str, str] | None = None,
              sanity: Sequence[tuple[int, str, str]] = ()) -> None:
        """(Re)create every plot for ``tl`` (and the compared rollout, if any); ``sanity``: the
        ``(step, label, color)`` marks of :func:`._sanity_card.sanity_marks` on the drift plot."""
        self.clear()
        self._tl, self._cmp = tl, compare
        self._sanity = tuple(sanity)
        gui, t, u = self._gui, tl.t_s, unit(tl)
        ticks = tl.t_s[tl.chunk_start_step[tl.chunk_start_step < tl.n_steps]]
        end = float(tl.episode_end_step / tl.fps) if tl.episode_end_step is not None else None
        common: dict[str, Any] = {"ticks": ticks, "end": end}
        if is_video_only(tl):
            with self.tab_drift:
                self._handles.append(gui.add_html(panel_note()))
            with self.tab_joints:
                self._handles.append(gui.add_html(panel_note()))
        with self.tab_drift:
            if is_video_only(tl):
                pass
            elif tl.kind == "episode":
                # an episode's timeline always has GT joints (the measured arm)
                assert tl.time_aligned_drift is not None and tl.joint_error is not None
                self._add(CursorPlot(gui, f"Tracking error |commanded − measured| [{u.strip() or 'units'}], "
                                          "L2 over 6 joints", t,
                                     [Line("tracking error", tl.time_aligned_drift, LIMIT_HEX, 1.6)], floor=0.0))
                self._add(CursorPlot(gui, f"Per joint: commanded − measured [{u.strip() or 'units'}]", t, [
                    Line(j, tl.joint_error[:, k], JOINT_HEX[k], 1.2) for k, j in enumerate(JOINT_NAMES)]))
            elif tl.has_gt_joints:
                assert tl.time_aligned_drift is not None  # set with the GT joints
                per_chunk = tl.per_chunk(tl.time_aligned_drift)[tl.step_chunk]
                self.drift_plot = self._add(CursorPlot(gui, f"Joint drift [{u.strip() or 'units'}], L2 over 6 joints", t, [
                    Line("time-aligned", tl.time_aligned_drift, LIMIT_HEX, 1.6),
                    *([Line("best-match", tl.best_match_drift, BM_HEX, 1.4)] if tl.best_match_drift is not None else []),
                    Line("time-aligned, chunk mean", per_chunk, LIMIT_HEX, 1.0, (4, 3)),
                    *([Line("DTW", tl.dtw_drift, DTW_HEX, 1.0, (2, 2))] if tl.dtw_drift is not None else []),
                ], floor=0.0, marks=self._marks_at(tl, sanity), **common))
            else:
                self._handles.append(gui.add_html(
                    "<div style='font-size:0.8rem;color:#6b7280;padding:4px'>No GT joints for this "
                    "rollout, so no joint drift. Serve it with <code>--dataset</code> pointing at its "
                    "LeRobot dataset to compare joints. Shown: joints over their limits per step.</div>"))
                self.drift_plot = self._add(CursorPlot(gui, "Joints past their URDF limit (count)", t, [
                    Line("joints over limit", tl.limit_violation.sum(axis=1).astype(float), LIMIT_HEX)],
                    floor=0.0, marks=self._marks_at(tl, sanity), **common))
            if compare is not None and not is_video_only(tl) and not is_video_only(compare):
                per_step, per_chunk_div, collapse = prompt_divergence(tl.pred, compare.pred, tl.steps_per_chunk)
                n = len(per_step)
                div = np.full(tl.n_steps, np.nan)
                div[:n] = per_step
                div_chunk = np.full(tl.n_steps, np.nan)
                div_chunk[:n] = per_chunk_div[tl.step_chunk[:n]]
                meet = f", together again from chunk {collapse}" if collapse is not None else ""
                self._add(CursorPlot(gui, f"Divergence from {compare.tag} [{u.strip() or 'units'}]{meet}", t, [
                    Line("per step", div, CMP_HEX, 1.5),
                    Line("chunk mean", div_chunk, CMP_HEX, 1.0, (4, 3)),
                ], floor=0.0, **common))
        with self.tab_joints:
            if not is_video_only(tl):
                self.joint_plot = self._add(CursorPlot(gui, "", t, self._joint_lines(self.joint.value), **common))
                self.joint_plot.set_lines(self._joint_lines(self.joint.value), title=self._joint_title())
        with self.tab_ee:
            if tl.ee_error_mm is not None:
                labels = tl.labels
                self._add(CursorPlot(gui, f"End-effector {'tracking ' if tl.kind == 'episode' else ''}error [mm]", t, [
                    Line(f"|{labels.pred} − {labels.gt}| at gripper frame", tl.ee_error_mm, PRED_HEX)],
                    floor=0.0, **common))
            if tl.rollout.views:
                self.psnr_plot = self._add(CursorPlot(gui, "Video PSNR, imagined vs GT [dB]", *self._psnr_xy(psnr),
                                                      **common))
            if tl.video_views():
                self.agreements, self._frozen = self._known_agreements(), {}
                x, lines, marks = self._agreement_xy()
                self.agreement_plot = self._add(CursorPlot(gui, self._agreement_title(), x, lines, marks=marks,
                                                           **common))
                self.update_psnr(psnr, match_errors)  # a frame match that failed before: the title says so

    @staticmethod
    def _marks_at(tl: RolloutTimeline, sanity: Sequence[tuple[int, str, str]]) -> list[Mark]:
        return [(float(tl.t_s[step]), label, color) for step, label, color in sanity]

    def set_sanity_marks(self, sanity: Sequence[tuple[int, str, str]]) -> None:
        """Redraw the drift plot's sanity marks when they change (a view's video break, once known)."""
        if self._tl is None or self.drift_plot is None or tuple(sanity) == self._sanity:
            return
        self._sanity = tuple(sanity)
        self.drift_plot.set_lines(self.drift_plot.lines, marks=self._marks_at(self._tl, sanity))

    def _add(self, plot: CursorPlot) -> CursorPlot:
        self.plots.append(plot)
        return plot

    def set_cursor(self, t: float) -> None:
        for p in self.plots:
            p.set_cursor(t)

    # -- series -------------------------------------------------------------------------------
    def _joint_title(self) -> str:
        tl = self._tl
        j = self.joint.value
        u = "0..100" if j == "gripper" else ("deg" if tl is None or tl.units.arm == "degrees" else "-100..100")
        labels = tl.labels if tl is not None else None
        pair = f"{labels.pred} vs {labels.gt}" if labels is not None and tl is not None and tl.has_gt_joints else (
            labels.pred if labels is not None else "predicted")
        return f"{j} [{u}]: {pair}, limits dashed"

    def _joint_lines(self, joint: str) -> list[Line]:
        tl = self._tl
        assert tl is not None
        j = JOINT_NAMES.index(joint)
        lines = [Line(tl.labels.pred, tl.pred[:, j], PRED_HEX, 1.6)]
        if tl.gt_aligned is not None:
            lines.append(Line(tl.labels.gt, tl.gt_aligned[:, j], GT_HEX, 1.6))
        if self._cmp is not None:
            y = np.full(tl.n_steps, np.nan)
            n = min(tl.n_steps, self._cmp.n_steps)
            y[:n] = self._cmp.pred[:n, j]
            lines.append(Line(f"{self._cmp.tag}", y, CMP_HEX, 1.2))
        lo, hi = tl.limits[j]
        lines += [Line("lower limit", np.full(tl.n_steps, lo), LIMIT_HEX, 1.0, (5, 4)),
                  Line("upper limit", np.full(tl.n_steps, hi), LIMIT_HEX, 1.0, (5, 4))]
        return lines

    def show_joint(self, joint: str) -> None:
        if self.joint_plot is not None and self._tl is not None:
            self.joint_plot.set_lines(self._joint_lines(joint), title=self._joint_title())

    def _psnr_xy(self, psnr: dict[str, np.ndarray | None]) -> tuple[np.ndarray, list[Line]]:
        """PSNR per imagined frame, placed at the time of the step each frame shows."""
        tl = self._tl
        assert tl is not None
        colors = ("#e8590c", "#1c7ed6", "#2b8a3e", "#ae3ec9")
        series = {v: p for v, p in psnr.items() if p is not None}
        self._psnr_views = tuple(series)
        if not series:
            return tl.t_s, [Line("computing… / no GT video", np.full(tl.n_steps, np.nan), "#adb5bd")]
        n = max(len(p) for p in series.values())
        x = tl.frame_step(n) / tl.fps
        # Several frames can show one step (single chunks): keep x ascending by a tiny offset.
        x = x + np.arange(n) * 1e-6
        lines = []
        for i, (v, p) in enumerate(series.items()):
            y = np.full(n, np.nan)
            y[: len(p)] = p
            lines.append(Line(v, y, colors[i % len(colors)], 1.4))
        return x, lines

    # -- video-action agreement ----------------------------------------------------------------
    def _known_agreements(self) -> dict[str, VideoAction]:
        """Agreement of the views whose video metrics are known (never computes them here)."""
        tl = self._tl
        assert tl is not None
        known = tl.known_video_metrics()
        out = {}
        for view in tl.video_views():
            if view in known and known[view].match is not None:
                va = tl.video_action(view)
                if va is not None:
                    out[view] = va
        return out

    def _agreement_xy(self) -> tuple[np.ndarray, list[Line], list[tuple[float, str]]]:
        """The video's GT time per view and the joints' GT time, per imagined frame, at the time
        of the step each frame shows; a mark where video and actions part."""
        tl = self._tl
        assert tl is not None
        if not self.agreements:
            return tl.t_s, [Line("computing… / no GT video", np.full(tl.n_steps, np.nan), "#adb5bd")], []
        n = max(va.video_gt_s.size for va in self.agreements.values())
        x = tl.frame_step(n) / tl.fps + np.arange(n) * 1e-6  # several frames may show one step
        colors = ("#e8590c", "#1c7ed6", "#2b8a3e", "#ae3ec9")
        lines, marks = [], []
        for i, (view, va) in enumerate(self.agreements.items()):
            lines.append(Line(f"video's GT time, {view}", _padded(va.video_gt_s, n), colors[i % len(colors)], 1.4))
            split = va.split_chunk()
            if split is not None:
                marks.append((float(tl.t_s[min(split * tl.steps_per_chunk, tl.n_steps - 1)]),
                              f"{view}: video and actions part (chunk {split})"))
        first = next(iter(self.agreements.values()))
        if first.joints_gt_s is not None:
            lines.append(Line("joints' GT time", _padded(first.joints_gt_s, n), PRED_HEX, 1.2, (4, 3)))
        return x, lines, marks

    def _agreement_title(self) -> str:
        """The agreement plot's title, with what its lines cannot show: a view whose frame match
        failed, a frozen video (no lag), and frames with no match."""
        notes = [f"{view}: no frame match ({why})" for view, why in self._match_errors]
        for view, va in self.agreements.items():
            if self._frozen.setdefault(view, va.frozen()):
                notes.append(f"{view}: video {FROZEN}, no lag")
                continue
            lag = va.lag_s if va.lag_s is not None else va.video_gt_s
            missing = int((~np.isfinite(lag)).sum())
            if missing:
                notes.append(f"{view}: {NO_MATCH} at {missing} of {lag.size} frames")
        return " · ".join([AGREEMENT_TITLE, *notes])

    def lag_text(self, step: int) -> str:
        """The lag of each view at ``step`` for the readout ("" before any is known): "no match"
        where the frame has no lag (its video matched no GT frame, or the joints are off the GT
        path), "video frozen" for a frozen video."""
        tl = self._tl
        if tl is None or not self.agreements:
            return ""
        f = tl.frame_index(step)
        parts = []
        for view, va in self.agreements.items():
            if f >= va.video_gt_s.size:
                continue
            lag = va.lag_s
            if not np.isfinite(va.video_gt_s[f]):
                parts.append(f"{view}: {NO_MATCH}")
            elif lag is None:
                parts.append(f"{view} video at GT {va.video_gt_s[f]:.2f} s")
            elif self._frozen.setdefault(view, va.frozen()):
                parts.append(f"{view}: video {FROZEN}")
            elif not np.isfinite(lag[f]):
                parts.append(f"{view}: {NO_MATCH}")
            else:
                parts.append(f"lag {view} {lag[f]:+.2f} s")
        return " · ".join(parts)

    def update_psnr(self, psnr: dict[str, np.ndarray | None], match_errors: dict[str, str] | None = None) -> None:
        """Redraw the PSNR and agreement plots once more views have their video metrics (or
        their frame match failed: the agreement plot's title says so)."""
        if self._tl is not None and self.agreement_plot is not None:
            known = self._known_views()
            failed = tuple(sorted((match_errors or {}).items()))
            if known != tuple(self.agreements) or failed != self._match_errors:
                self.agreements, self._match_errors, self._frozen = self._known_agreements(), failed, {}
                x, lines, marks = self._agreement_xy()
                self.agreement_plot.set_lines(lines, x=x, marks=marks, title=self._agreement_title())
        if self.psnr_plot is None or self._tl is None:
            return
        if tuple(v for v, p in psnr.items() if p is not None) == self._psnr_views:
            return
        x, lines = self._psnr_xy(psnr)
        self.psnr_plot.set_lines(lines, x=x)

    def set_gripper_distance(self, series: dict[str, np.ndarray]) -> None:
        """Under the drift plot, per view with a fixed camera: the pixel distance between the
        gripper tracked through the imagined video and where the predicted joints put it (a gap
        once the track is lost), added once the view's frames are decoded."""
        tl = self._tl
        if tl is None or not series or tuple(sorted(series)) == self._gripper_views or is_video_only(tl):
            return
        self._gripper_views = tuple(sorted(series))
        lines = [Line(f"{view}: tracked − projected", series[view], JOINT_HEX[i % len(JOINT_HEX)], 1.4)
                 for i, view in enumerate(self._gripper_views)]
        if self.gripper_plot is not None:
            self.gripper_plot.set_lines(lines)
            return
        ticks = tl.t_s[tl.chunk_start_step[tl.chunk_start_step < tl.n_steps]]
        with self.tab_drift:
            self.gripper_plot = self._add(CursorPlot(self._gui, GRIPPER_TITLE, tl.t_s, lines, floor=0.0, ticks=ticks))

    def _known_views(self) -> tuple[str, ...]:
        tl = self._tl
        assert tl is not None
        known = tl.known_video_metrics()
        return tuple(v for v in tl.video_views() if v in known and known[v].match is not None)


AGREEMENT_TITLE = "GT time: imagined video vs predicted joints [s]"
GRIPPER_TITLE = "Imagined gripper vs predicted joints [px]"


def _padded(values: np.ndarray, n: int) -> np.ndarray:
    out = np.full(n, np.nan)
    out[: values.size] = values
    return out
