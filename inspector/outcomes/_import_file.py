"""Outcome files a judge, a run sheet or a script wrote (``inspector outcomes import FILE PATH``):
JSON lines or CSV, one row per rollout (or per episode)."""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from .._files import read_regular_file
from ..data.session import parse_json_text
from ..errors import InspectorError
from ..said.outcome_record import FAILURE_TAGS, check_fields
from ..schema import MAX_WHOLE, shown, whole_problem

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
MAX_FILE_BYTES = 64 << 20
# The longest CSV cell read [characters]: the csv module's own field limit (a note is kept to its
# first 10,000 characters anyway). A longer cell is one error naming its line and column.
MAX_CELL_CHARS = 131_072


def read_outcome_file(file: str | Path, known_tags: Sequence[str] = FAILURE_TAGS) -> list[FileRow]:
    """The rows of a JSON-lines (one object per line) or CSV (a header row) outcomes file, each
    naming its rollout by ``tag`` or by ``episode`` (and optionally ``start_frame``), with
    success / progress / failure / note. CSV cells: success ``true/false/1/0/yes/no`` or empty,
    progress a number or empty.

    Raises:
        InspectorError: ``<file>: line N: <field>: <what is wrong>`` for the first bad row.
    """
    return list(iter_outcome_file(file, known_tags))


def iter_outcome_file(file: str | Path, known_tags: Sequence[str] = FAILURE_TAGS) -> Iterator[FileRow]:
    """:func:`read_outcome_file`'s rows one at a time, each parsed as it is reached: a file of
    millions of short rows is never held as millions of objects (:func:`match_rows` keeps what
    matches). The file's text is held (at most ``MAX_FILE_BYTES``); a bad row raises when reached.
    """
    path = Path(file)
    raw = read_regular_file(path, MAX_FILE_BYTES, "outcomes file")  # a FIFO or /dev/zero: refused unread
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InspectorError(path, f"not UTF-8 text (byte {exc.start:,})") from None
    del raw
    first = next((line for line in _lines(text) if line.strip()), "")
    parsed = _json_lines(path, text) if first.lstrip().startswith("{") else _csv_rows(path, text)
    any_rows = False
    for line, values in parsed:
        try:
            yield _file_row(line, values, known_tags)
        except ValueError as exc:
            raise InspectorError(path, f"line {line}: {exc}") from None
        any_rows = True
    if not any_rows:
        raise InspectorError(path, "no rows")


# What str.splitlines() splits at, to walk the lines without a list of them all.
_LINE_END = re.compile(r"\r\n|[\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029]")


def _lines(text: str) -> Iterator[str]:
    """``text.splitlines()``, one line at a time."""
    start = 0
    for end in _LINE_END.finditer(text):
        yield text[start:end.start()]
        start = end.end()
    if start < len(text):
        yield text[start:]


def _json_lines(path: Path, text: str) -> Iterator[tuple[int, dict[str, Any]]]:
    for n, line in enumerate(_lines(text), 1):
        if not line.strip():
            continue
        value = parse_json_text(path, line, f"line {n}")  # nesting, NaN and huge integers named by line
        if not isinstance(value, dict):
            raise InspectorError(path, f"line {n}: expected an object, found {shown(value)}")
        yield n, value


def _csv_rows(path: Path, text: str) -> Iterator[tuple[int, dict[str, Any]]]:
    reader = csv.reader(io.StringIO(text))
    records = _csv_records(path, text, reader)
    header = next(records, None)
    if not header or not any(h.strip() for h in header):
        raise InspectorError(path, "no header row")
    names = [h.strip() for h in header]
    for record in records:
        if not record:  # a blank line
            continue
        if len(record) > len(names):
            raise InspectorError(path, f"line {reader.line_num}: more cells than the header has")
        cells = {k: v.strip() for k, v in zip(names, record + [""] * (len(names) - len(record)))}
        try:
            typed = _typed_cells(cells)
        except ValueError as exc:
            raise InspectorError(path, f"line {reader.line_num}: {exc}") from None
        yield reader.line_num, typed


def _csv_records(path: Path, text: str, reader: Iterator[list[str]]) -> Iterator[list[str]]:
    """The reader's records, each cell at most :data:`MAX_CELL_CHARS` long; the csv module's own
    errors (a cell past its field limit, a NUL) as one line naming the line, and the column."""
    line = 0  # the last line of the record before
    header: list[str] = []

    def named(column: int) -> str:
        return f"column {column}" + (f" ({shown(header[column - 1].strip())})" if column <= len(header) else "")

    while True:
        try:
            record = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            column = _long_cell_column(text, line)
            if column is not None:
                raise InspectorError(path, f"line {line + 1}, {named(column)}: a cell longer than "
                                           f"{MAX_CELL_CHARS:,} characters") from None
            if "field limit" in str(exc):
                raise InspectorError(path, f"line {line + 1}: a cell longer than {MAX_CELL_CHARS:,} characters") from None
            raise InspectorError(path, f"line {line + 1}: not CSV ({exc})") from None
        line = getattr(reader, "line_num", line)
        for column, cell in enumerate(record, 1):
            if len(cell) > MAX_CELL_CHARS:  # the csv module's limit is process-wide: check ours
                raise InspectorError(path, f"line {line}, {named(column)}: a cell of {len(cell):,} characters "
                                           f"(at most {MAX_CELL_CHARS:,})")
        header = header or record
        yield record


