"""The Label panel: a person's outcome of the open rollout, at the speed of a keyboard.

Keys (bound per tab, ignored while typing in a text field): ``S`` success, ``F`` failure, ``1``-``9``
progress 10-90 %, ``0`` progress 100 %, ``T`` the next failure tag (none after the last), ``N`` the
next rollout without a label (in the Overview's current filter and order, else the picker's). The
panel's buttons, slider, tag selector and note do the same.

Every change is saved at once as the rollout's ``label`` outcome (:func:`inspector.outcomes.update_outcome`:
locked read-modify-write of the session's ``outcomes.json``, or a raw directory's sidecar, replaced
atomically), so nothing waits for a Save button and two tabs labelling the same session keep each
other's labels: each change writes only the fields it sets, merged into what is on disk now.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from html import escape
from typing import Any

from ..errors import InspectorError
from ..outcomes import FAILURE_TAGS, known_failure_tags, outcomes_path, read_outcomes, says_something, update_outcome
from ._cards import error_card
from ._host import OverviewHost
from ._keys import LABEL_HOTKEYS

NO_TAG = "(none)"
KEYS_HELP = ("<div style='font-size:0.7rem;color:#6b7280;padding:0 0.2rem'>keys: S success · F fail · "
             "1-9 progress 10-90% · 0 100% · T failure tag · N next unlabelled</div>")


class LabelPanel:
    """One tab's Label folder (see the module docstring).

    Attributes:
        last_saved: ``(key, record, seconds it took)`` of the last label written (for tests and
            benchmarks).
    """

    def __init__(self, tab: OverviewHost, order: float) -> None:
        self.tab = tab
        self.last_saved: tuple[str, Any, float] | None = None
        gui = tab.client.gui
        with gui.add_folder("Label", order=order) as self.folder:
            self.status = gui.add_html("")
            self.verdict = gui.add_button_group("Mark as", ("success", "fail", "clear"))
            self.progress = gui.add_slider("Progress %", 0, 100, 10, 0)
            self.failure = gui.add_dropdown("Failure tag", (NO_TAG, *FAILURE_TAGS))
            self.note = gui.add_text("Label note", "")
            self.next = gui.add_button("Next unlabelled", icon="player-track-next")
            gui.add_html(KEYS_HELP)
        self._record: dict[str, Any] | None = None
        self._wire()

    # ------------------------------------------------------------------------------------------
    # Reading

    def _session(self):
        entry = self.tab.app.catalog.get(self.tab.key) if self.tab.key else None
        return (entry, entry.session) if entry is not None else (None, None)

    def refresh(self) -> None:
        """Show the open rollout's outcome (every source) and the label queue."""
        entry, session = self._session()
        if entry is None or session is None:
            self.status.content = ("<div style='font-size:0.75rem;color:#6b7280'>Labels are kept with a "
                                   "session; a dataset's episodes carry their recorded outcome only.</div>")
            return
        try:
            document = read_outcomes(outcomes_path(session))
        except InspectorError as exc:
            self.status.content = error_card("outcomes file is unreadable (not overwritten)", exc)
            return
        tags = known_failure_tags(document)
        if tuple(self.failure.options) != (NO_TAG, *tags):
            self.failure.options = (NO_TAG, *tags)
        served = self.tab.app.catalog.outcomes
        sources = served.sources(session, entry.tag, document["rollouts"])
        label: dict[str, Any] = dict(sources.get("label") or {})
        self._record = label or None
        self._set_quietly(self.progress, int(round(label.get("progress") or 0)))
        self._set_quietly(self.failure, label.get("failure") or NO_TAG)
        self._set_quietly(self.note, label.get("note") or "")
        status = _status_html(served.shown(sources), sources, self._queue_text())
        if self.status.content != status:  # an unchanged panel costs the page nothing
            self.status.content = status

    def _queue_keys(self) -> list[str]:
        """The rollouts the queue walks: the Overview's current rows (its filter and order) when it
        has drawn some, else every served rollout with a session, in the picker's order."""
        overview = self.tab.overview
        shown = [r.key for r in overview.shown] if overview is not None else []
        catalog = self.tab.app.catalog
        keys = shown or catalog.keys()
        return [k for k in keys if (e := catalog.get(k)) is not None and e.session is not None and e.error is None]

    def _labelled(self, keys: list[str]) -> set[str]:
        """Those of ``keys`` with a label that says something (one read per session)."""
        catalog = self.tab.app.catalog
        documents: dict[Any, Any] = {}
        out = set()
        for k in keys:
            e = catalog.get(k)
            assert e is not None and e.session is not None
            path = outcomes_path(e.session)
            if path not in documents:
                try:
                    documents[path] = read_outcomes(path)["rollouts"]
                except InspectorError:
                    documents[path] = {}
            if says_something(documents[path].get(e.tag, {}).get("label")):
                out.add(k)
        return out

    def _queue_text(self) -> str:
        keys = self._queue_keys()
        return f"{len(self._labelled(keys))} of {len(keys)} labelled"

    # ------------------------------------------------------------------------------------------
    # Writing

    def set(self, **changes: Any) -> bool:
        """Save ``changes`` (success / progress / failure / note) as the open rollout's label."""
        entry, session = self._session()
        if entry is None or session is None:
            self.refresh()
            return False
        started = time.perf_counter()
        try:
            # only the served session's outcomes file (or its sidecar): the path comes from the catalog
            record = update_outcome(outcomes_path(session), entry.tag, changes, source="label", set_by="app")
        except (InspectorError, ValueError, OSError) as exc:
            self.status.content = error_card("label not saved", exc)
            return False
        self.last_saved = (entry.key, record, time.perf_counter() - started)
        self.refresh()
        return True

    def cycle_tag(self) -> bool:
        options = list(self.failure.options)
        current = (self._record or {}).get("failure") or NO_TAG
        following = options[(options.index(current) + 1) % len(options)] if current in options else options[0]
        return self.set(failure=None if following == NO_TAG else following)

    def open_next_unlabelled(self) -> bool:
        """Open the next rollout without a label after the open one (wrapping around)."""
        keys = self._queue_keys()
        labelled = self._labelled(keys)
        start = keys.index(self.tab.key) + 1 if self.tab.key in keys else 0
        for k in keys[start:] + keys[:start]:
            if k not in labelled and k != self.tab.key:
                overview = self.tab.overview
                if overview is not None and overview.visible:
                    overview.hide(start_frames=False)
                return self.tab.open(k)
        self.tab.client.add_notification("All labelled", self._queue_text(), auto_close_seconds=3.0)
        return False

    # ------------------------------------------------------------------------------------------
    # Wiring

    def _progress_setter(self, pct: float) -> Callable[[], bool]:
        return lambda: self.set(progress=pct)

    @staticmethod
    def _set_quietly(handle, value) -> None:
        if handle.value != value:
            handle.value = value

    def _wire(self) -> None:
        gui = self.tab.client.gui

        def user(fn):
            def cb(event) -> None:
                if event.client is not None and not self.tab.closed.is_set():
                    fn(event)
            return cb

        verdicts: dict[str, dict[str, Any]] = {"success": {"success": True}, "fail": {"success": False},
                    "clear": {"success": None, "progress": None, "failure": None, "note": ""}}
        self.verdict.on_click(user(lambda e: self.set(**verdicts[e.target.value])))
        self.progress.on_update(user(lambda e: self.set(progress=float(self.progress.value))))
        self.failure.on_update(user(lambda e: self.set(failure=None if e.target.value == NO_TAG else e.target.value)))
        self.note.on_update(user(lambda e: self.set(note=self.note.value)))
        self.next.on_click(user(lambda e: self.open_next_unlabelled()))
        actions: dict[str, Callable[[], bool]] = {"Label: success": lambda: self.set(success=True),
                   "Label: failure": lambda: self.set(success=False),
                   **{f"Label: progress {10 * k}%": self._progress_setter(10.0 * k) for k in range(1, 10)},
                   "Label: progress 100%": lambda: self.set(progress=100.0),
                   "Label: next failure tag": self.cycle_tag,
                   "Label: next unlabelled rollout": self.open_next_unlabelled}
        for label, key in LABEL_HOTKEYS.items():
            gui.add_command(label, hotkey=key).on_trigger(user(lambda e, a=actions[label]: a()))


