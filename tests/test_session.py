"""Native session format: writer API, validation, atomic writes, DreamZero-SO101 importer, info."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from inspector.data.session import SessionWriter, load_rollout, open_session
from inspector.errors import InspectorError


def _write_small_session(root: Path, **kwargs) -> Path:
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, size=(18, 32, 48, 3), dtype=np.uint8)
    with SessionWriter.create(root, model={"name": "m"}, **kwargs) as w:
        w.add_rollout("a", kind="autoregressive", actions=rng.normal(size=(2, 24, 6)),
                      prompt="Pick", episode_index=0, videos={"front": frames},
                      gt_actions=rng.normal(size=(30, 6)))
        w.add_rollout("b", kind="single_chunk", actions=rng.normal(size=(1, 24, 6)))
    return root


def test_writer_round_trip(tmp_path):
    root = _write_small_session(tmp_path / "s")
    s = open_session(root)
    assert sorted(s.rollouts) == ["a", "b"] and not s.errors
    a = s.rollouts["a"]
    assert a.actions.shape == (2, 24, 6) and a.gt_actions.shape == (30, 6)
    assert a.executed_actions().shape == (18, 6)
    assert len(a.video("front")) == 18
    assert not list(tmp_path.glob(".*partial"))


def test_failed_create_leaves_nothing(tmp_path):
    dest = tmp_path / "s"
    with pytest.raises(InspectorError):
        with SessionWriter.create(dest) as w:
            w.add_rollout("a", kind="autoregressive", actions=np.zeros((2, 24, 5)))  # wrong joint count
    assert not dest.exists()
    assert list(tmp_path.iterdir()) == []


def test_existing_session_is_never_replaced_by_a_failed_one(tmp_path):
    root = _write_small_session(tmp_path / "s")
    before = (root / "session.json").read_text()
    with pytest.raises(InspectorError):
        with SessionWriter.create(root, overwrite=True) as w:
            w.add_rollout("x", kind="nonsense", actions=np.zeros((1, 24, 6)))  # type: ignore[arg-type]
    assert (root / "session.json").read_text() == before
    assert sorted(open_session(root).rollouts) == ["a", "b"]


@pytest.mark.parametrize("mutate, message", [
    (lambda r: np.save(r / "actions.npy", np.zeros((2, 24, 5))), "shape: expected (n_chunks, 24, 6), found (2, 24, 5)"),
    (lambda r: np.save(r / "actions.npy", np.full((2, 24, 6), np.nan)), "non-finite"),
    (lambda r: (r / "actions.npy").write_bytes(b"\x93NUMPY garbage"), "not a readable .npy"),
    (lambda r: (r / "rollout.json").write_text("{nope"), "invalid JSON"),
    (lambda r: (r / "rollout.json").write_text("[]"), "expected a JSON object"),
    (lambda r: (r / "video" / "front.mp4").unlink(), "not found"),
    (lambda r: _edit(r, kind="sideways"), "kind: expected one of"),
    (lambda r: _edit(r, executed_per_chunk=30), "exceeds horizon"),
])
def test_bad_rollout_names_file_and_field_and_spares_the_others(tmp_path, mutate, message):
    root = _write_small_session(tmp_path / "s")
    mutate(root / "rollouts" / "a")
    s = open_session(root)
    assert "b" in s.rollouts  # one bad rollout never takes the others down
    err = str(s.errors["a"])
    assert message in err and str(root / "rollouts" / "a") in err and "\n" not in err


def _edit(rollout_dir: Path, **fields) -> None:
    meta = json.loads((rollout_dir / "rollout.json").read_text())
    meta.update(fields)
    (rollout_dir / "rollout.json").write_text(json.dumps(meta))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.dictionaries(st.sampled_from(["kind", "horizon", "executed_per_chunk", "frames_per_chunk", "fps",
                                        "start_frame", "episode_index", "views", "gt", "prompt", "extra"]),
                       st.one_of(st.none(), st.booleans(), st.integers(-5, 50), st.floats(allow_nan=True),
                                 st.text(max_size=5), st.lists(st.text(max_size=3), max_size=2),
                                 st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))))
def test_reader_property_any_metadata_gives_a_rollout_or_a_clear_error(tmp_path_factory, fields):
    root = tmp_path_factory.mktemp("p")
    np.save(root / "actions.npy", np.zeros((1, 24, 6)))
    (root / "rollout.json").write_text(json.dumps({"kind": "single_chunk", **fields}))
    try:
        r = load_rollout(root)
        assert r.actions.shape[0] == 1
    except InspectorError as exc:
        assert str(root) in str(exc) and "\n" not in str(exc)


def test_importer_reads_every_fixture_dir(imported_session):
    s = open_session(imported_session)
    assert not s.errors
    assert sorted(s.rollouts) == ["ep000_novel", "ep000_train", "f000", "f084", "f169", "train_ep0"]
    train = s.rollouts["ep000_train"]
    assert train.kind == "autoregressive" and train.actions.shape == (60, 24, 6)
    assert train.views == ["front", "gripper", "top"] and train.gt_views == ["front", "gripper", "top"]
    assert train.extra["chained_states"] is True  # state_trace[k+1] == action_trace[k][8]
    np.testing.assert_array_equal(train.states[1:], train.actions[:, 8])
    assert train.executed_actions().shape == (540, 6)
    assert train.gt_episode_length == 328 and train.prompt == "Pick the red cube"
    f084 = s.rollouts["f084"]
    assert f084.kind == "single_chunk" and f084.start_frame == 84 and f084.gt_actions.shape == (24, 6)
    mosaic = s.rollouts["train_ep0"]  # gt_future.mp4 beside the mosaic: the front camera alone
    assert mosaic.views == ["front", "gripper", "top"] and mosaic.gt_views == ["front"]
    assert mosaic.extra["source"]["name"] == "train_ep0"
    # GT frames are scaled to the imagined clip's size to compare; the front view matches it
    from inspector.analysis.timeline import build_timeline

    psnr = build_timeline(mosaic).video_metrics("front").psnr_db
    assert len(psnr) == len(mosaic.video("front")) and np.isfinite(psnr).all()
    assert 15 < float(np.mean(psnr)) < 22  # a mosaic read as GT would score 4-10 dB


@pytest.mark.slow
def test_importer_reads_the_layout_made_from_the_demo(dz_layout_session):
    """Every kind of DreamZero-SO101 source directory (``dreamzero_layout.py``): autoregressive,
    single chunk with per-view clips, mosaic sample."""
    s = open_session(dz_layout_session)
    assert not s.errors
    assert sorted(s.rollouts) == ["ep000_train", "f000", "f076", "f153", "train_ep0"]
    train = s.rollouts["ep000_train"]
    assert train.kind == "autoregressive" and train.actions.shape == (60, 24, 6)
    assert train.views == ["front", "gripper"] and train.gt_views == ["front", "gripper"]
    assert train.extra["chained_states"] is True  # state_trace[k+1] == action_trace[k][8]
    np.testing.assert_array_equal(train.states[1:], train.actions[:, 8])
    assert train.executed_actions().shape == (540, 6) and train.gt_actions is None
    assert train.gt_episode_length == 409 and train.prompt == "Pick the red cube and place it in the bowl"
    f076 = s.rollouts["f076"]
    assert f076.kind == "single_chunk" and f076.start_frame == 76 and f076.gt_actions.shape == (24, 6)
    assert f076.views == ["front", "gripper"] and f076.gt_views == ["front", "gripper"]
    mosaic = s.rollouts["train_ep0"]  # the 2x2 mosaic cut into views; gt_future.mp4: the front alone
    assert mosaic.views == ["front", "gripper", "top"] and mosaic.gt_views == ["front"]
    assert mosaic.extra["source"]["name"] == "train_ep0"
    from inspector.analysis.timeline import build_timeline

    # the cut front quarter is the imagined front clip: against its GT it scores as the clip does
    psnr = build_timeline(mosaic).video_metrics("front").psnr_db
    clip = build_timeline(s.rollouts["f000"]).video_metrics("front").psnr_db
    assert len(psnr) == len(mosaic.video("front")) == 9 and np.isfinite(psnr).all()
    np.testing.assert_allclose(psnr, clip, atol=1.5)


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "inspector", *args], capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_cli_import_prints_one_line_per_rollout(dz_layout, tmp_path):
    out = _cli("import", "dreamzero-so101", str(dz_layout), "-o", str(tmp_path / "s"))
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert sorted(line.split(":")[0] for line in lines[:-1]) == ["ep000_train", "f000", "f076", "f153", "train_ep0"]
    assert lines[-1] == f"wrote session {tmp_path / 's'}"
    assert "60 chunk(s) x 24 steps" in next(line for line in lines if line.startswith("ep000_train:"))


@pytest.mark.slow
def test_cli_bad_input_is_one_line_exit_2(tmp_path):
    out = _cli("import", "dreamzero-so101", str(tmp_path / "missing"), "-o", str(tmp_path / "s"))
    assert out.returncode == 2
    assert out.stderr.startswith("error: ") and out.stderr.count("\n") == 1 and "Traceback" not in out.stderr
    assert not (tmp_path / "s").exists()


@pytest.mark.slow
def test_failed_import_leaves_no_partial_session(dz_layout, tmp_path):
    src = tmp_path / "src"
    import shutil
    shutil.copytree(dz_layout / "zeroshot_chunk", src)
    meta = json.loads((src / "f153" / "meta.json").read_text())
    meta["actions_pred"] = meta["actions_pred"][:3] + [[1, 2, 3]]
    (src / "f153" / "meta.json").write_text(json.dumps(meta))
    out = _cli("import", "dreamzero-so101", str(src), "-o", str(tmp_path / "s"))
    assert out.returncode == 2 and "f153/meta.json" in out.stderr and "actions_pred" in out.stderr
    assert not (tmp_path / "s").exists() and not list(tmp_path.glob(".s.*"))


@pytest.mark.slow
def test_cli_info_json_session_and_dataset(dz_layout_session, lerobot_dir):
    out = _cli("info", str(dz_layout_session), "--json")
    info = json.loads(out.stdout)
    assert info["format"] == "session"
    by_tag = {r["tag"]: r for r in info["rollouts"]}
    assert by_tag["ep000_train"] == {"tag": "ep000_train", "kind": "autoregressive", "n_chunks": 60, "horizon": 24,
                                     "executed_per_chunk": 9, "views": ["front", "gripper"],
                                     "has_gt_joints": False, "video_only": False}
    assert by_tag["f076"]["has_gt_joints"] is True
    info = json.loads(_cli("info", str(lerobot_dir / "so101_v30"), "--json").stdout)
    assert info["format"] == "lerobot" and info["codebase_version"] == "v3.0" and info["fps"] == 30
    assert info["cameras"] == ["front", "wrist"] and info["robot_type"] == "so101_follower"
    assert [e["length"] for e in info["episodes"]] == [150, 210, 240]
    assert info["episodes"][2]["task"] == "Put the red cube on top of the blue cube"


def test_every_public_name_resolves():
    import inspector

    assert len(inspector.__all__) >= 8
    for name in inspector.__all__:
        value = getattr(inspector, name)
        assert name == "JOINT_NAMES" or value.__name__ == name
    with pytest.raises(AttributeError):
        inspector.not_a_name  # noqa: B018


@pytest.mark.slow
def test_info_on_a_session_says_model_units_and_gt(tmp_path):
    import subprocess
    import sys

    root = _write_small_session(tmp_path / "s")
    out = subprocess.run([sys.executable, "-m", "inspector", "info", str(root)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[1] == "model: m" and lines[2].startswith("units: arm degrees")
    assert lines[3].startswith("GT source: ")
    single = next(line for line in lines if line.startswith("b "))
    assert " single_chunk " in single and " - " in single  # no "executed" for a single chunk
    version = subprocess.run([sys.executable, "-m", "inspector", "--version"], capture_output=True, text=True)
    assert version.returncode == 0 and version.stdout.startswith("inspector ")


# ----------------------------------------------------------------------------------------------
# What a write may replace, and what it leaves behind


@pytest.mark.parametrize("what", ["file", "directory", "symlink"])
def test_overwrite_replaces_only_a_session(tmp_path, what):
    """``overwrite=True`` (``import --overwrite``) replaces a session and nothing else: a file,
    a directory of the user's own files, a link to a session are refused and left as they were."""
    dest = tmp_path / "dest"
    if what == "file":
        dest.write_text("mine")
    elif what == "directory":
        dest.mkdir()
        (dest / "notes.txt").write_text("mine")
    else:
        dest.symlink_to(_write_small_session(tmp_path / "real"), target_is_directory=True)
    with pytest.raises(InspectorError, match="refusing") as err:
        _write_small_session(dest, overwrite=True)
    assert "\n" not in str(err.value)
    if what == "file":
        assert dest.read_text() == "mine"
    elif what == "directory":
        assert [p.name for p in dest.iterdir()] == ["notes.txt"]
    else:
        assert dest.is_symlink() and sorted(open_session(dest).rollouts) == ["a", "b"]
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    # a session is replaced, an empty directory is simply used
    root = _write_small_session(tmp_path / "s")
    with SessionWriter.create(root, overwrite=True) as w:
        w.add_rollout("c", kind="single_chunk", actions=np.zeros((1, 24, 6)))
    assert sorted(open_session(root).rollouts) == ["c"]
    (tmp_path / "empty").mkdir()
    assert sorted(open_session(_write_small_session(tmp_path / "empty")).rollouts) == ["a", "b"]


