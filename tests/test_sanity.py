"""The sanity measures (chunk seams, completion, joint coherence, video break, latents) and the
``report --sanity`` verdict: exact values on made-up inputs, the demo's planted faults found where
they were planted, and the real DreamZero-SO101 outputs' figures."""

from __future__ import annotations

import json
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_processes import module_command_server
from scipy.spatial.distance import pdist, squareform

from inspector.analysis.coherence import coherence_record, coupling_error, gt_motion, phase_offset, phase_offsets
from inspector.analysis.completion import completion_step
from inspector.analysis.latents import pca_2d, silhouette
from inspector.analysis.seams import jerk, seam_jumps
from inspector.analysis.video_break import QUALITY_MEASURES, break_chunk, clip_quality, degradation
from inspector.data.session import SessionWriter, open_session
from inspector.data.video import VideoClip, encode_h264
from inspector.demo.generate import DEGRADE_FROM_CHUNK, PHASE_LAG_STEPS, SANITY_TAGS, SEAM_CHUNK, SEAM_JUMP_DEG
from inspector.report.build import format_report
from inspector.report.html import render_report_html
from inspector.report.sanity import load_thresholds, sanity_tests
from inspector.units import Units

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
TESTS = ["action-chunk fidelity", "latent stability", "joint coherence", "multi-task disambiguation",
         "autoregressive rollout"]


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def _cli(*args, cache: Path | None = None) -> subprocess.CompletedProcess:
    """``inspector *args`` as a process (reports: ``--jobs 1``, computed in that process: these tests
    are about the measures, not the pool)."""
    env = {**os.environ, **({"INSPECTOR_CACHE_DIR": str(cache)} if cache is not None else {})}
    if args[0] == "report":
        args = (*args, "--jobs", "1")
    return _run_command(*args, timeout=900, env=env)


def _in_process(capsys, *args) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``inspector *args`` run in this process: for input the
    command refuses before any work, where starting a process would be most of the test's time."""
    from inspector.cli import main

    capsys.readouterr()
    try:
        code = main([str(a) for a in args])
    except SystemExit as exc:  # argparse's way out
        code = exc.code if isinstance(exc.code, int) else 2
    out = capsys.readouterr()
    return code, out.out, out.err


# ----------------------------------------------------------------------------------------------
# The measures on inputs with known answers


def test_seam_jump_is_the_step_from_the_last_executed_action_to_the_next_chunk():
    chunks = np.zeros((4, 6, 6))
    chunks[:, :, 1] = np.arange(4)[:, None] * 3 + np.arange(6)[None] * 1.0  # each chunk continues the last
    chunks[2:, :, 0] += 12.0  # chunk 2 starts 12 deg off on shoulder_pan
    s = seam_jumps(chunks, executed_per_chunk=3)
    assert s.chunk.tolist() == [1, 2, 3]
    assert s.jump[1] == pytest.approx([12.0, 1.0, 0, 0, 0, 0])
    assert s.jump_norm[0] == pytest.approx(1.0) and s.jump_norm[1] == pytest.approx(np.hypot(12, 1))
    assert s.typical_step == pytest.approx(1.0)  # the prediction's own steps without GT
    assert s.threshold == pytest.approx(3.0)  # the floor
    assert s.flagged.tolist() == [False, True, False]


def test_seam_threshold_follows_the_gt_steps_and_gt_step_is_reported():
    gt = np.zeros((12, 6))
    gt[:, 2] = np.arange(12) * 4.0  # the real arm moves 4 deg a step
    chunks = np.stack([gt[k * 3:k * 3 + 6] if k * 3 + 6 <= 12 else np.pad(gt[k * 3:], ((0, k * 3 + 6 - 12), (0, 0)),
                                                                          mode="edge") for k in range(4)])
    chunks[3, :, 2] += 7.0  # 7 deg on top of the 4 deg step: an 11 deg jump, over 2 x 4 deg
    s = seam_jumps(chunks, 3, gt_aligned=gt)
    assert s.typical_step == pytest.approx(4.0) and s.threshold == pytest.approx(8.0)
    assert s.gt_step.tolist() == pytest.approx([4.0, 4.0, 4.0])
    assert s.jump_norm.tolist() == pytest.approx([4.0, 4.0, 11.0])
    assert s.flagged.tolist() == [False, False, True]