def _status_html(shown: Any, sources: dict[str, Any], queue: str) -> str:
    """The outcome the tables use, where it comes from, the other sources, and the queue."""
    def one(record: Any) -> str:
        parts = []
        if record.get("success") is not None:
            parts.append("success" if record["success"] else "failure")
        if record.get("progress") is not None:
            parts.append(f"progress {record['progress']:.0f}%")
        if record.get("failure"):
            parts.append(record["failure"])
        return " · ".join(parts) or "—"

    head = "no outcome yet" if shown is None else f"{escape(one(shown))} <span style='color:#6b7280'>({shown['source']})</span>"
    others = [f"{s}: {escape(one(r))}" for s, r in sources.items() if shown is None or r is not shown]
    colour = "#2b8a3e" if shown and shown.get("success") else "#c92a2a" if shown and shown.get("success") is False else "#495057"
    return (f"<div class='inspector-label' data-labelled='{int(bool(sources.get('label')))}' "
            f"style='font-size:0.8rem;padding:0 0.2rem'><b style='color:{colour}'>{head}</b>"
            + (f"<div style='font-size:0.7rem;color:#6b7280'>{' · '.join(others)}</div>" if others else "")
            + f"<div class='inspector-label-queue' style='font-size:0.7rem'>{escape(queue)}</div></div>")
