"""Flags and notes per rollout and per chunk, kept in the session's ``annotations.json``.

Several tabs (or several app processes) may write at once, so every change is a read-modify-write
under an exclusive ``fcntl.flock`` on ``<session>/.annotations.lock``, and the file is replaced
atomically (:func:`inspector._files.locked_update`): concurrent edits of different entries all
survive, and a reader never sees half a file. A file that exists but does not parse is never overwritten. A
writer killed mid-write leaves the previous file intact and at most a ``.annotations.json.*.tmp``
behind; the next writer, holding the lock, removes it. An ``annotations.json`` that is a symbolic
link leading outside the session directory is neither read nor written, and the lock file is
never followed through a link.

Layout::

    {"schema": "inspector.annotations/1",
     "rollouts": {"<tag>": {"flag": true, "note": "...", "updated": "<ISO time>",
                            "chunks": {"12": {"flag": true, "note": "..."}}}}}
"""

from __future__ import annotations

import os
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from .._files import json_bytes, locked_update, read_json, refuse_link_out
from ..data.session import ANNOTATIONS_FILE
from ..errors import InspectorError

SCHEMA = "inspector.annotations/1"
LOCK_FILE = ".annotations.lock"
# How a refused link's error names where it may lead: the session directory, which the app serves.
OUTSIDE = "the served roots"
MAX_NOTE_CHARS = 10_000


def annotations_path(session_root: str | Path) -> Path:
    """``<session_root>/annotations.json``, checked not to lead outside the session directory.

    Raises:
        InspectorError: it is a symbolic link that resolves outside ``session_root``.
    """
    root = Path(session_root)
    path = root / ANNOTATIONS_FILE
    refuse_link_out(path, root, outside=OUTSIDE)
    return path


def read_annotations(session_root: str | Path) -> dict[str, Any]:
    """The session's annotations (an empty document when the file does not exist yet).

    Everything in a file that exists is checked before use (it may have been edited by hand, or
    be hostile): JSON the standard allows, within the parser's depth and integer limits, and the
    layout above (extra keys are kept). A file that fails is reported and never overwritten.

    Raises:
        InspectorError: the file exists but is not valid annotations JSON (or not a file), or
            leads outside the session directory.
    """
    path = annotations_path(session_root)
    if not os.path.lexists(path):
        return {"schema": SCHEMA, "rollouts": {}}
    try:
        data = read_json(path)
        _check_layout(data)
    except InspectorError as exc:
        raise InspectorError(path, f"{exc.what}; not overwriting it") from None
    data.setdefault("schema", SCHEMA)
    data.setdefault("rollouts", {})
    return data


def _read_path(path: Path) -> dict[str, Any]:
    """:func:`read_annotations` of the session holding ``path`` (what :func:`locked_update` reads)."""
    return read_annotations(path.parent)


def _check_layout(data: Any) -> None:
    """Raise an :class:`InspectorError` naming the first field that breaks the layout."""
    def fail(field: str, expected: str, found: Any) -> None:
        shown = type(found).__name__ if isinstance(found, (dict, list)) else repr(found)[:40]
        raise InspectorError(ANNOTATIONS_FILE, f"{field}: expected {expected}, found {shown}")

    def check_entry(entry: Any, field: str) -> None:
        if not isinstance(entry, dict):
            fail(field, "an object", entry)
        for key, kind, name in (("flag", bool, "true or false"), ("note", str, "a string"),
                                ("updated", str, "a string")):
            if key in entry and not isinstance(entry[key], kind):
                fail(f"{field}.{key}", name, entry[key])

    if not isinstance(data, dict):
        fail("(top level)", "an object", data)
    rollouts = data.get("rollouts", {})
    if not isinstance(rollouts, dict):
        fail("rollouts", "an object", rollouts)
    for tag, entry in rollouts.items():
        check_entry(entry, f"rollouts.{tag}")
        chunks = entry.get("chunks", {})
        if not isinstance(chunks, dict):
            fail(f"rollouts.{tag}.chunks", "an object", chunks)
        for chunk, chunk_entry in chunks.items():
            if not (chunk.isascii() and chunk.isdigit() and len(chunk) <= 9):
                fail(f"rollouts.{tag}.chunks", "chunk indexes as keys", chunk)
            check_entry(chunk_entry, f"rollouts.{tag}.chunks.{chunk}")


def rollout_annotations(session_root: str | Path, tag: str) -> dict[str, Any]:
    """``{"flag": bool, "note": str, "chunks": {str(chunk): {...}}}`` of one rollout (empty if none)."""
    entry = read_annotations(session_root)["rollouts"].get(tag, {})
    return entry if isinstance(entry, dict) else {}


def update_annotation(session_root: str | Path, tag: str, *, chunk: int | None = None,
                      flag: bool | None = None, note: str | None = None) -> dict[str, Any]:
    """Set the flag and/or note of a rollout (``chunk=None``) or of one of its chunks.

    Only the fields passed change; everything else in the file is kept as it is on disk now.

    Args:
        session_root: the session directory (from the loaded session, never from a browser).
        tag: the rollout's tag (a key of the loaded session's rollouts).
        chunk: chunk index, or None for the rollout itself.
        flag, note: new values, or None to leave as is.

    Returns:
        The rollout's entry after the update.
    """
    root = Path(session_root)
    if note is not None:
        note = str(note)[:MAX_NOTE_CHARS]

    def change(data: dict[str, Any]) -> dict[str, Any]:
        entry: dict[str, Any] = data["rollouts"].setdefault(tag, {})
        target = entry if chunk is None else entry.setdefault("chunks", {}).setdefault(str(int(chunk)), {})
        if flag is not None:
            target["flag"] = bool(flag)
        if note is not None:
            target["note"] = note
        if chunk is not None and not target.get("flag") and not target.get("note"):
            entry["chunks"].pop(str(int(chunk)), None)  # an unflagged, empty chunk needs no entry
        entry["updated"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
        return entry

    return locked_update(annotations_path(root), _read_path, change, json_bytes, lock=root / LOCK_FILE,
                         outside=OUTSIDE)
