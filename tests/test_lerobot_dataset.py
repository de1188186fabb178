"""LeRobot reader against datasets LeRobot itself wrote, writer round trip, and bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from inspector.data.lerobot_dataset import (
    INFO_PATH,
    LeRobotDataset,
    find_dataset,
    is_lerobot_dataset,
    lerobot_home_dirs,
)
from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset
from inspector.data.video import decode
from inspector.errors import InspectorError
from inspector.units import JOINT_NAMES, Units, canonical_joint_name

# Collected at import time so each dataset is its own test (tests/data/lerobot/README.md).
_LEROBOT_DATA = Path(__file__).resolve().parent / "data" / "lerobot"
DATASETS = sorted(p.name for p in _LEROBOT_DATA.iterdir() if (p / INFO_PATH).is_file())

# What tests/data/lerobot/README.md says the datasets hold.
EXPECTED = {
    "so101_v30": dict(version="v3.0", cameras=["front", "wrist"], lengths=[150, 210, 240],
                      tasks=["Pick the red cube", "Pick the red cube and place it in the bowl",
                             "Put the red cube on top of the blue cube"]),
    "so101_v21": dict(version="v2.1", cameras=["front"], lengths=[165, 195],
                      tasks=["Pick the red cube", "Pick the red cube and place it in the bowl"]),
}


@pytest.fixture(params=DATASETS)
def dataset_root(request: pytest.FixtureRequest, lerobot_dir: Path) -> Path:
    return lerobot_dir / request.param


def _episode_rows(ds: LeRobotDataset, index: int) -> pa.Table:
    """The episode's rows straight from its parquet file, in frame order."""
    info = ds.episode_info(index)
    table = pq.read_table(info.data_file)
    ep = table.column("episode_index").to_numpy()
    table = table.filter(pa.array(ep == index))
    return table.take(pa.array(np.argsort(table.column("frame_index").to_numpy())))


def _by_name(table: pa.Table, key: str, names: list[str]) -> np.ndarray:
    """(T, 6) float64 columns of `key`, reordered by joint name into JOINT_NAMES order."""
    values = np.array(table.column(key).to_pylist(), dtype=np.float64)
    canon = [canonical_joint_name(n) for n in names]
    return values[:, [canon.index(j) for j in JOINT_NAMES]]


# --------------------------------------------------------------------------------------------------
# fixtures written by LeRobot
# --------------------------------------------------------------------------------------------------

def test_metadata(dataset_root: Path) -> None:
    ds = LeRobotDataset(dataset_root)
    info = json.loads((dataset_root / INFO_PATH).read_text())
    assert ds.codebase_version == info["codebase_version"]
    assert ds.fps == 30 and ds.robot_type == "so101_follower"
    assert ds.joint_names == list(JOINT_NAMES)
    assert ds.video_keys == [f"observation.images.{c}" for c in ds.cameras]
    assert ds.num_episodes == len(ds.episodes) == info["total_episodes"]
    assert sum(e.length for e in ds.episodes) == info["total_frames"]
    if (expected := EXPECTED.get(dataset_root.name)) is not None:
        assert ds.codebase_version == expected["version"]
        assert ds.cameras == expected["cameras"]
        assert [e.length for e in ds.episodes] == expected["lengths"]
        assert [ds.task(e.index) for e in ds.episodes] == expected["tasks"]
    assert ds.units.arm == "degrees" and ds.units.guessed and "degrees" in ds.units_reason


def test_values_equal_parquet(dataset_root: Path) -> None:
    ds = LeRobotDataset(dataset_root)
    for info in ds.episodes:
        ep = ds.episode(info.index)
        rows = _episode_rows(ds, info.index)
        assert ep.length == info.length == rows.num_rows
        assert ep.state.shape == ep.action.shape == (ep.length, 6)
        assert ep.state.dtype == ep.action.dtype == np.float64
        np.testing.assert_array_equal(
            ep.state, _by_name(rows, "observation.state", ds.features["observation.state"]["names"]))
        np.testing.assert_array_equal(ep.action, _by_name(rows, "action", ds.features["action"]["names"]))
        np.testing.assert_array_equal(ep.timestamps, rows.column("timestamp").to_numpy().astype(np.float64))
        np.testing.assert_array_equal(ep.frame_index, np.arange(ep.length))
        if info.from_index is not None:  # v3.0: the global index range matches the metadata
            index = rows.column("index").to_numpy()
            assert (index[0], index[-1] + 1) == (info.from_index, info.to_index)


