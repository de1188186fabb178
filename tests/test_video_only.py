"""Rollouts without joints: a session rollout with no ``actions.npy``, and lerobot-eval's default
output (no ``--eval.recording``), read as video-only rollouts by the importer, report, app and
exporter.

The evaluation output is written as ``lerobot_eval.py`` writes it (tests/eval_outputs.py), its
predicted video's first view being the render's frame of the same step plus a few grey levels, so
every check can tell which frame is paired with which.
"""

from __future__ import annotations

import json
import math
import subprocess

import numpy as np
import pytest
from cli_processes import module_command_server
from eval_outputs import PREDICTED_OFFSET, predicted_level, render_level, write_eval
from test_lerobot_eval_layout import level_of

from inspector.analysis import metrics
from inspector.analysis.timeline import build_timeline
from inspector.data.importers.lerobot_eval import import_eval
from inspector.data.session import ACTIONS_FILE, ROLLOUT_FILE, ROLLOUTS_DIR, SessionWriter, open_session
from inspector.data.video import VideoClip

TASKS = {("pusht", 0): [True, False], ("pusht", 1): [True]}
STEPS = 24


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def cli(*argv) -> subprocess.CompletedProcess:
    return _run_command(*argv, timeout=300)


@pytest.fixture(scope="module")
def evaluation(tmp_path_factory):
    root = tmp_path_factory.mktemp("eval") / "out"
    write_eval(root, TASKS, steps=STEPS, record=False, predicted_near_render=True)
    return root


@pytest.fixture(scope="module")
def session(evaluation, tmp_path_factory):
    dest, errors = import_eval(evaluation, tmp_path_factory.mktemp("imported") / "s", log=lambda _: None)
    assert errors == {}
    return open_session(dest)


def flat_frames(level: int, n: int) -> np.ndarray:
    return np.full((n, 32, 48, 3), level, np.uint8)


def test_session_writer_writes_a_rollout_without_joints(tmp_path):
    with SessionWriter.create(tmp_path / "s", model={"name": "wam"}) as w:
        w.add_rollout("dream", kind="autoregressive", actions=None, n_chunks=3, horizon=8, executed_per_chunk=8,
                      frames_per_chunk=4, fps=5.0, videos={"front": flat_frames(100, 12)},
                      gt_videos={"front": flat_frames(120, 12)})
    r = open_session(tmp_path / "s").rollouts["dream"]
    assert not (r.root / ACTIONS_FILE).exists()
    assert not r.has_joints and (r.n_chunks, r.horizon, r.views, r.gt_views) == (3, 8, ["front"], ["front"])
    assert r.actions.shape == (3, 8, 6) and np.isnan(r.actions).all()
    info = cli("info", tmp_path / "s")
    assert info.returncode == 0 and "video only" in info.stdout, info.stderr
    assert json.loads(cli("info", "--json", tmp_path / "s").stdout)["rollouts"][0]["video_only"] is True
    row = json.loads(cli("report", "--json", "--no-cache", tmp_path / "s").stdout)["rollouts"][0]
    assert row["video_only"] is True and row["rmse_deg"] is None and row["limit_violations"] is None
    assert row["video_psnr_db"]["front"] == pytest.approx(20 * math.log10(255 / 20), abs=1.0)


def test_a_video_only_rollout_json_is_checked(tmp_path):
    with SessionWriter.create(tmp_path / "s") as w:
        for tag in ("good", "bad"):
            w.add_rollout(tag, kind="single_chunk", actions=None, n_chunks=1, horizon=4, executed_per_chunk=4,
                          frames_per_chunk=4, videos={"front": flat_frames(100, 4)})
    meta_path = tmp_path / "s" / ROLLOUTS_DIR / "bad" / ROLLOUT_FILE
    meta = json.loads(meta_path.read_text())
    meta["n_chunks"] = 10 ** 9
    meta_path.write_text(json.dumps(meta))
    out = cli("report", "--json", "--no-cache", tmp_path / "s")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert [r["tag"] for r in report["rollouts"]] == ["good"]
    assert "rollout.json: n_chunks" in report["errors"]["s/bad"]


def test_each_episode_is_a_video_only_rollout_its_first_view_beside_the_render(session):
    assert sorted(session.rollouts) == ["pusht_0_ep000", "pusht_0_ep001", "pusht_1_ep000"]
    for r in session.rollouts.values():
        assert not r.has_joints and r.kind == "single_chunk" and (r.n_chunks, r.horizon, r.fps) == (1, STEPS, 10.0)
        assert r.views == ["camera_1", "render"] and r.gt_views == ["render"]
        assert r.extra["outcome"]["task"] == r.tag[:7]
    assert session.rollouts["pusht_0_ep001"].extra["outcome"]["success"] is False


def test_imagined_frame_f_is_compared_with_the_renders_frame_f(session):
    r = session.rollouts["pusht_0_ep001"]
    tl = build_timeline(r)
    imagined = VideoClip(r.video_path("render")).decode()
    second = VideoClip(r.video_path("camera_1")).decode()
    render = VideoClip(r.video_path("render", gt=True)).decode()
    index_of = tl.gt_index_of_frame("render")
    for f in range(STEPS):
        # the steps are 7 levels apart: within half a step is this step's frame
        assert abs(imagined[f].mean() - (render_level(f) + PREDICTED_OFFSET)) < 3.5
        assert abs(second[f].mean() - predicted_level(f)) < 3.5  # the right half: the second camera
        assert index_of(f) == f and abs(render[f].mean() - render_level(f)) < 3.5
    psnr = tl.video_metrics("render").psnr_db
    np.testing.assert_allclose(psnr, metrics.psnr(imagined, render[:STEPS]), rtol=1e-9)
    assert not np.allclose(psnr[:-1], metrics.psnr(imagined[:-1], render[1:STEPS]), atol=0.1)  # one frame off


