"""One tab's Notes folder: a flag and a note for the open rollout and for each of its chunks, kept
in the served session's ``annotations.json`` (:mod:`inspector.said.annotations`); a dataset's
episodes have none (the dataset is never written to).

A part of :class:`~._state.TabState` (which inherits it): it meets the rest of the tab only
through the attributes declared below.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from ..errors import InspectorError
from ..said.annotations import rollout_annotations, update_annotation
from ._cards import error_card, esc
from ._catalog import Loaded
from ._host import AppHost
from ._panels import ControlPanel

NOTES_NEED_A_SESSION = ("<div style='font-size:0.75rem;color:#6b7280'>Notes are kept in a session's "
                        "annotations.json; a dataset's episodes have none (the dataset is never written to)."
                        "</div>")


class TabNotes:
    """Load, show and save the Notes controls' flags and notes."""

    # What the notes use of their tab (:class:`~._state.TabState` sets them).
    app: AppHost
    lock: threading.RLock
    key: str | None
    loaded: Loaded | None
    controls: ControlPanel
    _notes: dict[str, Any]
    _shown_chunk: int | None

    if TYPE_CHECKING:
        @property
        def chunk(self) -> int: ...

        def _show_time(self, source=None) -> None: ...

        def _notify(self, title: str, body: str, color: str | None = None) -> None: ...

        @staticmethod
        def _set_quietly(handle, value) -> None: ...

    def _load_notes(self) -> None:
        c = self.controls
        self._notes = {}
        c.notes_info.content = ""
        entry = self.app.catalog.get(self.key) if self.key else None
        if entry is not None and entry.session is None:
            c.notes_info.content = NOTES_NEED_A_SESSION
        elif entry is not None:
            assert entry.session is not None  # the branch above took entries without a session
            try:
                self._notes = rollout_annotations(entry.session.root, entry.tag)
            except InspectorError as exc:
                c.notes_info.content = error_card("annotations.json is unreadable", exc)
        self._set_quietly(c.flag_rollout, bool(self._notes.get("flag", False)))
        self._set_quietly(c.note_rollout, str(self._notes.get("note", "")))
        self._shown_chunk = None

    def _show_chunk_notes(self, chunk: int) -> None:
        c = self.controls
        entry = (self._notes.get("chunks") or {}).get(str(chunk), {})
        c.flag_chunk.label = f"Flag chunk {chunk}"
        self._set_quietly(c.flag_chunk, bool(entry.get("flag", False)))
        self._set_quietly(c.note_chunk, str(entry.get("note", "")))
        flagged = sorted(int(k) for k, v in (self._notes.get("chunks") or {}).items() if v.get("flag"))
        if flagged:
            c.notes_info.content = (f"<div style='font-size:0.75rem'>flagged chunks: "
                                    f"{esc(', '.join(map(str, flagged)))}</div>")

    def save_notes(self, rollout_flag: bool | None = None, rollout_note: str | None = None,
                   chunk_flag: bool | None = None, chunk_note: str | None = None) -> bool:
        """Write the rollout's and the current chunk's flag/note to the session's annotations.json.

        Arguments left None are taken from the Notes controls. Returns True when written.
        """
        with self.lock:
            entry = self.app.catalog.get(self.key) if self.key else None
            if entry is None or self.loaded is None:
                return False
            c = self.controls
            if entry.session is None:  # a dataset episode: the dataset is never written to
                c.notes_info.content = NOTES_NEED_A_SESSION
                return False
            chunk = self.chunk
            try:
                # Only ever <served session>/annotations.json (the root comes from the catalog).
                if not self.app.sources.serves(entry.session.root):
                    raise InspectorError(entry.session.root, "not a served session; notes not written")
                update_annotation(entry.session.root, entry.tag,
                                  flag=c.flag_rollout.value if rollout_flag is None else rollout_flag,
                                  note=c.note_rollout.value if rollout_note is None else rollout_note)
                self._notes = update_annotation(
                    entry.session.root, entry.tag, chunk=chunk,
                    flag=c.flag_chunk.value if chunk_flag is None else chunk_flag,
                    note=c.note_chunk.value if chunk_note is None else chunk_note)
            except (InspectorError, OSError) as exc:
                c.notes_info.content = error_card("notes not saved", exc)
                return False
            self._shown_chunk = None
            self._show_time()
            self._notify("Notes saved", f"{entry.tag}, chunk {chunk} → annotations.json")
            return True
