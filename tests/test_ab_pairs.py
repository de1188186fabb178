"""A/B mode's pairs: rollouts of two sessions from the same start, least-compared first; and the
pair's arms in the 3D scene, as a (browser-less) client receives them: named by side only, posed
at the pair's playback step."""

from __future__ import annotations

import json
import random
import shutil
from pathlib import Path

import numpy as np
import pytest

from inspector.app import serve
from inspector.app._ab_arms import side_origin
from inspector.app._ab_mode import choose_pair, parse_progress, plan_candidates
from inspector.app._headless import HeadlessClient
from inspector.data.session import SessionWriter, open_session
from inspector.said.votes import Side, new_vote


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


DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"


def _named_demo(dest: Path, name: str, model: str) -> Path:
    shutil.copytree(DEMO, dest, ignore=shutil.ignore_patterns("votes.json", "outcomes.json", ".*.lock"))
    meta = json.loads((dest / "session.json").read_text())
    meta["name"], meta["model"] = name, {"name": model}
    (dest / "session.json").write_text(json.dumps(meta))
    return dest


@pytest.mark.slow  # two demo copies served, the arm meshes loaded
def test_the_pair_arms_are_drawn_side_by_side_named_by_side_only(tmp_path):
    secrets = ["ckpt_alpha_7731", "alpha-model-x", "ckpt_omega_1942", "omega-model-y", "run_k7", "run_q2"]
    sessions = [_named_demo(tmp_path / "run_k7", *secrets[:2]), _named_demo(tmp_path / "run_q2", *secrets[2:4])]
    app = serve(sessions, port=0, block=False, ab=True)
    try:
        with HeadlessClient(app.port, observe=True) as client:
            arms = [f"/ab/{side}/{who}" for side in "AB" for who in ("pred", "gt")]  # the demo has GT
            client.wait_until(lambda: all(a in client.scene_nodes for a in arms), what="both sides' arms")
            nodes = dict(client.scene_nodes)
            assert sum(n.startswith("/ab/A/pred/") for n in nodes) >= 6  # the arm's links, under its side
            named = [n for n in nodes for s in secrets if s in n]
            texts = [json.dumps(n["props"], default=str) for n in nodes.values()]
            assert not named and not [s for s in secrets for t in texts if s in t]
            labels = {n["props"]["text"] for n in nodes.values() if n["type"] == "LabelMessage"}
            assert labels == {"A", "B"}
            # A stands left of B as the camera sees it, the two well apart
            a, b = np.array(side_origin("A")), np.array(side_origin("B"))
            assert np.linalg.norm(a - b) >= 0.5 and np.allclose(nodes["/ab/A"]["props"].get("position", a), a)

            # Plainly lit and still until the page finds a GPU; a page that does unticks Light 3D
            # (this client stands for one): the environment map comes on and the arms play by themselves
            assert client.control(client.find_control("play arms"))["value"] is False
            client.set_gui_value(client.find_control("Light 3D"), False)
            client.wait_until(lambda: client.control(client.find_control("play arms"))["value"] is True,
                              what="play ticked")

            def moves() -> int:
                return sum(c for n, c in client.pose_updates.items() if n.startswith("/ab/B/pred/"))
            before = moves()
            client.wait_until(lambda: moves() > before + 20, what="the arms playing")
            tab = next(iter(app.ab_tabs.values()))
            assert tab.arms is not None and tab.arms.n_steps > 10
            step = tab.arms.n_steps - 3
            assert client.control(client.find_control("step"))["props"]["max"] == tab.arms.n_steps - 1
            # moving the step slider pauses play and holds the arms at that step
            client.set_gui_value(client.find_control("step"), step)
            client.wait_until(lambda: client.control(client.find_control("play arms"))["value"] is False,
                              what="play unticked")
            client.wait_until(lambda: tab.step == step, what="the slider's step")
            held = moves()
            assert not tab.playing.value and tab.step == step
            tab.set_step(0)  # the arms go back to the start, and the slider with them
            client.wait_until(lambda: moves() > held and client.control(client.find_control("step"))["value"] == 0,
                              what="the arms and the slider at step 0")
    finally:
        app.stop()


@pytest.mark.slow  # three demo copies served, the arm meshes loaded
def test_a_broken_votes_file_or_a_vanished_rollout_is_a_card_and_the_next_pair_comes(tmp_path):
    """A session whose votes.json does not parse takes no part (its file named, never overwritten);
    a pair whose rollout's files vanished after the start is set aside (its file named); the tab
    still gets a pair, and votes on the others are saved."""
    from demo_copies import demo_copy

    tags = ("single_f000", "single_f076")
    roots = [demo_copy(tmp_path / name, tags) for name in ("a", "b", "c")]
    truncated = '{"schema": "inspector.votes/1", "votes": [{"id": "x", "time": "2026'
    (roots[2] / "votes.json").write_text(truncated)
    app = serve(roots, port=0, block=False, ab=True)
    try:
        gone = roots[1] / "rollouts" / "single_f076" / "video"
        shutil.rmtree(gone)  # after the start: the session was read with it
        with HeadlessClient(app.port, observe=True) as client:
            client.wait_until(lambda: app.ab_tabs and client.html_containing("data-ab-pair"), what="a pair")
            tab = next(iter(app.ab_tabs.values()))
            for n in range(3):
                assert tab.shown is not None
                (ia, ta), (ib, tb) = tab.shown
                assert {ia, ib} == {0, 1} and ta == tb == "single_f000"  # never c, never the vanished rollout
                assert tab.vote("a") is not None
                client.wait_until(lambda n=n: f"data-ab-pair='{n + 2}'" in client.html_containing("data-ab-pair"),
                                  what=f"pair {n + 2}")
            card = client.html_containing("data-ab-problem")
            assert str(roots[2] / "votes.json") in card and "invalid JSON" in card
            assert str(gone) in card and card.count("data-ab-problem") == 2
    finally:
        app.stop()
    assert (roots[2] / "votes.json").read_text() == truncated
    assert len(json.loads((roots[0] / "votes.json").read_text())["votes"]) == 3
