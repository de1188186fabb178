"""One browser tab's state: which rollout, which step, playing or not, and its GUI and scene.

Each connected client gets a :class:`TabState`; nothing in it is shared with other tabs, so one
person scrubbing never moves another's view. Shared, read-only data (timelines, frames, meshes)
comes from the app's :class:`~._catalog.Catalog`.

:meth:`TabState.set_step` is the scrub step (FK-posed arms, trail, limit markers, video frames,
plot cursors, slider values): the entry point for benchmarks, e.g.::

    app = serve(["/tmp/s1"], port=0, block=False)
    with HeadlessClient(app.port):           # inspector.app._headless: a tab without a browser
        tab = app.wait_for_tabs(1)[0]
        tab.open("s1 / ep000_train")
        tab.set_step(100)
    app.stop()

Its playback (:mod:`._playback`), Notes folder (:mod:`._notes_panel`) and Export button
(:mod:`._export_action`) are parts it inherits, each in a module of its own that declares what it
uses of the tab; the step readout is :mod:`._readout`, pure functions of the timeline.

Every GUI callback runs on viser's thread pool; the tab's ``lock`` (re-entrant) serialises them
with the playback thread and the background frame loader. Programmatic value changes also fire
viser callbacks (with ``event.client`` None); those are ignored, so only the user's moves act.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from ..analysis.metrics import prompt_divergence
from ..data.session import CHAINED_KINDS
from ._cards import error_card, esc, headline_metrics, rollout_card, video_grid
from ._catalog import Loaded
from ._clip_clock import ClipClock
from ._export_action import TabExport
from ._frames import FramePair
from ._host import AppHost
from ._keys import HOTKEYS
from ._label_panel import LabelPanel
from ._light_3d import apply_light_3d
from ._notes_panel import TabNotes
from ._overview import OverviewPanel
from ._panels import LEFT_PANEL_PX, NO_COMPARE, RIGHT_PANEL_PX, ControlPanel, PlotPanel, VideoPanel
from ._playback import TabPlayback, _Clip
from ._readout import limit_text, readout_html
from ._sanity_card import flagged_seam_steps, sanity_marks, slider_marks
from ._scene import TabScene
from ._slider_marks import set_slider_marks
from ._video_only import is_video_only

# A page drawing WebGL in software (Light 3D ticked) spends ~150 ms on each 3D redraw and shows
# nothing new meanwhile: a step the user asks for goes out in two messages there, the frames, plot
# cursors and readout at once and the arms this long after, so the page paints the step's frames
# before it starts the redraw (a key shows its frame in ~30 ms, not ~230 ms).
ARMS_AFTER_FRAME_S = 0.05


class TabState(TabPlayback, TabNotes, TabExport):
    """Everything one tab shows, and the actions its controls trigger.

    Attributes:
        key: catalog key of the open rollout (None before the first open).
        loaded: its shared data, or None when it failed (then ``error`` says why).
        compare: the compared rollout's shared data, or None.
        step: current global executed step.
        playing, speed: playback state (speed as a factor of real time).
        pairs: the video pairs last shown (view, frame indices, PSNR) — for tests.
    """

    def __init__(self, app: AppHost, client) -> None:
        self.app = app
        self.client = client
        self.client_id: int = client.client_id
        self.lock = threading.RLock()
        self.closed = threading.Event()
        self.key: str | None = None
        self.loaded: Loaded | None = None
        self.error: BaseException | None = None
        self.compare_key: str | None = None
        self.compare: Loaded | None = None
        self.step = 0
        self.playing = False
        self.speed = 1.0
        self.pairs: list[FramePair] = []
        self.compare_pairs: dict[str, FramePair] = {}  # view -> the compared rollout's frames
        self.export_result: str | None = None  # what the last export did (for tests and logs)
        self._play_generation = 0
        self._video_html = ""
        self._clip: _Clip | None = None  # the playback clips the video panel is playing
        self._next_clip: _Clip | None = None  # the ones encoded for the steps after them
        self._clips_shown = 0  # ids of the clips sent to the page, so its reports name theirs
        self.clip_clock = ClipClock()  # where the page's clip is, as the page reports it
        self._notes: dict[str, Any] = {}
        self._shown_chunk: int | None = None
        self._listener = self._on_frames  # one bound method, so it can be removed again
        self.robot_note = ""
        self.overview: OverviewPanel | None = None  # built last: it covers the finished tab

        catalog = app.catalog
        # Plainly lit before the page draws anything: the environment map only for a page that
        # finds a GPU (see ._light_3d).
        self.hemisphere_light = apply_light_3d(client, True)
        gui = client.gui
        gui.configure_theme(control_width="large", show_share_button=False, brand_color=(230, 119, 0))
        with client.atomic():
            errors = {k for k, e in catalog.entries.items() if e.error}
            self.controls = ControlPanel(gui, catalog.keys(), errors, client.client_id)
            self.right_panel = gui.add_panel()
            with self.right_panel.add_tab("Video & plots", icon="video"):
                self.video = VideoPanel(gui)
                self.plots = PlotPanel(gui)
            gui.main_panel.dock_left()
            gui.main_panel.set_width(LEFT_PANEL_PX)
            self.right_panel.dock_right()
            self.right_panel.set_width(RIGHT_PANEL_PX)
        try:
            robot = app.robot()  # waits for the shared meshes on the first tab
            self.robot_note = robot.fallback_reason or ""
        except Exception as exc:  # draw paths and plots without arms rather than nothing
            robot, self.robot_note = None, f"robot model failed to load ({type(exc).__name__}: {exc})"
        self.scene = TabScene(client, robot)
        self._wire()  # only now: a control moved earlier would find no scene
        # the Label folder between the rollout card and the timeline: labelling is what a pass does most
        self.label = LabelPanel(self, order=(self.controls.card.order + self.controls.timeline_folder.order) / 2)
        self.overview = OverviewPanel(self)

    # ------------------------------------------------------------------------------------------
    # Opening rollouts

    def open(self, key: str) -> bool:
        """Show rollout ``key`` (a catalog key) from its first step.

        Returns:
            True when it opened; False when it failed (its error card is shown instead) or the key
            is not a served rollout.
        """
        entry = self.app.catalog.get(key)
        if entry is None:
            return False
        with self.lock:
            first = self.key is None
            self.pause()
            self._detach()
            self.key, self.loaded, self.error = key, None, None
            self._set_quietly(self.controls.picker, self.controls.key_to_option[key])
            self.controls.card.content = "<div style='font-size:0.8rem;color:#6b7280'>loading…</div>"
            try:
                loaded = self.app.catalog.load(key, start_frames=not (first and self._frames_on_hold()))
            except Exception as exc:  # shown, not thrown: the rest of the app keeps working
                self.error = exc
                self._show_error(entry.tag, exc)
                return False
            self.loaded = loaded
            # Listen first: a view that finishes meanwhile waits on our lock, then redraws.
            loaded.frames.add_listener(self._listener)
            if self.compare_key == key:
                self.compare_key, self.compare = None, None
                self._set_quietly(self.controls.compare, NO_COMPARE)
            elif self.compare is not None:
                self.compare.frames.add_listener(self._listener)
            with self.client.atomic():
                self._show_loaded()
                self.step = -1
                self._shown_chunk = None
                self.set_step(0, arms_now=True)
            return True

    def _frames_on_hold(self) -> bool:
        """The Overview covers the tab's first rollout (the one a tab opens with) while its rows
        are computed: the rollout's videos wait (decoding them would take the CPU the rows are
        computed with) until the Overview steps aside or every row is in (:meth:`start_frames`).
        A rollout opened on purpose decodes at once."""
        overview = self.overview  # None while the tab is being built
        return overview is not None and overview.visible and not self.app.overview_rows.done.is_set()

    def start_frames(self) -> None:
        """Start decoding the shown (and compared) rollout's videos, where they wait."""
        for loaded in (self.loaded, self.compare):
            if loaded is not None:
                loaded.frames.start()

    def set_compare(self, key: str | None) -> bool:
        """Compare with rollout ``key`` (None to stop): its arm, path, joints, imagined frames and
        the divergence."""
        with self.lock:
            if self.compare is not None:
                self.compare.frames.remove_listener(self._listener)
            if key is None or key == self.key or self.app.catalog.get(key) is None:
                self.compare_key, self.compare = None, None
                self.controls.compare_info.content = ""
                ok = key is None
            else:
                try:
                    self.compare = self.app.catalog.load(key)
                    self.compare_key = key
                    self.compare.frames.add_listener(self._listener)  # its frames arriving redraw too
                    ok = True
                except Exception as exc:
                    self.compare_key, self.compare = None, None
                    self.controls.compare_info.content = error_card(f"cannot compare with {key}", exc)
                    ok = False
            self._set_quietly(self.controls.compare, self.compare_key or NO_COMPARE)
            if self.loaded is not None:
                with self.client.atomic():
                    self._show_loaded(keep_notes=True)
                    self.set_step(self.step, force=True)
            return ok

    def _detach(self) -> None:
        for loaded in (self.loaded, self.compare):
            if loaded is not None:
                loaded.frames.remove_listener(self._listener)

    def _show_error(self, tag: str, exc: BaseException) -> None:
        c = self.controls
        with self.client.atomic():
            c.error.content = error_card(f"cannot open rollout {tag}", exc)
            c.error.visible = True
            c.card.content = ""
            c.readout.content = ""
            self.scene.show(None)
            self.plots.clear()
            self._video_html = ""
            self.video.html.content = "<div style='font-size:0.8rem;color:#6b7280'>—</div>"
            self.pairs = []
            self.label.refresh()  # a rollout that does not open may still be labelled

    def _show_loaded(self, keep_notes: bool = False) -> None:
        """Draw what changes per rollout: card, slider ranges, scene paths, plots, notes."""
        loaded = self.loaded
        assert loaded is not None
        tl = loaded.timeline
        c = self.controls
        c.error.visible = False
        self._refresh_card()
        self._set_quietly(c.chunk, 0)
        self._set_quietly(c.step_in_chunk, 0)
        c.chunk.max = max(tl.n_chunks - 1, 0)
        c.step_in_chunk.max = max(tl.steps_per_chunk - 1, 0)
        c.step_in_chunk.label = ("Step in chunk" if tl.kind in CHAINED_KINDS else
                                 "Frame" if tl.kind == "episode" else "Step")
        # one chunk (a single-chunk sample, an episode): no chunk slider or chunk buttons
        c.chunk.visible = c.nav.visible = tl.n_chunks > 1
        cmp = self.compare
        self.video.set_views(loaded.frames.views)
        self.video.set_overlay_available(loaded.frames.overlay is not None)
        # a video-only rollout has no arm to draw (nor does a video-only compared one)
        self.scene.show(None if is_video_only(tl) else loaded.scene,
                        cmp.scene if cmp is not None and not is_video_only(cmp.timeline) else None)
        marks = sanity_marks(tl)
        self.plots.build(tl, cmp.timeline if cmp is not None else None, loaded.frames.psnr, loaded.frames.match_errors,
                         sanity=marks)
        self._set_slider_marks(marks)
        self._refresh_compare_info()
        if not keep_notes:
            self._load_notes()
            self.label.refresh()

    def _set_slider_marks(self, marks: list[tuple[int, str, str]]) -> None:
        """Flagged seams, completion and video breaks marked on the chunk slider."""
        loaded = self.loaded
        assert loaded is not None
        set_slider_marks(self.controls.chunk, slider_marks(loaded.timeline, marks))

    def _refresh_marks(self) -> None:
        loaded = self.loaded
        if loaded is None:
            return
        marks = sanity_marks(loaded.timeline)
        self.plots.set_sanity_marks(marks)
        self._set_slider_marks(marks)

    def _refresh_card(self) -> None:
        loaded = self.loaded
        if loaded is None:
            return
        tl = loaded.timeline
        gt_note = "" if tl.has_gt_joints or is_video_only(tl) else "no GT joints: only the predicted arm is drawn"
        metrics = headline_metrics(tl, loaded.frames.psnr, loading_video=not loaded.frames.done.is_set())
        if self.robot_note:
            metrics.insert(0, ("robot model", self.robot_note))
        self.controls.card.content = rollout_card(tl, metrics, gt_note)

    def _refresh_compare_info(self) -> None:
        if self.compare is None or self.loaded is None:
            self.controls.compare_info.content = ""
            return

        a, b = self.loaded.timeline, self.compare.timeline
        _, per_chunk, collapse = prompt_divergence(a.pred, b.pred, a.steps_per_chunk)
        finite = per_chunk[np.isfinite(per_chunk)]
        peak = f"{finite.max():.1f}" if finite.size else "—"
        meet = f"they meet again from chunk {collapse}" if collapse is not None else "they do not meet again"
        self.controls.compare_info.content = (
            "<div style='font-size:0.78rem'>"
            f"<span style='color:#1c7ed6'>■</span> blue arm: <b>{esc(b.tag)}</b><br>"
            f"prompt: {esc(b.rollout.prompt or '—')}<br>"
            f"divergence per chunk: max {peak}; {esc(meet)}</div>")

    # ------------------------------------------------------------------------------------------
    # The scrub step

    def set_step(self, step: int, force: bool = False, source=None, cursor: bool = True,
                 arms_now: bool = False) -> int:
        """Move this tab to global step ``step`` (clamped): arms, trail, limits, video, plots, sliders.

        Args:
            step: global executed step.
            force: redraw even if the step did not change.
            source: the slider the user is moving, if any: it is not written back, so a drag whose
                updates are handled out of order never snaps the thumb back.
            cursor: move the plot cursors too (playback skips some: they are most of the bytes).
            arms_now: pose the arms in this batch even in Light 3D (a rollout that opens redraws
                its scene anyway: posing them later would cost a second software-drawn frame).

        Returns:
            The step shown.
        """
        with self.lock:
            loaded = self.loaded
            if loaded is None:
                return self.step
            tl = loaded.timeline
            step = int(np.clip(step, 0, tl.n_steps - 1))
            if step == self.step and not force:
                return step
            self.step = step
            arms_later = not (self.playing or arms_now) and bool(self.controls.light_3d.value)
            with self.client.atomic():
                if not arms_later:
                    self.scene.set_step(step, self._limit_text(step))
                self._render_video()
                if cursor:
                    self.plots.set_cursor(float(tl.t_s[step]))
                self._show_time(source)
            if arms_later:
                self.client.flush()
                timer = threading.Timer(ARMS_AFTER_FRAME_S, self._pose_arms, args=(loaded, step))
                timer.daemon = True
                timer.start()
            return step

    def _pose_arms(self, loaded: Loaded, step: int) -> None:
        """The 3D scene's part of a step shown frame first (see ``ARMS_AFTER_FRAME_S``); a newer
        step or another rollout poses the arms itself."""
        with self.lock:
            if self.closed.is_set() or self.loaded is not loaded or self.step != step:
                return
            with self.client.atomic():
                self.scene.set_step(step, self._limit_text(step))

    def set_chunk(self, chunk: int, step_in_chunk: int | None = None, source=None) -> int:
        """Go to ``chunk`` (clamped), keeping the step within the chunk unless one is given."""
        with self.lock:
            if self.loaded is None:
                return self.step
            tl = self.loaded.timeline
            chunk = int(np.clip(chunk, 0, tl.n_chunks - 1))
            within = self.step_in_chunk if step_in_chunk is None else step_in_chunk
            return self.set_step(tl.step_of(chunk, within), source=source)

    @property
    def chunk(self) -> int:
        return 0 if self.loaded is None else self.step // self.loaded.timeline.steps_per_chunk

    @property
    def step_in_chunk(self) -> int:
        return 0 if self.loaded is None else self.step % self.loaded.timeline.steps_per_chunk

    def jump_to_worst_chunk(self) -> int:
        with self.lock:
            if self.loaded is None:
                return self.step
            chunk, why = self.loaded.timeline.worst_chunk()
            self._notify(f"Worst chunk: {chunk}", why)
            return self.set_chunk(chunk, 0)

    def jump_to_next_seam(self) -> int:
        """The next flagged chunk seam after the current chunk (the first one after the last)."""
        with self.lock:
            if self.loaded is None:
                return self.step
            steps = flagged_seam_steps(self.loaded.timeline)
            if not steps:
                self._notify("No flagged seam", "no chunk jumps from the last one's executed action")
                return self.step
            later = [s for s in steps if s > self.step]
            step = later[0] if later else steps[0]
            chunk = step // self.loaded.timeline.steps_per_chunk
            self._notify(f"Seam: chunk {chunk}", f"{len(steps)} flagged seam(s)")
            return self.set_chunk(chunk, 0)

    def _limit_text(self, step: int) -> list[str]:
        return limit_text(self.loaded.timeline, step)  # type: ignore[union-attr]

    def _render_video(self) -> None:
        loaded = self.loaded
        assert loaded is not None
        if self.playing:
            if self._clip is not None and self._clip.shows(self):
                return  # the browser is playing these steps itself
            if self._next_clip is not None and self._next_clip.shows(self):
                self._show_next_clip()
                return
        self._clip = None
        self.clip_clock.stop()
        tl = loaded.timeline
        cmp = self.compare
        self.pairs, self.compare_pairs = self._pairs_at(self.step)
        html = video_grid(self.pairs, self.step, float(tl.t_s[self.step]), self.compare_pairs,
                          cmp.timeline.tag if cmp is not None else None, large=self.video.selected is not None)
        if html != self._video_html:  # the GT frame often stays while the imagined one moves
            self._video_html = html
            self.video.html.content = html

    def _pairs_at(self, step: int) -> tuple[list[FramePair], dict[str, FramePair]]:
        """What the video panel shows at ``step``: a pair per view shown, and by view the
        compared rollout's frames (at its last step once it is shorter)."""
        loaded, cmp = self.loaded, self.compare
        assert loaded is not None
        shown = [v for v in loaded.frames.views if self.video.selected in (None, v)]
        pairs = [loaded.frames.pair(v, step, overlay=self.video.overlay.value) for v in shown]
        if cmp is None:
            return pairs, {}
        cmp_step = min(step, cmp.timeline.n_steps - 1)
        return pairs, {v: cmp.frames.pair(v, cmp_step) for v in shown if v in cmp.frames.imagined_views}

    def _show_time(self, source=None) -> None:
        tl = self.loaded.timeline  # type: ignore[union-attr]
        c, step = self.controls, self.step
        chunk, within = divmod(step, tl.steps_per_chunk)
        for slider, value in ((c.chunk, chunk), (c.step_in_chunk, within)):
            if slider is not source:
                self._set_quietly(slider, value)
        c.readout.content = readout_html(tl, step, self.plots.lag_text(step))
        if chunk != self._shown_chunk:
            self._shown_chunk = chunk
            self._show_chunk_notes(chunk)

    # ------------------------------------------------------------------------------------------
    # Notifications

    def _notify(self, title: str, body: str, color: str | None = None) -> None:
        try:
            self.client.add_notification(title, body, auto_close_seconds=4.0, color=color)
        except Exception:
            pass  # the tab may be gone

    # ------------------------------------------------------------------------------------------
    # Background frames, wiring, teardown

    def _on_frames(self) -> None:
        """A view finished decoding (or its PSNR is ready): redraw what shows it."""
        with self.lock:
            if self.closed.is_set() or self.loaded is None:
                return
            with self.client.atomic():
                self._render_video()
                self.plots.update_psnr(self.loaded.frames.psnr, self.loaded.frames.match_errors)
                self.plots.set_gripper_distance(self.loaded.frames.gripper_distance())
                self._refresh_marks()  # a view's video break, once its video metrics are known
                self.plots.set_cursor(float(self.loaded.timeline.t_s[self.step]))
                self._refresh_card()

    def close(self) -> None:
        """The client went away: stop playback and let go of shared data."""
        self.closed.set()
        with self.lock:
            self.playing = False
            self._play_generation += 1
            self._detach()

    @staticmethod
    def _set_quietly(handle, value) -> None:
        """Set a control's value; the callback it fires (client None) is ignored by ``_wire``."""
        if handle.value != value:
            handle.value = value

    def _wire(self) -> None:
        c, gui = self.controls, self.client.gui

        def user(fn):
            """Run ``fn(event)`` only for the user's own changes, not our programmatic ones."""
            def cb(event) -> None:
                if event.client is not None and not self.closed.is_set():
                    fn(event)
            return cb

        c.picker.on_update(user(lambda e: self._picked(e.target.value)))
        self.video.view.on_update(user(lambda e: self._redraw_video()))
        self.video.overlay.on_update(user(lambda e: self._redraw_video()))
        self.video.clock.on_update(user(lambda e: self._clip_reported(e.target.value, time.monotonic())))
        # Slider callbacks may run out of order on the pool: read the latest value, not the event's.
        c.chunk.on_update(user(lambda e: self._slider_moved(c.chunk)))
        c.step_in_chunk.on_update(user(lambda e: self._slider_moved(c.step_in_chunk)))
        c.play.on_click(user(lambda e: self.pause() if self.playing else self.play()))
        c.speed.on_update(user(lambda e: setattr(self, "speed", float(e.target.value.rstrip("x")))))
        nav = {"◀ prev": lambda: self.set_chunk(self.chunk - 1),
               "next ▶": lambda: self.set_chunk(self.chunk + 1),
               "worst": self.jump_to_worst_chunk}
        c.nav.on_click(user(lambda e: nav[e.target.value]()))
        c.compare.on_update(user(lambda e: self.set_compare(None if e.target.value == NO_COMPARE else e.target.value)))
        c.save_notes.on_click(user(lambda e: self.save_notes()))
        c.export.on_click(user(lambda e: self.export()))
        c.light_3d.on_update(user(lambda e: self._light_3d(bool(e.target.value))))
        if not c.light_3d.value:  # the page unticked it before the callback was there (a slow start)
            self._light_3d(False)
        self.plots.joint.on_update(user(lambda e: self._show_joint(e.target.value)))
        # Step keys (ignored while typing in a text field; kept from viser's camera: see ._keys).
        actions = {
            "Previous step": lambda: self.set_step(self.step - 1),
            "Next step": lambda: self.set_step(self.step + 1),
            "Play / pause": lambda: self.pause() if self.playing else self.play(),
            "Previous chunk": lambda: self.set_chunk(self.chunk - 1),
            "Next chunk": lambda: self.set_chunk(self.chunk + 1),
            "Worst chunk": self.jump_to_worst_chunk,
            "Next flagged seam": self.jump_to_next_seam,
        }
        for label, key in HOTKEYS.items():
            gui.add_command(label, hotkey=key).on_trigger(user(lambda e, a=actions[label]: a()))

    def _light_3d(self, light: bool) -> None:
        self.hemisphere_light = apply_light_3d(self.client, light)

    def _picked(self, option: str) -> None:
        """The picker changed: open that rollout, or put back the open one for a name not served."""
        key = self.controls.key_of(option)
        if key is not None:
            self.open(key)
            return
        with self.lock:
            if self.key is not None:
                self._set_quietly(self.controls.picker, self.controls.key_to_option[self.key])

    def _slider_moved(self, slider) -> None:
        with self.lock:
            c = self.controls
            if slider is c.chunk:
                self.set_chunk(int(c.chunk.value), source=slider)
            else:
                self.set_chunk(self.chunk, int(c.step_in_chunk.value), source=slider)

    def _clip_reported(self, report: str, received: float) -> None:
        """The page's clip clock (its hidden field): the play loop follows it."""
        with self.lock:
            self.clip_clock.report(report, received)

    def _redraw_video(self) -> None:
        with self.lock:
            if self.loaded is not None:
                self._render_video()

    def _show_joint(self, joint: str) -> None:
        with self.lock:
            self.plots.show_joint(joint)
            if self.loaded is not None:
                self.plots.set_cursor(float(self.loaded.timeline.t_s[self.step]))
