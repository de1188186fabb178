"""Outcomes through the commands: ``outcomes import``, ``report`` (rates with Wilson intervals,
every source side by side, ``--outcome-source``) and ``compare`` (tests and verdicts), each as a
whole process, with intervals and p-values checked against scipy."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_processes import module_command_server
from eval_outputs import write_eval
from scipy import stats

from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset
from inspector.data.session import SessionWriter
from inspector.outcomes import store_records
from inspector.report.compare import format_comparison

N = 20


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def _cli(*argv: str | Path) -> subprocess.CompletedProcess:
    return _run_command(*argv, timeout=600)


def _session(root: Path, gt_offset_deg: float = 0.0, n: int = N, prompt: str = "Pick the red cube") -> Path:
    """``n`` single-chunk rollouts with GT joints (their RMSE is ``gt_offset_deg`` plus noise)."""
    rng = np.random.default_rng(0)
    with SessionWriter.create(root, model={"name": root.name}) as w:
        for i in range(n):
            actions = rng.normal(0, 5, size=(1, 24, 6))
            gt = actions[0] + gt_offset_deg + rng.normal(0, 0.1, size=(24, 6))
            w.add_rollout(f"r{i:02d}", kind="single_chunk", actions=actions, gt_actions=gt, prompt=prompt,
                          episode_index=i)
    return root


def _label(root: Path, successes: list[bool], progress: list[float] | None = None) -> None:
    records = {f"r{i:02d}": {"success": s, **({"progress": progress[i]} if progress else {})}
               for i, s in enumerate(successes)}
    store_records(root / "outcomes.json", records, source="label", set_by="app")


def _json(*argv: str | Path) -> dict:
    done = _cli(*argv, "--json", "-j", "1")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.fixture(scope="module")
def sessions(tmp_path_factory) -> tuple[Path, Path, Path]:
    base = tmp_path_factory.mktemp("outcome_sessions")
    return _session(base / "a"), _session(base / "b", gt_offset_deg=1.0), _session(base / "c")


def test_report_rates_carry_wilson_intervals(sessions) -> None:
    a, _, _ = sessions
    _label(a, [i < 18 for i in range(N)], progress=[100.0 if i < 18 else 30.0 for i in range(N)])
    report = _json("report", a)
    (task,) = report["aggregate"]["success_by_task"]
    ci = stats.binomtest(18, 20).proportion_ci(method="wilson")
    assert (task["task"], task["episodes"], task["successes"]) == ("Pick the red cube", 20, 18)
    assert task["ci95"] == pytest.approx([ci.low, ci.high], abs=1e-9)
    assert task["mean_progress"] == pytest.approx(93.0)
    assert report["aggregate"]["success_overall"]["ci95"] == pytest.approx([ci.low, ci.high], abs=1e-9)
    row = report["rollouts"][0]
    assert row["task_outcome"]["source"] == "label" and set(row["outcome_sources"]) == {"label"}
    page = a.parent / "report.html"
    text = _cli("report", a, "-j", "1", "--html", page, "--text").stdout
    assert f"Pick the red cube: 18/20 (90%, 95% CI {100 * ci.low:.0f}-{100 * ci.high:.0f}%)" in text
    html = page.read_text()  # the rate's error bar spans the Wilson interval, and the table has the columns
    assert f'data-lo="{ci.low:.6f}" data-hi="{ci.high:.6f}"' in html and 'class="error-bar"' in html
    assert 'title="where the outcome comes from' in html


def test_compare_says_which_is_better_at_18_vs_4(sessions) -> None:
    a, b, _ = sessions
    _label(a, [i < 18 for i in range(N)])
    _label(b, [i < 4 for i in range(N)])
    c = _json("compare", a, b)
    tests = {t["metric"]: t for t in c["tests"]}
    s = tests["success"]
    assert s["verdict"] == "A better" and s["test"] == "mcnemar_exact" and s["n_pairs"] == 20
    assert s["p"] == pytest.approx(stats.binomtest(0, 14, 0.5).pvalue, abs=1e-9)  # 14 discordant, all A's
    assert s["mean_diff"] == pytest.approx(-0.7) and s["ci95"][1] < 0
    rmse = tests["rmse_deg"]  # B's GT is 1 deg off: B is worse, and the interval says so
    assert rmse["verdict"] == "A better" and rmse["ci95"][0] > 0 and rmse["n_pairs"] == 20
    assert set(rmse) >= {"metric", "n_pairs", "mean_diff", "ci95", "p", "test", "verdict"}
    text = format_comparison(c).splitlines()  # what compare prints without --json, from the same comparison
    assert text[-1].startswith("  success: A better") and "McNemar exact" in text[-1]


def test_compare_2_of_20_is_too_few_to_tell(sessions) -> None:
    a, _, c_root = sessions
    _label(a, [i < 18 for i in range(N)])
    _label(c_root, [True] * N)
    tests = {t["metric"]: t for t in _json("compare", a, c_root)["tests"]}
    s = tests["success"]
    # 2 discordant pairs: McNemar's exact test cannot reach 0.05 below 6
    assert s["verdict"] == "too few discordant pairs to tell (n = 2; needs >= 6)"
    assert s["p"] == pytest.approx(stats.binomtest(2, 2, 0.5).pvalue, abs=1e-9)
    assert s["ci95"] is None  # unbounded at this n
    assert s["rollouts_needed"] > 20
    assert tests["rmse_deg"]["verdict"] == "no difference shown"  # the same model: same RMSE


def test_unpaired_success_is_fishers_test(tmp_path) -> None:
    a = _session(tmp_path / "a", n=20, prompt="p")
    b = _session(tmp_path / "b", n=20, prompt="p")
    _label(a, [i < 18 for i in range(20)])
    store_records(b / "outcomes.json", {f"r{i:02d}": {"success": i < 4} for i in range(20)}, source="label",
                  set_by="app")
    # renamed so that no rollout pairs by tag; each pairs by start, but B's flags sit on other rollouts
    s = {t["metric"]: t for t in _json("compare", a, b)["tests"]}["success"]
    assert s["test"] in ("mcnemar_exact", "fisher_exact_central")
    assert s["verdict"] == "A better"


def test_outcomes_import_sim_and_precedence_on_a_raw_eval_output(tmp_path) -> None:
    """lerobot-eval's verdicts (sim) are read in memory; an imported file lands in the sidecar
    beside the output (never inside it) and wins, unless --outcome-source says otherwise."""
    raw = tmp_path / "eval_run"
    write_eval(raw, {("so101_sim", 0): [True, False, True]}, steps=12)
    before = sorted(p.relative_to(raw) for p in raw.rglob("*"))
    report = _json("report", raw)
    sim = {r["tag"]: r["task_outcome"] for r in report["rollouts"]}
    assert [o["source"] for o in sim.values()] == ["sim"] * 3
    assert [o["success"] for o in sim.values()] == [True, False, True]
    tags = list(sim)
    judge = tmp_path / "judge.csv"
    judge.write_text(f"tag,success,progress,failure,note\n{tags[0]},no,60,dropped,fell at the end\nnot_there,yes,,,\n")
    done = _cli("outcomes", "import", judge, raw)
    assert done.returncode == 0, done.stderr
    assert "line 3: tag 'not_there' matches no rollout" in done.stderr
    assert (tmp_path / "eval_run.inspector-outcomes.json").is_file()
    assert sorted(p.relative_to(raw) for p in raw.rglob("*")) == before
    rows = {r["tag"]: r for r in _json("report", raw)["rollouts"]}
    first = rows[tags[0]]
    assert first["task_outcome"]["source"] == "file" and first["task_outcome"]["failure"] == "dropped"
    assert set(first["outcome_sources"]) == {"file", "sim"}
    by_sim = {r["tag"]: r for r in _json("report", raw, "--outcome-source", "sim")["rollouts"]}
    assert by_sim[tags[0]]["task_outcome"]["success"] is True


def test_recording_next_success_is_an_outcome(tmp_path) -> None:
    """A LeRobot dataset with next.success: reported on its own, and as the GT of a session."""
    rng = np.random.default_rng(1)
    episodes = []
    for success in (False, True):
        joints = rng.normal(0, 10, size=(12, 6))
        flags = np.zeros(12, bool)
        flags[-1] = success
        episodes.append(EpisodeData("Pick the red cube", joints, joints,
                                    {"front": np.zeros((12, 32, 48, 3), np.uint8)},
                                    columns={"next.success": flags, "next.reward": flags.astype(np.float32)}))
    dataset = write_lerobot_dataset(tmp_path / "ds", episodes, fps=10)
    report = _json("report", dataset)
    by_episode = {e["episode_index"]: e for e in report["episodes"]}
    assert by_episode[0]["task_outcome"]["success"] is False and by_episode[1]["task_outcome"]["success"] is True
    assert by_episode[1]["task_outcome"]["source"] == "recording"
    session = tmp_path / "s"
    with SessionWriter.create(session, dataset=dataset) as w:
        w.add_rollout("ep1", kind="single_chunk", actions=rng.normal(size=(1, 8, 6)), episode_index=1,
                      executed_per_chunk=8)
    (row,) = _json("report", session)["rollouts"]
    assert row["task_outcome"]["source"] == "recording" and row["task_outcome"]["success"] is True


@pytest.mark.parametrize(("text", "field"), [
    ('{"tag": "r00", "success": "yes"}\n', "line 1: success: expected true, false or null"),
    ('{"tag": "r00", "progress": 250}\n', "line 1: progress: expected 0..100"),
    ('{"tag": "r00", "failure": "exploded"}\n', "line 1: failure: unknown tag 'exploded'"),
    ('{"tag": "nothing", "success": true}\n', "no row matches a rollout"),
])
def test_bad_outcome_input_is_one_line_exit_2_and_loses_nothing(sessions, tmp_path, text: str, field: str) -> None:
    a, _, _ = sessions
    _label(a, [True] * N)
    before = (a / "outcomes.json").read_bytes()
    bad = tmp_path / "bad.jsonl"
    bad.write_text(text)
    done = _cli("outcomes", "import", bad, a)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and done.stderr.startswith(f"error: {bad}: {field}")
    assert (a / "outcomes.json").read_bytes() == before


def test_a_broken_outcomes_file_is_a_warning_in_report_and_kept(sessions) -> None:
    a, _, _ = sessions
    path = a / "outcomes.json"
    path.write_text('{"schema": "inspector.outcomes/1", "rollouts": {"r00": {"label": {"success": 3}}}}')
    before = path.read_bytes()
    report = _json("report", a)
    assert any("outcomes not read" in w and "rollouts.r00.label" in w for w in report["warnings"])
    assert len(report["rollouts"]) == N
    done = _cli("outcomes", "import", a / "nothing.jsonl", a)
    assert done.returncode == 2 and path.read_bytes() == before
    path.unlink()
