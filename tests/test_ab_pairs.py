"""A/B mode's pairs: rollouts of two sessions from the same start, least-compared first."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from inspector.app._ab_mode import choose_pair, parse_progress, plan_candidates
from inspector.data.session import SessionWriter, open_session
from inspector.data.votes import Side, new_vote


def _session(dest: Path, rollouts: dict[str, tuple[int, int, str]]):
    with SessionWriter.create(dest) as writer:
        for tag, (episode, start, prompt) in rollouts.items():
            writer.add_rollout(tag, kind="single_chunk", actions=np.zeros((1, 9, 6)), episode_index=episode,
                               start_frame=start, prompt=prompt)
    return open_session(dest)


def test_pairs_share_a_tag_or_else_a_start(tmp_path):
    a = _session(tmp_path / "a", {"x": (0, 0, "pick"), "y": (0, 30, "pick"), "only_a": (5, 0, "pick")})
    b = _session(tmp_path / "b", {"x": (0, 0, "pick"), "renamed_y": (0, 30, "pick"), "other": (0, 30, "place")})
    got = {(c.tag_i, c.tag_j) for c in plan_candidates([a, b])}
    assert got == {("x", "x"), ("y", "renamed_y")}


def test_the_least_compared_session_pair_comes_first(tmp_path):
    start = {"x": (0, 0, "pick"), "y": (0, 30, "pick")}
    sessions = [_session(tmp_path / name, start) for name in ("a", "b", "c")]
    roots = [str(s.root.resolve()) for s in sessions]
    candidates = plan_candidates(sessions)
    # a-b compared twice, a-c once (on x), b-c never: b-c comes next; then a-c on y (its x was voted)
    votes = [new_vote(Side(roots[0], "a", "x"), Side(roots[1], "b", "x"), "a"),
             new_vote(Side(roots[1], "b", "y"), Side(roots[0], "a", "y"), "tie"),
             new_vote(Side(roots[0], "a", "x"), Side(roots[2], "c", "x"), "b")]
    rng = random.Random(0)
    picked, _ = choose_pair(candidates, sessions, votes, rng)
    assert (picked.i, picked.j) == (1, 2)
    votes += [new_vote(Side(roots[1], "b", "x"), Side(roots[2], "c", "x"), "a"),
              new_vote(Side(roots[2], "c", "y"), Side(roots[1], "b", "y"), "a")]
    picked, _ = choose_pair(candidates, sessions, votes, rng)
    assert (picked.i, picked.j, picked.tag_i) == (0, 2, "y")
    swaps = {choose_pair(candidates, sessions, votes, rng)[1] for _ in range(50)}
    assert swaps == {True, False}  # sides are shuffled


def test_progress_field_text():
    assert parse_progress("") is None and parse_progress(" 80 % ") == 80.0
    for bad in ("120", "-1", "nan", "lots"):
        with pytest.raises(ValueError):
            parse_progress(bad)
