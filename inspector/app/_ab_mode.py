"""Blind pairwise comparison of checkpoints (``inspector serve --ab``), as RoboArena ranks policies.

Each tab shows two rollouts of different sessions (checkpoints) from the same start (the same tag,
or the same episode, start frame and prompt) side by side: their imagined video beside the GT one
(the rollout's own, else its dataset episode's from the start frame), the arm's predicted joints over time (one scale for both
sides), and in the 3D scene each side's arms: predicted, and GT where there is one (see
``._ab_arms``), posed at the pair's playback step (a step slider that plays, looping, at the
rollouts' rate while "play arms" is ticked; moving the slider pauses it). The sides are shuffled and nothing that names a session (its name, model, metrics, the
rollout's tag) is sent to the page until the vote is cast: in this mode the
page holds no picker or overview at all. The evaluator answers A better, B better or tie (keys
``A``, ``B``, ``=``), optionally with a progress score [%] for each and a note; the vote is saved
at once in both sessions' ``votes.json`` (:mod:`inspector.said.votes`), the names of the pair just
judged show beside it for :data:`REVEAL_S`, then the next pair comes and they go. Pairs come least-compared first: the session pair with the
fewest votes so far (read from disk, so several tabs and processes spread their votes together),
then its least-voted rollout pair, ties broken at random.

Bad input is a one-line card above the pair, naming the file, and the tab goes on: a session whose
``votes.json`` does not parse takes no part in pairs until it is fixed (a vote there could not be
saved, and the file is never overwritten), and a pair whose rollout cannot be read (its files gone
or broken since the start) is set aside for the next.
"""

from __future__ import annotations

import base64
import functools
import itertools
import math
import os
import random
import threading
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from html import escape
from importlib import resources
from pathlib import Path

import numpy as np

from .._files import not_regular, read_regular_file
from ..data.ground_truth import resolve_ground_truth
from ..data.session import Rollout, Session
from ..errors import InspectorError, one_line
from ..report.svg import Axes, colour_class, legend_html
from ..said.votes import Side, Vote, new_vote, readable_votes, save_vote
from ..units import JOINT_NAMES
from ._ab_arms import PairArms, rollout_scene
from ._label_ids import LABEL_IDS_HTML
from ._light_3d import LIGHT_3D_HINT, LIGHT_3D_HTML, LIGHT_3D_LABEL, apply_light_3d
from ._overview_table import scoped_css
from ._page_chrome import AB_TITLE, WEBGL_NOTICE_HTML, page_title_html
from ._page_script import page_script_html
from ._robot import SharedRobot

ANSWER_BUTTONS = {"a": "A better", "tie": "Tie", "b": "B better"}
# Keys -> the button they press (the page's script clicks it; viser's hotkeys know no "=").
_KEYS_JS = r"""
const BUTTONS = {a: 'A better', b: 'B better', '=': 'Tie'};
document.documentElement.addEventListener('keydown', (e) => {
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  const t = e.target;
  if (t instanceof Element && t.closest('input, textarea, [contenteditable="true"]')) return;
  const label = BUTTONS[e.key.toLowerCase()];
  if (!label) return;
  const button = [...document.querySelectorAll('button')].find((b) => b.textContent.trim() === label);
  if (!button) return;
  e.stopPropagation();  // not also viser's camera (A strafes)
  e.preventDefault();
  button.click();
});
"""
AB_KEYS_HTML = page_script_html("ab_keys", _KEYS_JS)
AB_HINT = "keys: A better · B better · = tie"
AB_PAGE_HTML = page_title_html(fixed=AB_TITLE) + WEBGL_NOTICE_HTML
AB_SCOPE = "ab-pair"
# the report's chart styles (lines coloured by class), scoped to the pair so they reach nothing else
CHART_CSS = scoped_css((resources.files("inspector.report") / "assets" / "chart.css").read_text(encoding="utf-8"),
                       AB_SCOPE)