# One cell of the excel dialect at a position: quoted (doubled quotes inside), or up to a separator.
_CELL = re.compile(r'"(?:[^"]+|"")*"?|[^,\r\n]*')
_LONG_RUN = re.compile(f"[^,\\r\\n]{{{MAX_CELL_CHARS + 1}}}")
_MAX_CELLS_SCANNED = 100_000  # cells looked at one by one, in a record with quotes, to name the long one


def _long_cell_column(text: str, after_line: int) -> int | None:
    """The column (from 1) of the first cell past :data:`MAX_CELL_CHARS` in the record that starts
    after line ``after_line`` of ``text``, or None when there is none (another CSV error) or it
    cannot be told quickly."""
    pos = 0
    for _ in range(after_line):
        pos = text.find("\n", pos) + 1
        if pos == 0:
            return None
    run, line_end = _LONG_RUN.search(text, pos), text.find("\n", pos)
    if run is not None and '"' not in text[pos:run.start()] and (line_end < 0 or run.start() < line_end):
        return text.count(",", pos, run.start()) + 1  # no quotes before it: every comma separates cells
    for column in range(1, _MAX_CELLS_SCANNED + 1):  # quoted cells (commas, line breaks in them): cell by cell
        cell = _CELL.match(text, pos)
        end = cell.end() if cell else pos
        if end - pos - (2 if text.startswith('"', pos) else 0) > MAX_CELL_CHARS:
            return column
        if end >= len(text) or text[end] != ",":
            return None  # the record ended (or the text did) with no long cell
        pos = end + 1
    return None


_TRUE, _FALSE = {"true", "1", "yes", "success"}, {"false", "0", "no", "failure", "fail"}
_WHOLE = re.compile(r"[+-]?[0-9]+")


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
        elif key in ("episode", "start_frame") and _WHOLE.fullmatch(cell):
            digits = len(cell.lstrip("+-").lstrip("0"))
            if digits > len(str(MAX_WHOLE)):  # past 2^53 - 1 whatever they are (and int() of 5000 fails)
                raise ValueError(f"{key}: expected a non-negative integer no larger than {MAX_WHOLE}, "
                                 f"found an integer of {digits} digits")
            out[key] = int(cell)  # exact, as JSON gives it; its range is checked with JSON's
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
        problem = None if number is None else whole_problem(number, 0, MAX_WHOLE)
        if problem:  # an index past 2^53 - 1 is refused, never "matches no rollout"
            raise ValueError(f"{key}: {problem}")
    if tag is None and episode is None:
        raise ValueError("no 'tag' or 'episode' to match a rollout by")
    fields.setdefault("note", "")
    return FileRow(line, tag, episode, start, check_fields(fields, known_tags))


# Rows that match no rollout kept to be named one by one; past these they are only counted.
MAX_UNMATCHED_LISTED = 100


@dataclass
class ImportResult:
    matched: dict[str, dict[str, Any]]  # tag -> fields
    unmatched: list[FileRow]  # the first MAX_UNMATCHED_LISTED rows that match no rollout, by line
    rows: int = 0  # rows read
    unmatched_rows: int = 0  # rows that match no rollout (all of them)
    first: FileRow | None = None  # the file's first row


def match_rows(rows: Iterable[FileRow], rollouts: Mapping[str, Rollout]) -> ImportResult:
    """Each row's rollouts: the one with its tag, or every rollout of its episode (at its start
    frame, when given). A row naming a rollout more precisely wins over one naming it less (tag >
    episode and start frame > episode); among equals, the later row wins.

    One pass, holding per rollout only the row that wins it so far: memory grows with the
    rollouts, not with the rows (an outcomes file may hold millions)."""
    by_episode: dict[int, list[str]] = {}
    for tag, r in sorted(rollouts.items()):
        if r.episode_index is not None:
            by_episode.setdefault(r.episode_index, []).append(tag)
    best: dict[str, tuple[tuple[bool, bool], dict[str, Any]]] = {}
    result = ImportResult({}, [])
    for row in rows:
        result.first = result.first or row
        result.rows += 1
        # the more specific a row, the more it weighs: a tag beats an episode at a start frame,
        # which beats a whole episode
        weight = (row.tag is not None, row.start_frame is not None)
        if row.tag is not None:
            tags = [row.tag] if row.tag in rollouts else []
        else:
            tags = [t for t in by_episode.get(cast(int, row.episode), [])
                    if row.start_frame is None or rollouts[t].start_frame == row.start_frame]
        if not tags:
            result.unmatched_rows += 1
            if len(result.unmatched) < MAX_UNMATCHED_LISTED:
                result.unmatched.append(row)
        for t in tags:
            if t not in best or weight >= best[t][0]:
                best[t] = (weight, row.fields)
    result.matched = {t: fields for t, (_, fields) in best.items()}
    return result