def test_jerk_is_the_third_difference_per_second_cubed():
    t = np.arange(10, dtype=float)
    q = np.zeros((10, 6))
    q[:, 0] = t ** 3  # third difference 6 everywhere
    assert jerk(q, fps=2.0) == pytest.approx(np.full(7, 6.0 * 8))


def test_completion_needs_a_departure_and_a_hold():
    dist = np.array([0, 0, 10, 20, 10, 1, 1, 1, 9, 1, 1, 1, 1], float)
    assert completion_step(dist, None, tol_deg=2, tol_mm=1, hold_steps=3) == 5
    assert completion_step(dist, None, tol_deg=2, tol_mm=1, hold_steps=4) == 9
    assert completion_step(dist, None, tol_deg=2, tol_mm=1, hold_steps=5) is None  # not held long enough
    assert completion_step(np.zeros(10), None, 2, 1, 3) is None  # never left: nothing done
    assert completion_step(dist, None, 2, 1, 3, away_deg=15) == 5  # away: the 20 deg step
    ee = np.where(np.arange(13) == 6, 50.0, 0.0)  # the tool point off at step 6
    assert completion_step(dist, ee, 2, 20, 3) == 9


def test_phase_offset_finds_a_known_lag_and_coupling_error_is_the_relative_angle_rms():
    t = np.arange(200) / 30.0
    gt = 40 * np.sin(2 * np.pi * t / 3.0)
    lagged = 40 * np.sin(2 * np.pi * (t - 7 / 30.0) / 3.0)
    assert phase_offset(lagged, gt, max_lag=30) == 7
    assert phase_offset(gt, lagged, max_lag=30) == -7
    assert phase_offset(np.zeros(200), np.zeros(200), 30) is None  # no GT motion: no lag
    pred, ref = np.zeros((200, 6)), np.zeros((200, 6))
    pred[:, 2] = 3.0  # elbow 3 deg off: both of its couplings 3 deg off
    assert coupling_error(pred, ref, 1, 2) == pytest.approx(3.0) and coupling_error(pred, ref, 2, 3) == pytest.approx(3.0)
    pred[:, 1] = 3.0  # the shoulder with it: that pair's relation is the GT's again
    assert coupling_error(pred, ref, 1, 2) == pytest.approx(0.0)
    q, g = np.zeros((200, 6)), np.zeros((200, 6))
    q[:, 3], g[:, 3] = lagged, gt
    record = coherence_record(q, g, np.ones(200, bool), fps=30.0)
    assert record is not None and record["phase_offset_steps"]["wrist_flex"] == 7
    assert record["phase_offset_s"]["wrist_flex"] == pytest.approx(7 / 30, abs=1e-4)
    assert record["out_of_phase"] == ["wrist_flex"]