MAX_VIDEO_MB = 32.0  # a view larger than this is not inlined into the page
# The arms' play loop: a few poses a second keep up with the videos' motion and leave a browser
# drawing WebGL in software (four arms) time to answer the vote keys.
PLAY_TICK_S = 0.1
# How long the names of the pair just judged show, beside its videos, before the next pair comes
# (and the names go: the next pair is judged without them) [s].
REVEAL_S = 2.5


@dataclass(frozen=True)
class Candidate:
    """Two rollouts from the same start, of sessions ``i`` < ``j`` (indexes into the served sessions)."""

    i: int
    tag_i: str
    j: int
    tag_j: str


def _start(rollout: Rollout) -> tuple:
    return (rollout.episode_index, rollout.start_frame, rollout.prompt)


def plan_candidates(sessions: Sequence[Session]) -> list[Candidate]:
    """Every pair of rollouts that share a start, across every pair of sessions: the same tag, else
    the same (episode, start frame, prompt), matched one to one in tag order."""
    out: list[Candidate] = []
    for i, j in itertools.combinations(range(len(sessions)), 2):
        a, b = sessions[i].rollouts, sessions[j].rollouts
        unmatched = [t for t in sorted(b) if t not in a]
        for tag in sorted(a):
            if tag in b:
                out.append(Candidate(i, tag, j, tag))
                continue
            twin = next((t for t in unmatched if _start(b[t]) == _start(a[tag])), None)
            if twin is not None:
                unmatched.remove(twin)
                out.append(Candidate(i, tag, j, twin))
    return out


def choose_pair(candidates: Sequence[Candidate], sessions: Sequence[Session], votes: Sequence[Vote],
                rng: random.Random) -> tuple[Candidate, bool] | None:
    """The least-compared candidate and whether to swap its sides (at random); None when there is none."""
    if not candidates:
        return None
    roots = [str(s.root.resolve()) for s in sessions]
    by_sessions: Counter[frozenset[str]] = Counter()
    by_rollouts: Counter[frozenset[tuple[str, str]]] = Counter()
    for v in votes:
        a, b = str(Path(v.a.session).resolve()), str(Path(v.b.session).resolve())
        by_sessions[frozenset((a, b))] += 1
        by_rollouts[frozenset(((a, v.a.rollout), (b, v.b.rollout)))] += 1

    def load(c: Candidate) -> tuple[int, int, float]:
        return (by_sessions[frozenset((roots[c.i], roots[c.j]))],
                by_rollouts[frozenset(((roots[c.i], c.tag_i), (roots[c.j], c.tag_j)))], rng.random())

    return min(candidates, key=load), rng.random() < 0.5


@functools.lru_cache(maxsize=64)
def _video_uri(path: str, size: int, mtime_ns: int) -> str:
    """A video file as a data URI (keyed by size and time too: a replaced file is read again)."""
    raw = read_regular_file(Path(path), int(MAX_VIDEO_MB * 2**20), "video shown in A/B mode")
    return "data:video/mp4;base64," + base64.b64encode(raw).decode("ascii")


def video_uri(path: Path) -> str | None:
    """A video as a data URI, or None when it is larger than :data:`MAX_VIDEO_MB` (not inlined).

    Raises:
        InspectorError: the file is gone, is not a regular file (a FIFO is never waited on) or
            cannot be read.
    """
    try:
        st = os.stat(path)
    except OSError as exc:
        raise InspectorError(path, "file not found" if isinstance(exc, FileNotFoundError)
                             else f"cannot read ({exc.strerror or exc})") from None
    problem = not_regular(st.st_mode)
    if problem:
        raise InspectorError(path, problem)
    if st.st_size > MAX_VIDEO_MB * 2**20:
        return None
    return _video_uri(str(path), st.st_size, st.st_mtime_ns)


def joint_ranges(*rollouts: Rollout) -> tuple[float, float]:
    """One y range for the joint plots of both sides, so their motions compare at a glance."""
    values = np.concatenate([r.executed_actions().ravel() for r in rollouts])
    values = values[np.isfinite(values)]
    return (float(values.min()), float(values.max())) if len(values) else (0.0, 1.0)


