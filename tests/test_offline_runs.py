"""DreamZero-SO101 offline-inference runs (``predicted_actions.csv`` + mosaic video) read as rollouts.

Runs are written as ``offline_inference.py`` writes them (tests/offline_runs.py); every check
compares what the importer, the app, the report and the exporter show with the files' own numbers
and frames.
"""

from __future__ import annotations

import base64
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import simplejpeg
from cli_processes import module_command_server
from offline_runs import front_level, write_run

from inspector.analysis.timeline import build_timeline
from inspector.data.importers.dreamzero_offline import import_offline
from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset
from inspector.data.session import open_session
from inspector.data.video import VideoClip
from inspector.units import JOINT_LIMITS_RAD, JOINT_NAMES

pytestmark = pytest.mark.slow  # the CLI as processes and a served app

# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()

SHUFFLED = ("gripper", "elbow_flex", "shoulder_pan", "wrist_roll", "shoulder_lift", "wrist_flex")


def cli(*argv, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``inspector *argv`` as a process (forked from one CLI start-up); reports and exports with ``--jobs 1`` (one worker at most:
    these tests are about the runs' files, not the pool)."""
    if argv[0] in ("report", "export"):
        argv = (*argv, "--jobs", "1")
    return _run_command(*argv, timeout=300, cwd=cwd)


def expected_radians(values: np.ndarray) -> np.ndarray:
    """Arm degrees -> radians, gripper 0..100 -> its URDF range: written out, not the code's own."""
    lo, hi = JOINT_LIMITS_RAD["gripper"]
    out = np.deg2rad(values)
    out[:, 5] = lo + values[:, 5] / 100 * (hi - lo)
    return out


def front_of(jpeg_uri: str) -> float:
    return float(simplejpeg.decode_jpeg(base64.b64decode(jpeg_uri.split(",", 1)[1]), colorspace="RGB").mean())


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> tuple[Path, dict[str, np.ndarray]]:
    """Two runs: three chunks with its columns in another order, and one chunk of PNG frames only."""
    root = tmp_path_factory.mktemp("offline") / "runs"
    actions = {"ar3": write_run(root / "ar3", 3, column_order=SHUFFLED),
               "one": write_run(root / "one", 1, seed=1, mp4=False, prompt="Pick the blue cube")}
    return root, actions


@pytest.fixture(scope="module")
def session(runs, tmp_path_factory):
    root, _ = runs
    dest, errors = import_offline(root, tmp_path_factory.mktemp("imported") / "s", log=lambda _: None)
    assert errors == {}
    return open_session(dest)


def test_import_keeps_the_files_numbers(session, runs):
    _, actions = runs
    ar, one = session.rollouts["ar3"], session.rollouts["one"]
    assert (ar.kind, ar.n_chunks, ar.horizon, ar.executed_per_chunk, ar.frames_per_chunk) == ("autoregressive", 3, 24, 24, 8)
    assert (one.kind, one.n_chunks, one.prompt) == ("single_chunk", 1, "Pick the blue cube")
    assert session.units.arm == "degrees"
    # columns mapped by name; the CSV holds 8 decimals
    np.testing.assert_allclose(ar.actions.reshape(-1, 6), actions["ar3"], atol=1e-8)
    np.testing.assert_allclose(one.actions.reshape(-1, 6), actions["one"], atol=1e-8)
    # each chunk starts from the last action of the one before (what the next chunk was fed)
    np.testing.assert_allclose(ar.states[1:], ar.actions[:, -1])
    np.testing.assert_allclose(ar.states[0], actions["ar3"][0] - 1.0)
    assert ar.views == ["front", "gripper", "top"]
    assert len(VideoClip(ar.video_path("front"))) == 25 and len(VideoClip(one.video_path("top"))) == 9


@pytest.mark.parametrize("tag", ["ar3", "one"])
def test_the_frame_at_step_t_is_the_files_frame_for_t(session, tag):
    """Frame f of the mosaic shows step 3 f (24 actions, 8 new frames per chunk)."""
    tl = build_timeline(session.rollouts[tag])
    assert tl.n_steps == 24 * session.rollouts[tag].n_chunks
    frames = VideoClip(session.rollouts[tag].video_path("front")).decode()
    for t in range(tl.n_steps):
        f = tl.frame_index(t)
        assert f == t // 3
        assert abs(frames[f].mean() - front_level(t // 3)) < 4, f"step {t}: frame {f}"
    top = VideoClip(session.rollouts[tag].video_path("top")).decode()
    assert np.abs(top[0].reshape(-1, 3).mean(0) - (200, 60, 40)).max() < 6  # the top-right quadrant


def test_app_draws_the_files_joints_and_frames(runs):
    from test_app import connect, key

    from inspector.app import serve

    root, actions = runs
    app = serve([root], port=0, block=False)
    try:
        client, tab = connect(app)
        with client:
            assert tab.open(key(app, "ar3"))
            np.testing.assert_allclose(tab.loaded.scene.q_pred, expected_radians(actions["ar3"]), atol=1e-9)
            assert tab.loaded.frames.done.wait(120)
            for t in (0, 7, 30, 71):
                tab.set_step(t, force=True)
                front = next(p for p in tab.pairs if p.view == "front")
                assert front.imagined_index == t // 3
                assert abs(front_of(front.imagined) - front_level(t // 3)) < 5
    finally:
        app.stop()


def test_report_measures_the_files_joints(runs):
    root, actions = runs
    out = cli("report", "--json", "--no-cache", root)
    assert out.returncode == 0, out.stderr
    rows = {r["tag"]: r for r in json.loads(out.stdout)["rollouts"]}
    assert set(rows) == {"ar3", "one"}
    hi = np.rad2deg(JOINT_LIMITS_RAD["shoulder_pan"][1])
    for tag, values in actions.items():
        assert rows[tag]["limit_violations"]["by_joint"]["shoulder_pan"] == int((values[:, 0] > hi + 2).sum()) > 0
    np.testing.assert_allclose(rows["one"]["chunk_joints"]["pred"], actions["one"], atol=1e-4)


def test_info_names_the_layout(runs):
    root, _ = runs
    out = cli("info", "--json", root)
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    assert info["format"] == "dreamzero-offline" and info["units_label"] == "arm degrees, gripper 0..100"
    by_tag = {r["tag"]: r for r in info["runs"]}
    assert (by_tag["ar3"]["n_chunks"], by_tag["ar3"]["frames"], by_tag["ar3"]["video"]) == (3, 25, "predicted_video.mp4")
    assert by_tag["one"]["video"].startswith("frames/") and by_tag["one"]["frames"] == 9
    assert any("no GT" in w for w in by_tag["ar3"]["warnings"])
    text = cli("info", root).stdout
    assert text.startswith("DreamZero-SO101 offline-inference runs: 2 run(s)")


def test_gt_from_the_sidecar_and_a_dataset(tmp_path):
    """``inspector_gt.json`` names the dataset, episode and start frame; the GT arm at step t is the
    episode's action at start + t."""
    rng = np.random.default_rng(3)
    eps = [EpisodeData("Pick the red cube", rng.normal(0, 20, (n, 6)), rng.normal(0, 20, (n, 6)))
           for n in (40, 120)]
    write_lerobot_dataset(tmp_path / "ds", eps)
    write_run(tmp_path / "runs" / "r", 2, sidecar={"dataset": "../../ds", "episode": 1, "start_frame": 10})
    info = json.loads(cli("info", "--json", tmp_path / "runs").stdout)
    assert info["runs"][0]["gt"] == {"dataset": str((tmp_path / "ds").resolve()), "episode": 1, "start_frame": 10}
    dest, _ = import_offline(tmp_path / "runs", tmp_path / "s", log=lambda _: None)
    s = open_session(dest)
    r = s.rollouts["r"]
    assert (r.episode_index, r.start_frame) == (1, 10)
    tl = build_timeline(r, s.dataset_root)
    np.testing.assert_allclose(tl.gt_aligned, eps[1].action[10:10 + 48], atol=1e-4)  # float32 in parquet
    # a flag overrides the sidecar
    dest2, _ = import_offline(tmp_path / "runs", tmp_path / "s2", episode=1, start_frame=30, log=lambda _: None)
    assert open_session(dest2).rollouts["r"].start_frame == 30
    dest3, _ = import_offline(tmp_path / "runs", tmp_path / "s3", start_frame=0, log=lambda _: None)
    assert open_session(dest3).rollouts["r"].start_frame == 0  # 0 given overrides the sidecar's 10
    # a dataset but no episode: the run is shown without GT joints, and says why
    write_run(tmp_path / "bare" / "r", 1)
    dest4, errors = import_offline(tmp_path / "bare", tmp_path / "s4", dataset=tmp_path / "ds", log=lambda _: None)
    bare = open_session(dest4).rollouts["r"]
    assert errors == {} and not bare.has_gt_joints and "no GT episode" in bare.extra["warnings"][0]
    out = cli("report", "--json", "--no-cache", tmp_path / "runs")
    assert out.returncode == 0, out.stderr
    row = json.loads(out.stdout)["rollouts"][0]
    assert row["episode_index"] == 1 and row["rmse_deg"] is not None


def test_export_verifies(runs, tmp_path):
    from test_export import rrd_verify

    root, _ = runs
    out = cli("export", root, "-o", tmp_path / "rrd", "--no-cache")
    assert out.returncode == 0, out.stderr
    files = sorted((tmp_path / "rrd").glob("*.rrd"))
    assert [f.stem for f in files] == ["ar3", "one"]
    for f in files:
        rrd_verify(f)


def test_import_cli_writes_a_session(runs, tmp_path):
    root, _ = runs
    out = cli("import", "dreamzero-offline", root / "ar3", "-o", tmp_path / "s")
    assert out.returncode == 0, out.stderr
    assert sorted(open_session(tmp_path / "s").rollouts) == ["ar3"]


def _rewrite_csv(run: Path, line: int, new: str) -> None:
    lines = (run / "predicted_actions.csv").read_text().splitlines()
    lines[line] = new
    (run / "predicted_actions.csv").write_text("\n".join(lines) + "\n")


def _edit_meta(run: Path, **fields) -> None:
    meta = json.loads((run / "metadata.json").read_text())
    meta.update(fields)
    (run / "metadata.json").write_text(json.dumps(meta))


BAD_RUNS = {
    "not-a-number": (lambda r: _rewrite_csv(r, 3, "2,1,2,x,4,5,6"), "predicted_actions.csv", "line 4, elbow_flex: not a number"),
    "missing-joint": (lambda r: _rewrite_csv(r, 0, "step,shoulder_pan,shoulder_lift,elbow_flex,wrist_flex,wrist_roll,grip"),
                      "predicted_actions.csv", "header: expected the 6 SO-101 joints"),
    "step-skipped": (lambda r: _rewrite_csv(r, 5, "7,1,2,3,4,5,6"), "predicted_actions.csv", "line 6, step: 7, expected 4"),
    "partial-chunk": (lambda r: _rewrite_csv(r, 1, ""), "predicted_actions.csv", "line"),
    "chunk-count": (lambda r: _edit_meta(r, chunk_count=4), "metadata.json", "chunk_count: 4"),
    "input-joints": (lambda r: _edit_meta(r, input_joint_positions={"shoulder_pan": 1}), "metadata.json",
                     "input_joint_positions: expected the 6 SO-101 joints"),
    "frame-count": (lambda r: _edit_meta(r, chunk_count=1, decoded_frame_count=25) or _rewrite_csv_rows(r, 24),
                    "predicted_video.mp4", "25 frames, but 1 chunk(s)"),
    "video-broken": (lambda r: (r / "predicted_video.mp4").write_bytes(b"not a video"), "predicted_video.mp4",
                     "cannot read video"),
    "sidecar-episode": (lambda r: (r / "inspector_gt.json").write_text('{"episode": -1}'), "inspector_gt.json",
                        "episode: expected a non-negative integer"),
}


def _rewrite_csv_rows(run: Path, n: int) -> None:
    lines = (run / "predicted_actions.csv").read_text().splitlines()
    (run / "predicted_actions.csv").write_text("\n".join(lines[: n + 1]) + "\n")


@pytest.fixture(scope="module")
def bad_runs(tmp_path_factory) -> tuple[Path, dict]:
    """(folder, the JSON report of them all): a folder per case of BAD_RUNS holding a good run and
    a bad one spoiled so, all reported by one command."""
    folder = tmp_path_factory.mktemp("bad-runs")
    for case, (spoil, _, _) in BAD_RUNS.items():
        write_run(folder / case / "good", 1)
        write_run(folder / case / "bad", 3, pngs=False)
        spoil(folder / case / "bad")
    out = cli("report", "--json", "--no-cache", *(folder / case for case in sorted(BAD_RUNS)))
    assert out.returncode == 0, out.stderr
    return folder, json.loads(out.stdout)


@pytest.mark.parametrize("case", sorted(BAD_RUNS))
def test_a_bad_run_is_one_line_and_never_takes_the_others_down(case, bad_runs, tmp_path):
    _, file, what = BAD_RUNS[case]
    folder, report = bad_runs
    root = folder / case
    assert [r["tag"] for r in report["rollouts"] if r["session"] == case] == ["good"]
    (tag, error), = ((tag, error) for tag, error in report["errors"].items() if tag.split("/")[0] == case)
    assert tag == f"{case}/bad" and f"{file}: " in error and what in error, error
    imported = cli("import", "dreamzero-offline", root, "-o", tmp_path / "s")
    assert imported.returncode == 2
    assert imported.stderr.count("\n") == 1 and imported.stderr.startswith("error: ")
    assert file in imported.stderr and what in imported.stderr, imported.stderr
    assert not (tmp_path / "s").exists()


def test_a_directory_no_layout_fits_names_the_layouts(tmp_path):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "notes.txt").write_text("hello")
    for argv in (("info", tmp_path / "x"), ("report", "--json", tmp_path / "x")):
        out = cli(*argv)
        assert out.returncode == 2 and out.stderr.count("\n") == 1
        assert "no layout recognised" in out.stderr and "offline-inference" in out.stderr and "LeRobot" in out.stderr


def test_joint_names_order_is_the_sessions(session):
    assert session.joint_names == list(JOINT_NAMES)


def test_a_run_too_long_to_hold_is_cut_view_by_view(runs, tmp_path, monkeypatch):
    """Past the memory budget each view streams from its own pass over the mosaic: same frames."""
    import inspector.data.importers.dreamzero_offline as offline

    root, _ = runs
    monkeypatch.setattr(offline, "VIEWS_IN_MEMORY_BYTES", 0)
    dest, _ = import_offline(root / "ar3", tmp_path / "s", log=lambda _: None)
    frames = VideoClip(open_session(dest).rollouts["ar3"].video_path("front")).decode()
    assert len(frames) == 25
    assert all(abs(frames[f].mean() - front_level(f)) < 4 for f in range(25))
