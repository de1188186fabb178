"""``inspector eval`` through the CLI against a real local policy server (tests/policy_server.py):
what the server receives, the session written (metrics exact against the server's known chunks),
faults one line each with nothing lost, resume, and bad input."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from inspector.data import open_dataset, open_session
from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset
from inspector.eval.wire import packb
from inspector.units import JOINT_NAMES

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cli_processes import module_command_server  # noqa: E402
from policy_server import DEFAULT_CONFIG, object_array, policy_server, ramp  # noqa: E402

pytestmark = pytest.mark.slow  # policy servers and the eval command as processes

LENGTHS = (60, 45)
HORIZON = 24
DEADLINE_S = 120  # generous: the suite runs on a busy 2-core machine


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def run_cli(*args: str, timeout: float = DEADLINE_S) -> subprocess.CompletedProcess:
    return _run_command(*args, timeout=timeout)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two episodes, cameras front and wrist (64x48), state a smooth curve per joint, action the
    state 1.5 ahead."""
    episodes = []
    for e, n in enumerate(LENGTHS):
        t = np.arange(n)[:, None]
        state = 20 * np.sin(t / 9 + np.arange(6)) + np.array([0, 10, 20, 30, 40, 50])
        frames = {cam: np.full((n, 48, 64, 3), 60 * (i + 1) + e, np.uint8) for i, cam in enumerate(("front", "wrist"))}
        episodes.append(EpisodeData(f"pick cube {e}", state, state + 1.5 * (1 + t / n), frames))
    return write_lerobot_dataset(tmp_path_factory.mktemp("eval") / "ds", episodes)


def expected_row(dataset: Path, episode: int, start: int, scale: float = 1.0) -> dict[str, object]:
    """The metrics of the server's answer (state + ramp, sent as float32) against the dataset's actions."""
    ep = open_dataset(dataset).episode(episode)
    pred = (ep.state[start] + scale * ramp(HORIZON)).astype(np.float32).astype(np.float64)
    err = pred - ep.action[start:start + HORIZON]
    return {"rmse_deg": float(np.sqrt(np.mean(err ** 2))), "per_step_mse": np.mean(err ** 2, axis=1),
            "per_joint_rmse": np.sqrt(np.mean(err ** 2, axis=0))}


def evenly_spaced(n: int, length: int) -> list[int]:
    return sorted({int(round(v)) for v in np.linspace(0, length - HORIZON, n)})


def error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("error: ")]


@pytest.mark.parametrize("form", ["array", "map"])
def test_samples_reach_the_server_and_the_session_measures_them_exactly(dataset: Path, tmp_path: Path, form: str) -> None:
    out = tmp_path / "run"
    with policy_server(form=form) as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "3")
    assert done.returncode == 0, done.stderr
    starts = {e: evenly_spaced(3, n) for e, n in enumerate(LENGTHS)}
    tags = [f"ep{e:03d}_f{f:04d}" for e in starts for f in starts[e]]
    # printed before the run: the camera mapping
    assert "observation/exterior_image_0_left <- front" in done.stderr
    assert "observation/wrist_image_left <- wrist" in done.stderr
    assert f"{len(tags)} rollout(s) written" in done.stdout and "p50" in done.stdout and "p95" in done.stdout

    # what the server received: one reset then one infer per sample, a fresh session id each,
    # images at the server's resolution, the state by joint, the episode's task
    assert len(server.infers) == len(tags) and len(server.resets) == len(tags)
    assert [r.session_id for r in server.infers] == server.resets
    assert len(set(server.resets)) == len(tags)
    ds = open_dataset(dataset)
    height, width = DEFAULT_CONFIG["image_resolution"]
    pairs = [(e, f) for e in starts for f in starts[e]]
    for received, (e, f) in zip(server.infers, pairs):
        ep = ds.episode(e)
        assert received.image_shapes == {"observation/exterior_image_0_left": (height, width, 3),
                                         "observation/wrist_image_left": (height, width, 3)}
        np.testing.assert_array_equal(received.joint_position, ep.state[f, :5])
        np.testing.assert_array_equal(received.gripper_position, ep.state[f, [JOINT_NAMES.index("gripper")]])
        assert received.prompt == ep.task

    session = open_session(out)
    assert sorted(session.rollouts) == sorted(tags) and not session.errors
    assert session.model["cameras"] == {"observation/exterior_image_0_left": "front",
                                        "observation/wrist_image_left": "wrist"}
    assert session.model["server_config"]["n_external_cameras"] == 1
    first = session.rollouts[tags[0]]
    assert first.kind == "single_chunk" and first.actions.shape == (1, HORIZON, 6)
    assert first.extra["eval"]["reply_form"] == form and first.extra["eval"]["latency_s"] > 0

    report = run_cli("report", str(out), "--json", "--jobs", "1")
    assert report.returncode == 0, report.stderr
    rows = {r["tag"]: r for r in json.loads(report.stdout)["rollouts"]}
    for e in starts:
        for f in starts[e]:
            row, want = rows[f"ep{e:03d}_f{f:04d}"], expected_row(dataset, e, f)
            assert row["rmse_deg"] == pytest.approx(want["rmse_deg"], rel=1e-9)
            np.testing.assert_allclose(row["per_step_mse"], want["per_step_mse"], rtol=1e-9)
            np.testing.assert_allclose(row["per_joint_rmse"], want["per_joint_rmse"], rtol=1e-9)
    table = run_cli("report", str(out), "--jobs", "1")
    assert "Single-chunk predictions" in table.stdout and tags[0] in table.stdout