def test_phase_offset_is_the_lag_of_the_best_pearson_correlation():
    """Every lag scored by scipy's Pearson correlation, the best kept (the smallest lag on a tie)."""
    from scipy.stats import pearsonr

    rng = np.random.default_rng(5)
    for _ in range(40):
        n = int(rng.integers(12, 300))
        gt = np.cumsum(rng.normal(size=n)) * 3
        pred = np.roll(gt, int(rng.integers(-15, 15))) + rng.normal(size=n) * rng.uniform(0, 3)
        vp, vg = np.diff(pred), np.diff(gt)
        max_lag = min(30, len(vg) // 3)
        scores = {lag: pearsonr(vp[lag:] if lag >= 0 else vp[:lag], vg[:len(vg) - lag] if lag >= 0 else vg[-lag:])[0]
                  for lag in range(-max_lag, max_lag + 1)}
        best = max(scores.values())
        expected = min((lag for lag, r in scores.items() if r >= best - 1e-12), key=lambda v: (abs(v), v))
        assert phase_offset(pred, gt, max_lag=30) == expected
        # the GT side computed once for a batch gives the same lag
        assert phase_offsets(pred[:, None], gt_motion(gt[:, None]), 30) == [expected]


def _silhouette_by_definition(x: np.ndarray, labels: list[int]) -> float:
    """Rousseeuw's definition, point by point, on scipy's distances."""
    d = squareform(pdist(x))
    lab = np.asarray(labels)
    out = []
    for i in range(len(x)):
        same = (lab == lab[i]) & (np.arange(len(x)) != i)
        if not same.any():
            out.append(0.0)
            continue
        a = d[i, same].mean()
        b = min(d[i, lab == other].mean() for other in set(labels) if other != lab[i])
        out.append((b - a) / max(a, b))
    return float(np.mean(out))


def test_silhouette_and_pca_match_their_definitions():
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.normal(0, 1, (12, 5)), rng.normal(4, 1, (9, 5)), rng.normal(-3, 2, (1, 5))])
    labels = [0] * 12 + [1] * 9 + [2]
    assert silhouette(x, labels) == pytest.approx(_silhouette_by_definition(x, labels), abs=1e-12)
    assert silhouette(x, [0] * len(x)) is None
    proj, ratio = pca_2d(x)
    centred = x - x.mean(axis=0)
    values, vectors = np.linalg.eigh(np.cov(centred.T))
    top = vectors[:, ::-1][:, :2]
    assert np.abs(proj) == pytest.approx(np.abs(centred @ top), abs=1e-9)  # the same axes, up to sign
    assert ratio == pytest.approx(values[::-1][:2] / values.sum(), abs=1e-12)


def test_video_break_is_the_chunk_from_which_it_stays_degraded(tmp_path):
    assert break_chunk([1, 1.2, 3, 1.1, 2.5, 4, 5]) == 4
    assert break_chunk([1, 1.2, 1.1]) is None
    assert break_chunk([1, np.nan, 3, np.nan, 4]) == 2
    rng = np.random.default_rng(0)
    base = np.kron(rng.integers(100, 140, (6, 8, 3)), np.ones((16, 16, 1))).astype(np.uint8)  # low-contrast blocks
    frames = []
    for k in range(6):
        sigma = 0.0 if k < 3 else 40.0
        for _ in range(4):
            frames.append(np.clip(base + rng.normal(0, sigma, base.shape), 0, 255).astype(np.uint8))
    path = tmp_path / "v.mp4"
    encode_h264(path, frames, 30.0, crf=12)
    quality = clip_quality(VideoClip(path))
    per_chunk, curve = degradation(quality, 4)
    assert quality.shape == (24, len(QUALITY_MEASURES)) and curve[0] == pytest.approx(1.0)
    assert break_chunk(curve) == 3 and curve[:3].max() < 1.5 and curve[3:].min() > 2


# ----------------------------------------------------------------------------------------------
# Latents in a session, and the verdict's configuration


def test_latents_round_trip_and_their_silhouette_in_the_report(tmp_path):
    rng = np.random.default_rng(1)
    with SessionWriter.create(tmp_path / "s", name="s", units=Units("degrees")) as w:
        for i in range(6):
            episode = i % 2
            w.add_rollout(f"r{i}", kind="single_chunk", actions=rng.normal(size=(1, 24, 6)), episode_index=episode,
                          latents=rng.normal(10.0 * episode, 1.0, size=(1, 16)))
    s = open_session(tmp_path / "s")
    assert s.rollouts["r0"].latents.shape == (1, 16)
    out = _cli("report", tmp_path / "s", "--json", "--sanity", "--no-cache")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert all(r["latents"] == {"n": 1, "dim": 16} for r in report["rollouts"])
    latents = report["latents"]
    x = np.stack([np.load(tmp_path / "s" / "rollouts" / f"r{i}" / "latents.npy")[0] for i in range(6)])
    assert latents["silhouette"] == pytest.approx(_silhouette_by_definition(x, [i % 2 for i in range(6)]), abs=1e-4)
    assert latents["n_vectors"] == 6 and latents["n_episodes"] == 2 and len(latents["points"]) == 6
    stability = report["sanity"][1]
    assert stability["test"] == "latent stability" and stability["verdict"] == "pass"


