"""The five tests of ``report --sanity`` on the rows the seed report defines them on: chunk
fidelity on the training distribution (zero-shot samples a line of their own) under either rule,
joint coherence only on rollouts spanning their episode with GT joints and decided by the phase
offsets too, the autoregressive test's two halves, and every threshold of a config range-checked,
hostile config files refused in one line."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from cli_processes import module_command_server

from inspector.analysis.coherence import coherence_record
from inspector.data.session import SessionWriter
from inspector.errors import InspectorError
from inspector.report.sanity import RANGES, action_chunk_fidelity, autoregressive_rollout, default_thresholds, headline, joint_coherence, load_thresholds
from inspector.units import JOINT_NAMES, Units

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"

_command_server, _run_command = module_command_server()


def _single(tag: str, mse, distribution: str | None = None) -> dict:
    return {"tag": tag, "kind": "single_chunk", "per_step_mse": None if mse is None else list(map(float, mse)),
            "distribution": distribution}


# ----------------------------------------------------------------------------------------------
# Test 1: action-chunk fidelity


def test_fidelity_is_judged_on_the_training_distribution_and_zero_shot_rows_get_their_own_line():
    t = default_thresholds()["action_chunk_fidelity"]
    rng = np.random.default_rng(0)
    train, far = rng.uniform(0.1, 0.6, (3, 24)), rng.uniform(100, 400, (2, 24))
    rows = [_single("t0", train[0], "training"), _single("t1", train[1], "training"), _single("u", train[2]),
            _single("z0", far[0], "zero-shot"), _single("z1", far[1], "zero-shot"), _single("nogt", None, "training"),
            _single("odd", train[0], "simulation")]
    test = action_chunk_fidelity(rows, t)
    curve = train[:, :8].mean(axis=0)
    assert test["verdict"] == "pass"
    assert test["figure"].startswith(f"mean curve's largest early step {curve.max():.2f} deg^2 (step {curve.argmax() + 1}) "
                                     "over 3 samples (1 with no stated distribution)")
    assert (f"zero-shot (not in the verdict): 2 samples, mean curve's largest early step "
            f"{far[:, :8].mean(axis=0).max():.2f} deg^2, 0/2 samples within") in test["figure"]
    assert "set aside: 1 without per-step MSE (no GT joints), 1 of another stated distribution" in test["figure"]
    assert test["rows"] == {"in_verdict": 3, "training": 2, "unstated": 1, "zero_shot": 2, "other_distribution": 1,
                            "no_per_step_mse": 1, "shorter_than_steps": 0}
    # the same samples with nothing stated pool, zero-shot ones included, and fail
    assert action_chunk_fidelity([{**r, "distribution": None} for r in rows], t)["verdict"] == "fail"
    # zero-shot samples alone judge nothing
    alone = action_chunk_fidelity(rows[3:5], t)
    assert alone["verdict"] == "not measurable" and "zero-shot (not in the verdict): 2 samples" in alone["figure"]


def test_mean_curve_and_per_sample_rules_compare_different_things():
    t = default_thresholds()["action_chunk_fidelity"]
    assert t["rule"] == "mean_curve"  # the seed report's claim is about the mean curve
    spike, calm = np.full(24, 0.2), np.full(24, 0.2)
    spike[2] = 1.5  # one sample over 1 deg^2 at step 3: the mean curve (0.85) is not
    rows = [_single("spike", spike), _single("calm", calm)]
    mean = action_chunk_fidelity(rows, t)
    assert mean["verdict"] == "pass" and mean["figure"].startswith("mean curve's largest early step 0.85 deg^2 (step 3)")
    assert "the mean per-step MSE curve" in mean["threshold"] and "steps 1-8, < 1 deg^2" in mean["threshold"]
    per = action_chunk_fidelity(rows, {**t, "rule": "per_sample"})
    assert per["verdict"] == "partial" and per["figure"].startswith("1/2 samples within")
    assert "each training-distribution single chunk's largest per-step MSE" in per["threshold"]
    # only the first `steps` steps count
    late = np.full(24, 0.2)
    late[8] = 50.0
    assert action_chunk_fidelity([_single("late", late)], t)["verdict"] == "pass"
    assert action_chunk_fidelity([_single("late", late)], {**t, "steps": 9})["verdict"] == "fail"
    # a sample with fewer steps than compared is set aside and counted, never padded
    short = action_chunk_fidelity([_single("short", [0.1] * 5), _single("calm", calm)], t)
    assert short["rows"]["shorter_than_steps"] == 1 and short["rows"]["in_verdict"] == 1
    assert "set aside: 1 shorter than 8 steps" in short["figure"]


@pytest.mark.slow
def test_real_single_chunks_with_their_stated_distributions(dreamzero_dir, tmp_path):
    """The real samples in a session that states their distribution: the training sample decides,
    the zero-shot ones (another dataset, 100-400 deg^2 early) are their own line."""
    samples = {"train_ep0": ("demo/train_ep0", "training"), "train_ep0_again": ("demo/train_ep0", None),
               "f000": ("zeroshot_chunk/f000", "zero-shot"), "f084": ("zeroshot_chunk/f084", "zero-shot"),
               "f169": ("zeroshot_chunk/f169", "zero-shot")}
    metas = {tag: json.loads((dreamzero_dir / folder / "meta.json").read_text()) for tag, (folder, _) in samples.items()}
    with SessionWriter.create(tmp_path / "s", name="s", units=Units("degrees")) as w:
        for tag, (_, distribution) in samples.items():
            w.add_rollout(tag, kind="single_chunk", actions=np.asarray(metas[tag]["actions_pred"])[None],
                          gt_actions=np.asarray(metas[tag]["actions_gt"]), executed_per_chunk=24,
                          extra={"distribution": distribution} if distribution else None)
    config = tmp_path / "per_sample.json"
    config.write_text(json.dumps({"action_chunk_fidelity": {"rule": "per_sample"}}))
    out = _run_command("report", tmp_path / "s", "--json", "--sanity", "--no-cache", "--jobs", "1", timeout=600)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    rows = {r["tag"]: r for r in report["rollouts"]}
    assert {tag: rows[tag]["distribution"] for tag in samples} == {tag: d for tag, (_, d) in samples.items()}
    for tag, meta in metas.items():  # the seed's own per-step MSE, recomputed from its actions
        assert rows[tag]["per_step_mse"] == pytest.approx(meta["per_step_mse"], rel=1e-6, abs=1e-9)
    fidelity = report["sanity"][0]
    train_curve = np.asarray(metas["train_ep0"]["per_step_mse"][:8])
    zero_curve = np.mean([metas[t]["per_step_mse"][:8] for t in ("f000", "f084", "f169")], axis=0)
    assert fidelity["verdict"] == "pass" and train_curve.max() < 1.0
    assert fidelity["figure"].startswith(f"mean curve's largest early step {train_curve.max():.2f} deg^2 "
                                         f"(step {train_curve.argmax() + 1}) over 2 samples (1 with no stated distribution)")
    assert f"zero-shot (not in the verdict): 3 samples, mean curve's largest early step {zero_curve.max():.2f} deg^2" \
        in fidelity["figure"]
    # the same report under the per-sample rule
    out = _run_command("report", tmp_path / "s", "--json", "--sanity-config", config, "--jobs", "1", timeout=600)
    assert out.returncode == 0, out.stderr
    per = json.loads(out.stdout)["sanity"][0]
    assert per["verdict"] == "pass" and per["figure"].startswith("2/2 samples within (1 with no stated distribution)")


@pytest.mark.slow
def test_real_outputs_verdicts_on_the_rows_they_define(dreamzero_dir, tmp_path):
    """``report --sanity`` on the real DreamZero-SO101 outputs as they ship (whatever their importer
    states about each sample's distribution, and wherever the break detector puts the breaks)."""
    out = _run_command("report", dreamzero_dir, "--json", "--sanity", "--jobs", "1", timeout=600,
                       env={**os.environ, "INSPECTOR_CACHE_DIR": str(tmp_path)})
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    rows = {r["tag"]: r for r in report["rollouts"]}
    sanity = {t["test"]: t for t in report["sanity"]}
    # test 1: the single chunks not stated zero-shot decide, on the mean curve of their first 8 steps
    single = [r for r in report["rollouts"] if r["kind"] == "single_chunk" and r["per_step_mse"]]
    decide = [r for r in single if r["distribution"] != "zero-shot"]
    curve = np.mean([r["per_step_mse"][:8] for r in decide], axis=0)
    fidelity = sanity["action-chunk fidelity"]
    assert fidelity["rows"]["in_verdict"] == len(decide) and fidelity["rows"]["zero_shot"] == len(single) - len(decide)
    assert fidelity["verdict"] == ("pass" if curve.max() < 1.0 else "fail")
    assert fidelity["figure"].startswith(f"mean curve's largest early step {curve.max():.2f} deg^2")
    assert rows["train_ep0"]["per_step_mse"][0] == pytest.approx(0.70, abs=0.005)  # train_ep0 alone: within
    if len(decide) < len(single):
        assert f"zero-shot (not in the verdict): {len(single) - len(decide)} samples" in fidelity["figure"]
    # test 3: single chunks of 24 steps and rollouts without GT joints: nothing spans an episode
    # with GT joints, and the figure says what is missing
    coherence = sanity["joint coherence"]
    assert coherence["verdict"] == "not measurable" and coherence["rows"]["in_verdict"] == 0
    assert "needs GT joints over a whole episode" in coherence["figure"] and "pass --dataset" in coherence["figure"]
    assert "2 spanning their episode without GT joints" in coherence["figure"]
    # no lag at the edge of the search window is reported: f169's wrist_flex peaked at +7 of +-7
    for row in report["rollouts"]:
        j = row["joint_coherence"]
        if j is not None:
            assert all(abs(j["phase_offset_steps"][k]) < j["phase_window_steps"] for k in j["out_of_phase"]), row["tag"]
    f169 = rows["f169"]["joint_coherence"]
    assert f169["phase_window_steps"] == 7 and f169["phase_offset_steps"]["wrist_flex"] is None
    assert "edge" in f169["phase_undetermined"]["wrist_flex"] and f169["out_of_phase"] == []
    assert "chunk 0 0.21 deg, never collapse" in sanity["multi-task disambiguation"]["figure"]
    # test 5: completion needs GT joints; the video half is given, each break placed against the
    # episode's end: 328 frames / 9 executed steps a chunk, so chunk 37 is the first past it
    auto = sanity["autoregressive rollout"]
    assert auto["verdict"] == "not measurable" and auto["figure"].startswith("completion not measurable: no GT joints")
    for tag in ("ep000_train", "ep000_novel"):
        row = rows[tag]
        first_after = -(-(row["episode_length"] - row["start_frame"]) // row["steps_per_chunk"])
        assert first_after == 37 == row["n_chunks"] - row["post_episode_chunks"]
        for view, b in row["video_break"].items():
            if b is not None:
                half = "before" if b < first_after else "after"
                listed = auto["figure"].split(f"breaks {half} the episode's end: ")[1].split(";")[0]
                assert f"{tag} {view} at chunk {b} (episode over from chunk 37)" in listed
    assert [t["verdict"] for t in report["sanity"]][1:4] == ["not measurable", "not measurable", "fail"]
    assert report["sanity_headline"] == headline(report["sanity"])


# ----------------------------------------------------------------------------------------------
# Test 3: joint coherence


def _gt(n: int) -> np.ndarray:
    t = np.arange(n) / 30.0
    return np.stack([20 * np.sin(2 * np.pi * t / (2.5 + 0.7 * j) + j) for j in range(6)], axis=1)


def _delayed(gt: np.ndarray, steps: dict[str, int]) -> np.ndarray:
    """``gt`` with the named joints running ``steps`` behind (the first values held)."""
    pred = gt.copy()
    for joint, lag in steps.items():
        j = JOINT_NAMES.index(joint)
        pred[:, j] = np.concatenate([np.full(lag, gt[0, j]), gt[:len(gt) - lag, j]]) if lag else gt[:, j]
    return pred


def _rollout(tag: str, pred: np.ndarray, gt: np.ndarray, n_chunks: int, per_chunk: int = 9, episode: int = 441,
             start: int = 0) -> dict:
    return {"tag": tag, "kind": "autoregressive" if n_chunks > 1 else "single_chunk", "n_chunks": n_chunks,
            "steps_per_chunk": per_chunk, "start_frame": start, "episode_length": episode,
            "joint_coherence": coherence_record(pred, gt, np.ones(len(gt), bool), fps=30.0)}


def test_joint_coherence_is_not_measurable_on_single_chunks_and_says_what_is_missing():
    t = default_thresholds()["joint_coherence"]
    gt = _gt(441)
    chunks = [_rollout(f"f{s}", gt[s:s + 24], gt[s:s + 24], 1, per_chunk=24, start=s) for s in (0, 100, 200)]
    no_gt = {**_rollout("long", gt, gt, 49), "joint_coherence": None}
    test = joint_coherence([*chunks, no_gt], t)
    assert test["verdict"] == "not measurable"
    assert test["figure"] == ("not measurable: needs GT joints over a whole episode (>= 90% of it): pass --dataset for "
                              "rollouts that run their episode (3 with GT joints over at most 5% of their episode, "
                              "1 spanning their episode without GT joints)")
    assert test["rows"] == {"in_verdict": 0, "short_with_gt": 3, "spanning_without_gt": 1, "episode_length_unknown": 0}


def test_phase_offsets_decide_joint_coherence():
    gt = _gt(441)
    loose = {**default_thresholds()["joint_coherence"], "max_coupling_error_deg": 360.0}  # the phase alone decides
    in_step = _rollout("in_step", gt, gt, 49)
    wrist_late = _rollout("wrist_late", _delayed(gt, {"wrist_flex": 10}), gt, 49)
    all_late = _rollout("all_late", _delayed(gt, dict.fromkeys(JOINT_NAMES, 10)), gt, 49)  # slow, yet coherent
    assert wrist_late["joint_coherence"]["phase_offset_steps"]["wrist_flex"] == 10
    test = joint_coherence([in_step, wrist_late, all_late], loose)
    assert test["verdict"] == "partial" and test["figure"].startswith("2/3 rollouts spanning their episode within")
    assert "pair lags off the GT's: wrist_late elbow_flex-wrist_flex -0.33 s" in test["figure"]
    assert joint_coherence([in_step, wrist_late, all_late], {**loose, "max_pair_lag_s": 0.4})["verdict"] == "pass"
    # the same lag on a rollout covering half its episode decides nothing until the share allows it
    half = _rollout("half", _delayed(gt, {"wrist_flex": 10})[:225], gt[:225], 25)
    assert joint_coherence([in_step, half], loose)["verdict"] == "pass"
    assert joint_coherence([in_step, half], {**loose, "min_episode_share": 0.5})["verdict"] == "partial"


def test_a_lag_at_the_window_edge_is_not_determined_and_never_a_finding():
    gt = _gt(441)
    late = _delayed(gt, {"wrist_flex": 12})
    # a single 24-step chunk searches +-7 steps: the correlation still rises at +7
    chunk = coherence_record(late[100:124], gt[100:124], np.ones(24, bool), fps=30.0)
    assert chunk is not None and chunk["phase_window_steps"] == 7
    assert chunk["phase_offset_steps"]["wrist_flex"] is None and chunk["phase_offset_s"]["wrist_flex"] is None
    assert chunk["phase_undetermined"]["wrist_flex"] == "best lag at the edge of the +-7-step window"
    assert chunk["out_of_phase"] == []
    # spanning the episode, the same lag is measured and decides
    whole = coherence_record(late, gt, np.ones(441, bool), fps=30.0)
    assert whole is not None and whole["phase_offset_steps"]["wrist_flex"] == 12 and whole["out_of_phase"] == ["wrist_flex"]
    row = {"tag": "edge", "kind": "autoregressive", "n_chunks": 49, "steps_per_chunk": 9, "start_frame": 0,
           "episode_length": 441, "joint_coherence": {**whole, **{k: chunk[k] for k in ("phase_offset_steps", "phase_offset_s")},
                                                      "coupling_error_deg": {"a-b": 0.1}}}
    test = joint_coherence([row], default_thresholds()["joint_coherence"])
    assert test["verdict"] == "pass" and "1 pair lag not determined" in test["figure"]


# ----------------------------------------------------------------------------------------------
# Test 5: autoregressive rollout, in two halves


def _chained(tag: str, done: bool | None, breaks: dict, n_chunks: int = 60, post: int | None = 14) -> dict:
    return {"tag": tag, "kind": "autoregressive", "seams": {"flagged": []}, "n_chunks": n_chunks,
            "post_episode_chunks": post, "video_break": breaks,
            "completion": None if done is None else {"time_s": 10.0 if done else None}}


@pytest.mark.parametrize("rows,verdict,says", [
    ([_chained("a", True, {"front": None}), _chained("b", True, {"front": None})], "pass",
     "completion: 2/2 complete in imagination; video: 2 views hold"),
    ([_chained("a", True, {"front": 50}), _chained("b", True, {"front": None})], "partial",
     "breaks after the episode's end: a front at chunk 50 (episode over from chunk 46)"),
    ([_chained("a", True, {"front": 20}), _chained("b", True, {"front": None})], "partial",
     "breaks before the episode's end: a front at chunk 20 (episode over from chunk 46)"),
    ([_chained("a", True, {"front": 12}, n_chunks=18, post=0)], "partial",
     "breaks before the episode's end: a front at chunk 12 (the episode outlasts the rollout)"),
    ([_chained("a", True, {"front": 20}, post=None)], "partial", "breaks, episode end unknown: a front at chunk 20"),
    ([_chained("a", True, {"front": None}), _chained("b", False, {"front": None})], "partial",
     "completion: 1/2 complete in imagination"),
    ([_chained("a", False, {"front": None})], "fail", "completion: 0/1 complete"),
    ([_chained("a", None, {"front": 50})], "not measurable",
     "completion not measurable: no GT joints (pass --dataset); video: 0 views hold; breaks after the episode's end"),
])
def test_autoregressive_rollout_reports_completion_and_where_the_video_breaks(rows, verdict, says):
    test = autoregressive_rollout(rows, default_thresholds()["autoregressive_rollout"])
    assert test["verdict"] == verdict and says in test["figure"], test["figure"]


def test_completion_share_threshold():
    rows = [_chained("a", True, {"front": None}), _chained("b", False, {"front": None})]
    assert autoregressive_rollout(rows, {"min_completed_fraction": 0.5})["verdict"] == "pass"


# ----------------------------------------------------------------------------------------------
# The config: every value range-checked where it is read, hostile files refused


@pytest.mark.parametrize("config,what", [
    ({"action_chunk_fidelity": {"steps": 0}}, "action_chunk_fidelity.steps: 0 is out of range: must be an integer >= 1 and <= 10000"),
    ({"action_chunk_fidelity": {"steps": 2.5}}, "action_chunk_fidelity.steps: 2.5 is out of range: must be an integer"),
    ({"action_chunk_fidelity": {"max_step_mse_deg2": 0}}, "max_step_mse_deg2: 0 is out of range: must be a number > 0"),
    ({"action_chunk_fidelity": {"rule": "median"}}, "action_chunk_fidelity.rule: expected one of 'mean_curve', 'per_sample', found 'median'"),
    ({"joint_coherence": {"min_episode_share": 1.5}}, "joint_coherence.min_episode_share: 1.5 is out of range: must be a number > 0 and <= 1"),
    ({"joint_coherence": {"max_pair_lag_s": -0.1}}, "joint_coherence.max_pair_lag_s: -0.1 is out of range"),
    ({"autoregressive_rollout": {"min_completed_fraction": 0}}, "min_completed_fraction: 0 is out of range: must be a number > 0"),
    ({"latent_stability": {"partial_silhouette": 0.6}}, "latent_stability.partial_silhouette: 0.6 is above pass_silhouette 0.5"),
    ({"multi_task_disambiguation": {"min_first_chunk_distance_deg": 10 ** 40}}, "min_first_chunk_distance_deg: 100000000000... is out of range"),
    ({"joint_coherence": {"max_coupling_error_deg": True}}, "joint_coherence.max_coupling_error_deg: expected a number, found True"),
    ({"joint_coherence": 3}, "joint_coherence: expected an object of thresholds, found int"),
])
def test_config_values_are_range_checked(tmp_path, config, what):
    path = tmp_path / "t.json"
    path.write_text(json.dumps(config))
    with pytest.raises(InspectorError) as caught:
        load_thresholds(path)
    assert caught.value.file == str(path) and what in caught.value.what, caught.value.what


def test_every_threshold_has_a_range_and_values_past_it_are_refused(tmp_path):
    defaults = default_thresholds()
    assert {t: set(keys) for t, keys in RANGES.items()} == {t: set(keys) for t, keys in defaults.items()}
    path = tmp_path / "t.json"
    for test, keys in RANGES.items():
        for key, allowed in keys.items():
            bad = ["neither"] if isinstance(allowed, tuple) else [allowed.hi + 1, allowed.lo - 1] + ([allowed.lo] if allowed.above else [])
            for value in bad:
                path.write_text(json.dumps({test: {key: value}}))
                with pytest.raises(InspectorError, match=f"{test}.{key}: "):
                    load_thresholds(path)
            path.write_text(json.dumps({test: {key: defaults[test][key]}}))  # its default is in range
            assert load_thresholds(path) == defaults


def _hostile(kind: str, tmp_path: Path) -> Path:
    path = tmp_path / f"{kind}.json"
    if kind == "dev_zero":
        path.symlink_to("/dev/zero")
    elif kind == "fifo":
        os.mkfifo(path)  # no writer: reading it would block forever
    elif kind == "deep":
        path.write_text("[" * 100_000 + "]" * 100_000)
    elif kind == "deep_object":
        path.write_text('{"joint_coherence": ' + '{"a": ' * 100_000 + "1" + "}" * 100_001)
    else:
        path.mkdir()
    return path


@pytest.mark.slow
@pytest.mark.parametrize("kind,what", [("dev_zero", "is a character device, not a regular file"),
                                       ("fifo", "is a FIFO, not a regular file"), ("deep", "invalid JSON (RecursionError"),
                                       ("deep_object", "invalid JSON (RecursionError"), ("directory", "directory")])
def test_hostile_sanity_configs_are_one_line_errors(tmp_path, kind, what):
    config = _hostile(kind, tmp_path)
    out = _run_command("report", DEMO, "--sanity", "--sanity-config", config, timeout=120)
    assert out.returncode == 2 and out.stdout == "", out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {config}: ") and what in lines[0], out.stderr