def test_frames_prompt_cameras_and_predicted_video(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    config = {**DEFAULT_CONFIG, "n_external_cameras": 2, "needs_wrist_camera": False}
    with policy_server(form="map", config=config, video=(9, 32, 40)) as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(out), "--episodes", "1", "--frames", "5,20",
                       "--prompt", "put it back", "--camera", "overhead=front")
    assert done.returncode == 0, done.stderr
    # the wrist camera fills the second external key when no wrist key is asked for; --camera adds a key
    assert [sorted(r.image_shapes) for r in server.infers] == [
        ["observation/exterior_image_0_left", "observation/exterior_image_1_left", "observation/overhead"]] * 2
    assert {r.prompt for r in server.infers} == {"put it back"}
    session = open_session(out)
    assert sorted(session.rollouts) == ["ep001_f0005", "ep001_f0020"]
    rollout = session.rollouts["ep001_f0020"]
    assert rollout.prompt == "put it back" and rollout.views == ["front"] and rollout.frames_per_chunk == 9
    assert rollout.video("front").decode().shape == (9, 32, 40, 3)
    assert session.model["cameras"]["observation/overhead"] == "front"


def test_every_chunk_replays_each_episode_open_loop(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    with policy_server(form="map") as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(out), "--every-chunk", "--executed-per-chunk", "9")
    assert done.returncode == 0, done.stderr
    frames = {e: list(range(0, n, 9)) for e, n in enumerate(LENGTHS)}
    # one reset per episode, then a chunk every 9 frames from the real state there, one session id
    assert len(server.resets) == 2 and len(server.infers) == sum(map(len, frames.values()))
    assert [r.session_id for r in server.infers] == [server.resets[e] for e in frames for _ in frames[e]]
    ds = open_dataset(dataset)
    sent = [(e, f) for e in frames for f in frames[e]]
    for received, (e, f) in zip(server.infers, sent):
        np.testing.assert_array_equal(received.joint_position, ds.episode(e).state[f, :5])
    session = open_session(out)
    assert sorted(session.rollouts) == ["ep000_replay", "ep001_replay"]
    report = json.loads(run_cli("report", str(out), "--json", "--jobs", "1").stdout)
    for row in report["rollouts"]:
        e = row["episode_index"]
        ep = ds.episode(e)
        assert row["kind"] == "open_loop_replay" and row["n_chunks"] == len(frames[e])
        pred = np.concatenate([(ep.state[f] + ramp(HORIZON)).astype(np.float32)[:9] for f in frames[e]])
        inside = pred[:ep.length]  # steps past the episode's end are reported apart
        drift = np.linalg.norm(inside - ep.action[:len(inside)], axis=1)
        assert row["time_aligned_drift"]["mean"] == pytest.approx(drift.mean(), rel=1e-9)
        assert row["post_episode_chunks"] == 0
    table = run_cli("report", str(out), "--jobs", "1").stdout
    assert "Open-loop replays" in table and "ep001_replay" in table


