"""Reading and writing a session's ``outcomes.json`` (or a raw directory's sidecar): locked,
atomic, and never overwriting a file that does not parse (:func:`inspector._files.locked_update`).

The records and what each field may hold: :mod:`.outcome_record`; where outcomes come from and
how they are imported: :mod:`inspector.outcomes`."""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from .._files import locked_update, parse_json, read_json_bytes, refuse_link_out
from ..data.session import OUTCOMES_FILE, OUTCOMES_SIDECAR_SUFFIX
from ..errors import InspectorError
from ..schema import json_text, mismatch, shown
from .outcome_record import (
    FAILURE_TAGS,
    FIELDS,
    SCHEMA,
    STORED_SOURCES,
    TAG_PATTERN,
    OutcomeRecord,
    OutcomesDocument,
    Source,
    check_fields,
    make_record,
    now_iso,
    says_something,
)

if TYPE_CHECKING:
    from ..data.session import Session

SIDECAR_SUFFIX = OUTCOMES_SIDECAR_SUFFIX

# The bytes of each outcomes file last found valid here (read or written), by path. A label is a
# read-modify-write of the whole file and the app reads it again to show the label and the queue:
# validating 1,000 records each time cost ~0.2 s a key press. Compared by content, so a file that
# another process changed is validated again.
_valid_bytes: dict[Path, bytes] = {}
_valid_lock = threading.Lock()


def sidecar_path(raw_dir: str | Path) -> Path:
    """Where the outcomes of a raw directory imported in memory live: beside it, never inside."""
    raw = Path(raw_dir).resolve()
    return raw.parent / f"{raw.name}{SIDECAR_SUFFIX}"


def outcomes_path(session: Session) -> Path:
    """The outcomes file of a loaded session (its sidecar when it was imported in memory)."""
    sidecar = getattr(session, "outcomes_file", None)
    return Path(sidecar) if sidecar is not None else Path(session.root) / OUTCOMES_FILE


def empty_document() -> OutcomesDocument:
    return {"schema": SCHEMA, "failure_tags": [], "rollouts": {}}


def read_outcomes(path: str | Path) -> OutcomesDocument:
    """The outcomes document at ``path`` (empty when the file does not exist yet).

    Raises:
        InspectorError: the file exists but is not a valid outcomes document (naming the field);
            it is never overwritten.
    """
    path = Path(path)
    refuse_link_out(path)
    if not os.path.lexists(path):
        return empty_document()
    try:
        raw = read_json_bytes(path)
        with _valid_lock:
            known_valid = _valid_bytes.get(path) == raw
        if known_valid:
            return cast(OutcomesDocument, _with_defaults(json.loads(raw)))
        data = parse_json(path, raw)
        problem = _document_problem(data)
    except InspectorError as exc:
        raise InspectorError(path, f"{exc.what}; not overwriting it") from None
    if problem:
        raise InspectorError(path, f"{problem}; not overwriting it")
    _remember_valid(path, raw)
    return cast(OutcomesDocument, _with_defaults(data))


def _with_defaults(data: dict[str, Any]) -> dict[str, Any]:
    """A valid document with the keys it may leave out (a file written by hand or by a script)."""
    data.setdefault("failure_tags", [])
    data.setdefault("rollouts", {})
    return data


def _remember_valid(path: Path, raw: bytes) -> None:
    with _valid_lock:
        _valid_bytes[path] = raw


def _encoder(path: Path) -> Callable[[OutcomesDocument], bytes]:
    """The bytes of a changed document (valid: read valid, then changed by checked fields),
    remembered as valid so that the next read of them skips the check."""
    def encode(document: OutcomesDocument) -> bytes:
        raw = encode_document(document)
        _remember_valid(path, raw)  # before the write: what it holds is valid whether or not it lands
        return raw
    return encode


def encode_document(document: Mapping[str, Any]) -> bytes:
    """The file's text: one rollout a line (easy to read and to diff), each line written by the
    json module's C encoder (an indented document goes through its pure-Python one, ~20 times
    slower: 0.1 s for 1,000 labelled rollouts)."""
    head = [f"  {json_text(k)}: {json_text(v)}" for k, v in document.items() if k != "rollouts"]
    rollouts = document.get("rollouts", {})
    lines = ",\n".join(f"    {json_text(tag)}: {json_text(by_source)}"
                        for tag, by_source in rollouts.items())
    head.append('  "rollouts": {' + (f"\n{lines}\n  }}" if rollouts else "}"))
    return ("{\n" + ",\n".join(head) + "\n}\n").encode()


