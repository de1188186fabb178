"""The vote store: every vote of concurrent writers is kept, in both sessions, and a broken file is
never overwritten."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from inspector.data.session import SessionWriter
from inspector.errors import InspectorError
from inspector.said.votes import Side, merged_votes, new_vote, read_votes, save_vote, votes_path

VOTES_PER_WRITER = 25

_WRITER = """
import sys
from inspector.said.votes import Side, new_vote, save_vote
a, b, n, answer = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
for i in range(n):
    save_vote(new_vote(Side(a, "a", "r0"), Side(b, "b", "r0"), answer, note=f"{answer} {i}"))
"""


def _session(dest: Path) -> Path:
    with SessionWriter.create(dest) as writer:
        writer.add_rollout("r0", kind="single_chunk", actions=np.zeros((1, 9, 6)))
    return dest.resolve()


def test_concurrent_writers_lose_no_vote(tmp_path):
    a, b = _session(tmp_path / "a"), _session(tmp_path / "b")
    writers = [subprocess.Popen([sys.executable, "-c", _WRITER, str(a), str(b), str(VOTES_PER_WRITER), answer])
               for answer in ("a", "b", "tie")]
    assert [w.wait(timeout=300) for w in writers] == [0, 0, 0]
    for root in (a, b):
        votes = read_votes(root)
        assert len(votes) == 3 * VOTES_PER_WRITER
        assert {v.note for v in votes} == {f"{ans} {i}" for ans in ("a", "b", "tie") for i in range(VOTES_PER_WRITER)}
    assert len(merged_votes([a, b])) == 3 * VOTES_PER_WRITER
    assert not list(a.glob(".votes.json.*.tmp"))


def test_a_broken_vote_file_is_never_overwritten(tmp_path):
    a, b = _session(tmp_path / "a"), _session(tmp_path / "b")
    votes_path(b).write_text('{"votes": [')
    with pytest.raises(InspectorError, match="invalid JSON"):
        save_vote(new_vote(Side(str(a), "a", "r0"), Side(str(b), "b", "r0"), "a"))
    assert votes_path(b).read_text() == '{"votes": ['
    assert not votes_path(a).exists()  # refused everywhere, not written half


def test_a_vote_round_trips_with_progress_and_note(tmp_path):
    a, b = _session(tmp_path / "a"), _session(tmp_path / "b")
    vote = new_vote(Side(str(a), "a", "r0", progress=75.0), Side(str(b), "b", "r0", progress=0.0), "a", note="A grasps")
    save_vote(vote)
    assert read_votes(a) == [vote] == read_votes(b)
    assert json.loads(votes_path(a).read_text())["schema"] == "inspector.votes/1"
    with pytest.raises(ValueError, match="progress"):
        new_vote(Side(str(a), "a", "r0", progress=101.0), Side(str(b), "b", "r0"), "tie")