def test_tasks(dataset_root: Path) -> None:
    ds = LeRobotDataset(dataset_root)
    for info in ds.episodes:
        ep = ds.episode(info.index)
        assert ep.task == info.task == info.tasks[0]
        # the per-frame task_index points at the same string in the tasks table
        task_index = set(_episode_rows(ds, info.index).column("task_index").to_pylist())
        assert [ds.tasks[i] for i in task_index] == [ep.task]


@pytest.mark.slow
def test_video_frames_line_up(dataset_root: Path) -> None:
    ds = LeRobotDataset(dataset_root)
    for info in ds.episodes:
        ep = ds.episode(info.index)
        for cam in ep.cameras:
            clip = ep.video(cam)
            assert len(clip) == ep.length, (cam, info.index)
            h, w, c = ds.features[f"observation.images.{cam}"]["shape"]
            frames = clip.decode()
            assert frames.shape == (ep.length, h, w, c)
            assert np.abs(clip.timestamps() - ep.timestamps).max() < 0.5 / ep.fps
            k = ep.length // 2
            # a frame decoded alone (seek from the keyframe before it) is the streamed one
            assert np.array_equal(ep.frame_at(cam, float(ep.timestamps[k])), frames[k])
            assert np.array_equal(ep.frame(cam, k), frames[k])
            assert [i for i, _ in clip.iter_frames(start=k)] == list(range(k, ep.length))


def test_v30_episodes_are_distinct_windows(lerobot_dir: Path) -> None:
    """Episode 1's window is exactly its frames of the shared file: no frame lost or borrowed from
    episodes 0 and 2 on either side."""
    root = lerobot_dir / "so101_v30"
    if not root.is_dir():
        pytest.skip(f"{root} not present")
    ds = LeRobotDataset(root)
    whole, _ = decode(ds.episodes[0].videos["front"].path)
    info = ds.episode_info(1)
    clip = ds.episode(1).video("front")
    assert np.array_equal(clip.decode(), whole[info.from_index:info.to_index])


# --------------------------------------------------------------------------------------------------
# writer round trip
# --------------------------------------------------------------------------------------------------

