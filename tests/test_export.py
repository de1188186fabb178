"""Rerun export: every written file verifies, reads back, and shows what the timeline computed.

Files are read back with ``rerun.chunk.RrdReader`` (rerun 0.41's reader; ``rr.dataframe`` is gone)
and checked with ``rerun rrd verify``. The joint transforms in a file, chained, must reproduce our
FK; every metric series must hold one sample per step; every imagined frame must be referenced.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr

from inspector.analysis.timeline import build_timeline
from inspector.cli import main as cli_main
from inspector.data.session import SessionWriter, open_session
from inspector.data.video import decode, probe
from inspector.errors import InspectorError
from inspector.export import layout as L
from inspector.export.recording import format_size, select_views, write_recording
from inspector.progress import FractionBar
from inspector.robot import meshes
from inspector.robot.kinematics import kinematics
from inspector.robot.meshes import cluster_vertices
from inspector.units import JOINT_LIMITS_RAD, JOINT_NAMES, to_radians

pytestmark = pytest.mark.slow  # recordings written and checked with rerun rrd verify

RERUN = Path(sys.executable).parent / "rerun"
ARM_CHAIN = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll")


# ----------------------------------------------------------------------------------------------
# Reading a recording back


class Recording:
    """The chunks of an .rrd file grouped by entity, with column helpers."""

    def __init__(self, path: Path):
        self.path = path
        reader = rr.chunk.RrdReader(path)
        self.blueprints = reader.blueprints()
        self.entities: dict[str, list[tuple[bool, pa.RecordBatch]]] = defaultdict(list)
        for chunk in reader.stream().to_chunks():
            self.entities[chunk.entity_path].append((chunk.is_static, chunk.to_record_batch()))

    def has(self, entity: str) -> bool:
        return f"/{entity}" in self.entities

    def temporal(self, entity: str, component: str, order_by: str = L.FRAME) -> tuple[np.ndarray, list]:
        """(index values, component values) over every temporal row, sorted by ``order_by``."""
        index, values = [], []
        for static, rb in self.entities[f"/{entity}"]:
            if not static and component in rb.schema.names:
                index.append(rb.column(order_by).cast(pa.int64()).to_numpy())
                values.extend(rb.column(component).to_pylist())
        idx = np.concatenate(index) if index else np.zeros(0, np.int64)
        order = np.argsort(idx, kind="stable")
        return idx[order], [values[i] for i in order]

    def static(self, entity: str, component: str) -> list:
        out = []
        for static, rb in self.entities[f"/{entity}"]:
            if static and component in rb.schema.names:
                out.extend(rb.column(component).to_pylist())
        return out

    def scalars(self, entity: str, order_by: str = L.TIME) -> tuple[np.ndarray, np.ndarray]:
        idx, values = self.temporal(entity, "Scalars:scalars", order_by)
        return idx, np.array([v[0] for v in values])

    def transforms(self, entity: str) -> np.ndarray:
        """(N, 4, 4) from the temporal Transform3D rows, in time order."""
        _, t = self.temporal(entity, "Transform3D:translation", L.TIME)
        _, q = self.temporal(entity, "Transform3D:quaternion", L.TIME)
        return _matrices(np.array([r[0] for r in t]), np.array([r[0] for r in q]))

    def static_transform(self, entity: str) -> np.ndarray:
        t = self.static(entity, "Transform3D:translation")[-1]
        q = self.static(entity, "Transform3D:quaternion")[-1]
        return _matrices(np.array(t), np.array(q))[0]


def _matrices(translations: np.ndarray, quats_xyzw: np.ndarray) -> np.ndarray:
    x, y, z, w = quats_xyzw.T
    m = np.zeros((len(translations), 4, 4))
    m[:, 0] = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), 0 * x], 1)
    m[:, 1] = np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), 0 * x], 1)
    m[:, 2] = np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), 0 * x], 1)
    m[:, :3, 3] = translations
    m[:, 3, 3] = 1.0
    return m


def rrd_verify(path: Path) -> None:
    out = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr


def chained_tool_points(rec: Recording, arm: str) -> np.ndarray:
    """(T, 3) tool point from the recording's joint transforms: base -> ... -> gripper_frame."""
    T = None
    for joint in ARM_CHAIN:
        m = rec.transforms(L.joint_transform_path(arm, joint))
        T = m if T is None else T @ m
    mount = rec.static(L.joint_transform_path(arm, "mount"), "Transform3D:child_frame")
    assert mount == [[f"{arm}/base_link"]]
    T = T @ rec.static_transform(L.joint_transform_path(arm, "gripper_frame_joint"))
    return T[:, :3, 3]


