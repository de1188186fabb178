"""GR00T-Dreams (DreamGen) neural trajectories read natively: info, report, the app, export, import.

The dumps are written here as NVIDIA/GR00T-Dreams' IDM_dump writes them (``groot_dreams_layout``);
every value is checked against the file's own numbers after the calibration's mapping, read
straight from the parquet by joint name.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from cli_processes import module_command_server
from groot_dreams_layout import SO100_JOINTS, VIDEO_KEY, idm_actions, modality, write_groot_dreams

from inspector.data.importers.calibration import GR00T_SO100_OFFSETS, parse_calibration
from inspector.errors import InspectorError
from inspector.units import JOINT_NAMES

pytestmark = pytest.mark.slow  # the CLI as processes and a browser page

RERUN = Path(sys.executable).parent / "rerun"
EPISODES = [("pick the grape", 20), ("place the strawberry in the bowl", 24), ("pick the grape", 18)]


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return _run_command(*args, timeout=timeout, env={**os.environ})


def _file_actions(root: Path, episode: int) -> np.ndarray:
    """(T, 6) an episode's action columns straight from its parquet, by name through modality.json."""
    slicing = json.loads((root / "meta" / "modality.json").read_text())["action"]
    rows = pq.read_table(root / "data" / "chunk-000" / f"episode_{episode:06d}.parquet").column("action").to_pylist()
    cols = [slicing[f"main_{j}"]["start"] for j in JOINT_NAMES]
    return np.array(rows, dtype=np.float64)[:, cols]


def _legacy_to_urdf(values: np.ndarray) -> np.ndarray:
    """GR00T's SO-100 legacy readings -> URDF zeros, written out by hand: pan - 90, 90 - lift, elbow - 90."""
    out = np.array(values, dtype=np.float64)
    out[:, 0] -= 90.0
    out[:, 1] = 90.0 - out[:, 1]
    out[:, 2] -= 90.0
    return out


@pytest.fixture(scope="module")
def dump(tmp_path_factory) -> Path:
    return write_groot_dreams(tmp_path_factory.mktemp("gd") / "so100.data_idm", EPISODES)


@pytest.fixture(scope="module")
def shuffled(tmp_path_factory) -> Path:
    """A dump whose modality.json puts the joints in other columns of a 44-wide action: only the
    names say which column is which joint."""
    root = tmp_path_factory.mktemp("gd_shuffled") / "shuffled"
    order = [5, 3, 0, 4, 1, 2]  # joint i lives in column order[i]... of 8 used columns
    columns = [10 + 3 * o for o in order]
    actions = []
    for e, (_, n) in enumerate(EPISODES[:2]):
        wide = np.full((n, 44), -999.0)
        wide[:, columns] = idm_actions(n, 10 + e)
        actions.append(wide)
    write_groot_dreams(root, EPISODES[:2], actions=actions)
    m = modality()
    m["action"] = {j: {"start": c, "end": c + 1, "absolute": False} for j, c in zip(reversed(SO100_JOINTS),
                                                                                       reversed(columns))}
    (root / "meta" / "modality.json").write_text(json.dumps(m))
    return root


# ----------------------------------------------------------------------------------------------
# Calibration


def test_the_default_calibration_is_lerobots_legacy_with_grootss_pan_centre():
    c = parse_calibration(None, "gr00t-so100")
    mean = np.array([113.7, 115.9, 108.6, 73.8, -42.7, 16.0])
    np.testing.assert_allclose(c.apply(mean), _legacy_to_urdf(mean[None])[0])
    assert dict((j, (z, s)) for j, z, s in c.joints) == GR00T_SO100_OFFSETS
    assert c.describe().startswith("gr00t-so100: shoulder_pan = x - 90, shoulder_lift = -x + 90")


def test_a_joint_is_overridden_by_name():
    c = parse_calibration("gr00t-so100,main_shoulder_pan=0,wrist_roll=10:-1", "none")
    np.testing.assert_allclose(c.apply([100, 100, 100, 50, 30, 5]), [100, -10, 10, 50, -20, 5])
    assert c.spec == "gr00t-so100,main_shoulder_pan=0,wrist_roll=10:-1"
    for bad in ("nonsense", "gr00t-so100,elbow=3", "shoulder_pan=x", "shoulder_pan=1:2"):
        with pytest.raises(ValueError):
            parse_calibration(bad, "none")