def test_faults_are_one_line_each_and_lose_nothing(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    faults = {1: "traceback", 3: "close", 5: "slow", 7: "shape", 9: "nan"}
    with policy_server(form="array", faults=faults, slow_s=8.0) as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "6", "--timeout", "3")
    assert done.returncode == 2
    starts = [(e, f) for e, n in enumerate(LENGTHS) for f in evenly_spaced(6, n)]
    tags = [f"ep{e:03d}_f{f:04d}" for e, f in starts]
    assert len(tags) == 12
    lines = error_lines(done.stderr)
    assert len(lines) == len(faults), done.stderr
    by_tag = {line.split(": ", 2)[1]: line.split(": ", 2)[2] for line in lines}
    assert sorted(by_tag) == sorted(tags[i] for i in faults)
    assert by_tag[tags[1]] == "server error: ValueError: Expected 5 joint values, got shape (7,)"
    assert "closed the connection" in by_tag[tags[3]]
    assert "within 3 s (--timeout)" in by_tag[tags[5]]
    assert "expected (N, 6)" in by_tag[tags[7]] and "(24, 8)" in by_tag[tags[7]]
    assert "non-finite value nan at step 3, joint elbow_flex" in by_tag[tags[9]]
    # every other sample is in the session, whole, and right; the client reconnected after each close
    session = open_session(out)
    good = [t for i, t in enumerate(tags) if i not in faults]
    assert sorted(session.rollouts) == sorted(good) and not session.errors
    assert server.connections == 4  # the first, and after the traceback, the close and the timeout
    for i, (e, f) in enumerate(starts):
        if i not in faults:
            pred = session.rollouts[tags[i]].actions[0]
            np.testing.assert_array_equal(pred, (open_dataset(dataset).episode(e).state[f] + ramp(HORIZON)).astype(np.float32))
    assert not [p for p in (out / "rollouts").iterdir() if p.name.startswith(".")]
    assert f"{len(faults)} failed" in done.stdout


def test_resume_requests_only_what_is_missing(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    with policy_server(faults={2: "traceback"}) as server:
        first = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "2")
    assert first.returncode == 2 and len(error_lines(first.stderr)) == 1
    assert len(open_session(out).rollouts) == 3
    with policy_server() as server:
        again = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "2")
        assert again.returncode == 2 and error_lines(again.stderr) == [f"error: {out}: already exists (pass --resume to continue it)"]
        resumed = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "2", "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert len(server.infers) == 1 and "3 already there" in resumed.stdout
    assert sorted(open_session(out).rollouts) == ["ep000_f0000", "ep000_f0036", "ep001_f0000", "ep001_f0021"]