def test_bad_latents_are_one_rollout_s_error(tmp_path):
    with SessionWriter.create(tmp_path / "s", name="s", units=Units("degrees")) as w:
        for tag in ("good", "bad"):
            w.add_rollout(tag, kind="single_chunk", actions=np.zeros((1, 24, 6)), episode_index=0)
    np.save(tmp_path / "s" / "rollouts" / "bad" / "latents.npy", np.zeros((2, 3, 4)))
    out = _cli("report", tmp_path / "s", "--json", "--no-cache")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert [r["tag"] for r in report["rollouts"]] == ["good"]
    assert "latents.npy" in report["errors"]["s/bad"]


def test_sanity_config_overrides_a_threshold_and_bad_ones_are_one_line(tmp_path, capsys):
    config = tmp_path / "t.json"
    config.write_text(json.dumps({"joint_coherence": {"max_coupling_error_deg": 50}}))
    t = load_thresholds(config)
    assert t["joint_coherence"]["max_coupling_error_deg"] == 50.0
    assert t["action_chunk_fidelity"]["max_step_mse_deg2"] == 1.0  # the rest kept
    for text, what in (('{"joint_coherence": {"max_coupling": 1}}', "joint_coherence.max_coupling: unknown"),
                       ('{"nope": {}}', "nope: unknown test"), ('{"joint_coherence": {"max_coupling_error_deg": "1"}}',
                                                                   "expected a number"), ("[1", "invalid JSON"),
                       ('{"action_chunk_fidelity": {"steps": 0}}', "action_chunk_fidelity.steps: 0 is out of range")):
        config.write_text(text)
        code, stdout, stderr = _in_process(capsys, "report", DEMO, "--sanity-config", config)
        assert code == 2 and stdout == ""
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"error: {config}: ") and what in lines[0], stderr


# ----------------------------------------------------------------------------------------------
# The demo: every planted fault found where it was planted, and nowhere else


@pytest.fixture(scope="module")
def demo_report() -> dict:
    """The demo's report, through the run's metrics cache (the rows other modules' reports of the
    demo computed are read back)."""
    out = _cli("report", DEMO, "--json", "--sanity")
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def _rows(report: dict) -> dict[str, dict]:
    return {r["tag"]: r for r in report["rollouts"]}


def test_demo_seam_jump_is_flagged_at_its_chunk_only(demo_report):
    rows = _rows(demo_report)
    seams = rows["seam_jump"]["seams"]
    assert seams["flagged"] == [SEAM_CHUNK]
    assert seams["worst"]["chunk"] == SEAM_CHUNK and seams["worst"]["jump_deg"] == pytest.approx(SEAM_JUMP_DEG, abs=2.0)
    assert abs(seams["worst"]["by_joint"][0]) == pytest.approx(SEAM_JUMP_DEG, abs=1.5)  # shoulder_pan
    assert seams["worst"]["gt_step_deg"] < 2.0 and seams["jerk_p95"] > 0 and seams["gt_jerk_p95"] > 0
    # per-seam detail only for the flagged seams: the row stays small at a thousand rollouts
    assert seams["flagged_jumps"] == [{k: seams["worst"][k] for k in ("chunk", "jump_deg", "gt_step_deg")}]
    assert seams["n_seams"] == rows["seam_jump"]["n_chunks"] - 1 and "jump_deg" not in seams
    for tag, row in rows.items():
        if tag != "seam_jump" and row["seams"] is not None:
            assert row["seams"]["flagged"] == [], tag
        if row["kind"] == "single_chunk":
            assert row["seams"] is None and row["completion"] is None and row["video_break"] == {}


