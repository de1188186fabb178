"""The web app without a browser: tabs driven through TabState and a headless websocket client."""

from __future__ import annotations

import base64
import io
import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import av
import numpy as np
import pytest
import simplejpeg
from browser import wait_until

from inspector.app import HeadlessClient, TabState, serve
from inspector.app._cards import headline_metrics
from inspector.app._frames import READY
from inspector.app._playback_clip import CLIP_STEPS
from inspector.app._state import ARMS_AFTER_FRAME_S
from inspector.errors import InspectorError
from inspector.said.annotations import read_annotations, update_annotation

pytestmark = pytest.mark.slow  # a served app per module and the serve command as a process

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
# The demo's rollouts the app tests use, by what they are for (``inspector info sessions/demo``).
LONG = "overrun_60chunks"  # 60 chunks of 9 steps (540) on a 409-frame episode
TRAIN, NOVEL = "prompt_train", "prompt_novel"  # a training/novel prompt pair, 49 chunks each
LIMITS = "limits_wrist"  # wrist_flex driven past its limit
SINGLE, OTHER_SINGLE = "single_f076", "single_f153"  # single chunks
BROKEN = "single_f000"  # broken copy: truncated actions.npy
CARRIED_GT = "single_f230"  # carries its own GT videos; broken copy: a truncated GT front video
SEAM = "seam_jump"  # shoulder_pan jumps 20 deg where chunk 12 takes over
ROLLOUTS = (LONG, TRAIN, NOVEL, LIMITS, SINGLE, OTHER_SINGLE, BROKEN, CARRIED_GT, SEAM)
VIEWS = ("front", "wrist")


def make_sessions(root: Path) -> tuple[Path, Path]:
    """The bundled demo (its dataset, and the rollouts of ``ROLLOUTS``) copied into a session, and
    a copy with faults planted.

    ``CARRIED_GT`` carries its GT videos with it (its episode's frames, cut from the dataset), as
    an evaluation that logged its GT would. The copy's ``BROKEN`` has a truncated ``actions.npy``
    (the rollout fails to load) and its ``CARRIED_GT`` a truncated GT front video (that view fails,
    the rest of the rollout works).
    """
    from inspector.data.lerobot_dataset import open_dataset
    from inspector.data.video import encode_h264

    good = root / "demo"
    shutil.copytree(DEMO, good)
    for rollout in (good / "rollouts").iterdir():
        if rollout.name not in ROLLOUTS:
            shutil.rmtree(rollout)
    carried = good / "rollouts" / CARRIED_GT
    meta = json.loads((carried / "rollout.json").read_text())
    episode = open_dataset(good / "dataset").episode(meta["episode_index"])
    for view in VIEWS:
        frames = []
        for _, rgb in episode.clip_from(view, meta["start_frame"]).iter_frames():
            frames.append(rgb)
            if len(frames) == meta["frames_per_chunk"]:
                break
        encode_h264(carried / "gt" / "video" / f"{view}.mp4", frames, meta["fps"])
    meta["gt"]["views"] = list(VIEWS)
    (carried / "rollout.json").write_text(json.dumps(meta, indent=2) + "\n")
    broken = root / "broken"
    shutil.copytree(good, broken)
    actions = broken / "rollouts" / BROKEN / "actions.npy"
    actions.write_bytes(actions.read_bytes()[:200])
    video = broken / "rollouts" / CARRIED_GT / "gt" / "video" / "front.mp4"
    video.write_bytes(video.read_bytes()[:3000])
    return good, broken


@pytest.fixture(scope="module")
def sessions(tmp_path_factory) -> tuple[Path, Path]:
    return make_sessions(tmp_path_factory.mktemp("app"))


@pytest.fixture(scope="module")
def app(sessions):
    app = serve([sessions[1]], port=0, block=False)
    yield app
    app.stop()


def connect(app, n_before: int | None = None) -> tuple[HeadlessClient, TabState]:
    """A new headless client and the tab the app built for it."""
    before = set(app.tabs)
    client = HeadlessClient(app.port)
    deadline = time.monotonic() + 60
    while True:
        new = [t for cid, t in list(app.tabs.items()) if cid not in before]
        if new:
            tab = new[0]
            with tab.lock:  # the first rollout opens right after the tab registers
                pass
            return client, tab
        assert time.monotonic() < deadline, "no tab for the headless client"
        time.sleep(0.05)