# ----------------------------------------------------------------------------------------------
# info


def test_info_names_the_layout_and_what_it_found(dump):
    out = _cli("info", str(dump))
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert text.startswith("GR00T-Dreams neural trajectories (IDM_dump): 3 episode(s) (3 marked <DREAM>)")
    assert "fps: 16 fps from the timestamps; meta/info.json says 8: the timestamps are trusted" in text
    assert "views: webcam 256x256 @ 16 fps" in text
    assert "calibration gr00t-so100: shoulder_pan = x - 90" in text
    assert "      1      24  <DREAM>place the strawberry in the bowl" in text
    info = json.loads(_cli("info", str(dump), "--json").stdout)
    assert info["format"] == "groot-dreams" and info["fps"] == 16 and info["info_fps"] == 8
    assert [e["length"] for e in info["episodes"]] == [20, 24, 18] and all(e["dream"] for e in info["episodes"])
    assert info["action_columns"] == {j: i for i, j in enumerate(SO100_JOINTS)}
    assert not [w for w in info["warnings"] if "past a joint limit" in w]


def test_a_wrong_calibration_is_said_not_hidden(dump):
    out = _cli("info", str(dump), "--calibration", "none", "--json")
    warnings = json.loads(out.stdout)["warnings"]
    assert any("stats.json's mean action is past a joint limit after calibration none" in w for w in warnings)
    assert any("100% of the steps are past a joint limit: the calibration (none) is probably wrong" in w
               for w in warnings)


def test_the_calibration_reaches_the_reports_workers(dump):
    out = _cli("report", str(dump), "--json", "--jobs", "2", "--calibration", "none")
    rows = json.loads(out.stdout)["neural_trajectories"]
    assert [r["calibration"] for r in rows] == ["none"] * 3
    assert all(r["limit_violations"]["steps"] == r["length"] for r in rows)
    assert all("the calibration (none) is probably wrong" in r["warnings"][0] for r in rows)


def test_a_dump_whose_actions_were_never_written_says_so(tmp_path):
    from inspector.data.importers.groot_dreams import NeuralTrajectories

    root = write_groot_dreams(tmp_path / "d", EPISODES[:1], actions=[np.zeros((20, 44))])
    assert NeuralTrajectories(root).trajectory(0).warnings == [
        "every action is 0: the IDM labels were never written (run dump_idm_actions.py)"]


def test_info_on_a_directory_no_layout_fits_is_one_line_naming_the_layouts(tmp_path):
    (tmp_path / "something").mkdir()
    out = _cli("info", str(tmp_path / "something"))
    assert out.returncode == 2 and len(out.stderr.splitlines()) == 1
    for name in ("session", "LeRobot dataset", "GR00T-Dreams neural trajectories"):
        assert name in out.stderr


# ----------------------------------------------------------------------------------------------
# report


def test_report_rows_are_the_files_numbers_after_calibration(shuffled):
    out = _cli("report", str(shuffled), "--json", "--jobs", "2")
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)["neural_trajectories"]
    assert [r["episode_index"] for r in rows] == [0, 1] and [r["length"] for r in rows] == [20, 24]
    for r in rows:
        raw = _file_actions(shuffled, r["episode_index"])
        assert (raw != -999).all()  # the named columns, not the filler around them
        expected = _legacy_to_urdf(raw)
        for k, j in enumerate(JOINT_NAMES):
            np.testing.assert_allclose(r["joint_range"][j], [expected[:, k].min(), expected[:, k].max()])
            np.testing.assert_allclose(r["raw_range"][j], [raw[:, k].min(), raw[:, k].max()])
        assert r["dream"] and r["task"].startswith("<DREAM>") and r["fps"] == 16 and r["calibration"] == "gr00t-so100"
        assert r["limit_violations"]["steps"] == 0 and r["warnings"] == []