def test_looser_tolerances_complete_sooner_and_flag_fewer_seams_never_read_from_the_cache(demo_report):
    # the same metrics cache as the defaults' report (the run's): their rows are not read back
    out = _cli("report", DEMO / "rollouts" / "early_wander", DEMO / "rollouts" / "seam_jump", "--json",
               "--completion-tol-deg", "20", "--completion-hold-s", "0.2", "--seam-floor", "30")
    assert out.returncode == 0, out.stderr
    loose, default = _rows(json.loads(out.stdout)), _rows(demo_report)
    c, c0 = loose["early_wander"]["completion"], default["early_wander"]["completion"]
    assert (c["tol_deg"], c["hold_s"], c0["tol_deg"], c0["hold_s"]) == (20.0, 0.2, 6.0, 0.5)
    assert c["time_s"] < c0["time_s"] and c["gt_time_s"] < c0["gt_time_s"]
    s, s0 = loose["seam_jump"]["seams"], default["seam_jump"]["seams"]
    assert s0["flagged"] == [SEAM_CHUNK] and s["flagged"] == [] and s["threshold_deg"] == 30.0
    assert s["worst"] == s0["worst"]  # the jumps themselves do not depend on the flag


@pytest.mark.parametrize("flag,value,what", [("--completion-tol-deg", "-1", "must be 0 or more"),
                                             ("--seam-multiple", "abc", "must be a number"),
                                             ("--completion-hold-s", "nan", "must be a finite number")])
def test_bad_tolerances_are_one_line(flag, value, what, capsys):
    code, stdout, stderr = _in_process(capsys, "report", DEMO, flag, value)
    assert code == 2 and stdout == ""
    assert stderr.strip().splitlines() == [f"error: {flag}: {what} (got {value!r})" if what == "must be a number"
                                               else f"error: {flag}: {what} (got {value})"]


def test_every_command_computing_the_measures_takes_the_tolerances():
    from inspector.analysis.measure_settings import MeasureSettings
    from inspector.cli import build_parser, measures

    flags = ["--completion-tol-deg", "9", "--completion-tol-mm", "30", "--completion-hold-s", "1",
             "--seam-multiple", "3", "--seam-floor", "4"]
    for command in (["report", "S"], ["compare", "A", "B"], ["serve", "S"], ["export", "S"]):
        assert measures(build_parser().parse_args([*command, *flags])) == MeasureSettings(9, 30, 1, 3, 4)
        assert measures(build_parser().parse_args(command)) == MeasureSettings()


def test_the_benchmarks_switch_turns_the_measures_off_and_keys_the_cache_apart(monkeypatch):
    from inspector.analysis.measure_settings import MeasureSettings
    from inspector.analysis.sanity import sanity_measures
    from inspector.analysis.timeline import build_timeline
    from inspector.cache import rollout_key
    from inspector.data.session import load_session_rollout

    rollout = load_session_rollout(open_session(DEMO), "seam_jump")
    tl = build_timeline(rollout)
    on = sanity_measures(tl, {})
    key = rollout_key(tl.rollout, tl.gt, 2.0, MeasureSettings())
    assert on["seams"] is not None and on["completion"] is not None and on["joint_coherence"] is not None
    assert key != rollout_key(tl.rollout, tl.gt, 2.0, MeasureSettings(seam_floor_deg=4.0))
    monkeypatch.setenv("INSPECTOR_SANITY_MEASURES", "off")
    assert sanity_measures(tl, {}) == {"seams": None, "completion": None, "joint_coherence": None,
                                       "video_break": {}, "video_degradation": {}, "latents": None}
    assert rollout_key(tl.rollout, tl.gt, 2.0, MeasureSettings()) != key


def test_demo_early_completion_and_its_wandering_tail(demo_report):
    rows = _rows(demo_report)
    c = rows["early_wander"]["completion"]
    assert c["early"] and c["time_s"] == pytest.approx(11.87, abs=0.2) and c["gt_time_s"] == pytest.approx(13.7, abs=0.1)
    assert c["drift_after"] > 5 * c["drift_before"] and c["max_after_deg"] > 25  # wanders 30 deg on shoulder_pan
    assert c["tempo"] == pytest.approx(c["gt_time_s"] / c["time_s"], abs=1e-3)
    for tag in ("prompt_train", "overrun_60chunks", "limits_wrist", "video_ahead_1s", "prompt_novel"):
        other = rows[tag]["completion"]
        assert other["time_s"] == pytest.approx(other["gt_time_s"], abs=0.3), tag  # on time
        assert other["drift_after"] < 1.0 and not other["early"], tag
    assert [t for t, r in rows.items() if r["completion"] and r["completion"]["early"]] == ["early_wander"]
    assert rows["tempo_0.8x"]["completion"]["time_s"] is None  # too slow to get there
    assert rows["overrun_60chunks"]["completion"]["gt_duration_s"] == pytest.approx(409 / 30, abs=1e-3)


