"""The 3D scene of one tab: GT and predicted arms, end-effector paths, the chunk's horizon trail.

What is drawn (all in the robot base frame, metres):

- the GT arm (opaque grey) and the predicted arm (translucent orange), both from the one shared
  URDF, posed per step with ``update_cfg``; a compared rollout's arm in translucent blue;
- the GT and predicted end-effector (gripper frame) paths as lines;
- the current chunk's whole predicted horizon (24 steps) as a trail: the executed steps thick and
  dark, the rest thin; horizon steps past a joint limit as red points;
- a table top under the arm; the camera frames both arms and every path when a rollout opens;
- a red sphere at each joint that is past its limit at the current step (listed, with values, in
  the timeline readout).

:class:`RolloutScene` holds the per-rollout arrays (computed once, shared by all tabs);
:class:`TabScene` holds one client's scene nodes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt

from ..analysis.timeline import RolloutTimeline
from ..robot.description import VIEW_DIRECTION, bounding_sphere
from ..robot.kinematics import kinematics
from ..units import JOINT_NAMES, to_radians
from ._robot import ArmView, SharedRobot

Array = npt.NDArray[np.float64]

GT_COLOR = (0.62, 0.64, 0.68)  # opaque grey: the real arm
PRED_COLOR = (1.0, 0.45, 0.05, 0.55)  # translucent orange: the model's arm
CMP_COLOR = (0.15, 0.45, 1.0, 0.45)  # translucent blue: the compared rollout
PRED_RGB = (240, 110, 10)
GT_RGB = (40, 160, 70)
CMP_RGB = (40, 110, 240)
EXECUTED_RGB = (200, 40, 0)
HORIZON_RGB = (250, 170, 60)
LIMIT_RGB = (230, 20, 20)
TABLE_RGB = (228, 224, 216)


@dataclass
class RolloutScene:
    """Scene arrays of one rollout, from its timeline. T steps, N chunks, H horizon.

    Attributes:
        q_pred: (T, 6) predicted joints [rad], JOINT_NAMES order.
        q_gt: (T, 6) GT joints at the same time [rad], or None.
        ee_pred, ee_gt: (T, 3) gripper-frame positions [m] (``ee_gt`` None without GT joints).
        trail: (N, H, 3) gripper-frame positions along every chunk's full horizon [m].
        trail_violation: (N, H) horizon steps with any joint past its limit.
        joint_pos: (T, 6, 3) position of each joint (its child link's origin) [m].
        executed: horizon steps of a chunk that are executed (the rest is only predicted).
    """

    q_pred: Array
    q_gt: Array | None
    ee_pred: Array
    ee_gt: Array | None
    trail: Array
    trail_violation: npt.NDArray[np.bool_]
    joint_pos: Array
    executed: int
    steps_per_chunk: int
    horizon_trail: bool = True  # an episode's one "chunk" is its whole command: its path says it all

    @property
    def n_steps(self) -> int:
        return int(self.q_pred.shape[0])

    @classmethod
    def from_timeline(cls, tl: RolloutTimeline, joint_links: dict[str, str]) -> RolloutScene:
        """Batched FK of everything the scene needs (a few ms for a 60-chunk rollout)."""
        fk = kinematics()
        q_pred = to_radians(tl.pred, tl.units)
        n, h = tl.chunks.shape[:2]
        trail = cast(Array, fk.gripper_positions(tl.chunks.reshape(-1, len(JOINT_NAMES)), tl.units).reshape(n, h, 3))
        links = tuple(joint_links[j] for j in JOINT_NAMES)
        poses = fk.link_poses(q_pred, links=links)
        joint_pos = np.stack([poses[link][:, :3, 3] for link in links], axis=1)
        executed = min(h, tl.steps_per_chunk)
        return cls(
            q_pred=q_pred,
            q_gt=None if tl.gt_aligned is None else to_radians(tl.gt_aligned, tl.units),
            ee_pred=tl.ee_pred,
            ee_gt=tl.ee_gt,
            trail=trail,
            trail_violation=cast(npt.NDArray[np.bool_], tl.chunk_limit_violation.any(axis=-1)),
            joint_pos=joint_pos,
            executed=executed,
            steps_per_chunk=tl.steps_per_chunk,
            horizon_trail=tl.kind != "episode",
        )


class _NoArm:
    """Stands in for an arm when the robot model could not be loaded (paths and plots still work)."""

    visible = False

    def __init__(self, *args) -> None:
        pass

    def set_joints(self, q_rad) -> None:
        pass


def _path_segments(points: Array) -> Array:
    """(P, 3) polyline -> (P-1, 2, 3) segments."""
    points = np.asarray(points, np.float32)
    if len(points) < 2:
        return np.zeros((0, 2, 3), np.float32)
    return np.stack([points[:-1], points[1:]], axis=1)


class TabScene:
    """One client's scene nodes; everything the scrub step changes goes through :meth:`set_step`.

    Args:
        client: the viser ClientHandle.
        robot: the shared robot (meshes loaded once per app), or None to draw no arms.
    """

    def __init__(self, client, robot: SharedRobot | None) -> None:
        self._client = client
        scene = client.scene
        # Shadows of translucent arms read as clutter, and cost a lot on GPU-less browsers.
        scene.configure_default_lights(cast_shadow=False)
        # a table top under the arm for scale and depth, the grid just above it (5 cm cells)
        scene.add_box("/table", dimensions=(1.0, 1.0, 0.01), position=(0.15, 0.0, -0.0055),
                      color=TABLE_RGB)
        scene.add_grid("/ground", width=1.0, height=1.0, cell_size=0.05, section_size=0.25,
                       position=(0.15, 0.0, 0.0))
        arm: Callable[..., ArmView | _NoArm] = ArmView if robot is not None else _NoArm
        self.gt_arm = arm(client, robot, "/arms/gt", GT_COLOR)
        self.pred_arm = arm(client, robot, "/arms/pred", PRED_COLOR)
        self._robot = robot
        self.cmp_arm: ArmView | _NoArm | None = None  # drawn on the first compare: most tabs never need it
        self._ee_pred = scene.add_icosphere("/now/pred", radius=0.008, color=PRED_RGB)
        self._ee_gt = scene.add_icosphere("/now/gt", radius=0.008, color=GT_RGB)
        self._limit_spheres = [
            scene.add_icosphere(f"/limits/{j}/sphere", radius=0.018, color=LIMIT_RGB, opacity=0.7,
                                visible=False)
            for j in JOINT_NAMES
        ]
        self._paths: list = []
        self._trail: list = []
        self._trail_shapes: tuple | None = None  # the trail nodes' array shapes (kept while they fit)
        self._frame_when_ready: tuple | None = None
        self._watching_camera = False
        # (data, compare, canvas aspect, camera position) of the last framing
        self._framed: tuple[RolloutScene, RolloutScene | None, float, np.ndarray] | None = None
        self._trail_chunk: int | None = None
        self.data: RolloutScene | None = None
        self.compare: RolloutScene | None = None

    # -- rollout changes ----------------------------------------------------------------------
    def show(self, data: RolloutScene | None, compare: RolloutScene | None = None) -> None:
        """Draw a rollout's static parts (paths) and hide what it lacks (GT arm without GT joints)."""
        scene = self._client.scene
        for node in self._paths + self._trail:
            node.remove()
        self._paths, self._trail, self._trail_chunk = [], [], None
        self.data, self.compare = data, compare
        has = data is not None
        self.pred_arm.visible = has
        self._ee_pred.visible = has
        self.gt_arm.visible = data is not None and data.q_gt is not None
        self._ee_gt.visible = self.gt_arm.visible
        if has and compare is not None and self.cmp_arm is None:
            arm: Callable[..., ArmView | _NoArm] = ArmView if self._robot is not None else _NoArm
            self.cmp_arm = arm(self._client, self._robot, "/arms/compare", CMP_COLOR)
        if self.cmp_arm is not None:
            self.cmp_arm.visible = has and compare is not None
        for marker in self._limit_spheres:
            marker.visible = False
        if data is None:
            return
        self._frame(data, compare)
        self._paths.append(scene.add_line_segments(
            "/paths/pred", _path_segments(data.ee_pred), PRED_RGB, thickness=2.0,
            thickness_units="screen"))
        if data.ee_gt is not None:
            self._paths.append(scene.add_line_segments(
                "/paths/gt", _path_segments(data.ee_gt), GT_RGB, thickness=2.0,
                thickness_units="screen"))
        if compare is not None:
            self._paths.append(scene.add_line_segments(
                "/paths/compare", _path_segments(compare.ee_pred), CMP_RGB, thickness=1.5,
                thickness_units="screen"))

    def _frame(self, data: RolloutScene, compare: RolloutScene | None) -> None:
        """Point the camera at everything drawn: both arms over the whole rollout, the tool paths
        and the chunk trails (a rollout that wanders off no longer runs out of the view). The
        canvas is the gap between the docked panels, often taller than wide: the scene is fitted
        to whichever of its two fields of view is narrower."""
        points = [data.joint_pos.reshape(-1, 3), data.ee_pred, data.trail.reshape(-1, 3), np.zeros((1, 3))]
        if data.ee_gt is not None:
            points.append(data.ee_gt)
        if compare is not None:
            points += [compare.joint_pos.reshape(-1, 3), compare.ee_pred]
        centre, radius = bounding_sphere(np.concatenate(points))
        camera = self._client.camera
        if not self._watching_camera:
            self._watching_camera = True
            camera.on_update(lambda _: self._camera_reported())
        try:
            fov, aspect = float(camera.fov), _aspect(camera)
        except AssertionError:  # the browser has not reported its camera yet: frame once it has
            self._frame_when_ready = (data, compare)
            return
        tan_v = np.tan(fov / 2)
        distance = radius / (0.9 * min(tan_v, tan_v * aspect))
        position = centre + np.asarray(VIEW_DIRECTION) * distance
        # position first: viser moves the look-at point along with a new position
        camera.position = tuple(float(v) for v in position)
        camera.look_at = tuple(float(v) for v in centre)
        self._framed = (data, compare, aspect, position)

    @property
    def framed_aspect(self) -> float | None:
        """Width / height of the canvas the camera was last fitted to (None before the first fit)."""
        return None if self._framed is None else self._framed[2]

    def _camera_reported(self) -> None:
        """The browser reported its camera: frame a rollout that waited for it, and frame again
        when the canvas changed shape under a camera the user has not moved (the panels dock
        after the first report: a view fitted to that canvas runs off the real one)."""
        pending, self._frame_when_ready = self._frame_when_ready, None
        if pending is not None and pending[0] is self.data:
            self._frame(*pending)
            return
        framed, camera = self._framed, self._client.camera
        if framed is None or framed[0] is not self.data:
            return
        aspect = _aspect(camera)
        untouched = np.linalg.norm(np.asarray(camera.position) - framed[3]) < 1e-4
        if untouched and abs(aspect - framed[2]) > 0.02 * framed[2]:
            self._frame(framed[0], framed[1])

    # -- the scrub step -----------------------------------------------------------------------
    def set_step(self, step: int, limit_text: list[str] | None = None) -> None:
        """Pose every arm at ``step``, move the trail to its chunk, mark joints over their limits.

        Args:
            step: global executed step (already clamped).
            limit_text: per joint, non-empty when that joint is past its limit at this step (the
                words are listed by the tab's readout; the scene marks the joint with a red sphere).
        """
        data = self.data
        if data is None:
            return
        self.pred_arm.set_joints(data.q_pred[step])
        self._ee_pred.position = tuple(data.ee_pred[step])
        if data.q_gt is not None:
            self.gt_arm.set_joints(data.q_gt[step])
            assert data.ee_gt is not None  # both come from the timeline's GT joints
            self._ee_gt.position = tuple(data.ee_gt[step])
        if self.compare is not None and self.cmp_arm is not None:
            self.cmp_arm.set_joints(self.compare.q_pred[min(step, self.compare.n_steps - 1)])
        chunk = min(step // data.steps_per_chunk, len(data.trail) - 1)
        if chunk != self._trail_chunk and data.horizon_trail:
            self._draw_trail(chunk)
        for j, text in enumerate(limit_text or [""] * len(JOINT_NAMES)):
            on = bool(text)
            sphere = self._limit_spheres[j]
            if on:
                sphere.position = tuple(data.joint_pos[step, j])
            if sphere.visible != on:
                sphere.visible = on

    def _draw_trail(self, chunk: int) -> None:
        """Show chunk ``chunk``'s horizon trail (executed part set apart).

        The trail's nodes are kept and given the chunk's points: removed and added again, they
        made the browser drop their shaders and compile them anew on every chunk step (8 shader
        programs over 6 steps in headless Chromium, 2 when kept)."""
        data = self.data
        assert data is not None
        pts = data.trail[chunk]
        e = min(data.executed, len(pts))
        # executed steps: a thick dark line with large dots; the rest of the horizon: thin and light
        colors = np.where(data.trail_violation[chunk][:, None], np.array(LIMIT_RGB),
                          np.where(np.arange(len(pts))[:, None] < e, np.array(EXECUTED_RGB),
                                   np.array(HORIZON_RGB))).astype(np.uint8)
        executed = _path_segments(pts[:e])
        horizon = _path_segments(pts[e - 1:] if e > 0 else pts) if e < len(pts) else None
        shapes = (executed.shape, pts.shape, None if horizon is None else horizon.shape)
        if self._trail and self._trail_shapes == shapes:
            self._trail[0].points = executed
            self._trail[1].points = pts.astype(np.float32)
            self._trail[1].colors = colors
            if horizon is not None:
                self._trail[2].points = horizon
        else:
            self._add_trail(executed, pts, colors, horizon)
            self._trail_shapes = shapes
        self._trail_chunk = chunk

    def _add_trail(self, executed: np.ndarray, pts: np.ndarray, colors: np.ndarray,
                   horizon: np.ndarray | None) -> None:
        scene = self._client.scene
        for node in self._trail:
            node.remove()
        self._trail = [
            scene.add_line_segments("/trail/executed", executed, EXECUTED_RGB, thickness=6.0,
                                    thickness_units="screen"),
            scene.add_point_cloud("/trail/points", pts.astype(np.float32), colors=colors,
                                  point_size=0.006, point_shape="circle"),
        ]
        if horizon is not None:
            self._trail.append(scene.add_line_segments("/trail/predicted", horizon, HORIZON_RGB,
                                                       thickness=1.5, thickness_units="screen"))


def _aspect(camera) -> float:
    """Width / height of the canvas a client's camera draws (AssertionError before it reported)."""
    return float(camera.image_width) / max(float(camera.image_height), 1.0)
