"""``inspector demo --checkpoints``: sessions derived from the demo with the differences
docs/development.md documents, written whole, never over what a person may have changed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from inspector.data.session import open_session
from inspector.demo.checkpoints import CHECKPOINTS, IMAGINED_SUCCESS_DEG, REAL_SUCCESS_DEG, write_checkpoints
from inspector.errors import InspectorError
from inspector.outcomes import effective_outcome, load_session_outcomes
from inspector.said.votes import read_votes


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("checkpoints")
    write_checkpoints(root, log=lambda line: None)
    return root


def final_errors(session: Path) -> dict[str, float]:
    s = open_session(session)
    return {tag: r.extra["final_error_deg"] for tag, r in s.rollouts.items()}


def test_each_checkpoint_holds_the_same_rollouts_with_an_error_that_falls_with_training(written: Path) -> None:
    errors = {step: final_errors(written / "sessions" / f"step-{step}") for step in CHECKPOINTS}
    tags = set(errors[CHECKPOINTS[0]])
    assert len(tags) == 12 and all(set(e) == tags for e in errors.values())
    worst, middle, best = (np.array([errors[s][t] for t in sorted(tags)]) for s in CHECKPOINTS)
    assert np.median(worst) > np.median(middle) > np.median(best)
    assert (best < worst).sum() >= 11  # step-72000 better than step-56000 rollout by rollout


def test_the_final_error_is_what_the_joints_say(written: Path) -> None:
    session = open_session(written / "sessions" / "step-56000")
    demo = open_session(Path(__file__).resolve().parents[1] / "sessions" / "demo")
    rollout = session.rollouts["red_cube_0"]
    base = demo.rollouts["prompt_train"]
    last = rollout.executed_per_chunk - 1
    offset = rollout.actions[-1, last, :5] - base.actions[-1, last, :5]
    assert np.abs(offset).max() == pytest.approx(rollout.extra["final_error_deg"], abs=1e-3)
    assert np.array_equal(rollout.actions[:, :, 5], base.actions[:, :, 5])  # the gripper untouched
    assert np.allclose(rollout.states[1:], rollout.actions[:, last])  # states follow the executed steps


def test_outcomes_follow_the_final_error_on_each_side(written: Path) -> None:
    for step in CHECKPOINTS:
        errors = final_errors(written / "sessions" / f"step-{step}")
        for side, limit in (("sessions", IMAGINED_SUCCESS_DEG), ("robot", REAL_SUCCESS_DEG)):
            session = open_session(written / side / f"step-{step}")
            outcomes = load_session_outcomes(session)
            for tag, err in errors.items():
                effective = effective_outcome(outcomes.sources(tag, session.rollouts[tag]))
                assert effective is not None and effective["success"] == (err < limit), (side, step, tag)


def test_votes_prefer_the_smaller_error_and_the_judge_file_imports(written: Path) -> None:
    votes = read_votes(written / "sessions" / "step-72000")
    assert len(votes) == 2 * 12  # against each of the two other checkpoints
    e72 = final_errors(written / "sessions" / "step-72000")
    e56 = final_errors(written / "sessions" / "step-56000")
    against_56 = [v for v in votes if v.a.name == "step-56000"]
    assert all(v.answer == ("tie" if abs(e56[v.a.rollout] - e72[v.b.rollout]) < 1.0 else "b") for v in against_56)
    rows = [json.loads(line) for line in (written / "judge.jsonl").read_text().splitlines()]
    assert {r["tag"] for r in rows} == set(e72) and all(isinstance(r["success"], bool) for r in rows)


def test_an_existing_destination_is_refused_unless_overwrite(written: Path) -> None:
    labels = written / "sessions" / "step-64000" / "outcomes.json"
    before = labels.read_bytes()
    with pytest.raises(InspectorError, match="step-56000"):
        write_checkpoints(written, log=lambda line: None)
    assert labels.read_bytes() == before