def joints_html(rollout: Rollout, y_range: tuple[float, float]) -> str:
    """The arm's predicted joints over the rollout's executed steps, one line per joint."""
    actions = rollout.executed_actions()
    t = np.arange(len(actions)) / rollout.fps
    ax = Axes(x_label="time [s]", y_label=f"joint [{'deg' if rollout.units.arm == 'degrees' else '±100'}; gripper 0..100]", width=420, height=200,
              y_min=y_range[0], y_max=y_range[1])
    for j, name in enumerate(JOINT_NAMES):
        ax.line(t, actions[:, j].tolist(), cls=colour_class(j), label=name)
    rollout.release_arrays()
    return ax.svg() + legend_html(ax.legend)


def side_html(label: str, rollout: Rollout, y_range: tuple[float, float] | None = None) -> str:
    """One side of the pair: its imagined video beside the GT one (the rollout's own, or its
    dataset episode's from the start frame on, as the rollout view pairs them), each captioned by
    the view the session names, and its arm's predicted joints; nothing that names the session or
    the rollout."""
    cells = []
    for view in rollout.views[:1]:
        uri = video_uri(rollout.video_path(view))
        cells.append(_video_cell(f"imagined · {view}", uri, "imagined"))
        cells.append(_gt_cell(rollout, view))
    videos = (f"<div style='display:grid;grid-template-columns:repeat(2,minmax(0,1fr));gap:0.3rem'>{''.join(cells)}</div>"
              if cells else "<div style='color:#6b7280'>no video</div>")
    joints = f"<div data-ab-joints='{label}'>{joints_html(rollout, y_range)}</div>" if y_range is not None else ""
    return (f"<div data-ab-side='{label}' style='flex:1;min-width:0'>"
            f"<div style='font-weight:700;font-size:1.1rem'>{label}</div>{videos}{joints}</div>")


def _gt_cell(rollout: Rollout, view: str) -> str:
    """The GT video of ``view``: carried with the rollout, else its dataset episode's from the
    rollout's start frame (looping over the episode's part), else a note that there is none."""
    if view in rollout.gt_views:
        return _video_cell(f"GT · {view}", video_uri(rollout.video_path(view, gt=True)), "gt")
    try:
        clip = resolve_ground_truth(rollout).clips.get(view)
    except Exception:  # any failure: the pair still compares by its imagined videos
        clip = None
    if clip is None:
        return f"<div style='color:#6b7280;font-size:0.75rem'>GT · {escape(view)}: none</div>"
    start = clip.start_s or 0.0
    try:  # the GT loops over the rollout's time, as the imagined video does
        end: float | None = start + len(rollout.executed_actions()) / float(rollout.fps or 30.0)
    except Exception:  # no joints to time it by (video only): to the episode's end
        end = clip.end_s
    finally:
        rollout.release_arrays()
    if clip.end_s is not None and end is not None:
        end = min(end, clip.end_s)
    return _video_cell(f"GT · {view}", video_uri(clip.path), "gt", window=(start, end))


def _video_cell(caption: str, uri: str | None, role: str,
                window: tuple[float, float | None] | None = None) -> str:
    """A looping video; ``window``: the part of the file [s] it plays (a dataset file holds many
    episodes), from its start to its end or the file's."""
    if uri is None:
        return f"<div style='color:#6b7280'>{escape(caption)}: too large to show</div>"
    loop = ""
    if window is not None:
        start, end = window
        uri += f"#t={start:.3f}"
        loop = (f" ontimeupdate='if(this.currentTime<{start:.3f}-0.05||this.currentTime>={end if end is not None else 1e9:.3f})"
                f"this.currentTime={start:.3f}'")
    return (f"<figure style='margin:0.2rem 0'><video data-ab-video='{role}' src='{uri}'{loop} autoplay loop muted "
            f"playsinline style='width:100%'></video><figcaption style='font-size:0.75rem;color:#6b7280'>"
            f"{escape(caption)}</figcaption></figure>")


