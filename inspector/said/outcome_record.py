"""The outcome record, its fields' checks, and the rule that picks the outcome tables use."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from typing import Any, Literal, TypedDict

from ..schema import shown

SCHEMA = "inspector.outcomes/1"
Source = Literal["label", "file", "sim", "recording"]
SOURCES: tuple[Source, ...] = ("label", "file", "sim", "recording")
STORED_SOURCES: tuple[Source, ...] = ("label", "file")
# A person over a file (a judge or a run sheet) over what the data itself says.
PRECEDENCE: tuple[Source, ...] = ("label", "file", "sim", "recording")
# How a rollout failed: the taxonomy the app cycles through with T. A session adds its own in
# ``failure_tags`` (``inspector outcomes import --add-tag NAME``).
FAILURE_TAGS: tuple[str, ...] = ("missed_grasp", "wrong_object", "dropped", "collision", "timeout", "frozen",
                                 "other")
TAG_PATTERN = re.compile(r"^[a-z][a-z0-9_]{0,39}$")
MAX_NOTE_CHARS = 10_000
FIELDS = ("success", "progress", "failure", "note")
RECORDING_SUCCESS, RECORDING_REWARD = "next.success", "next.reward"


class OutcomeRecord(TypedDict):
    """One source's outcome of one rollout."""

    success: bool | None  # did the task succeed (None: not said)
    progress: float | None  # how far the task got [0..100 %]
    failure: str | None  # how it failed: a tag of FAILURE_TAGS or the session's own
    note: str
    source: Source
    set_at: str | None  # ISO 8601 time (UTC) it was set, where known
    set_by: str | None  # where from: "app", the imported file's name, eval_info.json, a dataset


class OutcomesDocument(TypedDict):
    schema: str
    failure_tags: list[str]
    rollouts: dict[str, dict[str, OutcomeRecord]]


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def make_record(source: Source, *, success: bool | None = None, progress: float | None = None,
                failure: str | None = None, note: str = "", set_at: str | None = None,
                set_by: str | None = None) -> OutcomeRecord:
    return {"success": success, "progress": progress, "failure": failure, "note": note, "source": source,
            "set_at": set_at, "set_by": set_by}


def says_something(record: Mapping[str, Any] | None) -> bool:
    """Whether a record decides anything a table shows (a note alone does not)."""
    return bool(record) and any(record.get(k) is not None for k in ("success", "progress", "failure"))  # type: ignore[union-attr]


def effective_outcome(sources: Mapping[str, OutcomeRecord], prefer: str | None = None) -> OutcomeRecord | None:
    """The outcome tables use: ``sources[prefer]`` when ``prefer`` is given (None when that source
    has nothing for the rollout), else the first source in :data:`PRECEDENCE` whose record says
    anything (success, progress or a failure tag)."""
    if prefer is not None:
        record = sources.get(prefer)
        return record if says_something(record) else None
    return next((sources[s] for s in PRECEDENCE if says_something(sources.get(s))), None)


# ----------------------------------------------------------------------------------------------
# Checking values (from the app, an imported file or a stored document)


def check_fields(values: Mapping[str, Any], known_tags: Sequence[str] = FAILURE_TAGS) -> dict[str, Any]:
    """``values`` (a subset of success / progress / failure / note) checked: the same keys, as
    stored. A progress given as a whole number becomes a float.

    Raises:
        ValueError: ``"<field>: <what is wrong>"`` for the first bad field.
    """
    out: dict[str, Any] = {}
    for key, value in values.items():
        if key == "success":
            if value is not None and type(value) is not bool:
                raise ValueError(f"success: expected true, false or null, found {shown(value)}")
        elif key == "progress":
            if value is not None:
                if type(value) not in (int, float) or not math.isfinite(value):
                    raise ValueError(f"progress: expected a number 0..100 or null, found {shown(value)}")
                if not 0 <= value <= 100:
                    raise ValueError(f"progress: expected 0..100 [%], found {shown(value)}")
                value = float(value)
        elif key == "failure":
            if value is not None:
                if not isinstance(value, str):
                    raise ValueError(f"failure: expected a tag or null, found {shown(value)}")
                if value not in known_tags:
                    raise ValueError(f"failure: unknown tag {shown(value)}; known: {', '.join(known_tags)}")
        elif key == "note":
            if not isinstance(value, str):
                raise ValueError(f"note: expected a string, found {shown(value)}")
            value = value[:MAX_NOTE_CHARS]
        else:
            raise ValueError(f"{shown(key)}: not an outcome field (fields: {', '.join(FIELDS)})")
        out[key] = value
    return out