def test_rollout_overwrite_replaces_only_a_rollout(tmp_path):
    root = _write_small_session(tmp_path / "s")
    (root / "rollouts" / "mine").mkdir()
    (root / "rollouts" / "mine" / "data.csv").write_text("1,2")
    with SessionWriter.append(root) as w:
        with pytest.raises(InspectorError, match="is not a rollout"):
            w.add_rollout("mine", kind="single_chunk", actions=np.zeros((1, 24, 6)), overwrite=True)
        w.add_rollout("b", kind="single_chunk", actions=np.ones((1, 24, 6)), overwrite=True)
    assert (root / "rollouts" / "mine" / "data.csv").read_text() == "1,2"
    assert open_session(root).rollouts["b"].actions.max() == 1.0
    assert not [p for p in (root / "rollouts").iterdir() if p.name.startswith(".")]


@pytest.mark.slow
def test_concurrent_imports_to_one_destination_leave_no_staging(dz_layout, tmp_path):
    """Imports racing to one destination: one session results (complete), every other import
    exits 2 with one line, and no ``.<name>.*.partial`` staging directory (or ``.old-``) is left."""
    src = dz_layout / "zeroshot_chunk" / "f076"
    dest = tmp_path / "out" / "s"
    for extra in ([], ["--overwrite"]):
        procs = [subprocess.Popen([sys.executable, "-m", "inspector", "import", "dreamzero-so101", str(src),
                                   "-o", str(dest), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True) for _ in range(4)]
        results = [(p.wait(timeout=300), p.stdout.read(), p.stderr.read()) for p in procs]
        for p in procs:
            p.stdout.close()
            p.stderr.close()
        ok = [r for r in results if r[0] == 0]
        assert ok and all(rc in (0, 2) for rc, _, _ in results), results
        for rc, _, err in results:
            if rc == 2:
                assert err.startswith(f"error: {dest}: ") and err.count("\n") == 1, err
        if not extra:
            assert len(ok) == 1, results  # without --overwrite only the first one in lands
        assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["s"]
        s = open_session(dest)
        assert sorted(s.rollouts) == ["f076"] and not s.errors


def test_commit_that_loses_the_race_leaves_nothing(tmp_path):
    """The writer API: a session whose place was taken while it was written is dropped whole."""
    dest = tmp_path / "s"
    w = SessionWriter.create(dest)
    w.add_rollout("a", kind="single_chunk", actions=np.zeros((1, 24, 6)))
    _write_small_session(dest)  # another writer got there first
    with pytest.raises(InspectorError, match="already exists"):
        with w:
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]
    assert sorted(open_session(dest).rollouts) == ["a", "b"]