def test_report_exits_0_with_success_per_task_psnr_per_view_and_null_joints(evaluation):
    out = cli("report", "--json", "--no-cache", "--jobs", "1", evaluation)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert len(report["rollouts"]) == 3 and not report.get("errors")
    for row in report["rollouts"]:
        assert row["video_only"] is True
        for field in ("rmse_deg", "per_joint_rmse", "per_step_mse", "time_aligned_drift", "best_match_drift",
                      "dtw_drift", "tempo", "ee_error_mm", "limit_violations", "worst_chunk", "chunk_joints"):
            assert row[field] is None, field
        assert set(row["video_psnr_db"]) == {"render"}
        assert row["video_psnr_db"]["render"] > 35  # a few grey levels apart (frame by frame: the test above)
    agg = report["aggregate"]
    assert agg["n"] == 3 and agg["mean_rmse_deg"] is None
    assert agg["mean_video_psnr_db"]["render"] == pytest.approx(
        np.mean([r["video_psnr_db"]["render"] for r in report["rollouts"]]))
    by_task = {t["task"]: (t["episodes"], t["successes"]) for t in agg["success_by_task"]}
    assert by_task == {"pusht_0": (2, 1), "pusht_1": (1, 1)}
    text = cli("report", "--no-cache", "--jobs", "1", evaluation).stdout
    assert "pusht_0: 1/2 (50%, 95% CI 9-91%)" in text and "PSNR render" in text


def test_info_says_video_only(evaluation):
    out = cli("info", "--json", evaluation)
    assert out.returncode == 0, out.stderr
    assert all(e["video_only"] and e["render"] and e["predicted_video"] for e in json.loads(out.stdout)["episodes"])
    assert "(video only)" in cli("info", evaluation).stdout


def test_app_shows_the_imagined_and_the_render_side_by_side_and_no_arm(evaluation):
    from test_app import connect, key

    from inspector.app import serve

    app = serve([evaluation], port=0, block=False)
    try:
        assert len(app.catalog.entries) == 3
        client, tab = connect(app)
        with client:
            assert tab.open(key(app, "pusht_0_ep001"))
            assert tab.scene.data is None and not tab.scene.pred_arm.visible and not tab.scene.gt_arm.visible
            assert "none: video only" in tab.controls.card.content
            assert "failure" in tab.controls.card.content
            assert tab.plots.joint_plot is None
            assert tab.loaded.frames.done.wait(120)
            for t in (0, 11, 23):
                tab.set_step(t, force=True)
                pairs = {p.view: p for p in tab.pairs}
                assert abs(level_of(pairs["render"].imagined) - render_level(t) - PREDICTED_OFFSET) < 4
                assert abs(level_of(pairs["render"].gt) - render_level(t)) < 4
                assert abs(level_of(pairs["camera_1"].imagined) - predicted_level(t)) < 4
                assert not pairs["camera_1"].gt
    finally:
        app.stop()


def test_export_writes_the_videos_and_verifies(evaluation, tmp_path):
    from test_export import rrd_verify

    out = cli("export", evaluation, "-o", tmp_path / "rrd", "--no-cache", "--rollout", "pusht_1_ep000")
    assert out.returncode == 0, out.stderr
    files = sorted((tmp_path / "rrd").glob("*.rrd")) if (tmp_path / "rrd").is_dir() else [tmp_path / "rrd"]
    assert files
    for f in files:
        rrd_verify(f)


def test_compare_pairs_video_only_rows_by_psnr_and_success(evaluation, tmp_path):
    """B's predicted first view is another picture altogether: A wins every pair on PSNR."""
    write_eval(tmp_path / "b", {("pusht", 0): [True, True], ("pusht", 1): [False]}, steps=STEPS, record=False)
    out = cli("compare", "--json", "--no-cache", "--jobs", "1", evaluation, tmp_path / "b")
    assert out.returncode == 0, out.stderr
    c = json.loads(out.stdout)
    assert len(c["pairs"]) == 3 and c["summary"]["n_compared"] == 0  # no RMSE on either side
    psnr = c["video_psnr_db"]["render"]
    assert (psnr["n_compared"], psnr["a_better"], psnr["b_better"]) == (3, 3, 0)
    deltas = [p["delta_video_psnr_db"]["render"] for p in c["pairs"]]
    assert psnr["mean_delta_db"] == pytest.approx(np.mean(deltas)) and max(deltas) < 0
    success = {t["metric"]: t for t in c["tests"]}["success"]  # the one success comparison
    assert success["paired"] and success["n_pairs"] == 3
    assert success["pairs"] == {"both": 1, "only_a": 1, "only_b": 1, "neither": 0} and "success" not in c
    from inspector.report.compare import format_comparison

    text = format_comparison(c)  # what compare prints without --json, from the same comparison
    assert "PSNR render over 3 pair(s)" in text and "only A 1, only B 1" in text