def _document_problem(data: Any) -> str | None:
    if not isinstance(data, dict):
        return f"(top level): expected an object, found {shown(data)}"
    if data.get("schema") != SCHEMA:
        return f"schema: expected {SCHEMA!r}, found {shown(data.get('schema'))}"
    tags = data.get("failure_tags", [])
    if not isinstance(tags, list) or not all(isinstance(t, str) and TAG_PATTERN.match(t) for t in tags):
        return "failure_tags: expected a list of tags (lower case, digits, _)"
    rollouts = data.get("rollouts", {})
    if not isinstance(rollouts, dict):
        return f"rollouts: expected an object, found {shown(rollouts)}"
    known = (*FAILURE_TAGS, *tags)
    for tag, by_source in rollouts.items():
        if not isinstance(by_source, dict):
            return f"rollouts.{tag}: expected an object, found {shown(by_source)}"
        for source, record in by_source.items():
            where = f"rollouts.{tag}.{source}"
            if source not in STORED_SOURCES:
                return f"{where}: not a stored source ({', '.join(STORED_SOURCES)})"
            problem = mismatch(record, OutcomeRecord, where)
            if problem:
                return problem
            try:
                check_fields({k: record[k] for k in FIELDS}, known)
            except ValueError as exc:
                return f"{where}.{exc}"
            if record["source"] != source:
                return f"{where}.source: expected {source!r}, found {shown(record['source'])}"
    return None


def known_failure_tags(document: Mapping[str, Any]) -> tuple[str, ...]:
    return (*FAILURE_TAGS, *(t for t in document.get("failure_tags", []) if t not in FAILURE_TAGS))


def update_outcome(path: str | Path, tag: str, changes: Mapping[str, Any], *, source: Source = "label",
                   set_by: str | None = "app") -> OutcomeRecord | None:
    """Change some fields of one rollout's ``source`` record (a label, by default); the fields
    not named keep what is on disk now, as do all other rollouts and sources.

    ``changes`` may set ``success`` / ``progress`` / ``failure`` to None to clear them; a record
    left saying nothing and with no note is removed.

    Returns:
        The record after the change (None: removed).

    Raises:
        ValueError: a bad field (``"<field>: <what>"``).
        InspectorError: the file on disk is not a valid outcomes document (left as it is).
    """
    path = Path(path)

    def change(document: OutcomesDocument) -> OutcomeRecord | None:
        checked = check_fields(changes, known_failure_tags(document))
        by_source = document["rollouts"].setdefault(tag, {})
        record = cast(dict[str, Any], by_source.get(source) or make_record(source))
        record.update(checked, set_at=now_iso(), set_by=set_by)
        kept: OutcomeRecord | None = cast(OutcomeRecord, record)
        if not says_something(record) and not record["note"]:
            by_source.pop(source, None)
            kept = None
        else:
            by_source[source] = cast(OutcomeRecord, record)
        if not by_source:
            document["rollouts"].pop(tag, None)
        return kept

    return locked_update(path, read_outcomes, change, _encoder(path))


def store_records(path: str | Path, records: Mapping[str, Mapping[str, Any]], *, source: Source,
                  set_by: str | None, add_tags: Sequence[str] = ()) -> None:
    """Replace the ``source`` record of each rollout in ``records`` (tag -> fields), in one write.

    Raises:
        ValueError: a bad field or tag.
        InspectorError: the file on disk is not a valid outcomes document.
    """
    path = Path(path)
    refuse_link_out(path)
    for t in add_tags:
        if not TAG_PATTERN.match(t):
            raise ValueError(f"failure tag {t!r}: lower case letters, digits and _, starting with a letter")

    def change(document: OutcomesDocument) -> None:
        document["failure_tags"] += [t for t in add_tags if t not in known_failure_tags(document)]
        known = known_failure_tags(document)
        at = now_iso()
        for tag, fields in records.items():
            record = make_record(source, set_at=at, set_by=set_by)
            cast(dict[str, Any], record).update(check_fields(fields, known))
            document["rollouts"].setdefault(tag, {})[source] = record

    locked_update(path, read_outcomes, change, _encoder(path))
