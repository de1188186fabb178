"""lerobot-eval output directories (eval_info.json, videos/, recordings/) read as rollouts.

Outputs are written as ``lerobot_eval.py`` writes them (tests/eval_outputs.py); every check compares
what the importer, the app, the report and the exporter show with the files' own numbers and
frames.
"""

from __future__ import annotations

import base64
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import simplejpeg
from cli_processes import module_command_server
from eval_outputs import camera_level, predicted_level, render_level, write_eval

from inspector.analysis.timeline import build_timeline
from inspector.app._overview_rows import OverviewRow
from inspector.app._overview_table import FAILED, Query, select_rows, table_html
from inspector.data.importers.lerobot_eval import import_eval
from inspector.data.session import open_session
from inspector.data.video import VideoClip
from inspector.report.build import format_report
from inspector.units import JOINT_LIMITS_RAD

pytestmark = pytest.mark.slow  # the CLI as processes and a served app

TASKS = {("so101_sim", 0): [True, False], ("so101_sim", 1): [True]}


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def cli(*argv) -> subprocess.CompletedProcess:
    return _run_command(*argv, timeout=300)


def expected_radians(values: np.ndarray) -> np.ndarray:
    lo, hi = JOINT_LIMITS_RAD["gripper"]
    out = np.deg2rad(values)
    out[:, 5] = lo + values[:, 5] / 100 * (hi - lo)
    return out


def level_of(jpeg_uri: str) -> float:
    return float(simplejpeg.decode_jpeg(base64.b64decode(jpeg_uri.split(",", 1)[1]), colorspace="RGB").mean())


@pytest.fixture(scope="module")
def evaluation(tmp_path_factory):
    root = tmp_path_factory.mktemp("eval") / "out"
    return root, write_eval(root, TASKS)


@pytest.fixture(scope="module")
def report(evaluation) -> dict:
    """``report --json`` of the evaluation (in one process: the pool is not the point here)."""
    root, _ = evaluation
    out = cli("report", "--json", "--no-cache", "--jobs", "1", root)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.fixture(scope="module")
def session(evaluation, tmp_path_factory):
    root, _ = evaluation
    dest, errors = import_eval(root, tmp_path_factory.mktemp("imported") / "s", log=lambda _: None)
    assert errors == {}
    return open_session(dest)


def test_each_episode_is_a_rollout_with_the_recorded_arms(session, evaluation):
    _, recorded = evaluation
    assert sorted(session.rollouts) == ["so101_sim_0_ep000", "so101_sim_0_ep001", "so101_sim_1_ep000"]
    for task, recs in recorded.items():
        for k, rec in enumerate(recs):
            r = session.rollouts[f"{task}_ep{k:03d}"]
            assert (r.kind, r.n_chunks, r.horizon, r.fps) == ("single_chunk", 1, 24, 10.0)
            np.testing.assert_allclose(r.actions[0], rec.action, atol=1e-4)  # float32 in parquet
            np.testing.assert_allclose(r.gt_actions, rec.state, atol=1e-4)
            assert r.extra["outcome"]["success"] is rec.success
            assert r.extra["outcome"]["sum_reward"] == pytest.approx(rec.sum_reward)
            assert r.views == ["predicted"] and r.gt_views == ["render", "top"]


def test_the_frame_at_step_t_is_the_files_frame_for_t(session):
    r = session.rollouts["so101_sim_0_ep001"]
    tl = build_timeline(r)
    assert tl.labels.pred == "commanded (action)" and tl.labels.gt == "executed (state)"
    pred = VideoClip(r.video_path("predicted")).decode()
    render = VideoClip(r.video_path("render", gt=True)).decode()
    top = VideoClip(r.video_path("top", gt=True)).decode()
    index_of = tl.gt_index_of_frame("render")
    for t in range(tl.n_steps):
        f = tl.frame_index(t)
        assert f == t
        assert abs(pred[f].mean() - predicted_level(t)) < 4
        assert abs(render[index_of(f)].mean() - render_level(t)) < 4
        assert abs(top[index_of(f)].mean() - camera_level(t)) < 4


