"""``compare``'s verdicts: each from one test, the interval from the same test, "too few pairs
to tell" where no outcome could be significant, one success comparison, strict JSON, and each
side named by the model and checkpoint its session states."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from inspector.report.compare import compare_reports, format_comparison, side_name
from inspector.report.significance import verdict_text

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
DECIDED = ("A better", "B better")


def _row(tag: str, rmse: float, success: bool | None = None, progress: float | None = None) -> dict:
    outcome = None if success is None and progress is None else {"success": success, "progress": progress}
    return {"tag": tag, "rmse_deg": rmse, "episode_index": 0, "start_frame": 0, "prompt": "p", "kind": "single_chunk",
            "time_aligned_drift": None, "task_outcome": outcome}


def _tests(rows_a: list[dict], rows_b: list[dict]) -> dict[str, dict]:
    c = compare_reports({"rollouts": rows_a}, {"rollouts": rows_b})
    json.dumps(c, allow_nan=False)  # strict: what is not measured is null
    return {t["metric"]: t for t in c["tests"]}


def test_four_differing_pairs_of_17_are_too_few_to_tell():
    """The demo's case: 13 pairs tie, 4 are worse in B. Wilcoxon's exact p is 2/16 = 0.125 and no
    outcome of 4 pairs could go below 0.05, so there is no verdict either way and no interval."""
    a = [_row(f"r{i}", 1.0) for i in range(17)]
    b = [_row(f"r{i}", 1.0 + (0.3 + 0.1 * i if i < 4 else 0.0)) for i in range(17)]
    t = _tests(a, b)["rmse_deg"]
    assert t["verdict"] == "too few pairs to tell (n = 4; needs >= 6)"
    assert (t["n_pairs"], t["n_informative"], t["ties"]) == (17, 4, 13)
    assert t["p"] == pytest.approx(stats.wilcoxon([0.3, 0.4, 0.5, 0.6]).pvalue) == pytest.approx(0.125)
    assert t["ci95"] is None and t["estimate"] == pytest.approx(0.45)  # the median of the Walsh averages
    assert t["mean_diff"] == pytest.approx(1.8 / 17)
    assert "too few pairs to tell (n = 4; needs >= 6)" in verdict_text(t) and "A better" not in verdict_text(t)


@pytest.mark.parametrize("seed", range(40))
def test_every_verdict_is_its_own_tests(seed: int):
    """Random evaluations (3 to 40 pairs, some tied, success flags on both sides): a side is better
    exactly when its test gives p < 0.05 with enough informative pairs, and then the interval
    leaves 0 out on that side; otherwise it holds 0 or is unbounded. p is scipy's."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 41))
    shift = rng.choice([0.0, 0.2, 1.0])
    a_rmse = rng.uniform(1, 5, n)
    b_rmse = np.where(rng.random(n) < 0.3, a_rmse, a_rmse + rng.normal(shift, 0.5, n))
    a_ok, b_ok = rng.random(n) < 0.5, rng.random(n) < rng.choice([0.2, 0.5, 0.9])
    tests = _tests([_row(f"r{i}", a_rmse[i], bool(a_ok[i])) for i in range(n)],
                   [_row(f"r{i}", b_rmse[i], bool(b_ok[i])) for i in range(n)])
    rmse, success = tests["rmse_deg"], tests["success"]
    d = b_rmse - a_rmse
    informative = d[np.abs(d) > 1e-9]
    if len(informative):
        assert rmse["p"] == pytest.approx(stats.wilcoxon(informative).pvalue, abs=1e-9)
    discordant = int((a_ok != b_ok).sum())
    if discordant:
        assert success["p"] == pytest.approx(stats.binomtest(int((b_ok & ~a_ok).sum()), discordant).pvalue, abs=1e-9)
    for t in (rmse, success):
        lower_is_better = not t["higher_is_better"]
        decided = t["verdict"] in DECIDED
        enough = t["n_informative"] >= t["min_informative"]
        assert decided == (enough and t["p"] < 0.05), t
        if not enough:
            assert t["ci95"] is None and (not t["n_informative"] or t["verdict"].startswith("too few"))
            continue
        lo, hi = t["ci95"]
        assert (lo <= 0 <= hi) == (not decided), t  # one test: interval and verdict agree
        if decided:
            b_is_higher = lo > 0
            assert t["verdict"] == ("B better" if b_is_higher != lower_is_better else "A better")