# ----------------------------------------------------------------------------------------------
# Fixtures


@pytest.fixture(scope="session", autouse=True)
def _mesh_cache(tmp_path_factory):
    """Decimated meshes go to a per-run cache (inherited by CLI subprocesses)."""
    old = os.environ.get("INSPECTOR_CACHE_DIR")
    os.environ["INSPECTOR_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))
    yield
    if old is None:
        os.environ.pop("INSPECTOR_CACHE_DIR", None)
    else:
        os.environ["INSPECTOR_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def fixture_session(dz_layout_session) -> Path:
    """The DreamZero-SO101 layout made from the demo, imported (``dreamzero_layout.py``)."""
    return dz_layout_session


@pytest.fixture(scope="session")
def fixture_export(fixture_session, tmp_path_factory):
    """ep000_train (60 chunks on a 409-frame episode, two views, carried GT video, no GT joints,
    the gripper planted past its limit) exported once."""
    session = open_session(fixture_session)
    tl = build_timeline(session.rollouts["ep000_train"])
    calls: list[tuple[float, str]] = []
    path = write_recording(tl, tmp_path_factory.mktemp("rrd") / "ep000_train.rrd",
                           progress=lambda f, m: calls.append((f, m)))
    return tl, path, Recording(path), calls


def _gt_path(n: int) -> np.ndarray:
    """(n, 6) a smooth reach in degrees / gripper 0..100, well inside the limits, that never
    revisits a pose (so best-match finds the GT time unambiguously)."""
    t = np.linspace(0, 1, n)[:, None]
    phase = 0.5 - 0.5 * np.cos(np.pi * t)
    base = np.array([-30.0, -60.0, 60.0, 30.0, -40.0, 10.0])
    amp = np.array([60.0, 50.0, -40.0, -30.0, 80.0, 70.0])
    return base + amp * phase


def _slow_prediction(gt: np.ndarray, n_chunks: int, horizon: int = 24, executed: int = 9,
                     speed: float = 0.8) -> np.ndarray:
    """(N, H, 6) chunks that follow ``gt`` at ``speed`` times its pace (held at its last pose)."""
    steps = np.arange(n_chunks)[:, None] * executed + np.arange(horizon)[None]
    src = np.minimum(steps * speed, len(gt) - 1)
    lo = np.floor(src).astype(int)
    hi = np.minimum(lo + 1, len(gt) - 1)
    w = (src - lo)[..., None]
    return gt[lo] * (1 - w) + gt[hi] * w


def _frames(n: int, h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 255, size=(1, h, w, 3))
    ramp = (np.arange(n)[:, None, None, None] * 3) % 255
    return ((base + ramp) % 255).astype(np.uint8)


@pytest.fixture(scope="session")
def synthetic_session(tmp_path_factory) -> Path:
    """GT joints carried with the rollouts: ``slow`` (60 chunks at 0.8x the GT's pace, outlasting
    its 400-step episode, elbow past its limit for a few steps) and a short ``short``."""
    gt = _gt_path(400)
    chunks = _slow_prediction(gt, 60)
    elbow = JOINT_NAMES.index("elbow_flex")
    chunks[10, :3, elbow] = np.rad2deg(JOINT_LIMITS_RAD["elbow_flex"][1]) + 5.0  # steps 90..92
    root = tmp_path_factory.mktemp("syn") / "session"
    with SessionWriter.create(root, model={"name": "synthetic-wam", "checkpoint": "step-1"}) as w:
        w.add_rollout("slow", kind="autoregressive", actions=chunks, prompt="Reach and return",
                      episode_index=0, videos={"front": _frames(540, 32, 48, 0)},
                      gt_actions=gt, gt_videos={"front": _frames(400, 48, 72, 1)},  # 3:2, as the imagined 48x32
                      gt_episode_length=400)
        w.add_rollout("short", kind="autoregressive", actions=_slow_prediction(gt, 3),
                      prompt="Short", videos={"front": _frames(27, 32, 48, 2)}, gt_actions=gt[:60])
    return root


@pytest.fixture(scope="session")
def synthetic_export(synthetic_session, tmp_path_factory):
    tl = build_timeline(open_session(synthetic_session).rollouts["slow"])
    path = write_recording(tl, tmp_path_factory.mktemp("rrd") / "slow.rrd")
    return tl, path, Recording(path)


# ----------------------------------------------------------------------------------------------
# The imported rollout: 60 chunks, two views, no GT joints


def test_fixture_recording_verifies_and_is_small(fixture_export):
    tl, path, rec, _ = fixture_export
    rrd_verify(path)
    assert path.stat().st_size < 10e6
    assert len(rec.blueprints) == 1
    assert not list(path.parent.glob(".*partial"))


def test_fixture_joint_transforms_reproduce_fk(fixture_export):
    tl, _, rec, _ = fixture_export
    ours = kinematics().gripper_frame_poses(to_radians(tl.pred, tl.units))[:, :3, 3]
    from_file = chained_tool_points(rec, "pred")
    assert from_file.shape == (tl.n_steps, 3)
    np.testing.assert_allclose(from_file, ours, atol=1e-5)
    assert not rec.has(L.arm_root("gt"))  # no GT joints, no GT arm


def test_fixture_timelines_and_arm_geometry(fixture_export):
    tl, _, rec, _ = fixture_export
    frames, _ = rec.temporal(L.joint_transform_path("pred", "elbow_flex"), "Transform3D:quaternion")
    assert list(frames) == [tl.frame_index(s) for s in range(tl.n_steps)]
    chunks, _ = rec.temporal(L.joint_transform_path("pred", "elbow_flex"), "Transform3D:quaternion",
                             order_by=L.CHUNK)
    assert chunks.max() == tl.n_chunks - 1
    meshes = [e for e in rec.entities if e.startswith(f"/{L.arm_root('pred')}/visual_geometries/")]
    blobs = [rec.static(e[1:], "Asset3D:blob") for e in meshes]
    assert len(meshes) >= 13 and all(blobs)
    albedo = [a[0] for e in meshes for a in rec.static(e[1:], "Asset3D:albedo_factor")]
    assert albedo and all(a & 0xFF < 255 for a in albedo)  # the prediction is translucent


def test_fixture_video_references_count_imagined_frames(fixture_export):
    tl, _, rec, _ = fixture_export
    for view in tl.rollout.views:
        frames, refs = rec.temporal(L.video_path(view, "imagined"), "VideoFrameReference:timestamp")
        assert list(frames) == list(range(540))
        assert np.all(np.diff([r[0] for r in refs]) > 0)
        assert rec.static(L.video_path(view, "imagined"), "AssetVideo:media_type") == [["video/mp4"]]
        gt_frames, _ = rec.temporal(L.video_path(view, "gt"), "VideoFrameReference:timestamp")
        assert list(gt_frames) == list(range(409))  # carried GT: frame i pairs with imagined frame i
    assert not rec.has("image")  # never one image per frame


def test_fixture_series_lengths(fixture_export):
    tl, _, rec, _ = fixture_export
    for j, joint in enumerate(JOINT_NAMES):
        _, pred = rec.scalars(L.joint_plot(joint, "pred"))
        np.testing.assert_allclose(pred, tl.pred[:, j])
        _, bad = rec.scalars(L.joint_plot(joint, "limit_violation"))
        assert len(bad) == tl.limit_violation[:, j].sum()
        assert rec.static(L.joint_plot(joint, "pred"), "SeriesLines:names") == [[f"{joint} predicted"]]
        for k, side in enumerate(("lower_limit", "upper_limit")):
            _, limit = rec.scalars(L.joint_plot(joint, side))
            np.testing.assert_allclose(limit, [tl.limits[j, k]] * 2)
    assert tl.limit_violation.any()  # planted: the gripper at -40 (limit -10), as raw model outputs do
    for view in tl.video_views():
        frames, psnr = rec.scalars(L.psnr_path(view), order_by=L.FRAME)
        expected = tl.video_metrics(view).psnr_db
        assert len(psnr) == np.isfinite(expected).sum() == 409
        np.testing.assert_allclose(psnr, expected[frames])
    _, events = rec.temporal(L.EVENTS, "TextLog:text", L.TIME)
    starts = [t for t in events if " starts (" in t[0] or "episode ends" in t[0]]  # seams and breaks log there too
    assert len(starts) == tl.n_chunks + 1  # every chunk start and the episode's end
    assert any("episode ends at step 409" in t[0] for t in starts)
    _, end = rec.scalars(f"{L.MARKERS}/episode_end", order_by=L.FRAME)
    assert len(end) == 1
    assert not rec.has(L.DRIFT_SERIES[0][1])  # no GT joints, no drift


def test_fixture_description(fixture_export):
    tl, _, rec, _ = fixture_export
    text = rec.static(L.DESCRIPTION, "TextDocument:text")[0][0]
    for needle in ("ep000_train", "Pick the red cube", "DreamZero", "arm degrees", "PSNR",
                   "past its limit", "How to read"):
        assert needle in text, needle


def test_fixture_progress_reports(fixture_export):
    _, _, _, calls = fixture_export
    fractions = [f for f, _ in calls]
    assert fractions[0] == 0.0 and fractions[-1] == 1.0
    assert all(b >= a for a, b in zip(fractions, fractions[1:]))
    assert any("PSNR" in m for _, m in calls)


# ----------------------------------------------------------------------------------------------
# GT joints: drift, both arms, tempo


def test_gt_joint_recording(synthetic_export):
    tl, path, rec = synthetic_export
    rrd_verify(path)
    assert tl.has_gt_joints and tl.tempo == pytest.approx(0.8, abs=0.05)
    for arm, joints in (("pred", tl.pred), ("gt", tl.gt_aligned)):
        ours = kinematics().gripper_frame_poses(to_radians(joints, tl.units))[:, :3, 3]
        np.testing.assert_allclose(chained_tool_points(rec, arm), ours, atol=1e-5)
        assert rec.has(L.arm_root(arm)) and rec.has(L.ee_path(arm))
    for attr, entity, name, _ in L.DRIFT_SERIES:
        _, values = rec.scalars(entity)
        np.testing.assert_allclose(values, getattr(tl, attr))
        assert rec.static(entity, "SeriesLines:names")[0][0].startswith(name)
    for j, joint in enumerate(JOINT_NAMES):
        _, err = rec.scalars(f"{L.JOINT_ERROR}/{joint}")
        np.testing.assert_allclose(err, tl.joint_error[:, j])
        _, gt = rec.scalars(L.joint_plot(joint, "gt"))
        np.testing.assert_allclose(gt, tl.gt_aligned[:, j])
    _, ee = rec.scalars(L.EE_ERROR)
    np.testing.assert_allclose(ee, tl.ee_error_mm)
    _, rmse = rec.scalars(L.CHUNK_RMSE)
    assert len(rmse) == np.isfinite(tl.chunk_rmse).sum() > 0
    _, elbow_bad = rec.scalars(L.joint_plot("elbow_flex", "limit_violation"), order_by=L.FRAME)
    assert len(elbow_bad) == 3
    frames, _ = rec.temporal(L.video_path("front", "gt"), "VideoFrameReference:timestamp")
    assert list(frames) == list(range(400))
    text = rec.static(L.DESCRIPTION, "TextDocument:text")[0][0]
    assert f"| {tl.tempo:.2f} |" in text and "synthetic-wam / step-1" in text
    assert "after the episode" in text  # 540 steps outlast the 400-step episode


def test_dataset_gt_video_is_reencoded_to_h264(lerobot_dir, tmp_path):
    """GT from a LeRobot v3.0 dataset (AV1, three episodes in one file): the episode's frames
    become a new H.264 asset, frame k paired with the imagined frame showing the same step."""
    dataset = lerobot_dir / "so101_v30"
    if probe(next((dataset / "videos").rglob("*.mp4"))).codec == "h264":
        pytest.skip("fixture video is already H.264")
    root = tmp_path / "ds_session"
    with SessionWriter.create(root, dataset=dataset) as w:
        from inspector.data.lerobot_dataset import LeRobotDataset

        gt = LeRobotDataset(dataset).episode(1).action
        w.add_rollout("ep1", kind="autoregressive", actions=_slow_prediction(gt, 4, speed=1.0),
                      episode_index=1, start_frame=20, videos={"front": _frames(36, 36, 48, 3)})  # 4:3, as the dataset's
        # imagines a camera the dataset lacks: every dataset camera is then a GT-only view
        w.add_rollout("side", kind="autoregressive", actions=_slow_prediction(gt, 4, speed=1.0),
                      episode_index=1, start_frame=20, videos={"side": _frames(36, 32, 48, 4)})
    session = open_session(root)
    tl = build_timeline(session.rollouts["ep1"])
    assert tl.has_gt_joints and tl.gt.views == ["front"]
    path = write_recording(tl, tmp_path / "ep1.rrd")
    rrd_verify(path)
    rec = Recording(path)
    blob = rec.static(L.video_path("front", "gt"), "AssetVideo:blob")[0][0]
    asset = tmp_path / "gt_front.mp4"
    asset.write_bytes(bytes(blob))
    assert probe(asset).codec == "h264"
    frames, _ = rec.temporal(L.video_path("front", "gt"), "VideoFrameReference:timestamp")
    assert list(frames) == list(range(36))
    decoded, _ = decode(asset)
    assert len(decoded) == 36
    expected = tl.gt.clips["front"].frame(tl.gt_index_of_frame("front")(5))
    mse = np.mean((decoded[5].astype(float) - expected.astype(float)) ** 2)
    assert 10 * np.log10(255 ** 2 / max(mse, 1e-9)) > 28  # the same picture, lossy-encoded
    _, psnr = rec.scalars(L.psnr_path("front"))
    assert len(psnr) == 36

    side = build_timeline(session.rollouts["side"])
    assert sorted(side.gt.views) == ["front", "wrist"] and not side.video_views()
    rec = Recording(write_recording(side, tmp_path / "side.rrd"))
    for view in ("front", "wrist"):
        frames, _ = rec.temporal(L.video_path(view, "gt"), "VideoFrameReference:timestamp")
        assert list(frames) == list(range(36)) and not rec.has(L.video_path(view, "imagined"))
    assert rec.has(L.video_path("side", "imagined")) and not rec.has(L.psnr_path("side"))
    only_side = Recording(write_recording(side, tmp_path / "only_side.rrd", views=["side"]))
    assert not only_side.has(L.video_path("wrist", "gt"))


# ----------------------------------------------------------------------------------------------
# Pieces


def test_views_are_checked(synthetic_export):
    tl, _, _ = synthetic_export
    assert select_views(tl, None) == ["front"]
    with pytest.raises(InspectorError, match="no view 'side'.*views: \\['front'\\]"):
        select_views(tl, ["side"])


def test_failed_export_leaves_no_file(synthetic_session, tmp_path, monkeypatch):
    import inspector.export.recording as export

    tl = build_timeline(open_session(synthetic_session).rollouts["short"])
    dest = tmp_path / "x.rrd"
    dest.write_bytes(b"old")

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(export, "log_view", boom)
    with pytest.raises(RuntimeError):
        write_recording(tl, dest)
    assert dest.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.rrd"]


def _limit_file_size(max_bytes: int):
    """``preexec_fn`` for a child whose writes past ``max_bytes`` fail with EFBIG ("File too
    large"), as on a full disk, instead of killing it with SIGXFSZ."""
    def limit() -> None:
        import resource
        import signal

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (max_bytes, max_bytes))
    return limit


@pytest.fixture
def small_tmpfs(tmp_path):
    """A 200 kB tmpfs (a disk that fills up for real); skipped where mounting is not allowed."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    out = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", str(mnt)],
                         capture_output=True, text=True)
    if out.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {out.stderr.strip() or out.returncode}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], check=False)


@pytest.mark.parametrize("disk", ["file-size-limit", "full-tmpfs"])
def test_cli_export_write_error_is_one_line_and_leaves_nothing(synthetic_session, tmp_path, request, disk):
    """A write that fails mid-export (disk full, file too large): exit 2, exactly one line
    ``error: <file>: <what>`` on stderr (no traceback, no log lines from rerun), no file left."""
    if disk == "full-tmpfs":
        out_dir, preexec, reason = request.getfixturevalue("small_tmpfs"), None, "No space left on device"
    else:  # the recording is ~1 MB: a 300 kB limit cuts it, not the small cache and log files
        out_dir, preexec, reason = tmp_path / "out", _limit_file_size(300_000), "File too large"
        out_dir.mkdir()
    dest = out_dir / "short.rrd"
    run = subprocess.run([sys.executable, "-m", "inspector", "export", str(synthetic_session), "--rollout", "short",
                          "-o", str(dest)], capture_output=True, text=True, timeout=300, preexec_fn=preexec)
    assert run.returncode == 2, run.stderr
    assert run.stderr == f"error: {dest}: cannot write the recording ({reason})\n", run.stderr
    assert list(out_dir.iterdir()) == []
    if disk != "file-size-limit":
        return
    # the same command without the limit works: the limit, nothing else, made it fail (and the
    # installed command writes the recording and says so: see test_cli_entry_point)
    ok = tmp_path / "ok.rrd"
    run = subprocess.run([sys.executable, "-m", "inspector", "export", str(synthetic_session), "--rollout", "short",
                          "-o", str(ok)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith(f"wrote {ok} (") and run.stdout.count("\n") == 1
    assert ok.stat().st_size > 300_000
    rrd_verify(ok)


def test_cluster_vertices_keeps_winding():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1e-5, 0, 0]], float)
    f = np.array([[0, 1, 2], [3, 1, 2], [0, 3, 1]])
    nv, nf = cluster_vertices(v, f, 1e-3)
    assert len(nv) == 3 and len(nf) == 1  # the duplicate and the sliver are gone
    np.testing.assert_allclose(nv[nf[0]], v[:3], atol=1e-4)  # same corners, same winding


@pytest.mark.parametrize("span_m", [0.3, 5e3])  # an arm's part; one past 21 bits of 0.5 mm cells
def test_cluster_vertices_matches_sorting_whole_rows(span_m):
    """Rows are sorted as one packed key each; the cells, their order and the faces kept are those
    ``np.unique(axis=0)`` gives, so cached meshes keep their bytes."""
    rng = np.random.default_rng(3)
    v = rng.uniform(-span_m, span_m, (3000, 3))
    v[1000:2000] = v[:1000] + rng.normal(0, 1e-4, (1000, 3))  # neighbours that share a cell
    f = rng.integers(0, len(v), (5000, 3))
    f[2500:] = f[:2500, ::-1]  # the same triangles again, reversed: kept once each
    keys = np.round(v / meshes.CELL_M).astype(np.int64)
    _, cell_of, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    cell_of = cell_of.reshape(-1)
    expected_v = np.zeros((len(counts), 3))
    np.add.at(expected_v, cell_of, v)
    expected_v /= counts[:, None]
    nf = cell_of[f]
    nf = nf[(nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])]
    _, first = np.unique(np.sort(nf, axis=1), axis=0, return_index=True)
    got_v, got_f = cluster_vertices(v, f, meshes.CELL_M)
    np.testing.assert_array_equal(got_v, expected_v)
    np.testing.assert_array_equal(got_f, nf[np.sort(first)])
    assert len(got_v) < len(v) and len(got_f) < len(f)


def test_progress_bar_and_sizes():
    class Tty:
        def __init__(self):
            self.text = ""

        def isatty(self):
            return True

        def write(self, s):
            self.text += s

        def flush(self):
            pass

    stream = Tty()
    bar = FractionBar("ep0", stream=stream, delay_s=0.0)
    bar(0.5, "video")
    assert "ep0" in stream.text and "50%" in stream.text and "video" in stream.text
    bar.close()
    quiet = FractionBar("ep0", stream=open(os.devnull, "w"), delay_s=0.0)
    quiet(0.5)  # not a TTY: draws nothing, raises nothing
    assert format_size(4_400_000) == "4.4 MB" and format_size(512) == "512 B"


# ----------------------------------------------------------------------------------------------
# Command line


def test_cli_exports_one_file_per_rollout(synthetic_session, tmp_path, capsys):
    out = tmp_path / "out"
    # one worker writing both: exports in two at once are the Ctrl-C test's (and test_metrics_cache's)
    assert cli_main(["export", str(synthetic_session), "-o", str(out), "--jobs", "1"]) == 0
    files = sorted(p.name for p in out.iterdir())
    assert files == ["short.rrd", "slow.rrd"]
    printed = capsys.readouterr().out.splitlines()
    assert [line.split(" (")[0] for line in printed] == [f"wrote {out / name}" for name in files]  # in order
    for name in files:
        rrd_verify(out / name)


def test_cli_single_rollout_to_file(fixture_session, tmp_path, capsys):
    dest = tmp_path / "f076.rrd"
    assert cli_main(["export", str(fixture_session), "--rollout", "f076", "-o", str(dest),
                     "--views", "front"]) == 0
    rrd_verify(dest)
    rec = Recording(dest)
    assert rec.has(L.video_path("front", "imagined")) and not rec.has(L.video_path("gripper", "imagined"))
    assert rec.has(L.arm_root("gt"))  # single chunks carry GT joints


def test_cli_rollout_directory_and_source_dir(dz_layout, fixture_session, tmp_path):
    assert cli_main(["export", str(fixture_session / "rollouts" / "f000"), "-o",
                     str(tmp_path / "a.rrd")]) == 0
    rrd_verify(tmp_path / "a.rrd")
    src = dz_layout / "zeroshot_chunk" / "f153"
    assert cli_main(["export", str(src), "-o", str(tmp_path / "b")]) == 0
    assert [p.name for p in (tmp_path / "b").iterdir()] == ["f153.rrd"]


@pytest.mark.parametrize("args, message", [
    (["{missing}", "-o", "{tmp}/x.rrd"], "error: {missing}: not found"),
    (["{session}", "--rollout", "nope", "-o", "{tmp}/x.rrd"],
     "error: {session}: no rollout 'nope'; rollouts: ['short', 'slow']"),
    (["{session}", "-o", "{tmp}/x.rrd"], "error: {tmp}/x.rrd: one file for 2 rollouts"),
    (["{session}", "--views", "side", "-o", "{tmp}/d"], "error: {session}: no view 'side'"),
])
def test_cli_bad_input_exits_2(synthetic_session, tmp_path, capsys, args, message):
    fill = {"missing": tmp_path / "missing", "session": synthetic_session, "tmp": tmp_path}
    argv = ["export", *[a.format(**fill) for a in args]]
    assert cli_main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(message.format(**fill)) and err.count("\n") == 1
    assert not list(tmp_path.glob("*.rrd"))


def test_cli_broken_rollout_spares_the_others(synthetic_session, tmp_path, capsys):
    import shutil

    root = tmp_path / "s"
    shutil.copytree(synthetic_session, root)
    np.save(root / "rollouts" / "short" / "actions.npy", np.zeros((3, 24, 5)))
    assert cli_main(["export", str(root), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {root / 'rollouts' / 'short' / 'actions.npy'}: shape")
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["slow.rrd"]


def test_several_rollouts_are_written_by_fresh_worker_processes(synthetic_session, tmp_path, monkeypatch):
    """rerun's SDK keeps native memory per recording written, so a session is written by worker
    processes that fresh ones replace every few recordings; outcomes come back in the jobs' order."""
    from inspector.export import jobs as export_jobs
    from inspector.export.jobs import ExportJob, run_export_jobs

    monkeypatch.setattr(export_jobs, "EXPORTS_PER_WORKER", 1)
    # three jobs, three workers (the long rollout once: it is the fresh processes that are tested)
    jobs = [ExportJob(str(synthetic_session), tag, str(tmp_path / f"{i}_{tag}.rrd"), None, None, 2.0, False)
            for i, tag in enumerate(("short", "slow", "short"))]
    outcomes = list(run_export_jobs(jobs, workers=1))
    assert [(o.tag, o.dest, o.error) for o in outcomes] == [(j.tag, j.dest, None) for j in jobs]
    pids = [o.worker_pid for o in outcomes]
    assert len(set(pids)) == len(jobs) and os.getpid() not in pids
    for o in outcomes:
        assert Path(o.dest).stat().st_size == o.size
    rrd_verify(Path(outcomes[-1].dest))


def test_ctrl_c_stops_a_session_export_leaving_only_whole_files(tmp_path):
    """Ctrl-C (SIGINT to the terminal's process group) while workers write: exit 130 soon, no
    temporary file left, and every recording there is complete.

    A copy of four demo rollouts: a single chunk first, whose recording is written in a moment
    (the Ctrl-C then comes while the other worker writes a whole rollout), and three long ones."""
    import shutil
    import signal

    source = Path(__file__).resolve().parents[1] / "sessions" / "demo"
    tags = ("single_f000", "tempo_0.8x", "video_ahead_1s", "video_degrades")  # in the order they are written
    demo = tmp_path / "demo"
    shutil.copytree(source, demo, ignore=lambda folder, names: [
        n for n in names if Path(folder) == source / "rollouts" and n not in tags])
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "inspector", "export", str(demo), "-o", str(out), "--no-cache"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        first = proc.stdout.readline()  # blocks until the first recording is written (or the export ends)
        assert first.startswith(f"wrote {out / tags[0]}.rrd"), first + proc.stderr.read()
        os.killpg(proc.pid, signal.SIGINT)
        rest, err = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    written = sorted(out.iterdir())
    assert [p for p in written if p.suffix != ".rrd"] == []  # no .partial
    assert 1 <= len(written) < len(tags)
    for path in written:
        rrd_verify(path)


def test_cli_entry_point(tmp_path):
    """The installed ``inspector`` command, as a user runs it: a path that is not there is one
    line and exit 2. (Its export of a rollout, written and said, is the file-size-limit test's
    run without the limit: one export of the short rollout fewer.)"""
    bad = subprocess.run([sys.executable, "-m", "inspector", "export", str(tmp_path / "nope"),
                          "-o", str(tmp_path / "x.rrd")], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and bad.stderr == f"error: {tmp_path / 'nope'}: not found\n"


# ----------------------------------------------------------------------------------------------
# Layout: what a researcher sees when the file opens


def test_the_3d_view_frames_every_path(fixture_export):
    """Every predicted tool point and every chunk's horizon lies inside the viewer's field of view
    from the recording's eye (the prediction used to run off the top)."""
    from inspector.export.recording import eye_fitting

    tl, _, _, _ = fixture_export
    eye, target = (np.array(v) for v in eye_fitting(tl))
    axis = (target - eye) / np.linalg.norm(target - eye)
    trail = kinematics().gripper_positions(tl.chunks.reshape(-1, 6), tl.units)
    for pts in (tl.ee_pred, trail):
        rays = pts - eye
        angle = np.degrees(np.arccos(np.clip(rays @ axis / np.linalg.norm(rays, axis=1), -1, 1)))
        assert np.percentile(angle, 99) < 27.5, np.percentile(angle, 99)


def test_blueprint_titles_and_layout():
    import rerun.blueprint as rrb

    no_gt = L.build_blueprint(L.Contents(views={"front": (True, False)}, gt_joints=False))
    episode = L.build_blueprint(L.Contents(views={"front": (False, True)}, gt_joints=True,
                                           pred_name="commanded (action)", gt_name="measured (state)",
                                           chunks=False))

    def views(node):
        for child in getattr(node, "contents", None) or []:
            if isinstance(child, rrb.View):
                yield child
            else:
                yield from views(child)

    def names(bp):
        return [v.name for v in views(bp.root_container)]

    assert "Arm: predicted (no GT joints)" in names(no_gt)
    assert "Arms: measured (state) (opaque) vs commanded (action) (translucent)" in names(episode)
    assert "Chunk RMSE" not in names(episode) and "front camera" in names(episode)
    joints = next(c for c in _containers(no_gt.root_container) if getattr(c, "name", None) == "Joints")
    assert joints.grid_columns == 2  # joint names are not cut short


def _containers(node):
    for child in getattr(node, "contents", None) or []:
        if not hasattr(child, "origin"):
            yield child
            yield from _containers(child)


def test_chunk_starts_are_events_not_plot_markers(synthetic_export):
    _, _, rec = synthetic_export
    assert not [e for e in rec.entities if "chunk_start" in e]
    texts = rec.temporal(L.EVENTS, "TextLog:text")[1]
    assert any("chunk 1 starts" in str(t) for t in texts)


def test_outcomes_travel_in_the_recording(synthetic_session, tmp_path):
    """A labelled rollout's recording carries every source as static text, the effective success
    and progress as series, and still verifies."""
    from inspector.export.outcomes import OUTCOME, PROGRESS_SERIES, SUCCESS_SERIES
    from inspector.outcomes import store_records

    store_records(synthetic_session / "outcomes.json", {"short": {"success": False, "progress": 40, "note": "judge"}},
                  source="file", set_by="judge.jsonl")
    store_records(synthetic_session / "outcomes.json", {"short": {"success": True, "progress": 90}},
                  source="label", set_by="app")
    try:
        tl = build_timeline(open_session(synthetic_session).rollouts["short"])
        path = write_recording(tl, tmp_path / "short.rrd")
        rrd_verify(path)
        rec = Recording(path)
        text = rec.static(OUTCOME, "TextDocument:text")[0][0]
        assert "**success** (source: label)" in text and "| file | False | 40.0 |" in text and "judge" in text
        frames, success = rec.scalars(SUCCESS_SERIES, order_by=L.FRAME)
        assert success.tolist() == [1.0, 1.0] and frames.tolist() == [tl.frame_index(0), tl.frame_index(tl.n_steps - 1)]
        assert rec.scalars(PROGRESS_SERIES)[1].tolist() == [90.0, 90.0]
    finally:
        (synthetic_session / "outcomes.json").unlink()


def test_export_outcome_source_chooses_the_recorded_outcome(tmp_path):
    """``inspector export --outcome-source``: a lerobot-eval rollout the simulator calls a success
    and a person labelled a failure at 30 % is recorded with the chosen source's success and
    progress series (the text keeps both sources); a source the rollout lacks gives no series."""
    from eval_outputs import write_eval

    from inspector.data.sources import open_sources
    from inspector.export.outcomes import OUTCOME, PROGRESS_SERIES, SUCCESS_SERIES
    from inspector.outcomes import outcomes_path, store_records

    raw = tmp_path / "eval_run"
    write_eval(raw, {("so101_sim", 0): [True]}, steps=12)
    sources = open_sources([raw], lazy=True)
    try:
        (tag,) = sources.sessions[0].tags()
        store_records(outcomes_path(sources.sessions[0]), {tag: {"success": False, "progress": 30}},
                      source="label", set_by="app")
    finally:
        sources.close()

    def exported(source: str) -> Recording:
        dest = tmp_path / f"{source}.rrd"
        assert cli_main(["export", str(raw), "-o", str(dest), "--outcome-source", source, "--no-cache"]) == 0
        rrd_verify(dest)
        return Recording(dest)

    by_sim, by_label, by_file = exported("sim"), exported("label"), exported("file")
    assert "**success** (source: sim)" in by_sim.static(OUTCOME, "TextDocument:text")[0][0]
    assert by_sim.scalars(SUCCESS_SERIES)[1].tolist() == [1.0, 1.0] and not by_sim.has(PROGRESS_SERIES)
    text = by_label.static(OUTCOME, "TextDocument:text")[0][0]
    assert "**failure** (source: label)" in text and "| sim | True |" in text
    assert by_label.scalars(SUCCESS_SERIES)[1].tolist() == [0.0, 0.0]
    assert by_label.scalars(PROGRESS_SERIES)[1].tolist() == [30.0, 30.0]
    assert not by_file.has(SUCCESS_SERIES)
    assert "| label | False | 30.0 |" in by_file.static(OUTCOME, "TextDocument:text")[0][0]
