"""The one locked read-check-change-replace behind annotations, outcomes and votes
(``inspector._files.locked_update``): concurrent writers lose nothing, a file that does not parse is
never overwritten, and a file or lock that is a symbolic link leading away is refused."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from inspector._files import json_bytes, locked_update, read_json_object
from inspector.errors import InspectorError
from inspector.said.votes import Side, new_vote, read_votes, save_vote

REPO = Path(__file__).resolve().parent.parent


def read_items(path: Path) -> dict[str, Any]:
    """An ``{"items": [...]}`` document (empty when there is no file), checked."""
    if not os.path.lexists(path):
        return {"items": []}
    data = read_json_object(path)
    if not isinstance(data.get("items"), list):
        raise InspectorError(path, "items: expected a list")
    return data


def append(path: Path, item: str) -> None:
    locked_update(path, read_items, lambda doc: doc["items"].append(item), json_bytes)


def test_threads_appending_at_once_lose_nothing(tmp_path: Path) -> None:
    path = tmp_path / "items.json"
    writers, each = 8, 25

    def write(w: int) -> None:
        for i in range(each):
            append(path, f"{w}-{i}")

    threads = [threading.Thread(target=write, args=(w,)) for w in range(writers)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads)
    items = read_items(path)["items"]
    assert sorted(items) == sorted(f"{w}-{i}" for w in range(writers) for i in range(each))
    assert sorted(p.name for p in tmp_path.iterdir()) == [".items.json.lock", "items.json"]  # no temp left


WRITER = """
import os, sys
from pathlib import Path
from inspector._files import json_bytes, locked_update, read_json_object
path, name, count = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
read = lambda p: read_json_object(p) if os.path.lexists(p) else {"items": []}
for i in range(count):
    locked_update(path, read, lambda doc: doc["items"].append(f"{name}-{i}"), json_bytes)
"""


@pytest.mark.slow
def test_processes_appending_at_once_lose_nothing(tmp_path: Path) -> None:
    path = tmp_path / "items.json"
    writers, each = 4, 30
    procs = [subprocess.Popen([sys.executable, "-c", WRITER, str(path), f"p{w}", str(each)], cwd=REPO)
             for w in range(writers)]
    assert [p.wait(timeout=300) for p in procs] == [0] * writers
    assert sorted(read_items(path)["items"]) == sorted(f"p{w}-{i}" for w in range(writers) for i in range(each))


@pytest.mark.parametrize("content", [b"{not json", b'{"items": 3}', b'{"items": [NaN]}', b"\xff\xfe"])
def test_a_file_that_does_not_parse_is_never_overwritten(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "items.json"
    path.write_bytes(content)
    with pytest.raises(InspectorError) as err:
        append(path, "x")
    assert str(path) in str(err.value)
    assert path.read_bytes() == content
    assert not list(tmp_path.glob(".items.json.*.tmp"))


def test_a_change_that_fails_writes_nothing(tmp_path: Path) -> None:
    path = tmp_path / "items.json"
    append(path, "kept")
    before = path.read_bytes()

    def refuse(doc: dict[str, Any]) -> None:
        doc["items"].append("half")
        raise ValueError("items: refused")

    with pytest.raises(ValueError, match="refused"):
        locked_update(path, read_items, refuse, json_bytes)
    assert path.read_bytes() == before


def test_a_temp_left_by_a_killed_writer_is_removed(tmp_path: Path) -> None:
    path = tmp_path / "items.json"
    (tmp_path / ".items.json.abc123.tmp").write_text("{half")
    append(path, "x")
    assert read_items(path)["items"] == ["x"]
    assert not list(tmp_path.glob(".items.json.*.tmp"))


def test_a_file_linked_outside_its_directory_is_refused(tmp_path: Path) -> None:
    inside, outside = tmp_path / "session", tmp_path / "elsewhere.json"
    inside.mkdir()
    outside.write_text('{"items": []}')
    (inside / "items.json").symlink_to(outside)
    with pytest.raises(InspectorError, match="resolves outside its directory"):
        append(inside / "items.json", "x")
    assert outside.read_text() == '{"items": []}'


def test_a_lock_file_that_is_a_link_is_refused(tmp_path: Path) -> None:
    target = tmp_path / "target"
    (tmp_path / ".items.json.lock").symlink_to(target)
    with pytest.raises(InspectorError, match="symbolic link"):
        append(tmp_path / "items.json", "x")
    assert not target.exists() and not (tmp_path / "items.json").exists()


def test_votes_linked_outside_their_session_are_neither_read_nor_written(tmp_path: Path) -> None:
    a, b, outside = tmp_path / "a", tmp_path / "b", tmp_path / "elsewhere.json"
    for root in (a, b):
        root.mkdir()
    outside.write_text('{"schema": "inspector.votes/1", "votes": []}')
    (a / "votes.json").symlink_to(outside)
    vote = new_vote(Side(str(a), "a", "r0"), Side(str(b), "b", "r0"), "a")
    for call in (lambda: read_votes(a), lambda: save_vote(vote)):
        with pytest.raises(InspectorError, match="resolves outside"):
            call()
    assert outside.read_text() == '{"schema": "inspector.votes/1", "votes": []}'
    assert not (b / "votes.json").exists()  # a refused file refuses the vote everywhere