def test_demo_phase_lag_is_found_on_its_joint(demo_report):
    rows = _rows(demo_report)
    coherence = rows["phase_lag_wrist"]["joint_coherence"]
    assert coherence["phase_offset_steps"]["wrist_flex"] == PHASE_LAG_STEPS
    assert coherence["phase_offset_s"]["wrist_flex"] == pytest.approx(PHASE_LAG_STEPS / 30, abs=1e-3)
    assert coherence["out_of_phase"] == ["wrist_flex"]
    assert all(abs(v) <= 1 for j, v in coherence["phase_offset_steps"].items() if j != "wrist_flex" and v is not None)
    assert coherence["coupling_error_deg"]["elbow_flex-wrist_flex"] > 3 * coherence["coupling_error_deg"][
        "shoulder_lift-elbow_flex"]
    # out of phase elsewhere only where the whole rollout runs at another speed (tempo faults)
    flagged = {t for t, r in rows.items() if r["joint_coherence"] and r["joint_coherence"]["out_of_phase"]}
    assert flagged == {"phase_lag_wrist", "tempo_0.8x", "early_wander"}
    assert rows["bias_elbow"]["joint_coherence"]["coupling_error_deg"]["shoulder_lift-elbow_flex"] > 5  # its bias


def test_demo_video_break_is_at_the_planted_chunk_only(demo_report):
    for row in demo_report["rollouts"]:  # the break, its cause and its curve; the per-chunk measures stay out
        assert all(set(d) == {"break_chunk", "cause", "degradation"} for d in row["video_degradation"].values())
    rows = _rows(demo_report)
    assert rows["video_degrades"]["video_break"] == {"front": DEGRADE_FROM_CHUNK, "wrist": DEGRADE_FROM_CHUNK}
    assert {d["cause"] for d in rows["video_degrades"]["video_degradation"].values()} == {"noise"}
    curve = rows["video_degrades"]["video_degradation"]["front"]["degradation"]
    assert max(curve[:DEGRADE_FROM_CHUNK]) < 1.5 and min(curve[DEGRADE_FROM_CHUNK:]) > 2.0
    for tag, row in rows.items():
        if tag != "video_degrades" and row["kind"] == "autoregressive":
            assert row["video_break"] == {"front": None, "wrist": None}, tag


def test_no_demo_rollout_s_video_is_called_frozen(demo_report):
    """The negative control of the frozen-video check (tests/test_video_action.py), on every rollout
    of the demo: none of their videos stands still while the joints move."""
    rows = _rows(demo_report)
    assert len(rows) == 17
    for tag, row in rows.items():
        assert set(row["video_action"]) == {"front", "wrist"}, tag
        for view, entry in row["video_action"].items():
            assert entry["frozen"] is not True, (tag, view)
            if row["kind"] == "autoregressive":  # measured, not merely unknown (a single chunk may match nothing)
                assert entry["frozen"] is False, (tag, view)


def test_demo_sanity_verdict(demo_report):
    sanity = demo_report["sanity"]
    assert [t["test"] for t in sanity] == TESTS
    assert [t["verdict"] for t in sanity] == ["pass", "not measurable", "partial", "partial", "partial"]
    # the six single chunks state no distribution: all are the verdict's, and say so
    assert sanity[0]["figure"].startswith("mean curve's largest early step 0.30 deg^2 (step 8) over 6 samples "
                                          "(6 with no stated distribution)")
    assert sanity[0]["rows"]["in_verdict"] == 6 and sanity[0]["rows"]["unstated"] == 6
    # coupling decides 8 rollouts spanning >= 90% of their episode; the shorter ones are counted aside
    assert sanity[2]["figure"].startswith("4/8 rollouts spanning their episode within")
    assert "set aside: 9 with GT joints over at most 51% of their episode" in sanity[2]["figure"]
    assert sanity[1]["figure"] == "not measurable: no latents"
    assert "collapse from chunk 2" in sanity[3]["figure"] and "chunk 0 14.60 deg" in sanity[3]["figure"]
    assert sanity[4]["figure"].startswith("completion: 6/11 complete in imagination; video: 20 views hold")
    assert "breaks before the episode's end: video_degrades front at chunk 12" in sanity[4]["figure"]
    assert all(t["threshold"] for t in sanity)
    assert demo_report["sanity_headline"] == "sanity 1/5 (3 partial, 1 not measurable)"
    assert demo_report["latents"] is None
    m = demo_report["aggregate"]["sanity_measures"]
    assert (m["rollouts_with_flagged_seams"], m["flagged_seams"], m["video_views_broken"]) == (1, 1, 2)
    assert sanity_tests(demo_report) == sanity  # the verdict is a function of the report alone


