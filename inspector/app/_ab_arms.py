"""The pair's arms in A/B mode: each side's predicted arm, and its GT arm where it has one, side by
side in one 3D scene, posed at the pair's playback step.

The arms are the rollout view's own (:class:`~._robot.ArmView`, :class:`~._scene.RolloutScene`,
the same colours: GT opaque grey, predicted translucent orange); each side's pair of arms hangs
under a frame moved sideways as the camera sees it, A on the left, B on the right, each with its
letter above it. Scene nodes are named by side only (``/ab/A/pred``, ``/ab/B/gt``): nothing in the
scene names a session, a model or a rollout.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..analysis.timeline import build_timeline
from ..data.session import Rollout
from ..robot.description import VIEW_DIRECTION, bounding_sphere
from ._robot import ArmView, SharedRobot
from ._scene import GT_COLOR, PRED_COLOR, TABLE_RGB, RolloutScene, _aspect, _NoArm

SIDES = ("A", "B")
SIDE_OFFSET_M = 0.3  # each side's base from the middle: two arms at full reach still do not touch
# the camera's right, seen along VIEW_DIRECTION: A is moved left of the middle, B right of it
_RIGHT = np.array([-VIEW_DIRECTION[1], VIEW_DIRECTION[0], 0.0]) / np.hypot(VIEW_DIRECTION[0], VIEW_DIRECTION[1])
LOOK_AT = (0.12, 0.0, 0.1)
CAMERA_DISTANCE_M = 1.3  # both sides' arms in view on a canvas about as wide as high
LABEL_HEIGHT_M = 0.42  # each side's letter, above its arms


def side_origin(side: str) -> tuple[float, float, float]:
    """Where ``side``'s arms stand [m, robot base frame of the middle]."""
    sign = -1.0 if side == SIDES[0] else 1.0
    return tuple(float(v) for v in sign * SIDE_OFFSET_M * _RIGHT)  # type: ignore[return-value]


def rollout_scene(rollout: Rollout, joint_links: dict[str, str]) -> RolloutScene | None:
    """The arms' joints of one side, or None when its arrays cannot be read (its videos still show)."""
    try:
        return RolloutScene.from_timeline(build_timeline(rollout), joint_links)
    except Exception:  # any failure: that side shows no arm, the vote goes on
        return None
    finally:
        rollout.release_arrays()


class PairArms:
    """The two sides' arms in one client's scene.

    Args:
        client: the viser client (or server) whose scene it is drawn in.
        robot: the shared robot, or None to draw no arms (its meshes failed to load).
    """

    def __init__(self, client, robot: SharedRobot | None) -> None:
        scene = client.scene
        scene.configure_default_lights(cast_shadow=False)  # as the rollout view: see ._scene
        scene.add_box("/table", dimensions=(1.0, 1.4, 0.01), position=(0.15, 0.0, -0.0055), color=TABLE_RGB)
        arm: Callable[..., ArmView | _NoArm] = ArmView if robot is not None else _NoArm
        self.arms: dict[str, dict[str, ArmView | _NoArm]] = {}
        self.labels = {}
        for side in SIDES:
            scene.add_frame(f"/ab/{side}", show_axes=False, position=side_origin(side))
            self.labels[side] = scene.add_label(f"/ab/{side}/label", side, position=(0.0, 0.0, LABEL_HEIGHT_M),
                                                font_screen_scale=2.0, anchor="bottom-center")
            self.arms[side] = {"gt": arm(client, robot, f"/ab/{side}/gt", GT_COLOR),
                               "pred": arm(client, robot, f"/ab/{side}/pred", PRED_COLOR)}
        self.data: dict[str, RolloutScene | None] = dict.fromkeys(SIDES)
        self._camera = getattr(client, "camera", None)  # a server has no one camera: the app's initial one
        self._framed: tuple[float, np.ndarray] | None = None  # (canvas aspect, camera position) of the last fit
        if self._camera is not None:
            self._camera.position = tuple(np.asarray(LOOK_AT) + CAMERA_DISTANCE_M * np.asarray(VIEW_DIRECTION))
            self._camera.look_at = LOOK_AT
            self._camera.on_update(lambda _: self._camera_reported())

    @property
    def n_steps(self) -> int:
        """Steps of the longer side (the shorter one holds its last pose), 0 without arms."""
        return max((d.n_steps for d in self.data.values() if d is not None), default=0)

    def show(self, a: RolloutScene | None, b: RolloutScene | None) -> None:
        """Put a new pair's arms up (a GT arm only where that side has GT joints), at step 0."""
        for side, data in zip(SIDES, (a, b)):
            self.data[side] = data
            self.arms[side]["pred"].visible = data is not None
            self.arms[side]["gt"].visible = data is not None and data.q_gt is not None
        self.set_step(0)
        self._framed = None
        self.frame()

    def frame(self) -> None:
        """Point the camera at both sides' arms over their whole rollouts and their letters, fitted
        to the canvas (the narrower of its two fields of view) as the rollout view fits its arm: the
        arms fill the view rather than stand small in a large scene."""
        camera = self._camera
        if camera is None:
            return
        points = []
        for side, data in self.data.items():
            origin = np.asarray(side_origin(side))
            points.append(origin + np.array([[0.0, 0.0, 0.0], [0.0, 0.0, LABEL_HEIGHT_M]]))
            if data is not None:
                points.append(data.joint_pos.reshape(-1, 3) + origin)
        centre, radius = bounding_sphere(np.concatenate(points))
        try:
            fov, aspect = float(camera.fov), _aspect(camera)
        except AssertionError:  # the browser has not reported its camera yet: fit once it has
            return
        tan_v = np.tan(fov / 2)
        position = centre + np.asarray(VIEW_DIRECTION) * radius / (0.9 * min(tan_v, tan_v * aspect))
        camera.position = tuple(float(v) for v in position)  # position first: viser moves look_at with it
        camera.look_at = tuple(float(v) for v in centre)
        self._framed = (aspect, position)

    def _camera_reported(self) -> None:
        """Fit the view once the browser has reported its canvas, and again when the canvas changes
        shape under a camera the user has not moved."""
        camera, framed = self._camera, self._framed
        if camera is None:
            return
        try:
            aspect = _aspect(camera)
        except AssertionError:
            return
        if framed is None:
            self.frame()
        elif (np.linalg.norm(np.asarray(camera.position) - framed[1]) < 1e-4
              and abs(aspect - framed[0]) > 0.02 * framed[0]):
            self.frame()

    def set_step(self, step: int) -> None:
        """Pose every arm at ``step`` (clamped to each side's own length)."""
        for side, data in self.data.items():
            if data is None:
                continue
            k = int(np.clip(step, 0, data.n_steps - 1))
            self.arms[side]["pred"].set_joints(data.q_pred[k])
            if data.q_gt is not None:
                self.arms[side]["gt"].set_joints(data.q_gt[k])
