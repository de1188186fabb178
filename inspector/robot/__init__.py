"""The SO-101: its URDF (``description``), batched forward kinematics (``kinematics``), decimated meshes
(``meshes``), and the arm seen through a camera (``camera``, ``silhouette``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "RobotModel": ".description",
    "load_urdf": ".description",
    "resolved_urdf_text": ".description",
    "urdf_path": ".description",
    "bounding_sphere": ".description",
    "So101Kinematics": ".kinematics",
    "decimated_mesh": ".meshes",
    "Camera": ".camera",
    "named_points": ".camera",
    "arm_mesh": ".silhouette",
    "arm_masks": ".silhouette",
})

if TYPE_CHECKING:
    from .camera import Camera as Camera
    from .camera import named_points as named_points
    from .description import RobotModel as RobotModel
    from .description import bounding_sphere as bounding_sphere
    from .description import load_urdf as load_urdf
    from .description import resolved_urdf_text as resolved_urdf_text
    from .description import urdf_path as urdf_path
    from .kinematics import So101Kinematics as So101Kinematics
    from .meshes import decimated_mesh as decimated_mesh
    from .silhouette import arm_masks as arm_masks
    from .silhouette import arm_mesh as arm_mesh