def test_one_bad_episode_is_an_error_naming_its_file_and_the_others_are_reported(tmp_path):
    root = write_groot_dreams(tmp_path / "d", EPISODES)
    bad = idm_actions(24, 1)
    bad[7, 3] = np.nan
    f = root / "data" / "chunk-000" / "episode_000001.parquet"
    table = pq.read_table(f)
    table = table.set_column(table.column_names.index("action"), "action",
                             pa.array([np.asarray(a) for a in bad], pa.list_(pa.float64())))
    pq.write_table(table, f)
    out = _cli("report", str(root), "--json", "--jobs", "1")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert [r["episode_index"] for r in report["neural_trajectories"]] == [0, 2]
    (err,) = report["errors"].values()
    assert "episode_000001.parquet: action: non-finite value nan at row 7, joint main_wrist_flex" in err


@pytest.mark.parametrize("breakage, file, what", [
    (lambda m: m["action"].pop("main_gripper"), "modality.json", "action: no slice for ['main_gripper']"),
    (lambda m: m["action"]["main_elbow_flex"].update(end=7), "modality.json", "action.main_elbow_flex"),
])
def test_a_bad_modality_is_one_line_naming_the_file_and_field(tmp_path, breakage, file, what):
    root = write_groot_dreams(tmp_path / "d", EPISODES[:1])
    m = modality()
    breakage(m)
    (root / "meta" / "modality.json").write_text(json.dumps(m))
    for args in (("info", str(root)), ("report", str(root), "--json")):
        out = _cli(*args)
        assert out.returncode == 2 and out.stdout == "" and len(out.stderr.splitlines()) == 1, out.stderr
        assert file in out.stderr and what in out.stderr


def test_actions_narrower_than_the_modality_say_which_row(tmp_path):
    from inspector.data.importers.groot_dreams import NeuralTrajectories

    root = write_groot_dreams(tmp_path / "d", EPISODES[:1], actions=[idm_actions(20, 0)[:, :4]])
    with pytest.raises(InspectorError, match="action: row 0 has 4 values; meta/modality.json puts main_gripper"):
        NeuralTrajectories(root).trajectory(0)


# ----------------------------------------------------------------------------------------------
# The app (in process), export and import


@pytest.fixture(scope="module")
def app(dump):
    from inspector.app import InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    app = InspectorApp(open_sources([dump], confine=True, datasets=True), port=0,
                       metrics_cache=MetricsCache(enabled=False))
    yield app
    app.stop()


def test_the_app_draws_the_files_joints_and_shows_the_files_frames(app, dump):
    from inspector.app import HeadlessClient
    from inspector.app._frames import jpeg_data_uri
    from inspector.data.video import VideoClip

    keys = app.catalog.keys()
    assert keys[1] == "so100.data_idm / episode 1 · 24 frames (1.5 s) · <DREAM>place the strawberry in the bowl"
    with HeadlessClient(app.port):
        tab = app.wait_for_tabs(1)[0]
        assert tab.open(keys[1])
        tl = tab.loaded.timeline
        np.testing.assert_allclose(tl.pred, _legacy_to_urdf(_file_actions(dump, 1)))
        assert not tl.has_gt_joints and tl.fps == 16 and tl.n_steps == 24
        card = tab.controls.card.content
        for text in ("&lt;DREAM&gt;place the strawberry", "gr00t-so100: shoulder_pan = x - 90",
                     "16 fps from the timestamps; meta/info.json says 8", "joint ranges", "no GT arm"):
            assert text in card, text
        frames = tab.loaded.frames
        assert frames.decoded.wait(120)
        clip = VideoClip(dump / "videos" / "chunk-000" / VIDEO_KEY / "episode_000001.mp4")
        size = frames.display_size("webcam")
        shown = {t: frames.pair("webcam", t) for t in (0, 9, 23)}
        for t, pair in shown.items():
            assert pair.imagined_index == t and pair.gt is None
            assert pair.imagined == jpeg_data_uri(clip.frame(t), size)
        assert len({p.imagined for p in shown.values()}) == 3