def _ctrl_c_as_at_a_terminal() -> None:
    """In the child: SIGINT as a terminal delivers it. A suite started in the background by a
    shell without job control inherits SIGINT ignored, and Python then installs no handler for it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_an_interrupted_run_keeps_every_finished_sample(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    with policy_server(delay_s=0.4) as server:
        proc = subprocess.Popen([sys.executable, "-m", "inspector", "eval", server.url, str(dataset), "-o", str(out),
                                 "--samples", "5"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=_ctrl_c_as_at_a_terminal)
        deadline = time.monotonic() + DEADLINE_S
        while time.monotonic() < deadline and len(list((out / "rollouts").glob("ep*"))) < 2:
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=DEADLINE_S)
        assert proc.returncode == 130
        kept = open_session(out)
        assert 2 <= len(kept.rollouts) < 10 and not kept.errors
        assert not [p for p in (out / "rollouts").iterdir() if p.name.startswith(".")]
        server.delay_s = 0.0  # (the delay only gave the interrupt its window)
        resumed = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "5", "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert len(open_session(out).rollouts) == 10


def test_compare_pairs_two_checkpoints_sample_by_sample(dataset: Path, tmp_path: Path) -> None:
    for name, scale in (("a", 1.0), ("b", 2.0)):
        with policy_server(scale=scale) as server:
            done = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / name), "--samples", "2",
                           "--checkpoint", f"step-{name}")
        assert done.returncode == 0, done.stderr
    assert open_session(tmp_path / "b").model["checkpoint"] == "step-b"
    compared = run_cli("compare", str(tmp_path / "a"), str(tmp_path / "b"), "--json", "--jobs", "1")
    assert compared.returncode == 0, compared.stderr
    result = json.loads(compared.stdout)
    assert len(result["pairs"]) == 4 and not result["unmatched_a"] and not result["unmatched_b"]
    for pair in result["pairs"]:
        e, f = int(pair["a"]["tag"][2:5]), int(pair["a"]["tag"][7:])
        want = expected_row(dataset, e, f, 2.0)["rmse_deg"] - expected_row(dataset, e, f)["rmse_deg"]
        assert pair["delta_rmse_deg"] == pytest.approx(want, rel=1e-9)
    page = tmp_path / "report.html"
    html = run_cli("report", str(tmp_path / "a"), "--html", str(page), "--jobs", "1")
    assert html.returncode == 0 and "<svg" in page.read_text(encoding="utf-8")


def test_bad_input_is_one_line_and_exit_2(dataset: Path, tmp_path: Path) -> None:
    with policy_server(config={**DEFAULT_CONFIG, "n_external_cameras": 2}) as server:
        few = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "x"))
    assert few.returncode == 2 and len(few.stderr.strip().splitlines()) == 1
    assert "has 2 camera(s) ['front', 'wrist']" in few.stderr and "needs 3" in few.stderr
    with policy_server(config={**DEFAULT_CONFIG, "action_space": "cartesian_position"}) as server:
        cartesian = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "x"))
    with policy_server() as server:
        missing = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "x"), "--episodes", "1,7")
        camera = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "x"), "--camera", "top=side")
    assert cartesian.returncode == 2 and "action_space 'cartesian_position'" in cartesian.stderr
    assert missing.returncode == 2 and "no episode 7" in missing.stderr
    assert camera.returncode == 2 and "no camera 'side'" in camera.stderr
    with policy_server() as server:
        port = server.port
    nobody = run_cli("eval", f"127.0.0.1:{port}", str(dataset), "-o", str(tmp_path / "x"), "--timeout", "5")
    assert nobody.returncode == 2 and nobody.stderr.startswith(f"error: ws://127.0.0.1:{port}: cannot connect")
    assert len(nobody.stderr.strip().splitlines()) == 1
    for flag, value in (("--episodes", "3-1"), ("--camera", "front"), ("--timeout", "0")):
        bad = run_cli("eval", "127.0.0.1:1", str(dataset), "-o", str(tmp_path / "x"), flag, value)
        assert bad.returncode == 2 and bad.stderr.startswith(f"error: {flag}: "), bad.stderr
    assert not (tmp_path / "x").exists()
    assert os.listdir(tmp_path) == []


def test_progress_bar_counts_requests_with_rate(dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from inspector.eval import EvalPlan, evaluate

    with policy_server(delay_s=0.3) as server:
        result = evaluate(EvalPlan(server.url, str(dataset), str(tmp_path / "run"), episodes=[1], samples=3),
                          log=lambda line: None, progress=True)
    assert result.ok and len(result.written) == 3 and len(result.latency_s) == 3
    assert min(result.latency_s) >= 0.3  # each reply waited for the server's delay
    bar = capsys.readouterr().err
    assert "eval" in bar and "3/3" in bar and "request/s" in bar


@pytest.mark.parametrize("version, cameras", [("so101_v30", ["front", "wrist"]), ("so101_v21", ["front"])])
def test_lerobot_written_datasets_send_their_own_frames(lerobot_dir: Path, tmp_path: Path, version: str,
                                                        cameras: list[str]) -> None:
    """Datasets LeRobot itself wrote (AV1): each image sent is the dataset's frame, decoded alone."""
    dataset = lerobot_dir / version
    config = {**DEFAULT_CONFIG, "image_resolution": None, "n_external_cameras": 1,
              "needs_wrist_camera": "wrist" in cameras}
    with policy_server(config=config) as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "run"), "--samples", "2")
    assert done.returncode == 0, done.stderr
    ds = open_dataset(dataset)
    sent = [(e.index, f) for e in ds.episodes for f in evenly_spaced(2, e.length)]
    assert len(server.infers) == len(sent)
    keys = ["observation/exterior_image_0_left", "observation/wrist_image_left"][:len(cameras)]
    for received, (e, f) in zip(server.infers, sent):
        episode = ds.episode(e)
        for key, camera in zip(keys, cameras):
            np.testing.assert_array_equal(received.images[key], episode.frame(camera, f))
        np.testing.assert_array_equal(received.joint_position, episode.state[f, :5])