def test_demo_phase_lag_decides_joint_coherence_once_its_half_episode_counts(demo_report):
    """phase_lag_wrist runs 25 of the episode's 49 chunks: set aside at the default share (90%),
    judged at 50%, where its wrist 10 steps late puts the elbow-wrist pair 0.33 s off the GT's."""
    from inspector.report.sanity import default_thresholds, joint_coherence

    t = default_thresholds()["joint_coherence"]
    assert "phase_lag_wrist" not in joint_coherence(demo_report["rollouts"], t)["figure"]
    half = joint_coherence(demo_report["rollouts"], {**t, "min_episode_share": 0.5})
    assert "phase_lag_wrist elbow_flex-wrist_flex -0.33 s" in half["figure"]
    assert half["rows"]["in_verdict"] == 10  # and seam_jump, 25 chunks too


def test_demo_text_report_shows_the_measures_and_the_verdict(demo_report):
    text = format_report(demo_report)  # what report --sanity prints from the same report
    lines = text.splitlines()
    table = lines[lines.index(next(line for line in lines if line.startswith("Sanity measures"))):]
    seam = next(line for line in table if line.startswith("seam_jump "))
    assert seam.split()[1] == str(SEAM_CHUNK)
    assert any(line.startswith("video_degrades ") and "front chunk 12" in line for line in table)
    assert any(line.startswith("early_wander ") and " 11.87 " in line for line in table)
    assert "Sanity tests: sanity 1/5 (3 partial, 1 not measurable)" in text
    assert set(SANITY_TAGS) <= {line.split()[0] for line in table if line.strip()}


# ----------------------------------------------------------------------------------------------
# The real DreamZero-SO101 outputs


def test_real_outputs_sanity_figures(dreamzero_dir, tmp_path):
    out = _cli("report", dreamzero_dir, "--json", "--sanity", cache=tmp_path)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    rows = _rows(report)
    for tag in ("ep000_train", "ep000_novel"):
        seams = rows[tag]["seams"]
        # no GT joints: the threshold is twice the prediction's own fastest steps (p95 ~2.5 deg)
        assert seams["gt_jerk_p95"] is None and seams["threshold_deg"] == pytest.approx(5.1, abs=0.1)
        # the first chunks' splices jump 10-14 deg (shoulder_lift against elbow_flex)
        assert seams["worst"]["chunk"] == 2 and 12 < seams["worst"]["jump_deg"] < 14.5
        assert {1, 2, 3} <= set(seams["flagged"]) and len(seams["flagged"]) > 15
        assert rows[tag]["completion"] is None and rows[tag]["joint_coherence"] is None  # no GT joints
        assert set(rows[tag]["video_break"]) == {"front", "top", "gripper"}
    # the no-reference curve sees the front view lose its sharpness long before the episode's end
    # (past it from chunk 37): the imagined camera closes in on the cube
    assert rows["ep000_train"]["video_break"]["front"] == 9 and rows["ep000_novel"]["video_break"]["front"] == 8
    # the gripper view blurs as it nears the cube and its colours never come back (test_video_break.py)
    assert rows["ep000_train"]["video_break"]["gripper"] == 5
    assert rows["f084"]["joint_coherence"]["coupling_error_deg"] == pytest.approx(
        {"shoulder_lift-elbow_flex": 2.9636, "elbow_flex-wrist_flex": 4.125}, abs=1e-3)
    # the verdicts on these rows: tests/test_sanity_verdict.py


