"""LeRobot datasets on their own: episodes browsed in the app, exported, reported (tracking error).

The datasets are the ones LeRobot itself wrote (``tests/data/lerobot``: v3.0 with three episodes and two
AV1 cameras, v2.1 with two episodes and one) and the demo's own dataset.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from cli_processes import module_command_server

from inspector.data.session import SessionWriter
from inspector.errors import InspectorError
from inspector.units import JOINT_NAMES

pytestmark = pytest.mark.slow  # the CLI as processes, a Hub server and a browser page

REPO = Path(__file__).resolve().parents[1]
DEMO_DATASET = REPO / "sessions" / "demo" / "dataset"
RERUN = Path(sys.executable).parent / "rerun"


@pytest.fixture(scope="module")
def v30(lerobot_dir) -> Path:
    return lerobot_dir / "so101_v30"


@pytest.fixture(scope="module")
def v21(lerobot_dir) -> Path:
    return lerobot_dir / "so101_v21"


def _raw_joints(root: Path, episode: int) -> tuple[np.ndarray, np.ndarray]:
    """(state, action) of a v3.0 episode read straight from the parquet, by joint name."""
    info = json.loads((root / "meta" / "info.json").read_text())
    table = pq.read_table(root / "data" / "chunk-000" / "file-000.parquet",
                          filters=[("episode_index", "=", episode)]).to_pydict()
    out = []
    for key in ("observation.state", "action"):
        names = [n.removesuffix(".pos") for n in info["features"][key]["names"]]
        values = np.array(table[key], dtype=np.float64)
        out.append(values[:, [names.index(j) for j in JOINT_NAMES]])
    return out[0], out[1]


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def _cli(*args: str, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return _run_command(*args, timeout=timeout, env={**os.environ, **(env or {})})


# ----------------------------------------------------------------------------------------------
# The app


@pytest.fixture(scope="module")
def app(v30, v21):
    from inspector.app import InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    app = InspectorApp(open_sources([v30, v21], confine=True, datasets=True), port=0,
                       metrics_cache=MetricsCache(enabled=False))
    yield app
    app.stop()


def test_the_picker_lists_every_episode_with_task_and_length(app):
    keys = app.catalog.keys()
    assert len(keys) == 5  # 3 + 2 episodes
    assert "so101_v30 / episode 2 · 240 frames (8.0 s) · Put the red cube on top of the blue cube" in keys
    assert any(k.startswith("so101_v21 / episode 1 · 195 frames") for k in keys)
    assert app.catalog.default_key() == keys[0]


def test_an_episode_shows_commanded_and_measured_arms_and_its_cameras(app, v30):
    from inspector.app import HeadlessClient

    key = next(k for k in app.catalog.keys() if k.startswith("so101_v30 / episode 1 "))
    state, action = _raw_joints(v30, 1)
    with HeadlessClient(app.port):
        tab = app.wait_for_tabs(1)[0]
        assert tab.open(key)
        tl = tab.loaded.timeline
        assert tl.kind == "episode" and tl.n_steps == 210 and tl.n_chunks == 1
        np.testing.assert_allclose(tl.pred, action)  # the translucent arm: the command
        np.testing.assert_allclose(tl.gt_aligned, state)  # the opaque arm: what was measured
        np.testing.assert_allclose(tl.time_aligned_drift, np.linalg.norm(action - state, axis=1))
        assert tl.best_match_drift is None and tl.dtw_drift is None  # one clock: no alignment needed
        assert not tab.controls.chunk.visible and tab.controls.step_in_chunk.label == "Frame"
        card = tab.controls.card.content
        assert "commanded arm (action)" in card and "measured arm (observation.state)" in card
        assert "tracking error" in card and "Pick the red cube and place it in the bowl" in card
        assert tab.loaded.frames.decoded.wait(120)
        tab.set_step(150, force=True)
        assert {p.view for p in tab.pairs} == {"front", "wrist"}
        assert all(p.gt and p.gt_index == 150 and not p.has_imagined for p in tab.pairs)
        assert "frame 150 / 209" in tab.controls.readout.content
        assert tab.plots.plots[0].handle.title.startswith("Tracking error |commanded − measured|")
        assert not tab.save_notes()  # the dataset is never written to
        assert "annotations.json" in tab.controls.notes_info.content


def test_episode_frames_are_the_dataset_frames(app, v30):
    from inspector.app._frames import jpeg_data_uri
    from inspector.data.lerobot_dataset import LeRobotDataset

    key = next(k for k in app.catalog.keys() if k.startswith("so101_v30 / episode 2 "))
    loaded = app.catalog.load(key)
    assert loaded.frames.decoded.wait(120)
    frame = LeRobotDataset(v30).episode(2).frame("wrist", 37)
    pair = loaded.frames.pair("wrist", 37)
    assert pair.gt == jpeg_data_uri(frame, loaded.frames.display_size("wrist"))


# ----------------------------------------------------------------------------------------------
# report and export


def test_report_on_a_dataset_gives_per_episode_tracking_rows(v30):
    out = _cli("report", str(v30), "--json")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    rows = report["episodes"]
    assert [r["episode_index"] for r in rows] == [0, 1, 2] and [r["length"] for r in rows] == [150, 210, 240]
    for row in rows:
        state, action = _raw_joints(v30, row["episode_index"])
        err = np.abs(action - state)
        for k, j in enumerate(JOINT_NAMES):
            assert row["tracking_error"]["mean"][j] == pytest.approx(err[:, k].mean())
            assert row["tracking_error"]["max"][j] == pytest.approx(err[:, k].max())
            assert row["joint_range"][j] == pytest.approx([state[:, k].min(), state[:, k].max()])
        assert row["tracking_error"]["l2_mean"] == pytest.approx(np.linalg.norm(action - state, axis=1).mean())
        assert set(row["limit_violations"]) == {"measured", "commanded"}
    text = _cli("report", str(v30)).stdout
    assert "Dataset episodes" in text and "Put the red cube on top of the blue cube" in text


def test_export_an_episode(v30, tmp_path):
    dest = tmp_path / "ep1.rrd"
    out = _cli("export", str(v30), "--episode", "1", "-o", str(dest), "--no-cache")
    assert out.returncode == 0, out.stderr
    verify = subprocess.run([str(RERUN), "rrd", "verify", str(dest)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_export import Recording

    from inspector.export import layout as L

    rec = Recording(dest)
    description = rec.static(L.DESCRIPTION, "TextDocument:text")[0][0]
    assert "Episode 1 of `so101_v30`" in str(description) and "tracking error" in str(description).lower()
    for view in ("front", "wrist"):  # each camera as an H.264 asset, one reference per frame
        frames, _ = rec.temporal(L.video_path(view, "gt"), "VideoFrameReference:timestamp")
        assert list(frames) == list(range(210))
    missing = _cli("export", str(v30), "--episode", "7", "-o", str(tmp_path / "x.rrd"))
    assert missing.returncode == 2 and "no episode 7" in missing.stderr and len(missing.stderr.splitlines()) == 1
    assert not (tmp_path / "x.rrd").exists()


# ----------------------------------------------------------------------------------------------
# Rollouts whose episode the dataset lacks


def test_a_rollout_whose_episode_is_missing_is_stated(v30, tmp_path):
    from inspector.report.build import build_report

    with SessionWriter.create(tmp_path / "s", dataset=str(v30)) as w:
        w.add_rollout("ep001_train", kind="autoregressive", actions=np.zeros((2, 24, 6)), episode_index=1)
        w.add_rollout("ep206_train", kind="autoregressive", actions=np.zeros((2, 24, 6)), episode_index=206)
    report = build_report([str(tmp_path / "s")], jobs=1, use_cache=False)
    assert {r["tag"] for r in report["rollouts"]} == {"ep001_train", "ep206_train"}
    assert report["warnings"] == ["ep206_train: dataset so101_v30 has no episode 206 (episodes 0..2)"]
    row = next(r for r in report["rollouts"] if r["tag"] == "ep206_train")
    assert row["time_aligned_drift"] is None and "has no episode 206" in row["gt_source"]

    from inspector.app import HeadlessClient, InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    app = InspectorApp(open_sources([tmp_path / "s"], confine=True), port=0, metrics_cache=MetricsCache(enabled=False))
    try:
        with HeadlessClient(app.port):
            tab = app.wait_for_tabs(1)[0]
            assert tab.open(next(k for k in app.catalog.keys() if k.endswith("ep206_train")))
            assert "dataset so101_v30 has no episode 206" in tab.controls.card.content
    finally:
        app.stop()


# ----------------------------------------------------------------------------------------------
# Many episodes: the index only


def test_a_dataset_of_thousands_of_episodes_opens_from_its_index(tmp_path):
    """2,000 episodes: serving reads meta/ only (its data file may even be gone), memory stays small,
    and opening an episode whose data is missing shows an error card naming the file."""
    from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset

    rng = np.random.default_rng(0)
    episodes = [EpisodeData(f"task {i % 7}", rng.normal(0, 10, (4, 6)), rng.normal(0, 10, (4, 6)))
                for i in range(2000)]
    root = write_lerobot_dataset(tmp_path / "many", episodes)
    data = root / "data" / "chunk-000" / "file-000.parquet"
    data.rename(data.with_suffix(".moved"))

    from inspector.app import HeadlessClient, InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    start = time.perf_counter()
    app = InspectorApp(open_sources([root], confine=True, datasets=True), port=0,
                       metrics_cache=MetricsCache(enabled=False))
    try:
        assert len(app.catalog.keys()) == 2000
        assert time.perf_counter() - start < 60  # generous: seconds on a quiet machine
        with HeadlessClient(app.port):
            tab = app.wait_for_tabs(1)[0]
            assert tab.error is not None and "file-000.parquet" in tab.controls.error.content
        assert app.catalog.loaded_count() == 0
    finally:
        app.stop()


# ----------------------------------------------------------------------------------------------
# Hub datasets


def test_a_dataset_named_org_name_is_fetched_from_the_hub_once(v21, tmp_path):
    pytest.importorskip("huggingface_hub")
    from hub_server import FakeHub

    home = tmp_path / "lerobot_home"
    env = {"HF_LEROBOT_HOME": str(home), "HF_HUB_DISABLE_TELEMETRY": "1", "HF_HOME": str(tmp_path / "hf"),
           "INSPECTOR_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("HF_HUB_OFFLINE", None)
    with FakeHub(v21, "me/so101_small") as hub:
        out = _cli("report", "me/so101_small", "--json", env={**env, "HF_ENDPOINT": hub.url})
        assert out.returncode == 0, out.stderr
        assert [r["episode_index"] for r in json.loads(out.stdout)["episodes"]] == [0, 1]
        assert any(p.endswith("meta/info.json") for p in hub.requests)
    assert (home / "me" / "so101_small" / "meta" / "info.json").is_file()
    assert not [p for p in (home / "me").iterdir() if p.name.startswith(".")]  # no staging left
    # now local: found offline, without the hub
    again = _cli("report", "me/so101_small", "--json", env={**env, "HF_HUB_OFFLINE": "1"})
    assert again.returncode == 0, again.stderr


def test_offline_a_missing_hub_dataset_is_one_line_saying_how_to_get_it(tmp_path):
    env = {"HF_LEROBOT_HOME": str(tmp_path / "home"), "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path / "hf")}
    out = _cli("report", "me/nowhere", "--json", env=env)
    assert out.returncode == 2 and out.stdout == ""
    assert len(out.stderr.splitlines()) == 1 and "HF_HUB_OFFLINE" in out.stderr
    assert "huggingface-cli download me/nowhere" in out.stderr


def test_an_unreachable_hub_is_one_line(tmp_path):
    pytest.importorskip("huggingface_hub")
    env = {"HF_LEROBOT_HOME": str(tmp_path / "home"), "HF_HOME": str(tmp_path / "hf"),
           "HF_ENDPOINT": "http://127.0.0.1:9", "HF_HUB_ETAG_TIMEOUT": "2", "HF_HUB_DOWNLOAD_TIMEOUT": "2"}
    out = _cli("serve", "me/nowhere", "--port", "0", env=env, timeout=120)
    assert out.returncode == 2 and len(out.stderr.splitlines()) == 1, out.stderr
    assert "cannot download" in out.stderr and "me/nowhere" in out.stderr
    assert not (tmp_path / "home" / "me" / "nowhere").exists()


def test_find_dataset_refuses_a_directory_without_info(tmp_path):
    from inspector.data.lerobot_dataset import find_dataset

    with pytest.raises(InspectorError, match="meta/info.json is missing"):
        find_dataset(tmp_path, download=True)


# ----------------------------------------------------------------------------------------------
# In a real browser


@pytest.mark.browser
@pytest.mark.slow
def test_episode_view_in_chromium(v30, tmp_path, browser):
    """Pick an episode in Debian Chromium: its cameras, both arms' card and plots, and the frame
    slider moving the camera frames."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
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

    app = serve([str(v30)], port=0, block=False)
    try:
        page = browser.new_page(viewport={"width": 1600, "height": 1000})
        open_app(page, app.url)
        hide_software_webgl_notice(page)
        tab = wait_until(lambda: app.tabs.get(page_client_id(page)), what="the page's tab")
        key = next(k for k in app.catalog.keys() if k.startswith("so101_v30 / episode 2 "))
        select_option(page, "Rollout", key)
        wait_until(lambda: tab.key == key and tab.loaded is not None, what="episode 2 to open")
        wait_until(lambda: set(frame_sources(page)) == {"front/gt", "wrist/gt"}, timeout=60,
                   what="both cameras' frames in the page")
        # the card may follow the frames on a busy machine: wait for it (raises if it never shows)
        for text in ("commanded arm (action)", "Put the red cube on top of the blue cube"):
            page.get_by_text(text).first.wait_for(state="visible", timeout=60_000)
        before = frame_sources(page)["front/gt"]
        thumb = slider_thumb(page, "Frame")
        thumb.focus()
        for _ in range(5):
            page.keyboard.press("ArrowRight")
        wait_until(lambda: tab.step == 5, what="the frame slider to move the tab")
        wait_until(lambda: frame_sources(page)["front/gt"] != before, what="the camera frame to change")
        shot = tmp_path / "episode.png"

        def scene_drawn() -> bool:  # the software renderer draws the arms within a frame or two
            page.screenshot(path=str(shot))
            return canvas_is_drawn(shot.read_bytes(), (420, 120, 960, 900))
        wait_until(scene_drawn, timeout=60, interval=0.5, what=f"the 3D canvas to be drawn (see {shot})")
        page.close()
    finally:
        app.stop()