def parse_progress(text: str) -> float | None:
    """A progress field's text -> percent, None when empty.

    Raises:
        ValueError: not a number from 0 to 100.
    """
    text = text.strip().rstrip("%").strip()
    if not text:
        return None
    value = float(text)
    if not (math.isfinite(value) and 0.0 <= value <= 100.0):
        raise ValueError("progress is a number from 0 to 100 [%]")
    return value


class ABTab:
    """One tab in A/B mode: the pair on show, the vote controls, the names of the last judged pair.

    Args:
        sessions: the served sessions (two or more).
        client: the tab's viser client.
        seed: of the pair order and the side shuffle (None: random).
        robot: the shared robot for the arms (None: no meshes to draw).
        joint_links: joint name -> child link, from the shared robot; None draws no 3D scene.
        reveal_s: how long the names of a pair just judged show before the next pair [s].

    Attributes:
        shown: the pair on show as ((session index, tag) of side A, of side B), or None.
        votes_cast: the votes this tab saved.
        arms: the pair's arms (None without ``joint_links``).
        step: the pair's playback step.
    """

    def __init__(self, sessions: Sequence[Session], client, seed: int | None = None,
                 robot: SharedRobot | None = None, joint_links: dict[str, str] | None = None,
                 reveal_s: float = REVEAL_S) -> None:
        self.sessions = list(sessions)
        self.reveal_s = reveal_s
        self.client = client
        self.lock = threading.RLock()
        self.closed = threading.Event()
        self.candidates = plan_candidates(self.sessions)
        self.set_aside: dict[Candidate, InspectorError] = {}  # pairs whose rollouts could not be read, and why
        self.rng = random.Random(seed)
        self.shown: tuple[tuple[int, str], tuple[int, str]] | None = None
        self.votes_cast: list[Vote] = []
        self.joint_links = joint_links
        self.arms: PairArms | None = None
        self.step = 0
        self._fps = 30.0
        gui = client.gui
        apply_light_3d(client, True)  # plainly lit before the page draws anything (see ._light_3d)
        gui.configure_theme(control_width="large", show_share_button=False, brand_color=(230, 119, 0))
        with client.atomic():
            # data-inspector-client: the Light 3D script unticks the box once per connection by it
            gui.add_html(f"<div data-inspector-client='{int(client.client_id)}' "
                         "style='font-weight:600;font-size:0.95rem;padding:0 0.2rem'>Blind A/B comparison"
                         f"{AB_KEYS_HTML}{AB_PAGE_HTML}{LABEL_IDS_HTML}{LIGHT_3D_HTML if joint_links is not None else ''}</div>")
            self.problems = gui.add_html("")  # one line per file at fault (a votes.json, a rollout's file)
            self.pair_html = gui.add_html("")
            self.step_slider = gui.add_slider("step", 0, 1, 1, 0, hint="the arms' step (both sides)")
            # Light 3D until the page finds a GPU, and the arms still until then (see _light_3d)
            self.playing = gui.add_checkbox("play arms", False, hint="the arms play, looping, at the rollouts' rate")
            self.light_3d = gui.add_checkbox(LIGHT_3D_LABEL, True, hint=LIGHT_3D_HINT)
            self.step_slider.visible = self.playing.visible = self.light_3d.visible = joint_links is not None
            self.buttons = {answer: gui.add_button(label) for answer, label in ANSWER_BUTTONS.items()}
            gui.add_html(f"<div style='font-size:0.7rem;color:#6b7280;padding:0 0.2rem'>{AB_HINT}</div>")
            self.progress = {side: gui.add_text(f"progress {side.upper()} [%]", "", hint="optional, 0 to 100")
                             for side in ("a", "b")}
            self.note = gui.add_text("note", "")
            self.message = gui.add_html("")
            self.revealed = gui.add_html("")
            gui.main_panel.dock_left()
            gui.main_panel.set_width(900)
            if joint_links is not None:
                self.arms = PairArms(client, robot)
        for answer, button in self.buttons.items():
            button.on_click(lambda e, a=answer: self.vote(a) if e.client is not None else None)
        self.step_slider.on_update(lambda e: self._slid(int(e.target.value)) if e.client is not None else None)
        self.light_3d.on_update(lambda e: self._light_3d(bool(e.target.value)) if e.client is not None else None)
        if not self.light_3d.value:  # the page unticked it before the callback was there
            self._light_3d(False)
        self.show_next()
        if self.arms is not None:
            threading.Thread(target=self._play, name="inspector-ab-arms", daemon=True).start()

    def set_step(self, step: int) -> None:
        """Pose the pair's arms at ``step`` (wrapped round the longer side's length)."""
        with self.lock:
            if self.arms is None or self.arms.n_steps == 0:
                return
            self.step = step % self.arms.n_steps
            with self.client.atomic():
                self.arms.set_step(self.step)
                if int(self.step_slider.value) != self.step:
                    self.step_slider.value = self.step

    def _light_3d(self, light: bool) -> None:
        """Plain lighting (see ``._light_3d``), with the arms still: in a browser drawing WebGL in
        software (where the box stays ticked) four arms posed a few times a second made the vote
        keys wait seconds; the slider still poses them, and "play arms" can be ticked. Unticked (by
        the page where it finds a GPU, or by the user), the environment map and the arms play."""
        apply_light_3d(self.client, light)
        self.playing.value = not light

    def _slid(self, step: int) -> None:
        """The user moved the step slider: the arms hold there (play is unticked)."""
        with self.lock:
            self.playing.value = False
            self.set_step(step)

    def _play(self) -> None:
        """While "play arms" is ticked, step the arms at the rollouts' rate until the tab closes."""
        while not self.closed.wait(PLAY_TICK_S):
            with self.lock:
                if self.playing.value and not self.closed.is_set():
                    self.set_step(self.step + max(1, round(self._fps * PLAY_TICK_S)))

    def show_next(self) -> None:
        """Put the least-compared pair on show (of the sessions whose votes file reads, and the
        pairs whose rollouts do); each file at fault is a line on the tab's problem card."""
        with self.lock:
            votes, broken = readable_votes([s.root for s in self.sessions])
            while True:
                usable = [c for c in self.candidates
                          if c not in self.set_aside and c.i not in broken and c.j not in broken]
                choice = choose_pair(usable, self.sessions, votes, self.rng)
                if choice is None:
                    self._show_nothing(bool(broken or self.set_aside))
                    break
                try:
                    self._show_pair(*choice)
                    break
                except Exception as exc:  # any failure: this pair is set aside, the next one shown
                    self.set_aside[choice[0]] = exc if isinstance(exc, InspectorError) else InspectorError(
                        self.sessions[choice[0].i].root, f"{type(exc).__name__}: {exc}")
            self.problems.content = problems_html([*broken.values(), *self.set_aside.values()])

    def _show_nothing(self, problems: bool) -> None:
        self.shown = None
        if self.arms is not None:
            self.arms.show(None, None)
        self.pair_html.content = ("<div style='color:#6b7280'>No pair to compare: "
                                  + ("the files above are at fault." if problems else
                                     "no two sessions share a start (the same tag, or the same episode, start "
                                     "frame and prompt).") + "</div>")

    def _show_pair(self, c: Candidate, swap: bool) -> None:
        """Put candidate ``c`` on show (its sides swapped when ``swap``).

        Raises:
            InspectorError: a side's video or arrays cannot be read (nothing on show changes).
        """
        with self.lock:
            a, b = ((c.j, c.tag_j), (c.i, c.tag_i)) if swap else ((c.i, c.tag_i), (c.j, c.tag_j))
            ra, rb = self.sessions[a[0]].rollouts[a[1]], self.sessions[b[0]].rollouts[b[1]]
            prompt = escape(ra.prompt or "(no prompt)")
            try:
                y_range: tuple[float, float] | None = joint_ranges(ra, rb)
            except InspectorError:  # an array that cannot be read: the videos still compare
                y_range = None
            sides = side_html("A", ra, y_range) + side_html("B", rb, y_range)  # raises before anything changes
            self.shown = (a, b)
            self.revealed.content = ""  # the last pair's names go as this one comes
            self._show_arms(ra, rb)
            self.pair_html.content = (
                f"<div class='{AB_SCOPE}' data-ab-pair='{len(self.votes_cast) + 1}' style='padding:0 0.8rem 0 0.2rem'>"
                f"<div style='font-size:0.85rem;margin-bottom:0.3rem'>task: {prompt}</div>"
                f"<div style='display:flex;gap:0.5rem'>{sides}</div>"
                f"<style>{CHART_CSS}</style></div>")

    def _show_arms(self, ra: Rollout, rb: Rollout) -> None:
        """Put the pair's arms up at step 0 (a side whose arrays cannot be read shows none)."""
        if self.arms is None or self.joint_links is None:
            return
        self._fps = float(ra.fps or 30.0)
        with self.client.atomic():
            self.arms.show(rollout_scene(ra, self.joint_links), rollout_scene(rb, self.joint_links))
            self.step_slider.max = max(self.arms.n_steps - 1, 1)
            self.step_slider.value = self.step = 0

    def vote(self, answer: str, progress_a: float | None = None, progress_b: float | None = None,
             note: str | None = None) -> Vote | None:
        """Save ``answer`` ("a", "b", "tie") on the pair on show, reveal it and show the next.

        Progress and note default to the fields' contents (empty: none). Returns the saved vote,
        or None when nothing is on show or a field is invalid (the page says which).
        """
        with self.lock:
            if self.shown is None or self.closed.is_set():
                return None
            try:
                pa = progress_a if progress_a is not None else parse_progress(self.progress["a"].value)
                pb = progress_b if progress_b is not None else parse_progress(self.progress["b"].value)
            except ValueError:
                self.message.content = ("<div style='color:#c92a2a'>progress: a number from 0 to 100, or "
                                        "empty</div>")
                return None
            (ia, ta), (ib, tb) = self.shown
            sa, sb = self.sessions[ia], self.sessions[ib]
            v = new_vote(Side(str(sa.root.resolve()), sa.name, ta, pa), Side(str(sb.root.resolve()), sb.name, tb, pb),
                         answer, self.note.value if note is None else note)
            try:
                save_vote(v)
            except (InspectorError, OSError) as exc:
                self.message.content = f"<div style='color:#c92a2a'>not saved: {escape(str(exc))}</div>"
                return None
            self.votes_cast.append(v)
            self.message.content = ""
            for field in (*self.progress.values(), self.note):
                field.value = ""
            # the names show beside the pair just judged, then go as the next pair comes
            self.shown = None
            self.revealed.content = reveal_html(v, sa, sb)
            timer = threading.Timer(self.reveal_s, self._next_after_reveal)
            timer.daemon = True
            timer.start()
            return v

    def _next_after_reveal(self) -> None:
        with self.lock:
            if not self.closed.is_set():
                self.show_next()

    def close(self) -> None:
        self.closed.set()


def problems_html(problems: Sequence[InspectorError]) -> str:
    """One red line per file at fault (``<file>: <what>``), or nothing."""
    return "".join(f"<div data-ab-problem style='color:#c92a2a;font-size:0.8rem;padding:0 0.2rem;"
                   f"overflow-wrap:anywhere'>⚠ {escape(one_line(str(p)))}</div>" for p in problems)


def reveal_html(v: Vote, a: Session, b: Session) -> str:
    said = {"a": "A better", "b": "B better", "tie": "tie"}[v.answer]
    def who(side: Side, s: Session) -> str:
        model = s.model.get("name") or ""
        return f"{escape(s.name)}{f' ({escape(str(model))})' if model else ''} · {escape(side.rollout)}"
    return (f"<div data-ab-revealed='{escape(v.id)}' style='font-size:0.8rem;padding:0 0.2rem'>"
            f"last pair ({said}): A was {who(v.a, a)}; B was {who(v.b, b)}</div>")


def served_sessions(sessions: Sequence[Session]) -> list[Session]:
    """The sessions A/B mode compares (those with at least one loaded rollout)."""
    return [s for s in sessions if s.rollouts]