def key(app, tag: str) -> str:
    return next(k for k, e in app.catalog.entries.items() if e.tag == tag)


def test_tab_opens_and_scrubs(app):
    client, tab = connect(app)
    with client:
        assert tab.open(key(app, LONG))
        tl = tab.loaded.timeline
        assert tl.n_steps == 540 and tab.step == 0
        assert tab.set_step(100) == 100
        assert (tab.chunk, tab.step_in_chunk) == (100 // 9, 100 % 9)
        assert tab.controls.chunk.value == 11 and tab.controls.step_in_chunk.value == 1
        assert tab.set_step(10_000) == 539  # clamped
        assert tab.set_chunk(3) == 3 * 9 + 8  # keeps the step within the chunk
        # The frames arrive in the background, then every view shows a pair.
        assert tab.loaded.frames.done.wait(60)
        tab.set_step(20, force=True)
        assert {p.view for p in tab.pairs} == set(VIEWS)
        assert all(p.status == READY and p.imagined and p.gt for p in tab.pairs)
        assert all(p.imagined_index == tl.frame_index(20) for p in tab.pairs)
        before = [p.imagined for p in tab.pairs]
        tab.set_step(200)
        assert [p.imagined for p in tab.pairs] != before
        # Past the real episode's end (409 steps) there is no GT frame, and it says so.
        tab.set_step(450)
        assert all(p.gt is None and "end" in p.gt_note for p in tab.pairs)
        assert tab.loaded.timeline.episode_end_step == 409


def test_worst_chunk_and_limits(app):
    client, tab = connect(app)
    with client:
        assert tab.open(key(app, LIMITS))
        tl = tab.loaded.timeline
        assert tab.jump_to_worst_chunk() == tl.worst_chunk()[0] * tl.steps_per_chunk
        bad = int(np.flatnonzero(tl.limit_violation.any(axis=1))[0])
        tab.set_step(bad)
        texts = tab._limit_text(bad)
        assert any(texts) and all(("limit" in t) == v for t, v in zip(texts, tl.limit_violation[bad]))


def test_seam_key_cycles_through_flagged_seams_and_the_card_lists_the_measures(app):
    client, tab = connect(app)
    with client:
        assert tab.open(key(app, SEAM))
        tl = tab.loaded.timeline
        assert tab.jump_to_next_seam() == 12 * tl.steps_per_chunk  # the planted seam, the only one flagged
        assert tab.jump_to_next_seam() == 12 * tl.steps_per_chunk  # wraps round to it
        rows = dict(headline_metrics(tl))
        assert rows["chunk seams flagged"].startswith("12 · worst 20.")
        assert rows["completion"].startswith("never")
        # the timeline (chunk slider) and the drift plot mark the flagged seam, there only
        assert [(m.value, m.label) for m in tab.controls.chunk._marks] == [(12.0, "seam")]
        drift = tab.plots.drift_plot
        assert drift is not None and drift.handle.visible
        series = [o["label"] for o in drift.handle.series]
        seam_x = drift.handle.data[0][np.isfinite(drift.handle.data[series.index("seam flagged")])]
        assert np.allclose(seam_x, tl.t_s[12 * tl.steps_per_chunk])
        assert tab.open(key(app, LIMITS))
        assert tab.jump_to_next_seam() == tab.step  # none flagged: stays
        # no seam mark left over from the last rollout (this one completes: that is marked)
        assert [m.label for m in tab.controls.chunk._marks or ()] == ["done"]
        assert "seam flagged" not in [o["label"] for o in tab.plots.drift_plot.handle.series]


def test_a_light_3d_page_gets_a_steps_frames_before_its_arms(app):
    """A page drawing WebGL in software (Light 3D) is sent a step's frames and readout at once and
    the arms' pose just after, so it paints the frames before a 3D redraw blocks it; a page with
    a GPU gets the whole step in one message."""
    client, tab = connect(app)
    with client:
        assert tab.open(key(app, LONG))
        ee_pred = tab.scene.data.ee_pred

        def posed_at(step: int) -> bool:
            return bool(np.allclose(tab.scene._ee_pred.position, ee_pred[step], atol=1e-6))

        with tab.lock:  # nothing else runs on this tab meanwhile
            assert tab.controls.light_3d.value is True  # every page starts plainly lit (see _light_3d)
            tab.controls.light_3d.value = False  # as a page with a GPU unticks it
            tab.set_step(50)
            assert posed_at(50)  # Light 3D off: all at once
            tab.controls.light_3d.value = True
            tab.set_step(60)
            assert "step 60" in tab.controls.readout.content and "data-step='60'" in tab._video_html
            assert posed_at(50)  # the arms follow
        wait_until(lambda: posed_at(60), what="the arms posed at the new step")
        with tab.lock:  # two quick steps: the arms go to the last one
            tab.set_step(70)
            tab.set_step(80)
        wait_until(lambda: posed_at(80), what="the arms posed at the last step")
        time.sleep(2 * ARMS_AFTER_FRAME_S)
        assert posed_at(80)


def test_tabs_are_independent(app):
    c1, t1 = connect(app)
    c2, t2 = connect(app)
    with c1, c2:
        assert t1 is not t2 and t1.client_id != t2.client_id
        assert t1.open(key(app, LONG)) and t2.open(key(app, LONG))
        t1.set_step(250)
        assert t2.step == 0 and t2.controls.chunk.value == 0
        assert t1.loaded.timeline is t2.loaded.timeline  # shared, built once
        t2.open(key(app, SINGLE))
        assert t1.key == key(app, LONG) and t1.step == 250


def test_slider_move_from_client_moves_only_that_tab(app):
    c1, t1 = connect(app)
    c2, t2 = connect(app)
    with c1, c2:
        t1.open(key(app, LONG))
        t2.open(key(app, LONG))
        # What a browser sends when the user drags the chunk slider (uuid: viser's internal id).
        c1.set_gui_value(t1.controls.chunk._impl.uuid, 7)
        deadline = time.monotonic() + 10
        while t1.chunk != 7 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert t1.chunk == 7 and t1.step == 63
        assert t2.step == 0


def test_broken_rollout_shows_error_card_and_others_work(app):
    client, tab = connect(app)
    with client:
        assert not tab.open(key(app, BROKEN))
        assert isinstance(tab.error, InspectorError)
        assert tab.controls.error.visible and "actions.npy" in tab.controls.error.content
        assert tab.loaded is None
        tab.set_step(5)  # harmless without a rollout
        assert tab.open(key(app, SINGLE))
        assert not tab.controls.error.visible and tab.error is None


def test_broken_video_fails_alone(app):
    client, tab = connect(app)
    with client:
        assert tab.open(key(app, CARRIED_GT))
        frames = tab.loaded.frames
        assert frames.done.wait(60)
        assert frames.status["front"] == READY and frames.status["wrist"] == READY
        assert frames.gt_status["front"] != READY and "front.mp4" in frames.gt_status["front"]
        assert frames.gt_status["wrist"] == READY
        tab.set_step(3, force=True)
        by_view = {p.view: p for p in tab.pairs}
        assert by_view["front"].imagined and by_view["front"].gt is None
        assert by_view["wrist"].imagined and by_view["wrist"].gt
        assert "front.mp4" in tab.video.html.content


def test_timeline_failure_shows_error_card(app, monkeypatch):
    import inspector.app._catalog as catalog_module

    def explode(rollout, **settings):
        raise RuntimeError("metrics blew up")

    monkeypatch.setattr(catalog_module, "build_timeline", explode)
    client, tab = connect(app)
    with client:
        assert not tab.open(key(app, OTHER_SINGLE))
        assert "metrics blew up" in tab.controls.error.content
        assert OTHER_SINGLE in tab.controls.error.content
        monkeypatch.undo()
        assert tab.open(key(app, OTHER_SINGLE))  # a failure is not cached


def test_names_from_the_browser_are_never_paths(app):
    client, tab = connect(app)
    with client:
        opened = tab.key
        assert not tab.open("../../../etc/passwd")
        assert not tab.open("/etc")
        assert tab.key == opened


def test_compare_mode(app):
    client, tab = connect(app)
    with client:
        tab.open(key(app, TRAIN))
        n_plots = len(tab.plots.plots)
        assert tab.set_compare(key(app, NOVEL))
        assert tab.compare is not None and tab.scene.cmp_arm is not None and tab.scene.cmp_arm.visible
        assert len(tab.plots.plots) == n_plots + 1  # the divergence plot
        assert NOVEL in tab.controls.compare_info.content
        # the compared rollout's imagined frames sit beside the open one's, view by view
        assert tab.compare.frames.decoded.wait(120)
        tab.set_step(300, force=True)
        assert set(tab.compare_pairs) == set(VIEWS)
        assert all(p.imagined and p.imagined_index == 300 for p in tab.compare_pairs.values())
        html = tab.video.html.content
        assert html.count("data-kind='compare'") == len(VIEWS) and f"{NOVEL} · imagined" in html
        assert tab.set_compare(None) and not tab.scene.cmp_arm.visible
        tab.set_step(301, force=True)
        assert tab.compare_pairs == {} and "data-kind='compare'" not in tab.video.html.content


def test_view_selector_shows_one_view_large(app):
    client, tab = connect(app)
    with client:
        tab.open(key(app, LONG))
        assert tab.loaded.frames.decoded.wait(120)
        assert tab.video.view.options == ("all views", *VIEWS)
        tab.video.view.value = "wrist"
        tab._redraw_video()
        assert [p.view for p in tab.pairs] == ["wrist"]
        assert "repeat(1," in tab.video.html.content  # stacked, full width


def test_one_chunk_has_no_chunk_controls_and_the_camera_frames_the_scene(app):
    client, tab = connect(app)
    with client:
        tab.open(key(app, SINGLE))  # a single chunk
        assert not tab.controls.chunk.visible and not tab.controls.nav.visible
        assert tab.controls.step_in_chunk.label == "Step" and tab.controls.step_in_chunk.max == 23
        assert "chunk" not in tab.controls.readout.content.split("<br>")[0]
        tab.open(key(app, LONG))
        assert tab.controls.chunk.visible and tab.controls.chunk.max == 59
        # the camera looks at the middle of what is drawn, from far enough to see all of it
        scene = tab.loaded.scene
        pts = np.concatenate([scene.joint_pos.reshape(-1, 3), scene.ee_pred])
        look = np.array(client_camera(tab).look_at)
        assert np.all(look > pts.min(axis=0) - 0.05) and np.all(look < pts.max(axis=0) + 0.05)
        assert np.linalg.norm(np.array(client_camera(tab).position) - look) > 0.3


def client_camera(tab):
    return tab.client.camera


def test_playback_advances_and_stops(app):
    client, tab = connect(app)
    tab.open(key(app, LONG))
    tab.speed = 4.0
    tab.play()
    time.sleep(0.6)
    tab.pause()
    reached = tab.step
    assert reached > 10
    time.sleep(0.3)
    assert tab.step == reached
    tab.play()
    client.close()  # the tab goes away: its playback thread must stop
    assert tab.closed.wait(10)
    wait_until(lambda: not tab.playing, 30)  # close() takes the tab's lock after setting closed
    frozen = tab.step
    time.sleep(0.3)
    assert tab.step == frozen and not tab.playing


def test_notes_from_two_tabs_both_survive(app, sessions):
    c1, t1 = connect(app)
    c2, t2 = connect(app)
    with c1, c2:
        k = key(app, LONG)
        t1.open(k)
        t2.open(k)
        t1.set_chunk(4)
        t2.set_chunk(9)
        results = []
        threads = [threading.Thread(target=lambda t=t, n=n: results.append(
            t.save_notes(rollout_flag=True, chunk_flag=True, chunk_note=n)))
            for t, n in ((t1, "tab one"), (t2, "tab two"))]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        assert results == [True, True]
        data = json.loads((sessions[1] / "annotations.json").read_text())
        chunks = data["rollouts"][LONG]["chunks"]
        assert chunks["4"] == {"flag": True, "note": "tab one"}
        assert chunks["9"] == {"flag": True, "note": "tab two"}


def test_export_sends_the_recording(app):
    pytest.importorskip("inspector.export.recording")
    client, tab = connect(app)
    with client:
        assert tab.open(key(app, SINGLE))
        before = client.received_bytes
        thread = tab.export()
        thread.join(120)
        assert tab.export_result is not None and tab.export_result.startswith("sent"), tab.export_result
        size = int(tab.export_result.split()[1])
        assert size > 100_000
        # The file went to this client (messages are zstd-compressed on the wire: compare loosely).
        deadline = time.monotonic() + 10
        while client.received_bytes - before < size // 4 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert client.received_bytes - before >= size // 4


def test_annotations_concurrent_writers(tmp_path):
    def writer(offset: int) -> None:
        for i in range(25):
            update_annotation(tmp_path, "r", chunk=offset + i, flag=True, note=f"n{offset + i}")

    threads = [threading.Thread(target=writer, args=(k * 100,)) for k in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    chunks = read_annotations(tmp_path)["rollouts"]["r"]["chunks"]
    assert len(chunks) == 100 and chunks["305"]["note"] == "n305"
    update_annotation(tmp_path, "r", chunk=305, flag=False, note="")
    assert "305" not in read_annotations(tmp_path)["rollouts"]["r"]["chunks"]


def test_annotations_never_overwrite_a_damaged_file(tmp_path):
    (tmp_path / "annotations.json").write_text("{ not json")
    with pytest.raises(InspectorError, match="annotations.json"):
        update_annotation(tmp_path, "r", flag=True)
    assert (tmp_path / "annotations.json").read_text() == "{ not json"


def test_cursor_plot_markers(app):
    from inspector.app._plots import CursorPlot, Line

    x = np.arange(20) / 10.0
    plot = CursorPlot(app.server.gui, "t", x, [Line("a", np.sin(x), "#000")], ticks=[0.0, 0.9], end=1.5)
    plot.set_cursor(0.55)
    data = plot.handle.data
    assert len({len(d) for d in data}) == 1
    assert np.all(np.diff(data[0]) >= 0)
    cursor = data[-1]
    assert np.isfinite(cursor).sum() == 2 and np.all(data[0][np.isfinite(cursor)] == 0.55)
    assert np.isfinite(data[-2]).sum() == 2  # episode end line
    assert np.isfinite(data[-3]).sum() == 6  # two chunk ticks, three samples each
    assert np.isfinite(data[1]).all()  # the data line runs unbroken through every marker
    plot.handle.remove()
    # marks of one label are one series, one vertical line each, not joined to each other
    plot = CursorPlot(app.server.gui, "t", x, [Line("a", np.sin(x), "#000")],
                      marks=[(0.3, "seam", "#f00"), (1.2, "seam", "#f00"), (0.7, "done", "#0f0")])
    labels = [o["label"] for o in plot.handle.series]
    assert labels.count("seam") == 1 and labels.count("done") == 1
    xs, seam = plot.handle.data[0], plot.handle.data[labels.index("seam")]
    assert sorted(set(xs[np.isfinite(seam)])) == [0.3, 1.2] and np.isfinite(seam).sum() == 4
    between = (xs > 0.3) & (xs < 1.2)
    assert not np.isfinite(seam[between]).any()  # nothing drawn from one mark to the next
    plot.handle.remove()


def test_serve_without_demo_says_how_to_build_it(monkeypatch, tmp_path):
    import inspector.app._server as server_module

    monkeypatch.setattr(server_module, "BUNDLED_DEMO", tmp_path / "missing")
    with pytest.raises(InspectorError, match="inspector demo --rebuild"):
        serve([], port=0, block=False)


def test_cli_serve_subprocess(sessions):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "inspector", "serve", str(sessions[0]), "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        deadline = time.monotonic() + 60
        lines = []
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            lines.append(line)
            if "inspector: serving" in line or proc.poll() is not None:
                break
        assert f"inspector: serving {len(ROLLOUTS)} rollout(s)" in "".join(lines), "".join(lines)
        assert f"127.0.0.1:{port}" in "".join(lines)  # loopback unless --host
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as r:
            assert r.status == 200 and b"<html" in r.read().lower()
        with HeadlessClient(port):
            time.sleep(1.0)  # a tab builds in the subprocess without errors
        assert proc.poll() is None
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()


def test_playback_swaps_in_clips_of_the_shown_frames_and_back(app):
    """Play: every video panel gets an H.264 clip of exactly the frames it would step through, at
    the playback rate; a second Play finds them cached; Pause brings the step's images back."""
    client, tab = connect(app)
    with client:
        tab.open(key(app, LONG))
        wait_until(tab.loaded.frames.done.is_set, timeout=120, what="the frames")
        tl = tab.loaded.timeline
        tab.speed = 0.25  # a slow clock: the clip is ready long before playback ends
        tab.play()
        wait_until(lambda: tab._clip is not None, timeout=120, what="the playback clips")
        with tab.lock:
            clip, html = tab._clip, tab.video.html.content
        panels = {(p.view, "imagined") for p in tab.pairs if p.imagined} | {(p.view, "gt") for p in tab.pairs if p.gt}
        assert set(clip.uris) == panels and html.count("<video") == len(panels) and "<img" not in html
        # the clip stops where the GT panel loses its frame (past the real episode's end)
        assert clip.start == 0 and clip.end == min(tl.n_steps, CLIP_STEPS, tl.episode_end_step or tl.n_steps) and clip.fps == pytest.approx(tl.fps * 0.25)
        for (view, kind), uri in clip.uris.items():
            with av.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))) as video:
                frames = list(video.decode(video=0))
            assert len(frames) == clip.end - clip.start
            assert float(frames[-1].time) == pytest.approx((len(frames) - 1) / clip.fps, abs=2e-3)
            # the clip's first frame is the panel's frame at the clip's first step (H.264 close)
            shown = tab.loaded.frames.pair(view, clip.start)
            jpeg = shown.imagined if kind == "imagined" else shown.gt
            want = simplejpeg.decode_jpeg(base64.b64decode(jpeg.split(",", 1)[1]), colorspace="RGB").astype(float)
            got = frames[0].to_ndarray(format="rgb24").astype(float)
            h, w = got.shape[:2]
            assert np.abs(got - want[:h, :w]).mean() < 8, f"{view}/{kind}: the clip does not show the panel's frames"
        tab.pause()
        assert tab._clip is None and "<video" not in tab.video.html.content and "<img" in tab.video.html.content
        tab.set_step(0)
        tab.play()  # again: the clips come from the frame cache
        wait_until(lambda: tab._clip is not None, timeout=30, what="the cached clips")
        assert tab._clip.uris == clip.uris
        tab.speed = 0.5  # a clip is made for one speed: another goes back to images
        tab.set_step(tab.step + 1)
        assert "<video" not in tab.video.html.content
        tab.pause()


