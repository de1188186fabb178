"""One tab's playback: the steps advance at the rollout's rate times the speed, drawn at most
:data:`PLAYBACK_FPS` times a second, while the video panel plays clips of the coming steps
(:mod:`._playback_clip`), one segment ahead, and the play loop follows the clip the page reports
(:mod:`._clip_clock`).

A part of :class:`~._state.TabState` (which inherits it), kept apart because it runs on threads of
its own (the play loop and the clip encoder) and only meets the rest of the tab through the
attributes declared below, under the tab's lock.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, cast

from . import _playback_clip
from ._cards import video_grid
from ._catalog import Loaded
from ._clip_clock import ClipClock
from ._frames import FramePair
from ._panels import ControlPanel, PlotPanel, VideoPanel
from ._playback_clip import CLIP_STEPS, encode_clip

PLAYBACK_FPS = 30.0
PLOT_CURSOR_HZ = 10.0


class TabPlayback:
    """Play, pause and the threads that play (see the module docstring)."""

    # What playback uses of its tab (:class:`~._state.TabState` sets them).
    lock: threading.RLock
    closed: threading.Event
    client_id: int
    loaded: Loaded | None
    compare: Loaded | None
    step: int
    playing: bool
    speed: float
    controls: ControlPanel
    plots: PlotPanel
    video: VideoPanel
    pairs: list[FramePair]
    compare_pairs: dict[str, FramePair]
    clip_clock: ClipClock
    _play_generation: int
    _clip: _Clip | None
    _next_clip: _Clip | None
    _clips_shown: int
    _video_html: str

    if TYPE_CHECKING:
        def set_step(self, step: int, force: bool = False, source=None, cursor: bool = True,
                     arms_now: bool = False) -> int: ...

        def _render_video(self) -> None: ...

        def _pairs_at(self, step: int) -> tuple[list[FramePair], dict[str, FramePair]]: ...

    def play(self) -> None:
        """Start playing from the current step (from the start if at the end)."""
        with self.lock:
            if self.playing or self.loaded is None:
                return
            if self.step >= self.loaded.timeline.n_steps - 1:
                self.set_step(0)
            self.playing = True
            self._play_generation += 1
            self.controls.play.label = "Pause"
            self.controls.play.icon = "player-pause"
            threading.Thread(target=self._play_loop, args=(self._play_generation,),
                             name=f"inspector-play-{self.client_id}", daemon=True).start()
            if _playback_clip.ENABLED:
                threading.Thread(target=self._play_clips, args=(self._play_generation,),
                                 name=f"inspector-clip-{self.client_id}", daemon=True).start()

    def pause(self, at_end: bool = False) -> None:
        """Stop playing. ``at_end``: playback reached the last step; a clip that ends there plays
        on to its last frame, the last step's (a page that started it late is not cut short)."""
        with self.lock:
            if not self.playing:
                return
            clip_step = self.clip_clock.step(lead=False) if self._clip is not None else None
            self.clip_clock.stop()
            self.playing = False
            if clip_step is not None and not at_end:  # stop where the page's clip is
                self.set_step(min(clip_step, cast(Loaded, self.loaded).timeline.n_steps - 1), cursor=False)
            if self.loaded is not None:  # the cursors may lag a throttled playback step
                self.plots.set_cursor(float(self.loaded.timeline.t_s[self.step]))
            self._play_generation += 1
            self.controls.play.label = "Play"
            self.controls.play.icon = "player-play"
            self._next_clip = None
            # playing implies a loaded rollout (play() needs one; open() pauses before unloading)
            plays_out = at_end and self._clip is not None and self._clip.end >= cast(Loaded, self.loaded).timeline.n_steps
            if self.loaded is not None and self._clip is not None and not plays_out:
                self._render_video()  # the step's frames again, where the clips stopped

    def _play_loop(self, generation: int) -> None:
        """Advance at ``fps * speed`` steps per second, drawing at most PLAYBACK_FPS times a second;
        while the page plays a clip and reports it, to the step the clip shows (see ._clip_clock).

        Stops when paused, when the rollout changes, at the last step, or when the tab closes.
        """
        last = last_cursor = time.monotonic()
        budget = 0.0  # fractional steps owed (slow speeds advance less than a step per tick)
        while not self.closed.wait(1.0 / PLAYBACK_FPS):
            now = time.monotonic()
            with self.lock:
                # closed is set before close() takes the lock: a tick that got the lock first
                # must not move a closed tab's step
                if generation != self._play_generation or self.loaded is None or self.closed.is_set():
                    return
                tl = self.loaded.timeline
                clip_step = self.clip_clock.step(now) if self._clip is not None else None
                if clip_step is not None:  # the clip's clock
                    budget, last = 0.0, now
                    target = ClipClock.follow(self.step, clip_step)
                    if target == self.step:
                        continue
                else:  # the server's
                    budget += (now - last) * tl.fps * self.speed
                    last = now
                    n = int(budget)
                    if n == 0:
                        continue
                    budget -= n
                    target = self.step + n
                at_end = target >= tl.n_steps - 1
                # Plot cursors at PLOT_CURSOR_HZ: the arms and video move at the full rate.
                cursor = at_end or now - last_cursor >= 1.0 / PLOT_CURSOR_HZ
                last_cursor = now if cursor else last_cursor
                self.clip_clock.sent(self.set_step(target, cursor=cursor), now)
                if at_end:
                    self.pause(at_end=True)
                    return

    def _play_clips(self, generation: int) -> None:
        """Get the clips of the segment playback is in (from the frame cache, else encoded), swap
        them in, then the next segment's, one ahead at most (see :mod:`._playback_clip`). Until
        the first is ready, and whenever encoding falls behind, images play."""
        segment = None
        while True:
            with self.lock:
                if generation != self._play_generation or self.loaded is None:
                    return
                if segment is None:
                    segment = self.step // CLIP_STEPS * CLIP_STEPS
                if segment >= self.loaded.timeline.n_steps:
                    return
                clip = _Clip.plan(self, segment, CLIP_STEPS)
            if clip is None:
                return
            try:
                clip.encode(wanted=lambda: generation == self._play_generation and not self.closed.is_set())
            except Exception:  # noqa: BLE001 - the images keep playing (or playback ended): nothing is lost
                return
            with self.lock:
                if generation != self._play_generation or not self.playing:
                    return
                self._next_clip = clip
                if clip.shows(self):
                    self._show_next_clip()
            # one clip ahead at most: wait until this one is on screen (or passed by)
            while not self.closed.wait(0.05):
                with self.lock:
                    if generation != self._play_generation:
                        return
                    if self._next_clip is not clip or self.step >= clip.end:
                        break
            segment = clip.end

    def _show_next_clip(self) -> None:
        """Swap the prepared clip in, starting where playback is now."""
        clip, self._next_clip = self._next_clip, None
        assert clip is not None and self.loaded is not None
        offset_s = (self.step - clip.start) / clip.fps
        clips = {panel: f"{uri}#t={offset_s:.3f}" for panel, uri in clip.uris.items()}
        tl = self.loaded.timeline
        self._clips_shown += 1
        self._video_html = video_grid(
            self.pairs, self.step, float(tl.t_s[self.step]), self.compare_pairs,
            self.compare.timeline.tag if self.compare else None, large=self.video.selected is not None,
            clips=clips, clip_clock=(clip.start, clip.end, clip.fps, tl.fps), clip_id=self._clips_shown)
        self.video.html.content = self._video_html
        self.clip_clock.shown(self._clips_shown, clip.start, clip.end, clip.fps, self.step)
        self._clip = clip  # last: whoever sees it set finds the page sent the clips