def test_export_writes_a_recording_rerun_verifies(dump, tmp_path):
    out = _cli("export", str(dump), "--episode", "2", "-o", str(tmp_path / "e2.rrd"))
    assert out.returncode == 0, out.stderr
    verify = subprocess.run([str(RERUN), "rrd", "verify", str(tmp_path / "e2.rrd")], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr


def test_import_writes_a_session_with_the_same_numbers_and_video(dump, tmp_path):
    from inspector.data.session import open_session

    out = _cli("import", "groot-dreams", str(dump), "-o", str(tmp_path / "s"), "--calibration",
               "gr00t-so100,shoulder_pan=0")
    assert out.returncode == 0, out.stderr
    session = open_session(tmp_path / "s")
    assert sorted(session.rollouts) == ["episode_000000", "episode_000001", "episode_000002"] and not session.errors
    r = session.rollouts["episode_000001"]
    expected = _legacy_to_urdf(_file_actions(dump, 1))
    expected[:, 0] += 90.0  # shoulder_pan=0: the pan as the file has it
    np.testing.assert_allclose(r.actions[0], expected)
    assert r.kind == "single_chunk" and r.fps == 16 and r.views == ["webcam"] and r.episode_index is None
    assert r.extra["source"]["dream"] and r.extra["source"]["calibration"]["spec"] == "gr00t-so100,shoulder_pan=0"
    assert r.video_path("webcam").read_bytes() == (
        dump / "videos" / "chunk-000" / VIDEO_KEY / "episode_000001.mp4").read_bytes()
    again = _cli("import", "groot-dreams", str(dump), "-o", str(tmp_path / "s"))
    assert again.returncode == 2 and "already exists" in again.stderr


def test_import_of_something_else_is_one_line(tmp_path):
    out = _cli("import", "groot-dreams", str(tmp_path), "-o", str(tmp_path / "s"))
    assert out.returncode == 2 and len(out.stderr.splitlines()) == 1 and "GR00T-Dreams" in out.stderr
    assert not (tmp_path / "s").exists()


def test_a_missing_video_leaves_the_arm_and_says_so(tmp_path):
    from inspector.data.importers.groot_dreams import NeuralTrajectories

    root = write_groot_dreams(tmp_path / "d", EPISODES[:1], video=False)
    rollout, gt = NeuralTrajectories(root).rollout(0)
    assert rollout.views == [] and gt.actions is None
    assert any("generated video" in w and "not found" in w for w in rollout.extra["warnings"])


def test_every_camera_of_a_dump_is_a_view(tmp_path):
    """Two cameras: both views in the app's rollout, in an imported session (each its own file,
    told apart by its colour), in info; one camera's missing file drops that view alone."""
    from inspector.data.importers.groot_dreams import NeuralTrajectories
    from inspector.data.session import open_session
    from inspector.data.video import VideoClip

    keys = ("observation.images.front", "observation.images.wrist")
    root = write_groot_dreams(tmp_path / "d", EPISODES[:2], video_keys=keys)
    rollout, _ = NeuralTrajectories(root).rollout(1)
    assert rollout.views == ["front", "wrist"]
    out = _cli("import", "groot-dreams", str(root), "-o", str(tmp_path / "s"))
    assert out.returncode == 0, out.stderr
    r = open_session(tmp_path / "s").rollouts["episode_000001"]
    assert r.views == ["front", "wrist"]
    for c, view in enumerate(r.views):  # frames(..., camera=c): blue 60 + 80 c
        _, rgb = next(iter(VideoClip(r.video_path(view)).iter_frames()))
        assert abs(float(rgb[:20, :20, 2].mean()) - (60 + 80 * c)) < 6, view
    info = json.loads(_cli("info", "--json", str(root)).stdout)
    assert sorted(info["views"]) == ["front", "wrist"]
    (root / "videos" / "chunk-000" / keys[1] / "episode_000000.mp4").unlink()
    rollout, _ = NeuralTrajectories(root).rollout(0)
    assert rollout.views == ["front"]
    assert any("wrist's generated video" in w and "that view is not shown" in w for w in rollout.extra["warnings"])


# ----------------------------------------------------------------------------------------------
# Scale: the index only


def test_a_thousand_episode_dump_lists_from_its_index(tmp_path):
    """1,000 episodes: the app lists them from meta/ (and the first episode's timestamps) alone;
    the other episodes' data files are not even there."""
    root = write_groot_dreams(tmp_path / "many", EPISODES[:1])
    lines = [json.dumps({"episode_index": e, "tasks": ["pick the grape"], "length": 93, "video_id": f"c{e}"})
             for e in range(1000)]
    (root / "meta" / "episodes.jsonl").write_text("\n".join(lines) + "\n")

    from inspector.app import InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    start = time.perf_counter()
    app = InspectorApp(open_sources([root], confine=True, datasets=True), port=0,
                       metrics_cache=MetricsCache(enabled=False))
    try:
        assert len(app.catalog.keys()) == 1000
        assert time.perf_counter() - start < 60  # generous: about a second on a quiet machine
        assert app.catalog.loaded_count() == 0
        with pytest.raises(InspectorError, match="episode_000500.parquet"):
            app.catalog.load(app.catalog.keys()[500])
    finally:
        app.stop()


# ----------------------------------------------------------------------------------------------
# In a real browser


@pytest.mark.browser
@pytest.mark.slow
def test_a_neural_trajectory_in_chromium(dump, tmp_path, browser):
    """Pick an episode in Debian Chromium: the generated video (no GT frame), the card with the
    <DREAM> task and the calibration, and the arm moving on the canvas as the step slider moves."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import re

    from browser import (
        canvas_is_drawn,
        frame_sources,
        hide_software_webgl_notice,
        open_app,
        page_client_id,
        select_option,
        slider_thumb,
        wait_until,
    )

    from inspector.app import serve

    scene = (420, 120, 960, 900)
    app = serve([str(dump)], port=0, block=False)
    try:
        page = browser.new_page(viewport={"width": 1600, "height": 1000})
        open_app(page, app.url)
        hide_software_webgl_notice(page)
        tab = wait_until(lambda: app.tabs.get(page_client_id(page)), what="the page's tab")
        key = next(k for k in app.catalog.keys() if k.startswith("so100.data_idm / episode 1 "))
        select_option(page, "Rollout", key)
        wait_until(lambda: tab.key == key and tab.loaded is not None, what="episode 1 to open")
        wait_until(lambda: set(frame_sources(page)) == {"webcam/imagined"}, timeout=60,
                   what="the generated video's frame in the page")
        for text in ("<DREAM>place the strawberry in the bowl", "gr00t-so100: shoulder_pan = x - 90"):
            page.get_by_text(text).first.wait_for(state="visible", timeout=60_000)
        page.wait_for_timeout(2000)  # let the software renderer draw the arm
        before_shot = page.screenshot(clip={"x": scene[0], "y": scene[1], "width": scene[2] - scene[0],
                                            "height": scene[3] - scene[1]})
        assert canvas_is_drawn(page.screenshot(), scene), "the 3D canvas is blank"
        before = frame_sources(page)["webcam/imagined"]
        thumb = slider_thumb(page, re.compile(r"^Step$"))
        thumb.focus()
        for _ in range(12):
            page.keyboard.press("ArrowRight")
        wait_until(lambda: tab.step == 12, what="the step slider to move the tab")
        wait_until(lambda: frame_sources(page)["webcam/imagined"] != before, what="the video frame to change")
        assert tab.pairs[0].imagined_index == 12
        wait_until(lambda: page.screenshot(clip={"x": scene[0], "y": scene[1], "width": scene[2] - scene[0],
                                                 "height": scene[3] - scene[1]}) != before_shot,
                   timeout=60, what="the arm to move on the canvas")
        page.close()
    finally:
        app.stop()


def test_report_html_of_a_dump_alone_is_written(dump, tmp_path):
    """A report of datasets alone has no rollout rows: the page is still written (it raised before)."""
    out = _cli("report", str(dump), "--html", str(tmp_path / "r.html"))
    assert out.returncode == 0, out.stderr
    page = (tmp_path / "r.html").read_text()
    assert page.startswith("<!DOCTYPE html>")
    table = page.split('<table id="trajectories">')[1].split("</table>")[0]
    assert table.count("<tr>") == 1 + len(EPISODES) and "&lt;DREAM&gt;" in table  # the heading and each episode
