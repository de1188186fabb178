"""Hostile outcome files (``inspector outcomes import FILE PATH``) and vote files: whatever a file
holds or is, reading it ends in rows or in one error naming the file (and the line, the column, the
field), within its documented limits; never a traceback, a hang or a read without end.

The limits: a regular file of at most 64 MiB (``MAX_FILE_BYTES``), CSV cells of at most 131,072
characters (``MAX_CELL_CHARS``), JSON nested as deep as the parser goes, indexes up to 2^53 - 1.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from inspector._files import read_regular_file
from inspector.data.session import SessionWriter
from inspector.errors import InspectorError
from inspector.outcomes import read_outcome_file
from inspector.outcomes._import_file import MAX_CELL_CHARS, MAX_FILE_BYTES
from inspector.said.votes import read_votes, readable_votes, votes_path
from inspector.schema import MAX_WHOLE

REPO = Path(__file__).resolve().parents[1]


def _read_within(path: Path, timeout_s: float = 60.0):
    """``read_outcome_file(path)`` in a thread: the result, or the exception; a read that blocks (a
    FIFO waited on) fails the test instead of hanging the run."""
    done: list = []

    def read() -> None:
        try:
            done.append(read_outcome_file(path))
        except BaseException as exc:  # noqa: BLE001 (the test looks at what it is)
            done.append(exc)
    worker = threading.Thread(target=read, daemon=True)
    worker.start()
    worker.join(timeout_s)
    assert done, f"reading {path} did not return within {timeout_s} s"
    return done[0]


@pytest.mark.parametrize(("kind", "what"), [("zero", "is a character device, not a regular file"),
                                             ("fifo", "is a FIFO (named pipe), not a regular file"),
                                             ("directory", "is a directory, not a file")])
def test_a_file_that_is_no_regular_file_is_refused_unread(tmp_path: Path, kind: str, what: str) -> None:
    named = tmp_path / "judge.jsonl"
    if kind == "zero":
        named.symlink_to("/dev/zero")  # read to its end, it fills memory
    elif kind == "fifo":
        os.mkfifo(named)  # no writer: an open() for reading waits for ever
    else:
        named.mkdir()
    got = _read_within(named)
    assert isinstance(got, InspectorError) and got.file == str(named) and got.what == what


def test_a_file_past_its_limit_is_refused_before_it_is_read(tmp_path: Path) -> None:
    big = tmp_path / "judge.jsonl"
    with open(big, "wb") as f:
        f.truncate(MAX_FILE_BYTES + 1)  # sparse: no disk, but its size says what it is
    with pytest.raises(InspectorError, match=r"67,108,865 bytes: larger than any outcomes file"):
        read_outcome_file(big)
    at_limit = tmp_path / "small.csv"
    at_limit.write_bytes(b"tag,success\na,true\n")
    assert read_regular_file(at_limit, len(at_limit.read_bytes()), "x") == at_limit.read_bytes()


def test_a_votes_file_that_is_a_fifo_is_named_not_waited_on(tmp_path: Path) -> None:
    with SessionWriter.create(tmp_path / "s") as writer:
        writer.add_rollout("r0", kind="single_chunk", actions=np.zeros((1, 9, 6)))
    os.mkfifo(votes_path(tmp_path / "s"))
    with pytest.raises(InspectorError, match="votes.json: is a FIFO"):
        read_votes(tmp_path / "s")
    votes, broken = readable_votes([tmp_path / "s"])
    assert votes == [] and list(broken) == [0]


@pytest.mark.slow  # the CLI as a process
@pytest.mark.parametrize("kind", ["zero", "fifo"])
def test_outcomes_import_of_a_device_or_fifo_is_one_line(tmp_path: Path, kind: str) -> None:
    named = tmp_path / "judge.jsonl"
    named.symlink_to("/dev/zero") if kind == "zero" else os.mkfifo(named)
    out = subprocess.run([sys.executable, "-m", "inspector", "outcomes", "import", str(named),
                          str(REPO / "sessions" / "demo")], capture_output=True, text=True, timeout=300, cwd=REPO)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.count("\n") == 1 and out.stderr.startswith(f"error: {named}: is a "), out.stderr


# ---------------------------------------------------------------------------------------------
# Whatever the bytes: rows, or one InspectorError naming the file


def _outcome_or_error(text: bytes) -> list | InspectorError:
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "judge.jsonl"
        f.write_bytes(text)
        try:
            return read_outcome_file(f)
        except InspectorError as exc:
            assert exc.file == str(f)
            assert "\n" not in str(exc)
            return exc


_starts = st.sampled_from([b"", b"{", b'{"tag": "a", "note": ', b"tag,success,note\n", b'episode,note\n1,"'])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(start=_starts, body=st.binary(max_size=400), end=st.sampled_from([b"", b"}", b"\n", b'"\n']))
def test_any_bytes_are_rows_or_one_error(start: bytes, body: bytes, end: bytes) -> None:
    got = _outcome_or_error(start + body + end)
    assert isinstance(got, (list, InspectorError))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(depth=st.one_of(st.integers(1, 50), st.integers(500, 200_000)), opener=st.sampled_from(["[", '{"k":']),
       line=st.integers(1, 3))
def test_nesting_of_any_depth_is_rows_or_one_error_naming_the_line(depth: int, opener: str, line: int) -> None:
    closer = "]" if opener == "[" else "}"
    nested = opener * depth + "1" + closer * depth
    lines = ['{"tag": "a", "success": true}'] * (line - 1) + ['{"tag": "b", "note": "", "x": ' + nested + "}"]
    got = _outcome_or_error("\n".join(lines).encode())
    assert isinstance(got, InspectorError)  # "x" is no outcome field, however deep it is
    assert got.what.startswith(f"line {line}: "), got.what
    if depth >= 100_000:
        assert "invalid JSON (RecursionError" in got.what


def test_a_100000_deep_line_is_one_error(tmp_path: Path) -> None:
    f = tmp_path / "judge.jsonl"
    f.write_text('{"tag": "a", "success": true}\n' + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(InspectorError, match=r"line 2: invalid JSON \(RecursionError"):
        read_outcome_file(f)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(length=st.one_of(st.integers(0, 40), st.integers(MAX_CELL_CHARS - 2, MAX_CELL_CHARS + 2),
                        st.integers(MAX_CELL_CHARS, 300_000)),
       column=st.integers(1, 3), quoted=st.booleans(), row=st.integers(0, 2))
def test_a_csv_cell_past_its_limit_is_one_error_naming_line_and_column(length: int, column: int, quoted: bool,
                                                                         row: int) -> None:
    header = ["tag", "note", "success"]
    cells = ["a", "", "true"]
    text = "x" * length
    cells[column - 1] = f'"{text}"' if quoted else text
    lines = ["tag,note,success"] + ["b,,false"] * row + [",".join(cells)]
    got = _outcome_or_error(("\n".join(lines) + "\n").encode())
    if length > MAX_CELL_CHARS:
        assert isinstance(got, InspectorError)
        assert got.what.startswith(f"line {row + 2}, column {column} ('{header[column - 1]}'): a cell "), got.what
    else:
        assert not (isinstance(got, InspectorError) and "a cell" in got.what), got


def test_a_200_kb_note_is_one_line(tmp_path: Path) -> None:
    f = tmp_path / "sheet.csv"
    f.write_text("tag,success,note\na,true,ok\nb,false," + "n" * 200_000 + "\n")
    with pytest.raises(InspectorError, match=r"line 3, column 3 \('note'\): a cell longer than 131,072 characters"):
        read_outcome_file(f)


# ---------------------------------------------------------------------------------------------
# Indexes past 2^53 - 1: refused naming the field, never "matches no rollout"


@pytest.mark.parametrize("text", [
    f'{{"episode": {MAX_WHOLE + 1}, "success": true}}\n',
    f'{{"tag": "x", "episode": 0, "start_frame": {10**30}, "success": true}}\n',
    f"episode,success\n{MAX_WHOLE + 2},true\n",
    f"episode,start_frame,success\n1,{'9' * 5000},true\n",
])
def test_an_index_past_2_53_is_refused_naming_the_field(tmp_path: Path, text: str) -> None:
    f = tmp_path / ("judge.jsonl" if text.startswith("{") else "sheet.csv")
    f.write_text(text)
    field = "start_frame" if "start_frame" in text else "episode"
    with pytest.raises(InspectorError, match=rf"line \d: {field}: expected a non-negative integer no larger than "
                                             rf"{MAX_WHOLE}, found an integer of \d+ digits"):
        read_outcome_file(f)
    f.write_text(text.replace(str(MAX_WHOLE + 1), str(MAX_WHOLE)).replace(str(MAX_WHOLE + 2), str(MAX_WHOLE))
                 .replace(str(10**30), "0").replace("9" * 5000, "0"))
    assert read_outcome_file(f)  # the largest index is read (and then matches no rollout, said so)
