"""``inspector rank`` and ``inspector agreement`` on sessions written with known outcomes and votes:
the numbers the commands print equal scipy's and SIMPLER's formulas on the same rates, and bad
input is one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from inspector.cli import main
from inspector.data.session import SessionWriter
from inspector.outcomes import OUTCOMES_FILE, store_records
from inspector.said.votes import Side, new_vote, read_votes, save_vote, votes_path

TASKS = ("pick the cube", "open the drawer")
CHECKPOINTS = ("ckpt-a", "ckpt-b", "ckpt-c", "ckpt-d")
ROLLOUTS = 10  # per checkpoint and task
# successes out of ROLLOUTS per (checkpoint, task), imagined and real
IMAGINED = {("ckpt-a", TASKS[0]): 9, ("ckpt-a", TASKS[1]): 6, ("ckpt-b", TASKS[0]): 7, ("ckpt-b", TASKS[1]): 5,
            ("ckpt-c", TASKS[0]): 4, ("ckpt-c", TASKS[1]): 5, ("ckpt-d", TASKS[0]): 1, ("ckpt-d", TASKS[1]): 2}
REAL = {("ckpt-a", TASKS[0]): 8, ("ckpt-a", TASKS[1]): 3, ("ckpt-b", TASKS[0]): 7, ("ckpt-b", TASKS[1]): 4,
        ("ckpt-c", TASKS[0]): 2, ("ckpt-c", TASKS[1]): 4, ("ckpt-d", TASKS[0]): 2, ("ckpt-d", TASKS[1]): 0}


def _cli(*argv: str | Path) -> subprocess.CompletedProcess:
    """The command as a user runs it, as a whole process."""
    return subprocess.run([sys.executable, "-m", "inspector", *map(str, argv)], capture_output=True, text=True,
                          timeout=600)


def _main(capsys, *argv: str | Path) -> tuple[int, str, str]:
    """The command in this process (bad-input checks: faster than a process each)."""
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def _write_session(dest: Path, checkpoint: str, successes: dict[str, int], name: str | None = None,
                   n: int = ROLLOUTS, judged_by: str = "file") -> Path:
    """A session of ``checkpoint``: per task, ``n`` rollouts from starts 0..n-1, the first
    ``successes[task]`` of them successful (progress 100 %, the others 30 %), judged in an
    outcomes file (``judged_by="file"``, as a judge writes) or by a simulator (``"sim"``: the
    rollout's ``extra.outcome``, as lerobot-eval's import writes; it has no progress)."""
    records = {}
    with SessionWriter.create(dest, name=name or dest.name, model={"name": checkpoint}) as writer:
        for t, task in enumerate(successes):
            for i in range(n):
                ok = i < successes[task]
                tag = f"t{t}_r{i:02d}"
                writer.add_rollout(tag, kind="single_chunk", actions=np.zeros((1, 4, 6)), prompt=task,
                                   executed_per_chunk=4, episode_index=t, start_frame=i,
                                   extra={"outcome": {"success": ok, "task": task}} if judged_by == "sim" else None)
                records[tag] = {"success": ok, "progress": 100.0 if ok else 30.0}
    if judged_by == "file":
        store_records(dest / OUTCOMES_FILE, records, source="file", set_by="judge.jsonl")
    return dest


@pytest.fixture(scope="module")
def sides(tmp_path_factory) -> tuple[list[Path], list[Path]]:
    root = tmp_path_factory.mktemp("agreement")
    imagined = [_write_session(root / f"imagined_{c}", c, {t: IMAGINED[(c, t)] for t in TASKS}) for c in CHECKPOINTS]
    real = [_write_session(root / f"real_{c}", c, {t: REAL[(c, t)] for t in TASKS}) for c in CHECKPOINTS]
    return imagined, real


def _simpler_mmrv(sim: np.ndarray, real: np.ndarray) -> float:
    """SIMPLER's ``mean_maximum_rank_violation`` (simpler-env/SimplerEnv, simpler_env/utils/metrics.py)."""
    violations = []
    for i in range(len(sim)):
        worst = 0.0
        for j in range(len(sim)):
            if (sim[i] > sim[j]) != (real[i] > real[j]):
                worst = max(worst, abs(real[i] - real[j]))
        violations.append(worst)
    return float(np.mean(violations))