def test_app_draws_both_arms_and_shows_the_frames(evaluation):
    from test_app import connect, key

    from inspector.app import serve

    root, recorded = evaluation
    rec = recorded["so101_sim_0"][1]
    app = serve([root], port=0, block=False)
    try:
        client, tab = connect(app)
        with client:
            assert tab.open(key(app, "so101_sim_0_ep001"))
            np.testing.assert_allclose(tab.loaded.scene.q_pred, expected_radians(rec.action), atol=1e-5)
            np.testing.assert_allclose(tab.loaded.scene.q_gt, expected_radians(rec.state), atol=1e-5)
            assert tab.loaded.frames.done.wait(120)
            for t in (0, 9, 23):
                tab.set_step(t, force=True)
                pairs = {p.view: p for p in tab.pairs}
                assert abs(level_of(pairs["predicted"].imagined) - predicted_level(t)) < 5
                assert abs(level_of(pairs["render"].gt) - render_level(t)) < 5
                assert abs(level_of(pairs["top"].gt) - camera_level(t)) < 5
    finally:
        app.stop()


def test_report_rows_and_success_rate_per_task(evaluation, report):
    root, recorded = evaluation
    rows = {r["tag"]: r for r in report["rollouts"]}
    rec = recorded["so101_sim_0"][1]
    row = rows["so101_sim_0_ep001"]
    assert row["outcome"]["success"] is False and row["outcome"]["sum_reward"] == 0.0
    # the RMSE between the two arms is the files' own (commanded action vs executed state)
    assert row["rmse_deg"] == pytest.approx(np.sqrt(np.mean((rec.action - rec.state) ** 2)), abs=1e-3)
    lo = np.rad2deg(JOINT_LIMITS_RAD["shoulder_lift"][0])
    assert row["limit_violations"]["by_joint"]["shoulder_lift"] == int((rec.action[:, 1] < lo - 2).sum()) == 1
    by_task = {t["task"]: t for t in report["aggregate"]["success_by_task"]}
    assert by_task["so101_sim_0"]["success_rate"] == 0.5 and by_task["so101_sim_1"]["success_rate"] == 1.0
    assert by_task["so101_sim_0"]["mean_sum_reward"] == pytest.approx(1.5)
    text = format_report(report)  # what report prints without --json, from the same report
    assert "so101_sim_0: 1/2 (50%, 95% CI 9-91%)" in text and "Evaluated episodes" in text


def test_overview_shows_success_and_filters_failed_episodes(report, tmp_path):
    rows = [OverviewRow(key=r["tag"], session="out", tag=r["tag"], kind=r["kind"], prompt=r["prompt"],
                        session_root=tmp_path, summary=r) for r in report["rollouts"]]
    failed = select_rows(rows, Query(kind=FAILED), {})
    assert [r.tag for r in failed] == ["so101_sim_0_ep001"]
    html = table_html(rows, rows, {})
    assert "data-col='success'" in html and "✗" in html and "✓" in html


def test_info_names_the_layout(evaluation):
    root, _ = evaluation
    out = cli("info", "--json", root)
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    assert info["format"] == "lerobot-eval"
    assert [(t["task"], t["episodes"], t["successes"]) for t in info["tasks"]] == [("so101_sim_0", 2, 1), ("so101_sim_1", 1, 1)]
    assert all(e["predicted_video"] and e["render"] and e["cameras"] == ["top"] and e["length"] == 24
               for e in info["episodes"])
    assert any("not named" in w for w in info["warnings"])
    assert cli("info", root).stdout.startswith("lerobot-eval outputs: 3 episode(s) in 2 task(s)")


