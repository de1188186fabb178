"""The demo's exact cameras, read from the MuJoCo scene it is rendered with.

The demo scene's ``front`` camera sits in the world, and the arm's base body sits at the world
origin unrotated, so its pose in the world is its pose in the URDF's base frame; the ``wrist``
camera sits in the ``gripper`` body, which is the URDF's ``gripper_link`` (every MuJoCo body of
the arm is the URDF link of its name plus ``_link``, with the same frame: tests check both).
MuJoCo's cameras look down their -z with y up; :func:`inspector.robot.camera.camera_from_mujoco`
turns them to OpenCV axes.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..data.cameras import CAMERAS_FILE, write_cameras
from ..robot.camera import Camera, camera_from_mujoco

if TYPE_CHECKING:
    from .scene import DemoScene


def scene_cameras(scene: DemoScene) -> dict[str, Camera]:
    """Every camera of ``scene`` (its image size), by name.

    Raises:
        ValueError: the arm's base is not at the world origin, or a camera sits in a body that
            is no URDF link.
    """
    import mujoco

    from .scene import CAMERAS

    m = scene.model
    base = m.body("base")
    if not (np.allclose(base.pos, 0.0) and np.allclose(base.quat, [1.0, 0.0, 0.0, 0.0])):
        raise ValueError("the arm's base body is not at the world origin: the world is not its base frame")
    out = {}
    for name in CAMERAS:
        cam = m.camera(name)
        body = int(m.cam_bodyid[cam.id])
        parent = None if body == 0 else f"{mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body)}_link"
        out[name] = camera_from_mujoco(m.cam_pos[cam.id], m.cam_quat[cam.id], float(m.cam_fovy[cam.id]),
                                       scene.width, scene.height, parent=parent,
                                       source=f"the demo's MuJoCo scene (camera {name!r})")
    return out


def write_scene_cameras(scene: DemoScene, session_dir: Path) -> Path:
    """Write ``scene``'s cameras as ``session_dir/cameras.json``; returns its path."""
    path = Path(session_dir) / CAMERAS_FILE
    write_cameras(path, scene_cameras(scene))
    return path