def test_one_success_comparison_with_its_counts():
    """Success is compared once, in ``tests``: McNemar over the pairs flagged on both sides, with
    the pair counts, and the exact conditional interval (Clopper-Pearson on the discordant pairs)."""
    flags = [(True, False)] * 9 + [(True, True)] * 3 + [(False, False)] * 1
    a = [_row(f"r{i}", 1.0, sa) for i, (sa, _) in enumerate(flags)]
    b = [_row(f"r{i}", 1.0, sb) for i, (_, sb) in enumerate(flags)]
    c = compare_reports({"rollouts": a}, {"rollouts": b})
    assert "success" not in c  # no second, disagreeing summary
    (s,) = [t for t in c["tests"] if t["metric"] == "success"]
    assert s["paired"] and s["n_pairs"] == 13 and s["pairs"] == {"both": 3, "only_a": 9, "only_b": 0, "neither": 1}
    assert s["verdict"] == "A better" and s["p"] == pytest.approx(stats.binomtest(0, 9).pvalue)
    cp = stats.binomtest(0, 9).proportion_ci(method="exact")
    assert s["ci95"] == pytest.approx([(2 * cp.low - 1) * 9 / 13, (2 * cp.high - 1) * 9 / 13])
    text = format_comparison({"a": "A", "b": "B", **c})
    assert "success: A better" in text and "only A 9, only B 0" in text and text.count("success:") == 1


def test_unpaired_success_is_fishers_central_test_with_its_odds_ratio_interval():
    a = [_row(f"a{i}", 1.0, i < 18) | {"start_frame": i} for i in range(20)]
    b = [_row(f"b{i}", 1.0, i < 4) | {"start_frame": 100 + i} for i in range(20)]
    s = _tests(a, b)["success"]
    assert not s["paired"] and s["test"] == "fisher_exact_central" and s["verdict"] == "A better"
    table = [[4, 16], [18, 2]]
    one_sided = min(stats.fisher_exact(table, alternative=alt).pvalue for alt in ("less", "greater"))
    assert s["p"] == pytest.approx(2 * one_sided)
    assert s["ci95"][1] < 1  # B's odds below A's: the interval leaves 1 out
    few = _tests([_row("a", 1.0, True) | {"start_frame": 1}], [_row("b", 1.0, False) | {"start_frame": 2}])["success"]
    assert few["verdict"] == "too few rollouts to tell (n = 1 vs 1; needs >= 4 a side)"


def test_all_tied_pairs_show_no_difference():
    t = _tests([_row(f"r{i}", 2.0) for i in range(10)], [_row(f"r{i}", 2.0) for i in range(10)])["rmse_deg"]
    assert t["verdict"] == "no difference shown" and t["p"] is None and t["ci95"] is None
    assert verdict_text(t) == "rmse_deg: no difference shown: all 10 pairs tie"


def test_sides_are_named_by_model_and_checkpoint(tmp_path):
    session = tmp_path / "run_0412"
    shutil.copytree(DEMO, session, ignore=lambda folder, names: [n for n in names if n == "rollouts"
                                                                 and Path(folder) == DEMO])
    meta = json.loads((session / "session.json").read_text())
    assert side_name(session) == f"{meta['model']['name']}@{meta['model']['checkpoint']}"
    meta["model"] = {"name": "dreamzero-so101", "checkpoint": "72K"}
    (session / "session.json").write_text(json.dumps(meta))
    assert side_name(session) == "dreamzero-so101@72K"
    (session / "rollouts" / "r0").mkdir(parents=True)
    (session / "rollouts" / "r0" / "rollout.json").write_text("{}")
    assert side_name(session / "rollouts" / "r0") == "dreamzero-so101@72K"  # a rollout: its session's
    meta["model"] = {}
    (session / "session.json").write_text(json.dumps(meta))
    assert side_name(session) == "run_0412"  # not stated: the folder
    assert side_name(tmp_path / "raw_output") == "raw_output"