def test_agreement_equals_scipy_and_simpler_on_known_rates(sides, tmp_path):
    imagined, real = sides
    page = tmp_path / "agreement.html"
    run = _cli("agreement", "--imagined", *imagined, "--real", *real, "--json", "--bootstrap", "300", "--html", page)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    keys = sorted(IMAGINED)
    x = np.array([IMAGINED[k] / ROLLOUTS for k in keys])
    y = np.array([REAL[k] / ROLLOUTS for k in keys])
    assert [(p["checkpoint"], p["task"]) for p in out["points"]] == [list(k) for k in keys] or \
        [(p["checkpoint"], p["task"]) for p in out["points"]] == keys
    np.testing.assert_allclose([p["imagined"] for p in out["points"]], x)
    np.testing.assert_allclose([p["real"] for p in out["points"]], y)
    s = out["statistics"]
    assert s["pearson"]["value"] == pytest.approx(stats.pearsonr(x, y).statistic)
    assert s["spearman"]["value"] == pytest.approx(stats.spearmanr(x, y).statistic)
    assert s["kendall"]["value"] == pytest.approx(stats.kendalltau(x, y).statistic)
    assert s["mmrv"]["value"] == pytest.approx(_simpler_mmrv(x, y))
    assert s["mean_abs_difference"]["value"] == pytest.approx(np.mean(np.abs(x - y)))
    for name, entry in s.items():
        assert entry["low"] <= entry["high"] and entry["replicates"] == 300, name
    # every rollout has a twin from the same start on the other side: success on both where
    # i < min(imagined, real) successes, and so on
    c = out["confusion"]
    assert c["pairs"] == len(keys) * ROLLOUTS
    assert c["imagined_success_real_failure"] == sum(max(0, IMAGINED[k] - REAL[k]) for k in keys)
    assert c["imagined_failure_real_success"] == sum(max(0, REAL[k] - IMAGINED[k]) for k in keys)
    assert c["imagined_success_real_success"] == sum(min(IMAGINED[k], REAL[k]) for k in keys)
    html = page.read_text()
    assert html.count('class="pt') >= len(keys) and "imagined = real" in html
    assert f"Rollouts from the same start on both sides ({len(keys) * ROLLOUTS})" in html


def test_agreement_by_progress_uses_mean_progress(sides):
    from inspector.report.agreement import build_agreement

    imagined, real = sides
    out = build_agreement(imagined, real, by="progress", n_bootstrap=200)
    keys = sorted(IMAGINED)
    x = np.array([(IMAGINED[k] * 1.0 + (ROLLOUTS - IMAGINED[k]) * 0.3) / ROLLOUTS for k in keys])
    y = np.array([(REAL[k] * 1.0 + (ROLLOUTS - REAL[k]) * 0.3) / ROLLOUTS for k in keys])
    assert out["statistics"]["pearson"]["value"] == pytest.approx(stats.pearsonr(x, y).statistic)
    assert out["statistics"]["mmrv"]["value"] == pytest.approx(_simpler_mmrv(x, y))