def _synthetic_episode(T: int, task: str, seed: int, cameras=("front", "wrist"),
                       size=(48, 64)) -> EpisodeData:
    """Smooth joint paths in degrees / 0..100, and frames with a gradient and a moving square."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)[:, None]
    state = 40 * np.sin(2 * np.pi * t * (1 + np.arange(6)) + rng.uniform(0, 1, 6)) + [0, -60, 60, 70, 0, 50]
    action = np.roll(state, -3, axis=0)
    h, w = size
    frames = {}
    for c, cam in enumerate(cameras):
        base = np.zeros((T, h, w, 3), np.uint8)
        base[..., 0] = np.linspace(30, 220, w)[None, None, :]
        base[..., 1] = np.linspace(200, 40, h)[None, :, None]
        base[..., 2] = 90 + 60 * c
        for i in range(T):
            x = int((w - 12) * i / max(T - 1, 1))
            base[i, h // 3: h // 3 + 12, x: x + 12] = (250, 250, 20)
        frames[cam] = base
    return EpisodeData(task, state, action, frames)


def test_writer_round_trip(tmp_path: Path) -> None:
    episodes = [_synthetic_episode(40, "Pick the red cube", 0), _synthetic_episode(25, "Stack the cubes", 1)]
    root = write_lerobot_dataset(tmp_path / "ds", episodes, fps=30)
    assert [p.name for p in tmp_path.iterdir()] == ["ds"]  # no temp dir left behind
    ds = LeRobotDataset(root)
    assert ds.codebase_version == "v3.0" and ds.cameras == ["front", "wrist"] and ds.num_episodes == 2
    assert ds.units == Units("degrees") and not ds.units.guessed
    assert ds.features["observation.images.front"]["info"]["video.codec"] == "h264"
    assert ds.tasks == ["Pick the red cube", "Stack the cubes"]
    for i, src in enumerate(episodes):
        ep = ds.episode(i)
        assert ep.task == src.task and ep.length == len(src.state)
        np.testing.assert_array_equal(ep.state, src.state.astype(np.float32))
        np.testing.assert_array_equal(ep.action, src.action.astype(np.float32))
        np.testing.assert_allclose(ep.timestamps, np.arange(ep.length) / 30, atol=1e-6)
        for cam, frames in src.frames.items():
            clip = ep.video(cam)
            decoded = clip.decode()
            assert decoded.shape == frames.shape
            assert np.abs(clip.timestamps() - ep.timestamps).max() < 0.5 / 30
            diff = np.abs(decoded.astype(np.int16) - frames.astype(np.int16)).mean()
            assert diff < 4.0, (i, cam, diff)
    stats = json.loads((root / "meta" / "stats.json").read_text())
    all_state = np.concatenate([e.state for e in episodes]).astype(np.float32).astype(np.float64)
    np.testing.assert_allclose(stats["observation.state"]["mean"], all_state.mean(0), rtol=1e-6)
    np.testing.assert_allclose(stats["observation.state"]["std"], all_state.std(0), rtol=1e-5)
    assert stats["observation.state"]["count"] == [65]


def test_writer_matches_lerobot_layout(tmp_path: Path, lerobot_dir: Path) -> None:
    """Same info.json keys/features and the same parquet columns and types as LeRobot 0.4 writes."""
    ref = lerobot_dir / "so101_v30"
    if not ref.is_dir():
        pytest.skip(f"{ref} not present")
    root = write_lerobot_dataset(tmp_path / "ds", [_synthetic_episode(10, "t", 0, size=(240, 320))],
                                 units=None)
    ref_info, info = (json.loads((r / INFO_PATH).read_text()) for r in (ref, root))
    assert list(info) == list(ref_info)
    for key, feature in ref_info["features"].items():
        expected = json.loads(json.dumps(feature).replace('"av1"', '"h264"'))
        assert info["features"][key] == expected, key
    quantile = ("/q01", "/q10", "/q50", "/q90", "/q99")
    for rel in ("meta/episodes/chunk-000/file-000.parquet", "data/chunk-000/file-000.parquet",
                "meta/tasks.parquet"):
        ours = {f.name: f.type for f in pq.read_schema(root / rel)}
        theirs = {f.name: f.type for f in pq.read_schema(ref / rel) if not f.name.endswith(quantile)}
        assert ours == theirs, rel


def test_writer_refuses_to_overwrite(tmp_path: Path) -> None:
    root = write_lerobot_dataset(tmp_path / "ds", [_synthetic_episode(5, "a", 0, cameras=())])
    with pytest.raises(InspectorError, match="not empty"):
        write_lerobot_dataset(root, [_synthetic_episode(6, "b", 0, cameras=())])
    assert LeRobotDataset(root).episodes[0].length == 5  # untouched
    # a failing write with overwrite=True leaves the old dataset in place
    bad = _synthetic_episode(6, "b", 0, cameras=())
    bad.state[2, 1] = np.nan
    with pytest.raises(InspectorError, match="non-finite"):
        write_lerobot_dataset(root, [bad], overwrite=True)
    assert LeRobotDataset(root).episodes[0].length == 5
    write_lerobot_dataset(root, [_synthetic_episode(6, "b", 0, cameras=())], overwrite=True)
    assert LeRobotDataset(root).episodes[0].length == 6
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


# --------------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------------

@pytest.fixture
def small_root(tmp_path: Path) -> Path:
    """A 2-episode dataset with one tiny camera, written by our writer."""
    episodes = [_synthetic_episode(8, "a", 0, cameras=("front",), size=(16, 16)),
                 _synthetic_episode(6, "b", 1, cameras=("front",), size=(16, 16))]
    return write_lerobot_dataset(tmp_path / "ds", episodes, units=None)


def _edit_info(root: Path, edit) -> Path:
    path = root / INFO_PATH
    info = json.loads(path.read_text())
    edit(info)
    path.write_text(json.dumps(info))
    return path


def test_unknown_version(small_root: Path) -> None:
    info = _edit_info(small_root, lambda i: i.update(codebase_version="v9.9"))
    with pytest.raises(InspectorError, match=r"v9\.9.*supported.*v3\.0") as exc:
        LeRobotDataset(small_root)
    assert exc.value.file == str(info)


def test_missing_info(tmp_path: Path) -> None:
    with pytest.raises(InspectorError) as exc:
        LeRobotDataset(tmp_path)
    assert exc.value.file == str(tmp_path / INFO_PATH) and "info.json" in str(exc.value)


def test_invalid_json(small_root: Path) -> None:
    (small_root / INFO_PATH).write_text("{not json")
    with pytest.raises(InspectorError, match="invalid JSON") as exc:
        LeRobotDataset(small_root)
    assert exc.value.file.endswith("info.json")


def test_missing_state_feature(small_root: Path) -> None:
    _edit_info(small_root, lambda i: i["features"].pop("observation.state"))
    with pytest.raises(InspectorError, match="observation.state") as exc:
        LeRobotDataset(small_root)
    assert exc.value.file.endswith("info.json")


@pytest.mark.parametrize("names", [
    ["j1", "j2", "j3", "j4", "j5", "j6"],
    ["shoulder_pan.pos", "shoulder_lift.pos", "elbow_flex.pos", "wrist_flex.pos", "wrist_roll.pos"],
    ["shoulder_pan.pos"] * 6,
])
def test_wrong_joint_names(small_root: Path, names: list[str]) -> None:
    _edit_info(small_root, lambda i: i["features"]["observation.state"].update(names=names))
    with pytest.raises(InspectorError, match="observation.state") as exc:
        LeRobotDataset(small_root)
    assert exc.value.file.endswith("info.json")


def _rewrite_state(root: Path, edit) -> Path:
    """Apply `edit` to the (N, 6) float32 state of the data file and write it back."""
    path = root / "data" / "chunk-000" / "file-000.parquet"
    table = pq.read_table(path)
    state = np.array(table.column("observation.state").to_pylist(), dtype=np.float32)
    state = edit(state)
    col = pa.FixedSizeListArray.from_arrays(pa.array(state.reshape(-1)), state.shape[1])
    table = table.set_column(table.schema.get_field_index("observation.state"), "observation.state", col)
    pq.write_table(table, path)
    return path


def test_nan_in_state(small_root: Path) -> None:
    # row 10 of the file = episode 1 (starts at row 8), frame 2
    path = _rewrite_state(small_root, lambda s: (s.__setitem__((10, 3), np.nan), s)[1])
    ds = LeRobotDataset(small_root)
    ds.episode(0)  # the other episode is fine
    with pytest.raises(InspectorError, match=r"observation\.state.*frame_index 2.*wrist_flex") as exc:
        ds.episode(1)
    assert exc.value.file == str(path)


def test_wrong_state_width_in_data(small_root: Path) -> None:
    path = _rewrite_state(small_root, lambda s: s[:, :5])
    with pytest.raises(InspectorError, match=r"observation\.state.*6.*5") as exc:
        LeRobotDataset(small_root).episode(0)
    assert exc.value.file == str(path)


def test_joint_order_by_name(small_root: Path) -> None:
    """A dataset that stores the joints in another order reads back in JOINT_NAMES order."""
    before = LeRobotDataset(small_root).episode(1).state
    perm = [5, 4, 3, 2, 1, 0]
    for key in ("observation.state", "action"):
        _edit_info(small_root, lambda i: i["features"][key].update(
            names=[i["features"][key]["names"][p] for p in perm]))
    _rewrite_state(small_root, lambda s: s[:, perm])
    after = LeRobotDataset(small_root).episode(1).state
    np.testing.assert_array_equal(after, before)


def test_episode_out_of_range(small_root: Path) -> None:
    with pytest.raises(InspectorError, match=r"episode 5 is out of range; available: 0\.\.1") as exc:
        LeRobotDataset(small_root).episode(5)
    assert exc.value.file == str(small_root)


def test_missing_data_and_video(small_root: Path) -> None:
    ds = LeRobotDataset(small_root)
    video = ds.episodes[0].videos["front"].path
    video.unlink()
    with pytest.raises(InspectorError, match="not found") as exc:
        ds.episode(0).video("front")
    assert exc.value.file == str(video)
    with pytest.raises(InspectorError, match="no camera 'top'.*front"):
        ds.episode(0).video("top")
    data = ds.episodes[0].data_file
    data.unlink()
    with pytest.raises(InspectorError, match="not found") as exc:
        ds.episode(0)
    assert exc.value.file == str(data)


def test_truncated_video(small_root: Path) -> None:
    ds = LeRobotDataset(small_root)
    video = ds.episodes[0].videos["front"].path
    video.write_bytes(video.read_bytes()[:200])
    with pytest.raises(InspectorError) as exc:
        ds.episode(1).video("front")
    assert exc.value.file == str(video)


def test_units_stated_in_info(small_root: Path) -> None:
    _edit_info(small_root, lambda i: i.update(units={"arm": "range100", "gripper": "0..100"}))
    ds = LeRobotDataset(small_root)
    assert ds.units == Units("range100") and "info.json" in ds.units_reason
    _edit_info(small_root, lambda i: i.update(units={"arm": "furlongs"}))
    with pytest.raises(InspectorError, match="furlongs"):
        LeRobotDataset(small_root)


# --------------------------------------------------------------------------------------------------
# finding a dataset
# --------------------------------------------------------------------------------------------------

def test_find_dataset_in_hf_cache(small_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    home = tmp_path / "lerobot_home"
    (home / "me").mkdir(parents=True)
    shutil.copytree(small_root, home / "me" / "so101_pick")
    monkeypatch.setenv("HF_LEROBOT_HOME", str(home))
    assert lerobot_home_dirs()[0] == home
    assert find_dataset("me/so101_pick") == home / "me" / "so101_pick"
    assert find_dataset(small_root) == small_root  # a directory is taken as is
    assert is_lerobot_dataset(home / "me" / "so101_pick") and not is_lerobot_dataset(tmp_path)

    # HF_HOME/lerobot is the next place looked
    monkeypatch.delenv("HF_LEROBOT_HOME")
    monkeypatch.setenv("HF_HOME", str(tmp_path / "hf"))
    shutil.copytree(small_root, tmp_path / "hf" / "lerobot" / "org" / "name")
    assert find_dataset("org/name") == tmp_path / "hf" / "lerobot" / "org" / "name"


def test_find_dataset_not_found(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HF_LEROBOT_HOME", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InspectorError, match=r"not found locally.*(download|pip install)") as exc:
        find_dataset("nobody/nothing")
    assert exc.value.file == "nobody/nothing" and str(tmp_path / "nobody" / "nothing") in str(exc.value)
    with pytest.raises(InspectorError, match="info.json"):
        find_dataset(tmp_path)  # a directory that is no dataset
    with pytest.raises(InspectorError, match="no such dataset directory"):
        find_dataset(tmp_path / "a" / "b" / "c")


def test_episode_clip_from_a_start_frame(lerobot_dir: Path) -> None:
    """A rollout's GT clip starts at its start frame: frame i of the clip is episode frame start + i."""
    root = lerobot_dir / "so101_v30"
    if not root.is_dir():
        pytest.skip(f"{root} not present")
    ep = LeRobotDataset(root).episode(2)
    whole = ep.video("front").decode()
    tail = ep.clip_from("front", 100).decode(size=(160, 120))
    assert tail.shape == (240 - 100, 120, 160, 3)
    assert np.array_equal(tail[0], ep.frame("front", 100, size=(160, 120)))
    assert np.abs(tail[5].astype(int).mean() - whole[105].astype(int).mean()) < 3  # same picture, smaller