def test_demo_html_page_has_the_verdict_the_measures_and_the_break_curves(demo_report):
    page = render_report_html(demo_report)
    section = page[page.index("<h2>Sanity</h2>"):page.index("<h2>Definitions</h2>")]
    verdicts = re.findall(r'<tr class="verdict-[^"]+"><td class=t>([^<]+)</td><td class=t><b>([^<]+)</b>', section)
    assert verdicts == [(t["test"], t["verdict"]) for t in demo_report["sanity"]]
    assert "sanity 1/5 (3 partial, 1 not measurable)" in section
    measures = section[section.index('id="sanity-measures"'):]
    seam_row = re.search(r"<tr><td class=t>seam_jump</td><td class=t>([^<]+)</td>", measures)
    assert seam_row is not None and seam_row.group(1) == str(SEAM_CHUNK)
    assert 'id="video-break"' in section and "video_degrades front: break chunk 12" in section
    assert 'id="latents"' not in section  # the demo has no latents


def test_recording_carries_seams_completion_and_video_break(tmp_path):
    from test_export import Recording, rrd_verify

    from inspector.cli import main
    from inspector.export.layout import CHUNK, MARKERS

    for tag in ("seam_jump", "video_degrades"):  # in this process, as the command writes one rollout
        assert main(["export", str(DEMO), "--rollout", tag, "-o", str(tmp_path / f"{tag}.rrd"), "--no-cache"]) == 0
        rrd_verify(tmp_path / f"{tag}.rrd")
    seam = Recording(tmp_path / "seam_jump.rrd")
    chunks, _ = seam.scalars(f"{MARKERS}/seam_flagged", order_by=CHUNK)
    assert chunks.tolist() == [SEAM_CHUNK]
    at, jumps = seam.scalars("plots/seams/jump", order_by=CHUNK)
    assert at.tolist() == list(range(1, 25)) and int(np.argmax(jumps)) + 1 == SEAM_CHUNK
    assert not seam.has(f"{MARKERS}/video_break/front") and not seam.has(f"{MARKERS}/completion")
    video = Recording(tmp_path / "video_degrades.rrd")
    for view in ("front", "wrist"):
        chunks, _ = video.scalars(f"{MARKERS}/video_break/{view}", order_by=CHUNK)
        assert chunks.tolist() == [DEGRADE_FROM_CHUNK]
        _, curve = video.scalars(f"plots/video_degradation/{view}", order_by=CHUNK)
        assert len(curve) == 18 and curve[DEGRADE_FROM_CHUNK:].min() > 2


def test_app_marks_completion_seams_and_video_breaks_where_the_report_finds_them():
    """The app's timeline and drift plot marks (inspector.app._sanity_card.sanity_marks): the
    planted early completion of ``early_wander`` and the video break of ``video_degrades``."""
    from inspector.analysis.timeline import build_timeline
    from inspector.app._sanity_card import sanity_marks, slider_marks
    from inspector.data.session import load_session_rollout, read_session_with_gt

    session = read_session_with_gt(DEMO, None)
    wander = build_timeline(load_session_rollout(session, "early_wander"))
    marks = sanity_marks(wander)
    completes = [step for step, label, _ in marks if label == "completes"]
    assert len(completes) == 1 and completes[0] / wander.fps == pytest.approx(11.87, abs=0.01)
    assert not [m for m in marks if m[1] == "seam flagged"]
    assert slider_marks(wander, marks) == ((int(wander.step_chunk[completes[0]]), "done"),)

    degrades = build_timeline(load_session_rollout(session, "video_degrades"))
    assert not [m for m in sanity_marks(degrades) if "video" in m[1]]  # no video metrics yet: no break known
    degrades.video_metrics("front")
    breaks = [(step, label) for step, label, _ in sanity_marks(degrades) if "video" in label]
    assert breaks == [(int(degrades.chunk_start_step[DEGRADE_FROM_CHUNK]), "front video breaks")]