def test_agreement_bad_input_is_one_line(sides, tmp_path, capsys):
    imagined, real = sides
    renamed = _write_session(tmp_path / "other", "ckpt-z", {TASKS[0]: 3})
    code, _, err = _main(capsys, "agreement", "--imagined", renamed, "--real", *real)
    assert code == 2 and err.count("\n") == 1
    assert "no checkpoint in common" in err and "--match" in err
    # renamed onto a real checkpoint: one task in common, one point, too few for a correlation
    code, _, err = _main(capsys, "agreement", "--imagined", renamed, "--real", *real, "--match", "ckpt-z=ckpt-a")
    assert code == 2 and "1 checkpoint-task point " in err and "at least 3" in err
    other_task = _write_session(tmp_path / "task", "ckpt-a", {"stack the cups": 3})
    code, _, err = _main(capsys, "agreement", "--imagined", other_task, "--real", *real)
    assert code == 2 and "no task (prompt) in common" in err
    code, _, err = _main(capsys, "agreement", "--imagined", tmp_path, "--real", *real)
    assert code == 2 and err.startswith(f"error: {tmp_path}: not a session directory")


# ----------------------------------------------------------------------------------------------
# rank


def _vote(a: Path, ta: str, b: Path, tb: str, answer: str) -> None:
    save_vote(new_vote(Side(str(a.resolve()), a.name, ta), Side(str(b.resolve()), b.name, tb), answer))


def test_rank_without_votes_ranks_by_success_with_wilson_intervals(tmp_path):
    real = [_write_session(tmp_path / c, c, {t: REAL[(c, t)] for t in TASKS}, judged_by="sim") for c in CHECKPOINTS]
    run = _cli("rank", *real, "--json")
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    assert out["method"] == "success_rate" and "no votes" in out["note"]
    totals = {c: sum(REAL[(c, t)] for t in TASKS) for c in CHECKPOINTS}
    assert [r["model"] for r in out["ranking"]] == sorted(CHECKPOINTS, key=lambda c: -totals[c])
    first = out["ranking"][0]
    ci = stats.binomtest(first["successes"], first["episodes"]).proportion_ci(0.95, method="wilson")
    assert (first["low"], first["high"]) == pytest.approx((ci.low, ci.high))


def test_rank_from_votes_puts_the_preferred_session_first(tmp_path):
    sessions = [_write_session(tmp_path / name, name, {TASKS[0]: 2}, n=4) for name in ("strong", "middle", "weak")]
    strong, middle, weak = sessions
    rng = np.random.default_rng(0)
    for _ in range(12):  # the better side wins most votes; a few ties and upsets
        for better, worse in ((strong, middle), (middle, weak), (strong, weak)):
            i, j = rng.integers(0, 4, size=2)
            answer = rng.choice(["a", "a", "a", "tie", "b"])
            _vote(better, f"t0_r{i:02d}", worse, f"t0_r{j:02d}", str(answer))
    run = _cli("rank", weak, strong, middle, "--json", "--bootstrap", "300", "--html", tmp_path / "rank.html")
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    html = (tmp_path / "rank.html").read_text()
    assert html.count('<circle class="pt c0" data-key=') == 3 and "Wins of row over column" in html
    assert out["method"] == "bradley_terry" and out["votes"] == 36
    assert [r["session"] for r in out["ranking"]] == ["strong", "middle", "weak"]
    matrix = np.array(out["win_matrix"]["votes"])
    assert matrix.sum() == 2 * 36 and np.all(matrix[~np.eye(3, dtype=bool)] == 12)
    text = _cli("rank", weak, strong, middle, "--bootstrap", "100")
    assert text.returncode == 0 and text.stdout.splitlines()[2].split()[1] == "strong"


def test_votes_are_kept_in_both_sessions_and_counted_once(tmp_path):
    a = _write_session(tmp_path / "a", "x", {TASKS[0]: 1}, n=2)
    b = _write_session(tmp_path / "b", "y", {TASKS[0]: 1}, n=2)
    _vote(a, "t0_r00", b, "t0_r01", "tie")
    save_vote(new_vote(Side(str(a.resolve()), "a", "t0_r01", progress=40.0), Side(str(b.resolve()), "b", "t0_r00"), "b"))
    assert [v.answer for v in read_votes(a)] == [v.answer for v in read_votes(b)] == ["tie", "b"]
    from inspector.report.ranking import build_ranking

    c = _write_session(tmp_path / "c", "z", {TASKS[0]: 1}, n=2)
    _vote(a, "t0_r00", c, "t0_r00", "a")  # with a session not ranked below: left out, counted
    out = build_ranking([a, b], n_bootstrap=100)
    assert out["votes"] == 2 and out["votes_elsewhere"] == 1
    entry = {r["session"]: r for r in out["ranking"]}["a"]
    assert (entry["progress_mean"], entry["progress_scores"], entry["wins"], entry["losses"], entry["ties"]) == \
        (40.0, 1, 0.0, 1.0, 1)