# ==============================================================================================
# Servers that misbehave on purpose: what they send is refused as one line, nothing lost

def test_object_arrays_from_a_server_are_refused_as_one_line(dataset: Path, tmp_path: Path) -> None:
    """An array of dtype object (its bytes would be read as pointers: a crash) in the handshake
    stops the run before anything is written; in a reply, it is that sample's line."""
    config = {**DEFAULT_CONFIG, "calibration": object_array((4,))}
    with policy_server(handshake=packb(config)) as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "x"), "--samples", "1")
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith(f"error: {server.url}: handshake: not a msgpack_numpy message")
    assert "dtype '|O'" in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()

    out = tmp_path / "run"
    with policy_server(faults={1: "object"}) as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "2")
    assert done.returncode == 2, done.stderr
    lines = error_lines(done.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: ep000_f0036: reply: not a msgpack_numpy message")
    assert "dtype '|O'" in lines[0] and "only boolean, integer and float arrays" in lines[0]
    session = open_session(out)
    assert sorted(session.rollouts) == ["ep000_f0000", "ep001_f0000", "ep001_f0021"] and not session.errors


# The command's peak RSS is read in a small wrapper process: a child forked from this (large)
# test process inherits its resident size into its own maximum, so wait4() on it would report
# the test process's size, not the command's (1.2-2.0 GB late in a full run, ~300 MB alone).
_MEASURING_WRAPPER = """
import resource, subprocess, sys
out, err, *argv = sys.argv[1:]
with open(out, "w") as o, open(err, "w") as e:
    rc = subprocess.call(argv, stdout=o, stderr=e)
print(rc, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def _run_measured(args: list[str], tmp_path: Path) -> tuple[int, str, str, float]:
    """The CLI run as a child process: exit code, stdout, stderr and its peak RSS [MB]."""
    out, err = tmp_path / "stdout", tmp_path / "stderr"
    done = subprocess.run([sys.executable, "-c", _MEASURING_WRAPPER, str(out), str(err),
                           sys.executable, "-m", "inspector", *args],
                          capture_output=True, text=True, timeout=DEADLINE_S, check=True)
    code, maxrss_kib = done.stdout.split()
    return int(code), out.read_text(), err.read_text(), int(maxrss_kib) / 1024


def test_replies_larger_than_a_chunk_are_refused_and_memory_stays_bounded(dataset: Path, tmp_path: Path) -> None:
    """A chunk of 5000 steps is that sample's line; so is one of 8.3 million (400 MB, streamed):
    refused from its frame headers past --max-reply-mb, so that the client never holds it."""
    out = tmp_path / "run"
    with policy_server(faults={0: "long", 2: "huge"}, long_rows=5000) as server:
        code, stdout, stderr, peak_mb = _run_measured(
            ["eval", server.url, str(dataset), "-o", str(out), "--samples", "2"], tmp_path)
    assert code == 2, stderr
    lines = error_lines(stderr)
    assert lines == ["error: ep000_f0000: reply: action chunk: 5000 steps, more than the 1000 a chunk may have",
                     "error: ep001_f0000: the reply is larger than 128 MB, refused unread (--max-reply-mb raises "
                     "the limit)"], stderr
    session = open_session(out)
    assert sorted(session.rollouts) == ["ep000_f0036", "ep001_f0021"] and not session.errors
    assert sum(f.stat().st_size for f in out.rglob("*") if f.is_file()) < 1_000_000
    assert "2 failed" in stdout
    # the whole process, 128 MB of the reply read included (the old client read all 400 MB,
    # then converted them: 1.4-2.5 GB)
    assert peak_mb < 600, f"peak RSS {peak_mb:.0f} MB"


def test_max_reply_mb_sets_the_largest_reply(dataset: Path, tmp_path: Path) -> None:
    """A reply with predicted video of 1.1 MB: refused under --max-reply-mb 1, kept under 2; a replay
    of five such chunks is refused under 2."""
    with policy_server(form="map", video=(30, 96, 128)) as server:
        small = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "a"), "--episodes", "1",
                        "--frames", "3", "--max-reply-mb", "1")
        enough = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "b"), "--episodes", "1",
                         "--frames", "3", "--max-reply-mb", "2")
    assert small.returncode == 2 and error_lines(small.stderr) == [
        "error: ep001_f0003: the reply is larger than 1 MB, refused unread (--max-reply-mb raises the limit)"]
    assert not open_session(tmp_path / "a").rollouts
    assert enough.returncode == 0, enough.stderr
    assert open_session(tmp_path / "b").rollouts["ep001_f0003"].views == ["front"]
    # a replay holds its chunks' predicted frames until it is written: at most twice the limit
    with policy_server(form="map", video=(30, 96, 128)) as server:
        replay = run_cli("eval", server.url, str(dataset), "-o", str(tmp_path / "d"), "--episodes", "1",
                         "--every-chunk", "--max-reply-mb", "2")
    assert replay.returncode == 2 and error_lines(replay.stderr) == [
        "error: ep001_replay: reply: the predicted frames of this replay pass 4 MB by the chunk at frame 27 "
        "(twice --max-reply-mb)"]
    for value in ("0", "-1", "inf", "lots"):
        bad = run_cli("eval", "127.0.0.1:1", str(dataset), "-o", str(tmp_path / "c"), "--max-reply-mb", value)
        assert bad.returncode == 2 and bad.stderr.startswith("error: --max-reply-mb: "), bad.stderr


def test_an_output_that_is_no_session_is_refused_before_the_server_is_asked(dataset: Path, tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me too")
    with policy_server() as server:
        runs = {
            "directory": run_cli("eval", server.url, str(dataset), "-o", str(mine), "--samples", "1"),
            "directory --resume": run_cli("eval", server.url, str(dataset), "-o", str(mine), "--samples", "1",
                                          "--resume"),
            "file": run_cli("eval", server.url, str(dataset), "-o", str(a_file), "--samples", "1"),
            "under a file": run_cli("eval", server.url, str(dataset), "-o", str(a_file / "run"), "--samples", "1"),
        }
        assert server.connections == 0  # refused before any network traffic
    for name, done in runs.items():
        assert done.returncode == 2, name
        assert len(done.stderr.strip().splitlines()) == 1 and done.stderr.startswith("error: "), (name, done.stderr)
        assert "--overwrite" not in done.stderr, name  # eval has no such flag
    assert runs["directory"].stderr.strip() == (
        f"error: {mine}: is a directory that is not a session (no session.json); eval writes a new session where "
        "nothing is (or into an empty directory), and --resume continues a session; choose another -o")
    assert runs["directory --resume"].stderr == runs["directory"].stderr
    assert runs["file"].stderr.startswith(f"error: {a_file}: exists and is a file, not a session;")
    assert runs["under a file"].stderr.strip() == (
        f"error: {a_file / 'run'}: cannot be created: {a_file} is a file, not a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "mine"]
    assert [p.name for p in mine.iterdir()] == ["notes.txt"] and (mine / "notes.txt").read_text() == "keep me"
    assert a_file.read_text() == "keep me too"
    # an empty directory is a place for a new session
    empty = tmp_path / "empty"
    empty.mkdir()
    with policy_server() as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(empty), "--episodes", "1", "--frames", "0")
    assert done.returncode == 0, done.stderr
    assert sorted(open_session(empty).rollouts) == ["ep001_f0000"]


def test_resume_redoes_a_broken_rollout_in_place(dataset: Path, tmp_path: Path) -> None:
    """A truncated actions.npy, a rollout.json cut short, a NaN written over a value: each is
    asked again and replaced; a directory without rollout.json is the user's, left alone."""
    out = tmp_path / "run"
    with policy_server() as server:
        first = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "3")
    assert first.returncode == 0, first.stderr
    tags = sorted(open_session(out).rollouts)
    assert len(tags) == 6
    rollouts = out / "rollouts"
    truncated, cut, nan, mine = tags[0], tags[2], tags[3], tags[5]
    actions = rollouts / truncated / "actions.npy"
    actions.write_bytes(actions.read_bytes()[:200])
    meta = rollouts / cut / "rollout.json"
    meta.write_bytes(meta.read_bytes()[:30])
    values = np.load(rollouts / nan / "actions.npy")
    values[0, 5, 1] = np.nan
    np.save(rollouts / nan / "actions.npy", values)
    for f in (rollouts / mine).iterdir():
        f.unlink()
    (rollouts / mine / "notes.txt").write_text("mine")
    assert len(open_session(out).errors) == 4

    with policy_server() as server:
        resumed = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "3", "--resume")
    assert resumed.returncode == 2, resumed.stderr
    assert error_lines(resumed.stderr) == [
        f"error: {mine}: {rollouts / mine} is a directory without rollout.json, not a rollout: --resume replaces "
        "only a broken rollout; move it away to ask for this sample again"]
    assert f"redo {truncated}: {actions}: " in resumed.stderr
    assert (f"3 rollout(s) written, 3 broken rollouts redone ({', '.join(sorted([truncated, cut, nan]))}), "
            "2 already there (--resume), 1 failed") in resumed.stdout
    assert len(server.infers) == 3  # the broken ones, asked again
    session = open_session(out)
    assert sorted(session.rollouts) == sorted(set(tags) - {mine}) and list(session.errors) == [mine]
    ds = open_dataset(dataset)
    for tag in (truncated, cut, nan):
        e, f = int(tag[2:5]), int(tag[7:])
        np.testing.assert_array_equal(session.rollouts[tag].actions[0],
                                      (ds.episode(e).state[f] + ramp(HORIZON)).astype(np.float32))
    assert (rollouts / mine / "notes.txt").read_text() == "mine"
    assert not [p for p in rollouts.iterdir() if p.name.startswith(".")]
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_a_config_holding_arrays_survives_a_reconnection(dataset: Path, tmp_path: Path) -> None:
    """The config a server sends again on reconnecting is compared whole (arrays, a NaN, nesting
    as deep as msgpack goes); the session keeps what JSON can hold of it."""
    import msgpack

    out = tmp_path / "run"
    config = {**DEFAULT_CONFIG, "reset_pose": np.arange(6.0), "scale": float("nan")}
    handshake = packb(config)
    deep = b"\xa4deep" + b"\x91" * 1000 + b"\x01"  # a list in a list ... 1000 deep
    handshake = bytes([handshake[0] + 1]) + handshake[1:] + deep  # one more entry in the fixmap
    assert msgpack.unpackb(handshake)["deep"]
    with policy_server(handshake=handshake, faults={0: "close"}) as server:
        done = run_cli("eval", server.url, str(dataset), "-o", str(out), "--samples", "2")
    assert done.returncode == 2, done.stderr
    lines = error_lines(done.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: ep000_f0000: the server closed the connection")
    assert len(open_session(out).rollouts) == 3 and server.connections == 2
    stored = open_session(out).model["server_config"]
    assert stored["reset_pose"] == [0, 1, 2, 3, 4, 5] and stored["scale"] == "nan"
    assert json.dumps(stored["deep"]) == "[" * 16 + '"..."' + "]" * 16