class _Clip:
    """The panels' frames for steps ``start``..``end`` - 1 at the playback rate, and what they
    were made for (rollout, view selection, compared rollout, speed): a change of any of those
    goes back to stepping images."""

    def __init__(self, tab: TabPlayback, start: int, end: int, panels: dict[tuple[str, str], list[str]]) -> None:
        self.start, self.end, self.panels = start, end, panels
        self.uris: dict[tuple[str, str], str] = {}  # panel -> the clip's video URI, once encoded
        self.fps = tab.loaded.timeline.fps * tab.speed  # type: ignore[union-attr]
        self._made_for = self._what(tab)
        # Clips are kept in the server's frame cache, shared by the tabs showing the rollout (and
        # the same compared rollout): a second Play of a segment starts at once.
        frames = tab.loaded.frames  # type: ignore[union-attr]
        self._cache = frames.cache
        compare = tab.compare.frames.token if tab.compare is not None else None
        self._keys = {panel: ("clip", frames.token, compare if panel[1] == "compare" else None, panel,
                              start, end, round(self.fps, 6)) for panel in panels}

    @staticmethod
    def _what(tab: TabPlayback) -> tuple:
        return (tab.loaded, tab.video.selected, tab.compare, tab.speed)

    def shows(self, tab: TabPlayback) -> bool:
        """Whether the clips still show what the tab would at its step."""
        loaded, selected, compare, speed = self._made_for
        return (self.start <= tab.step < self.end and tab.loaded is loaded and tab.compare is compare
                and tab.video.selected == selected and tab.speed == speed)

    @classmethod
    def plan(cls, tab: TabPlayback, start: int, steps: int) -> _Clip | None:
        """The frames each panel shows for ``steps`` steps from ``start``, no further than every
        panel has a frame at every step; None while frames are loading."""
        loaded = tab.loaded
        assert loaded is not None
        end = min(loaded.timeline.n_steps, start + steps)
        panels: dict[tuple[str, str], list[str]] = {}
        for step in range(start, end):
            pairs, compare_pairs = tab._pairs_at(step)
            shown: dict[tuple[str, str], str | None] = {}
            for pair in pairs:
                if pair.has_imagined:
                    shown[(pair.view, "imagined")] = pair.imagined
                shown[(pair.view, "gt")] = pair.gt
            for view, pair in compare_pairs.items():
                shown[(view, "compare")] = pair.imagined
            if step == start:
                shown = {panel: uri for panel, uri in shown.items() if uri is not None}
                if not shown:
                    return None
                panels = {panel: [] for panel in shown}
            if any(shown.get(panel) is None for panel in panels):
                end = step  # a panel loses its frame here (loading, past the episode's end)
                break
            for panel in panels:
                panels[panel].append(shown[panel])  # type: ignore[arg-type]
        if end - start < 2:
            return None
        return cls(tab, start, end, panels)

    def encode(self, wanted: Callable[[], bool] = lambda: True) -> None:
        """Every panel's clip: from the cache, else encoded (in parallel: the encoder and the JPEG
        decoder release the GIL) and cached. Stops (:class:`ClipNotWanted`) once ``wanted`` says
        no: a paused playback or a closed tab leaves nothing encoding for it."""
        self.uris = {panel: uri for panel in self.panels if (uri := self._cache.get(self._keys[panel])) is not None}
        todo = {panel: uris for panel, uris in self.panels.items() if panel not in self.uris}
        if todo:
            with ThreadPoolExecutor(max_workers=len(todo), thread_name_prefix="inspector-clip") as pool:
                futures = {panel: pool.submit(encode_clip, uris, self.fps, wanted) for panel, uris in todo.items()}
                for panel, future in futures.items():
                    self.uris[panel] = future.result()
                    self._cache.put(self._keys[panel], self.uris[panel])
        self.panels = {}  # the JPEGs stay in the frame cache; the clips are what is needed now