@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_written_files_have_the_usual_mode(tmp_path, umask):
    """Session files and directories get the mode the umask gives (not mkstemp's 0600 or
    mkdtemp's 0700), so a session written for a team is readable by it."""
    import os
    import stat

    old = os.umask(umask)
    try:
        root = _write_small_session(tmp_path / "s")
        from inspector.said.annotations import update_annotation

        update_annotation(root, "a", flag=True)
    finally:
        os.umask(old)
    for path in [root, *root.rglob("*")]:
        if path.name.startswith(".annotations.lock"):
            continue
        mode = stat.S_IMODE(path.stat().st_mode)
        expected = (0o777 if path.is_dir() else 0o666) & ~umask
        assert mode == expected, f"{path.relative_to(tmp_path)}: {oct(mode)}, expected {oct(expected)}"


# ----------------------------------------------------------------------------------------------
# Error lines


@settings(max_examples=200, deadline=None)
@given(path=st.text(min_size=1), what=st.text())
def test_error_is_one_printable_line_whatever_the_path(path, what):
    """A path or message with newlines, escape sequences, bidi overrides or undecodable bytes
    still makes one line, with those characters written as escapes."""
    import unicodedata

    message = str(InspectorError(path, what))
    assert message.splitlines() == [message]
    assert not [c for c in message if unicodedata.category(c) in ("Cc", "Cf", "Cs", "Zl", "Zp")]
    assert InspectorError(path, what).file == path  # kept as given for programs


def test_error_escapes_control_characters():
    err = InspectorError("/data/ep\n0\x1b[31m\u2028\udcff/meta.json", "bad\n thing")
    assert str(err) == "/data/ep\\n0\\x1b[31m\\u2028\\udcff/meta.json: bad thing"