def test_a_closed_tab_stops_encoding_its_playback_clips(app, monkeypatch):
    """A tab closed (or paused) while its clips encode stops encoding them: no CPU goes on clips
    no one will see. Each panel's encoding is held at its start until the tab has closed."""
    import inspector.app._playback as playback_module
    from inspector.app._playback_clip import ASK_EVERY, ClipNotWanted, encode_clip

    closed, started, ended = threading.Event(), [], []

    def encode_once_closed(uris, fps, wanted=lambda: True):
        started.append(len(uris))
        assert closed.wait(60), "the tab was never closed"
        try:
            uri = encode_clip(uris, fps, wanted)
        except ClipNotWanted:
            ended.append("stopped")
            raise
        ended.append("finished")
        return uri

    monkeypatch.setattr(playback_module, "encode_clip", encode_once_closed)
    client, tab = connect(app)
    with client:
        tab.open(key(app, LONG))
        wait_until(tab.loaded.frames.done.is_set, timeout=120, what="the frames")
        tab.speed = 0.3  # a speed of its own: no clip of it is cached yet
        tab.play()
        panels = {(p.view, k) for p in tab.pairs for k, uri in (("imagined", p.imagined), ("gt", p.gt)) if uri}
        wait_until(lambda: len(started) == len(panels), timeout=60, what="every panel's clip to start encoding")
        assert min(started) > ASK_EVERY
        tab.close()
        closed.set()
        wait_until(lambda: len(ended) == len(panels), timeout=60, what="every panel's encoding to end")
    assert ended == ["stopped"] * len(panels)
