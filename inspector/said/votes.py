"""Blind pairwise votes between rollouts of two sessions, kept in each session's ``votes.json``.

A vote compares two rollouts of different sessions (checkpoints) from the same start. It is
written into both sessions' files, so either session carries every comparison it took part in;
readers merge the files and count a vote once (by its ``id``). Several tabs or app processes may
vote at once: each write is an append under an exclusive ``fcntl.flock`` on
``<session>/.votes.lock``, the file replaced atomically (:func:`inspector._files.locked_update`),
so no vote is lost and no reader sees half a file. A file that exists but does not parse is never
overwritten, and a ``votes.json`` that is a symbolic link leading outside its session is neither
read nor written.

Layout::

    {"schema": "inspector.votes/1",
     "votes": [{"id": "<hex>", "time": "<ISO time>", "answer": "a" | "b" | "tie",
                "a": {"session": "<absolute session directory>", "name": "<session name>",
                      "rollout": "<tag>", "progress": 0..100 | null},
                "b": {...}, "note": "..."}]}

``answer`` says which side was better (``tie``: neither). ``progress`` is the evaluator's score of
how far that rollout got through the task [%], 0 to 100 as in the
outcome records (:mod:`inspector.outcomes`), when given.
"""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from .._files import json_bytes, locked_update, read_json, refuse_link_out
from ..errors import InspectorError

VOTES_FILE = "votes.json"
LOCK_FILE = ".votes.lock"
SCHEMA = "inspector.votes/1"
ANSWERS = ("a", "b", "tie")
MAX_NOTE_CHARS = 10_000


@dataclass(frozen=True)
class Side:
    """One rollout of a vote: its session directory (absolute), the session's name, its tag."""

    session: str
    name: str
    rollout: str
    progress: float | None = None

    def to_json(self) -> dict[str, Any]:
        return {"session": self.session, "name": self.name, "rollout": self.rollout, "progress": self.progress}


@dataclass(frozen=True)
class Vote:
    id: str
    time: str
    answer: str  # "a", "b" or "tie"
    a: Side
    b: Side
    note: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "time": self.time, "answer": self.answer, "a": self.a.to_json(),
                "b": self.b.to_json(), "note": self.note}


def votes_path(session_root: str | Path) -> Path:
    return Path(session_root) / VOTES_FILE


def read_votes(session_root: str | Path) -> list[Vote]:
    """The votes kept in a session (none when it has no ``votes.json``).

    Raises:
        InspectorError: the file exists but is not votes JSON; names the file and the first bad field.
    """
    path = votes_path(session_root)
    return [_parse_vote(entry, f"votes[{i}]", path) for i, entry in enumerate(_document(path)["votes"])]


def _checked_document(path: Path) -> dict[str, Any]:
    """:func:`_document`, every vote in it checked (what :func:`save_vote` changes)."""
    data = _document(path)
    for i, entry in enumerate(data["votes"]):
        _parse_vote(entry, f"votes[{i}]", path)
    return data


def _document(path: Path) -> dict[str, Any]:
    """The file's JSON with a ``votes`` list (an empty document when there is no file).

    Raises:
        InspectorError: the file leads outside its session, or is not an object with a list of votes.
    """
    refuse_link_out(path)
    if not os.path.lexists(path):
        return {"schema": SCHEMA, "votes": []}
    data = read_json(path)
    if not isinstance(data, dict) or not isinstance(data.get("votes", []), list):
        raise InspectorError(path, "votes: expected an object with a list of votes")
    data.setdefault("votes", [])
    return data


def _parse_vote(entry: Any, field: str, path: Path) -> Vote:
    def fail(where: str, expected: str, found: Any) -> InspectorError:
        shown = type(found).__name__ if isinstance(found, (dict, list)) else repr(found)[:40]
        return InspectorError(path, f"{where}: expected {expected}, found {shown}")

    if not isinstance(entry, dict):
        raise fail(field, "an object", entry)
    for key in ("id", "time"):
        if not isinstance(entry.get(key), str):
            raise fail(f"{field}.{key}", "a string", entry.get(key))
    if entry.get("answer") not in ANSWERS:
        raise fail(f"{field}.answer", " or ".join(map(repr, ANSWERS)), entry.get("answer"))
    if not isinstance(entry.get("note", ""), str):
        raise fail(f"{field}.note", "a string", entry.get("note"))
    sides = []
    for name in ("a", "b"):
        side = entry.get(name)
        if not isinstance(side, dict):
            raise fail(f"{field}.{name}", "an object", side)
        for key in ("session", "name", "rollout"):
            if not isinstance(side.get(key), str) or not side.get(key):
                raise fail(f"{field}.{name}.{key}", "a non-empty string", side.get(key))
        progress = side.get("progress")
        if progress is not None and (isinstance(progress, bool) or not isinstance(progress, (int, float))
                                     or not 0.0 <= progress <= 100.0):
            raise fail(f"{field}.{name}.progress", "a number from 0 to 100 or null", progress)
        sides.append(Side(side["session"], side["name"], side["rollout"],
                          None if progress is None else float(progress)))
    return Vote(entry["id"], entry["time"], entry["answer"], sides[0], sides[1], entry.get("note", ""))


def new_vote(a: Side, b: Side, answer: str, note: str = "") -> Vote:
    """A vote with a fresh id and the current time (UTC)."""
    if answer not in ANSWERS:
        raise ValueError(f"answer must be one of {ANSWERS} (got {answer!r})")
    for side in (a, b):
        if side.progress is not None and not (math.isfinite(side.progress) and 0.0 <= side.progress <= 100.0):
            raise ValueError(f"progress must be from 0 to 100 % (got {side.progress})")
    return Vote(uuid.uuid4().hex, datetime.now(timezone.utc).isoformat(timespec="milliseconds"), answer, a, b,
                str(note)[:MAX_NOTE_CHARS])


def save_vote(vote: Vote) -> None:
    """Append ``vote`` to the ``votes.json`` of both its sessions (once each, by id).

    Each file is changed under its own lock and replaced atomically; a file that does not parse
    is left as it is and raises before anything is written.
    """
    roots = sorted({Path(vote.a.session), Path(vote.b.session)})
    for root in roots:  # check every file first: a broken one refuses the vote everywhere
        read_votes(root)

    def append(data: dict[str, Any]) -> None:
        if all(v["id"] != vote.id for v in data["votes"]):
            data["votes"].append(vote.to_json())

    for root in roots:  # each re-read and re-checked under its lock: another process may have written since
        locked_update(votes_path(root), _checked_document, append, json_bytes, lock=root / LOCK_FILE)


def merged_votes(session_roots: Sequence[str | Path]) -> list[Vote]:
    """Every vote kept in any of the sessions, each once (by id), in time order.

    Raises:
        InspectorError: a session's ``votes.json`` is not votes JSON (the first such file).
    """
    votes, broken = readable_votes(session_roots)
    if broken:
        raise next(iter(broken.values()))
    return votes


def readable_votes(session_roots: Sequence[str | Path]) -> tuple[list[Vote], dict[int, InspectorError]]:
    """:func:`merged_votes` of the sessions whose file reads, and the error of each that does not
    (by its index in ``session_roots``): one broken file leaves the others' votes counted."""
    seen: dict[str, Vote] = {}
    broken: dict[int, InspectorError] = {}
    for i, root in enumerate(session_roots):
        try:
            votes = read_votes(root)
        except InspectorError as exc:
            broken[i] = exc
            continue
        for vote in votes:
            seen.setdefault(vote.id, vote)
    return sorted(seen.values(), key=lambda v: (v.time, v.id)), broken