def test_rank_bad_votes_are_one_line_naming_the_file(tmp_path, capsys):
    a = _write_session(tmp_path / "a", "x", {TASKS[0]: 1}, n=2)
    b = _write_session(tmp_path / "b", "y", {TASKS[0]: 1}, n=2)
    _vote(a, "t0_r00", b, "no_such_rollout", "a")
    code, _, err = _main(capsys, "rank", a, b)
    assert code == 2 and err.count("\n") == 1
    assert "'no_such_rollout' is not in session 'b'" in err and err.startswith(f"error: {votes_path(b)}: ")
    good = json.loads(votes_path(a).read_text())
    good["votes"][0]["b"]["rollout"] = "t0_r01"
    for bad, expected in ((("answer", "maybe"), "votes[0].answer: expected 'a' or 'b' or 'tie', found 'maybe'"),
                          (("a", {"session": str(a), "name": "a", "rollout": "t0_r00", "progress": "high"}),
                           "votes[0].a.progress: expected a number from 0 to 100 or null, found 'high'"),
                          (("time", 12), "votes[0].time: expected a string, found 12")):
        doc = json.loads(json.dumps(good))
        doc["votes"][0][bad[0]] = bad[1]
        votes_path(a).write_text(json.dumps(doc))
        code, _, err = _main(capsys, "rank", a, b)
        assert code == 2 and err == f"error: {votes_path(a)}: {expected}\n"
    code, _, err = _main(capsys, "rank", a)
    assert code == 2 and "at least two sessions" in err


def test_serve_ab_needs_two_sessions(tmp_path, capsys):
    one = _write_session(tmp_path / "one", "x", {TASKS[0]: 1}, n=2)
    code, _, err = _main(capsys, "serve", "--ab", "--port", "0", one)
    assert code == 2 and err == "error: --ab: blind comparison needs two or more sessions with rollouts (got 1)\n"


def test_one_session_can_be_both_sides_by_outcome_source(tmp_path):
    """A simulated evaluation (its verdicts: ``sim``) whose imagined videos a judge also scored (an
    outcomes ``file``): each side reads its own source."""
    from inspector.report.agreement import build_agreement

    sessions = []
    for c in CHECKPOINTS:
        dest = _write_session(tmp_path / c, c, {t: REAL[(c, t)] for t in TASKS}, judged_by="sim")
        records = {f"t{t}_r{i:02d}": {"success": i < IMAGINED[(c, task)]} for t, task in enumerate(TASKS)
                   for i in range(ROLLOUTS)}
        store_records(dest / OUTCOMES_FILE, records, source="file", set_by="judge.jsonl")
        sessions.append(dest)
    out = build_agreement(sessions, sessions, imagined_source="file", real_source="sim", n_bootstrap=100)
    keys = sorted(IMAGINED)
    x = np.array([IMAGINED[k] / ROLLOUTS for k in keys])
    y = np.array([REAL[k] / ROLLOUTS for k in keys])
    assert out["statistics"]["pearson"]["value"] == pytest.approx(stats.pearsonr(x, y).statistic)
    assert out["sources"] == {"imagined": "file", "real": "sim"}
    # the effective outcome on both sides is the file's: perfect agreement
    same = build_agreement(sessions, sessions, n_bootstrap=100)
    assert same["statistics"]["pearson"]["value"] == pytest.approx(1.0)