# --------------------------------------------------------------------------------------------------
# malformed info.json: any value in any field gives InspectorError or a working dataset
# --------------------------------------------------------------------------------------------------

_json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-5, 5) | st.floats(allow_nan=True) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
    max_leaves=6)
_FIELDS = [("codebase_version",), ("fps",), ("total_episodes",), ("chunks_size",), ("data_path",),
           ("video_path",), ("features",), ("units",), ("features", "observation.state"),
           ("features", "observation.state", "names"), ("features", "observation.state", "shape"),
           ("features", "action", "names"), ("features", "observation.images.front"),
           ("features", "observation.images.front", "dtype")]


@pytest.fixture(scope="module")
def pristine_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_lerobot_dataset(tmp_path_factory.mktemp("h") / "ds",
                                 [_synthetic_episode(4, "a", 0, cameras=("front",), size=(16, 16))])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(where=st.sampled_from(_FIELDS), value=_json_values)
def test_malformed_info_never_crashes(pristine_root: Path, where: tuple[str, ...], value: object) -> None:
    info_path = pristine_root / INFO_PATH
    original = info_path.read_text()
    info = json.loads(original)
    node = info
    for key in where[:-1]:
        node = node[key]
    node[where[-1]] = value
    info_path.write_text(json.dumps(info))
    try:
        ds = LeRobotDataset(pristine_root)
        ep = ds.episode(0)
        for cam in ep.cameras:
            ep.video(cam)
    except InspectorError as exc:
        assert exc.file and exc.what
    finally:
        info_path.write_text(original)
