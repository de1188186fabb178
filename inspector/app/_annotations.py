"""Flags and notes per rollout and per chunk, kept in the session's ``annotations.json``.

Several tabs (or several app processes) may write at once, so every change is a read-modify-write
under an exclusive ``fcntl.flock`` on ``<session>/.annotations.lock``, and the file is replaced
atomically (``write_json_atomic``): concurrent edits of different entries all survive, and a
reader never sees half a file. A file that exists but does not parse is never overwritten.

Layout::

    {"schema": "inspector.annotations/1",
     "rollouts": {"<tag>": {"flag": true, "note": "...", "updated": "<ISO time>",
                            "chunks": {"12": {"flag": true, "note": "..."}}}}}
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ..errors import InspectorError
from ..session import ANNOTATIONS_FILE, write_json_atomic

SCHEMA = "inspector.annotations/1"
LOCK_FILE = ".annotations.lock"
MAX_NOTE_CHARS = 10_000


@contextlib.contextmanager
def _locked(session_root: Path) -> Iterator[None]:
    fd = os.open(session_root / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def read_annotations(session_root: str | Path) -> dict[str, Any]:
    """The session's annotations (an empty document when the file does not exist yet).

    Raises:
        InspectorError: the file exists but is not valid annotations JSON.
    """
    path = Path(session_root) / ANNOTATIONS_FILE
    if not path.is_file():
        return {"schema": SCHEMA, "rollouts": {}}
    try:
        data = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InspectorError(path, f"invalid JSON ({exc}); not overwriting it") from None
    if not isinstance(data, dict) or not isinstance(data.get("rollouts", {}), dict):
        raise InspectorError(path, "rollouts: expected an object; not overwriting it")
    data.setdefault("schema", SCHEMA)
    data.setdefault("rollouts", {})
    return data


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
    with _locked(root):
        data = read_annotations(root)
        entry = data["rollouts"].setdefault(tag, {})
        target = entry if chunk is None else entry.setdefault("chunks", {}).setdefault(str(int(chunk)), {})
        if flag is not None:
            target["flag"] = bool(flag)
        if note is not None:
            target["note"] = note
        if chunk is not None and not target.get("flag") and not target.get("note"):
            entry["chunks"].pop(str(int(chunk)), None)  # an unflagged, empty chunk needs no entry
        entry["updated"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
        write_json_atomic(root / ANNOTATIONS_FILE, data)
        return entry