def test_export_verifies(evaluation, tmp_path):
    from test_export import rrd_verify

    root, _ = evaluation
    out = cli("export", root, "-o", tmp_path / "rrd", "--no-cache", "--rollout", "so101_sim_1_ep000")
    assert out.returncode == 0, out.stderr
    files = list((tmp_path / "rrd").glob("*.rrd")) if (tmp_path / "rrd").is_dir() else [tmp_path / "rrd"]
    assert files and all(f.is_file() for f in files)
    for f in files:
        rrd_verify(f)


def test_import_cli_writes_a_session(evaluation, tmp_path):
    root, _ = evaluation
    out = cli("import", "lerobot-eval", root, "-o", tmp_path / "s")
    assert out.returncode == 0, out.stderr
    assert len(open_session(tmp_path / "s").rollouts) == 3


def test_batched_envs_record_one_dataset_each(tmp_path):
    """Episode i of a task ran in env i % n_envs: its arms come from env_<i % n>/ episode i // n."""
    recorded = write_eval(tmp_path / "out", {("so101_sim", 0): [True, False, False]}, n_envs=2)
    dest, errors = import_eval(tmp_path / "out", tmp_path / "s", log=lambda _: None)
    assert errors == {}
    s = open_session(dest)
    for k, rec in enumerate(recorded["so101_sim_0"]):
        np.testing.assert_allclose(s.rollouts[f"so101_sim_0_ep{k:03d}"].actions[0], rec.action, atol=1e-4)


def _edit_info(root: Path, change) -> None:
    info = json.loads((root / "eval_info.json").read_text())
    change(info)
    (root / "eval_info.json").write_text(json.dumps(info))


BAD = {
    "success-not-bool": (lambda r: _edit_info(r, lambda i: i["per_task"][0]["metrics"]["successes"].__setitem__(1, "yes")),
                         "eval_info.json", "per_task[0].metrics.successes[1]: expected true or false"),
    "reward-nan": (lambda r: _edit_info(r, lambda i: i["per_task"][0]["metrics"]["sum_rewards"].__setitem__(0, float("nan"))),
                   "eval_info.json", "per_task[0].metrics.sum_rewards[0]: expected a finite number, found nan"),
    "not-json": (lambda r: (r / "eval_info.json").write_text("{"), "eval_info.json", "invalid JSON"),
    "recording-broken": (lambda r: (r / "recordings" / "so101_sim_0" / "meta" / "info.json").write_text("{"),
                         "info.json", "invalid JSON"),
    "no-recording-of-an-episode": (lambda r: _edit_info(
        r, lambda i: [i["per_task"][0]["metrics"][k].append(v) for k, v in
                      (("successes", True), ("sum_rewards", 1.0), ("max_rewards", 1.0))]),
        "videos/so101_sim_0", "episode 2: neither a recording nor a video"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_line_and_never_takes_the_others_down(case, evaluation, tmp_path):
    spoil, file, what = BAD[case]
    root = Path(shutil.copytree(evaluation[0], tmp_path / "out"))  # a copy of write_eval(root, TASKS) to spoil
    _edit_info(root, lambda i: i["overall"].update(eval_s=float("nan")))  # lerobot-eval writes NaN: fine
    spoil(root)
    out = cli("report", "--json", "--no-cache", "--jobs", "1", root)
    if case == "not-json":  # eval_info.json itself unreadable: nothing to report, one line
        assert out.returncode == 2 and out.stderr.count("\n") == 1 and file in out.stderr and what in out.stderr
    else:
        assert out.returncode == 0, out.stderr
        report = json.loads(out.stdout)
        assert "so101_sim_1_ep000" in {r["tag"] for r in report["rollouts"]}
        assert any(file in e and what in e for e in report["errors"].values()), report["errors"]
    imported = cli("import", "lerobot-eval", root, "-o", tmp_path / "s")
    assert imported.returncode == 2 and imported.stderr.count("\n") == 1, imported.stderr
    assert file in imported.stderr and what in imported.stderr, imported.stderr
    assert not (tmp_path / "s").exists()
