"""``inspector compare``: pairing, the paired statistics, and the command on the demo session against
a copy of it with a known offset added to some rollouts' actions."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_processes import module_command_server
from scipy import stats

from inspector.report.compare import compare_reports, format_comparison, pair_rows, paired_summary

pytestmark = pytest.mark.slow  # the CLI as processes

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
OFFSET_DEG = 10.0  # added to shoulder_pan of every predicted action of the rollouts below
WORSENED = ["bias_elbow", "single_f076", "tempo_0.8x"]
RENAMED = ("prompt_train", "prompt_train_v2")  # pairs by its start, not its tag
REMOVED = "limits_wrist"  # unpaired in A


def _row(tag: str, rmse: float | None = 1.0, drift: float | None = None, episode: int | None = 0,
         start: int = 0, prompt: str = "p", kind: str = "single_chunk") -> dict:
    return {"tag": tag, "rmse_deg": rmse, "episode_index": episode, "start_frame": start, "prompt": prompt,
            "kind": kind, "time_aligned_drift": None if drift is None else {"mean": drift}}


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def _cli(*argv: str | Path) -> subprocess.CompletedProcess:
    return _run_command(*argv, timeout=900)


# ----------------------------------------------------------------------------------------------
# Pairing and statistics


def test_pairs_by_tag_then_by_start_in_tag_order():
    a = [_row("x"), _row("y", start=10), _row("z1", start=20), _row("z2", start=20), _row("lonely", start=99)]
    b = [_row("y", start=55), _row("x"), _row("w2", start=20), _row("w1", start=20), _row("new", start=7)]
    pairs, only_a, only_b = pair_rows(a, b)
    got = {(p[0]["tag"], p[1]["tag"], p[2]) for p in pairs}
    # same tag wins even when the start differs; the rest pair by start, n-th with n-th in tag order
    assert got == {("x", "x", "tag"), ("y", "y", "tag"), ("z1", "w1", "start"), ("z2", "w2", "start")}
    assert [r["tag"] for r in only_a] == ["lonely"] and [r["tag"] for r in only_b] == ["new"]


def test_start_pairing_prefers_the_tag_sharing_the_longest_prefix():
    a = [_row("limits_wrist"), _row("prompt_train"), _row("run_7")]
    b = [_row("prompt_train_v2"), _row("run_7b")]
    pairs, only_a, only_b = pair_rows(a, b)
    assert {(p[0]["tag"], p[1]["tag"]) for p in pairs} == {("prompt_train", "prompt_train_v2"), ("run_7", "run_7b")}
    assert [r["tag"] for r in only_a] == ["limits_wrist"] and only_b == []


def test_start_pairing_needs_episode_start_prompt_and_kind_alike():
    a = [_row("a1", episode=1), _row("a2", prompt="q"), _row("a3", kind="autoregressive"), _row("a4", start=3)]
    b = [_row("b1", episode=2), _row("b2", prompt="r"), _row("b3", kind="single_chunk"), _row("b4", start=3)]
    pairs, only_a, only_b = pair_rows(a, b)
    assert [(p[0]["tag"], p[1]["tag"]) for p in pairs] == [("a4", "b4")]
    assert len(only_a) == len(only_b) == 3


def test_paired_summary_agrees_with_scipy():
    rng = np.random.default_rng(0)
    a = rng.uniform(1, 5, 20)
    b = a + rng.normal(0.5, 0.3, 20)
    s = paired_summary(a, b)
    assert s["n_pairs"] == 20 and s["a_better"] + s["b_better"] + s["ties"] == 20
    assert s["a_better"] == int((b > a).sum())
    assert s["mean_delta"] == pytest.approx(float((b - a).mean()))
    assert s["spearman"] == pytest.approx(stats.spearmanr(a, b).statistic)
    assert s["wilcoxon_p"] == pytest.approx(stats.wilcoxon(b - a).pvalue)


def test_paired_summary_degenerate_cases_are_none_not_nan():
    same = paired_summary([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    assert same["ties"] == 3 and same["wilcoxon_p"] is None and same["spearman"] == pytest.approx(1.0)
    one = paired_summary([1.0], [2.0])
    assert one["a_better"] == 1 and one["spearman"] is None
    empty = paired_summary([], [])
    assert empty["n_pairs"] == 0 and empty["mean_delta"] is None
    json.dumps([same, one, empty], allow_nan=False)


def test_rows_without_rmse_pair_but_are_not_compared():
    report_a = {"rollouts": [_row("x", rmse=None, drift=2.0), _row("y", rmse=1.0, drift=None)]}
    report_b = {"rollouts": [_row("x", rmse=None, drift=3.0), _row("y", rmse=2.0, drift=None)]}
    c = compare_reports(report_a, report_b)
    assert c["summary"]["n_pairs"] == 2 and c["summary"]["n_compared"] == 1 and c["summary"]["a_better"] == 1
    drift = c["time_aligned_drift"]
    assert drift["n_compared"] == 1 and drift["a_better"] == 1 and drift["mean_delta_deg"] == pytest.approx(1.0)
    assert [p["delta_rmse_deg"] for p in c["pairs"]] == [None, 1.0]


# ----------------------------------------------------------------------------------------------
# The command on the demo against a copy with a known offset


@pytest.fixture(scope="module")
def worse_copy(tmp_path_factory) -> Path:
    """The demo session with OFFSET_DEG on shoulder_pan for WORSENED, one rollout renamed and one gone."""
    dest = tmp_path_factory.mktemp("compare") / "demo_worse"
    shutil.copytree(DEMO, dest)
    for tag in WORSENED:
        path = dest / "rollouts" / tag / "actions.npy"
        actions = np.load(path)
        actions[..., 0] += OFFSET_DEG
        np.save(path, actions)
    (dest / "rollouts" / RENAMED[0]).rename(dest / "rollouts" / RENAMED[1])
    shutil.rmtree(dest / "rollouts" / REMOVED)
    return dest


@pytest.fixture(scope="module")
def comparison(worse_copy) -> dict:
    out = _cli("compare", DEMO, worse_copy, "--json", "--jobs", "1")  # (the pool is not the point here)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_compare_finds_the_worsened_rollouts(comparison):
    s = comparison["summary"]
    assert s["n_pairs"] == s["n_compared"] == 16
    assert (s["a_better"], s["b_better"], s["ties"]) == (len(WORSENED), 0, 16 - len(WORSENED))
    pairs = {p["a"]["tag"]: p for p in comparison["pairs"]}
    for tag, p in pairs.items():
        if tag in WORSENED:
            assert p["delta_rmse_deg"] > 0.3 and p["delta_time_aligned_drift_deg"] > 0.3, tag
        else:
            assert p["delta_rmse_deg"] == 0 and p["delta_time_aligned_drift_deg"] == 0, tag
        assert p["delta_rmse_deg"] == pytest.approx(p["b"]["rmse_deg"] - p["a"]["rmse_deg"])
    deltas = [p["delta_rmse_deg"] for p in comparison["pairs"]]
    assert s["mean_delta_rmse_deg"] == pytest.approx(np.mean(deltas))
    assert s["wilcoxon_p"] == pytest.approx(stats.wilcoxon([d for d in deltas if d]).pvalue)
    assert s["spearman_rmse"] > 0.5
    drift = comparison["time_aligned_drift"]
    assert (drift["n_compared"], drift["a_better"], drift["b_better"]) == (16, len(WORSENED), 0)


def test_compare_gives_no_verdict_its_test_cannot_support(comparison):
    """3 worse pairs of 16, the rest tied: the signed-rank test (the same p as the summary's) could
    not reach 0.05 with 3 pairs, so no side is called better; the JSON is strict, success is not
    compared twice, and the sides are named by their session's model and checkpoint."""
    tests = {t["metric"]: t for t in comparison["tests"]}
    for metric in ("rmse_deg", "time_aligned_drift_deg"):
        t = tests[metric]
        assert t["verdict"] == f"too few pairs to tell (n = {len(WORSENED)}; needs >= 6)", t
        assert t["ci95"] is None and t["n_informative"] == len(WORSENED)
    assert tests["rmse_deg"]["p"] == comparison["summary"]["wilcoxon_p"]
    assert "success" not in comparison
    model = json.loads((DEMO / "session.json").read_text())["model"]
    label = f"{model['name']}@{model['checkpoint']}"
    assert comparison["names"] == {"a": label, "b": label}
    json.dumps(comparison, allow_nan=False)
    text = format_comparison(comparison)
    assert text.splitlines()[0] == f"A: {comparison['names']['a']} ({comparison['a']})"
    assert "A better:" not in text and "B better:" not in text


def test_compare_delta_of_a_single_chunk_is_the_offset_s_effect(comparison):
    """B's RMSE of single_f076 recomputed from A's own predicted and GT joints plus the offset."""
    p = next(p for p in comparison["pairs"] if p["a"]["tag"] == "single_f076")
    pred, gt = np.array(p["a"]["chunk_joints"]["pred"]), np.array(p["a"]["chunk_joints"]["gt"])
    pred[:, 0] += OFFSET_DEG
    expected = float(np.sqrt(np.mean((pred - gt) ** 2)))
    assert p["b"]["rmse_deg"] == pytest.approx(expected, abs=1e-3)  # joints kept to 4 decimals in rows


def test_compare_pairs_a_renamed_rollout_by_its_start(comparison):
    p = next(p for p in comparison["pairs"] if p["a"]["tag"] == RENAMED[0])
    assert p["b"]["tag"] == RENAMED[1] and p["paired_by"] == "start"
    assert comparison["unmatched_a"] == [REMOVED] and comparison["unmatched_b"] == []


def test_compare_text_is_a_short_table(comparison):
    text = format_comparison(comparison)  # what compare prints without --json, from the same comparison
    lines = text.splitlines()
    assert any(line.startswith("bias_elbow") and line.rstrip().endswith("A") for line in lines)
    assert any(line.startswith(f"{RENAMED[0]} ~ {RENAMED[1]}") for line in lines)
    assert any(line.startswith("RMSE over 16 pair(s): A better 3, B better 0, ties 13") for line in lines)
    assert any(line.startswith("Time-aligned drift over 16 pair(s)") for line in lines)
    assert f"Unpaired in A: {REMOVED}" in text


def test_compare_bad_input_is_one_line_exit_2(tmp_path, worse_copy):
    out = _cli("compare", DEMO, tmp_path / "nowhere")
    assert out.returncode == 2 and out.stderr.startswith("error: ") and len(out.stderr.splitlines()) == 1
    assert "nowhere" in out.stderr
    # nothing in common: a lone rollout of another episode, start and prompt
    lone = tmp_path / "lone"
    shutil.copytree(worse_copy, lone)
    for d in (lone / "rollouts").iterdir():
        if d.name != "overrun_60chunks":
            shutil.rmtree(d)
    (lone / "rollouts" / "overrun_60chunks").rename(lone / "rollouts" / "other")
    meta = json.loads((lone / "rollouts" / "other" / "rollout.json").read_text())
    meta["prompt"] = "something else"
    (lone / "rollouts" / "other" / "rollout.json").write_text(json.dumps(meta))
    out = _cli("compare", worse_copy, lone, "--jobs", "1")
    assert out.returncode == 2, out.stdout
    assert out.stderr.startswith("error: ") and "no rollout pairs" in out.stderr and len(out.stderr.splitlines()) == 1
