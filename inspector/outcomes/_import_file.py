"""Outcome files a judge, a run sheet or a script wrote (``inspector outcomes import FILE PATH``):
JSON lines or CSV, one row per rollout (or per episode)."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from ..errors import InspectorError
from ..schema import shown
from ._record import FAILURE_TAGS, check_fields

if TYPE_CHECKING:
    from ..data.session import Rollout



@dataclass
class FileRow:
    """One row of an outcomes file: how it names its rollout(s), and its fields."""

    line: int
    tag: str | None
    episode: int | None
    start_frame: int | None
    fields: dict[str, Any]

    def names(self) -> str:
        if self.tag is not None:
            return f"tag {self.tag!r}"
        return f"episode {self.episode}" + ("" if self.start_frame is None else f" start_frame {self.start_frame}")


_KEYS = ("tag", "episode", "start_frame")
_MAX_FILE_BYTES = 64 << 20


def read_outcome_file(file: str | Path, known_tags: Sequence[str] = FAILURE_TAGS) -> list[FileRow]:
    """The rows of a JSON-lines (one object per line) or CSV (a header row) outcomes file, each
    naming its rollout by ``tag`` or by ``episode`` (and optionally ``start_frame``), with
    success / progress / failure / note. CSV cells: success ``true/false/1/0/yes/no`` or empty,
    progress a number or empty.

    Raises:
        InspectorError: ``<file>: line N: <field>: <what is wrong>`` for the first bad row.
    """
    path = Path(file)
    try:
        if path.stat().st_size > _MAX_FILE_BYTES:
            raise InspectorError(path, f"larger than {_MAX_FILE_BYTES >> 20} MiB")
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InspectorError(path, exc.strerror or "cannot read") from None
    except UnicodeDecodeError:
        raise InspectorError(path, "not UTF-8 text") from None
    first = next((line for line in text.splitlines() if line.strip()), "")
    raw = _json_lines(path, text) if first.lstrip().startswith("{") else _csv_rows(path, text)
    rows = []
    for line, values in raw:
        try:
            rows.append(_file_row(line, values, known_tags))
        except ValueError as exc:
            raise InspectorError(path, f"line {line}: {exc}") from None
    if not rows:
        raise InspectorError(path, "no rows")
    return rows


def _json_lines(path: Path, text: str) -> list[tuple[int, dict[str, Any]]]:
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            value = json.loads(line, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
        except ValueError as exc:
            raise InspectorError(path, f"line {n}: not JSON ({exc})") from None
        if not isinstance(value, dict):
            raise InspectorError(path, f"line {n}: expected an object, found {shown(value)}")
        out.append((n, value))
    return out


def _csv_rows(path: Path, text: str) -> list[tuple[int, dict[str, Any]]]:
    reader = csv.DictReader(io.StringIO(text))
    if not reader.fieldnames:
        raise InspectorError(path, "no header row")
    out = []
    for values in reader:
        if None in values:
            raise InspectorError(path, f"line {reader.line_num}: more cells than the header has")
        cells = {k.strip(): (v or "").strip() for k, v in values.items()}
        try:
            out.append((reader.line_num, _typed_cells(cells)))
        except ValueError as exc:
            raise InspectorError(path, f"line {reader.line_num}: {exc}") from None
    return out


_TRUE, _FALSE = {"true", "1", "yes", "success"}, {"false", "0", "no", "failure", "fail"}


def _typed_cells(cells: dict[str, str]) -> dict[str, Any]:
    """CSV cells as JSON would have them (an empty cell is null)."""
    out: dict[str, Any] = {}
    for key, cell in cells.items():
        if cell == "":
            out[key] = None if key != "note" else ""
        elif key == "success":
            low = cell.lower()
            if low not in _TRUE | _FALSE:
                raise ValueError(f"success: expected true/false/1/0/yes/no, found {shown(cell)}")
            out[key] = low in _TRUE
        elif key in ("progress", "episode", "start_frame"):
            try:
                number = float(cell)
            except ValueError:
                raise ValueError(f"{key}: expected a number, found {shown(cell)}") from None
            out[key] = int(number) if key != "progress" and number.is_integer() else number
        else:
            out[key] = cell
    return out


def _file_row(line: int, values: dict[str, Any], known_tags: Sequence[str]) -> FileRow:
    fields = {k: v for k, v in values.items() if k not in _KEYS}
    tag, episode, start = values.get("tag"), values.get("episode"), values.get("start_frame")
    if tag is not None and not isinstance(tag, str):
        raise ValueError(f"tag: expected a string, found {shown(tag)}")
    for key, number in (("episode", episode), ("start_frame", start)):
        if number is not None and (type(number) is not int or number < 0):
            raise ValueError(f"{key}: expected a whole number >= 0, found {shown(number)}")
    if tag is None and episode is None:
        raise ValueError("no 'tag' or 'episode' to match a rollout by")
    fields.setdefault("note", "")
    return FileRow(line, tag, episode, start, check_fields(fields, known_tags))


@dataclass
class ImportResult:
    matched: dict[str, dict[str, Any]]  # tag -> fields
    unmatched: list[FileRow]


def match_rows(rows: Sequence[FileRow], rollouts: Mapping[str, Rollout]) -> ImportResult:
    """Each row's rollouts: the one with its tag, or every rollout of its episode (at its start
    frame, when given). A row naming a rollout more precisely wins over one naming it less (tag >
    episode and start frame > episode); among equals, the later row wins."""
    by_episode: dict[int, list[str]] = {}
    for tag, r in sorted(rollouts.items()):
        if r.episode_index is not None:
            by_episode.setdefault(r.episode_index, []).append(tag)
    matched: dict[str, dict[str, Any]] = {}
    unmatched = []
    # the more specific a row, the later it applies: a tag beats an episode at a start frame,
    # which beats a whole episode
    for row in sorted(rows, key=lambda r: (r.tag is not None, r.start_frame is not None)):
        if row.tag is not None:
            tags = [row.tag] if row.tag in rollouts else []
        else:
            tags = [t for t in by_episode.get(cast(int, row.episode), [])
                    if row.start_frame is None or rollouts[t].start_frame == row.start_frame]
        if not tags:
            unmatched.append(row)
        for t in tags:
            matched[t] = row.fields
    return ImportResult(matched, unmatched)
