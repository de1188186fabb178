"""A pinhole camera per view, and where the arm's points fall in its image.

A camera is its image size, its intrinsics ``K`` and its pose, either fixed in the robot's base
frame (``T_base_camera``: a camera on a tripod) or riding on a link (``parent`` plus
``T_parent_camera``: the SO-101 wrist camera on the gripper). Poses use OpenCV's camera axes:
x right, y down, z forward (out of the lens); lengths in metres. Pixel coordinates are OpenCV's
too: (0, 0) is the centre of the top-left pixel, u runs right, v down. No lens distortion is
modelled (the demo's cameras have none; a real one's is left in the reprojection error).

Named points of the arm (what calibration clicks and the overlays use): the origin of every URDF
link, by its URDF name, and :data:`GRIPPER_TIP`, the midpoint between the two jaw tips (the fixed
jaw's tip in ``gripper_link``, the moving jaw's in its own link, so the point follows the jaw as
it opens).

Usage::

    cam = Camera.from_dict(cameras_json["cameras"]["front"], "cameras.front")
    T_base_camera = cam.poses(fk_link_poses, n)            # (T, 4, 4)
    points = named_points(q_rad, ("gripper_tip",))         # {name: (T, 3)} [m, base frame]
    uv, depth = cam.project(points["gripper_tip"][:, None], T_base_camera)   # (T, 1, 2) [px]
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .description import BASE_LINK
from .kinematics import kinematics

GRIPPER_TIP = "gripper_tip"
JAW_LINK = "moving_jaw_so101_v1_link"
GRIPPER_LINK = "gripper_link"
# The jaw tips [m]: the lowest vertex (along the jaws, -z of gripper_link) of each jaw's mesh, the
# fixed jaw in gripper_link's frame, the moving jaw in its own link's frame (tests check both
# against the meshes).
FIXED_JAW_TIP = (-0.0089, -0.0002, -0.1044)
MOVING_JAW_TIP = (-0.0113, -0.0820, 0.0189)

MAX_IMAGE_SIDE = 16384  # [px]; no camera a dataset records is larger
MAX_FOCAL_PX = 1e6  # a focal length past this is no lens: a 1-pixel field of view at 16k pixels
# |R^T R - I| allowed in a written rotation: six decimals of each entry are enough
ROTATION_TOLERANCE = 1e-4
MAX_OFFSET_M = 100.0  # a camera this far from the arm sees nothing of it


@dataclass(frozen=True)
class Camera:
    """A pinhole camera, OpenCV axes (x right, y down, z forward).

    Attributes:
        width, height: image size [px].
        K: (3, 3) intrinsics ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` [px].
        T_base_camera: (4, 4) the camera's pose in the robot's base frame [m], or None when it
            rides on ``parent``.
        parent: the URDF link the camera is fixed to, or None for a fixed camera.
        T_parent_camera: (4, 4) its pose in ``parent``'s frame [m] (None for a fixed camera).
        source: where the camera came from (free text: "MuJoCo model ...", "inspector calibrate").
    """

    width: int
    height: int
    K: npt.NDArray[np.float64]
    T_base_camera: npt.NDArray[np.float64] | None = None
    parent: str | None = None
    T_parent_camera: npt.NDArray[np.float64] | None = None
    source: str = ""

    @property
    def is_fixed(self) -> bool:
        return self.parent is None

    def poses(self, link_poses: Mapping[str, npt.NDArray[np.floating]] | None, n: int) -> npt.NDArray[np.float64]:
        """(n, 4, 4) ``T_base_camera`` at each of ``n`` frames.

        Args:
            link_poses: ``{link: (n, 4, 4)}`` from :meth:`So101Kinematics.link_poses`, holding
                ``parent`` (unused, may be None, for a fixed camera).
            n: the number of frames.
        """
        if self.T_base_camera is not None:
            return np.broadcast_to(self.T_base_camera, (n, 4, 4))
        assert self.parent is not None and self.T_parent_camera is not None
        if link_poses is None or self.parent not in link_poses:
            raise ValueError(f"the camera rides on {self.parent!r}: its poses are needed")
        return np.asarray(link_poses[self.parent], np.float64) @ self.T_parent_camera

    def project(self, points_base: npt.ArrayLike, T_base_camera: npt.ArrayLike
                ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Pixels of points given in the base frame.

        Args:
            points_base: (..., N, 3) points [m]; leading axes broadcast against the poses'.
            T_base_camera: (..., 4, 4) camera poses (from :meth:`poses`, or one (4, 4)).

        Returns:
            (uv, depth): (..., N, 2) pixel coordinates [px] and (..., N) depth along the optical
            axis [m]. A point at or behind the camera (depth <= 0) gets NaN pixels.
        """
        p_cam = to_camera(points_base, T_base_camera)
        return self.pixels(p_cam), p_cam[..., 2]

    def pixels(self, p_cam: npt.NDArray[np.floating]) -> npt.NDArray[np.float64]:
        """(..., N, 2) pixels of (..., N, 3) points in the camera frame (NaN at depth <= 0)."""
        z = p_cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(z > 0, 1.0 / z, np.nan)
        u = self.K[0, 0] * p_cam[..., 0] * inv + self.K[0, 1] * p_cam[..., 1] * inv + self.K[0, 2]
        v = self.K[1, 1] * p_cam[..., 1] * inv + self.K[1, 2]
        return np.stack([u, v], axis=-1)

    def to_dict(self) -> dict[str, Any]:
        """The camera as ``cameras.json`` holds it (see docs/formats.md)."""
        out: dict[str, Any] = {"width": self.width, "height": self.height, "K": _rows(self.K)}
        if self.T_base_camera is not None:
            out["T_base_camera"] = _rows(self.T_base_camera)
        else:
            out["parent"] = self.parent
            out["T_parent_camera"] = _rows(self.T_parent_camera)
        if self.source:
            out["source"] = self.source
        return out

    @classmethod
    def from_dict(cls, data: object, where: str = "camera") -> Camera:
        """A camera from its ``cameras.json`` entry, every field checked.

        Raises:
            ValueError: ``"<where>.<field>: <what is wrong>"``, one line.
        """
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected an object, found {type(data).__name__}")
        known = {"width", "height", "K", "T_base_camera", "parent", "T_parent_camera", "source"}
        unknown = sorted(str(k) for k in data if k not in known)
        if unknown:
            raise ValueError(f"{where}: unknown field {unknown[0][:80]!r}; fields: {sorted(known)}")
        width = _side(data.get("width"), f"{where}.width")
        height = _side(data.get("height"), f"{where}.height")
        K = _intrinsics(data.get("K"), f"{where}.K")
        source = data.get("source", "")
        if not isinstance(source, str) or len(source) > 1000:
            raise ValueError(f"{where}.source: expected a string of at most 1000 characters")
        fixed, riding = "T_base_camera" in data, "parent" in data or "T_parent_camera" in data
        if fixed == riding:
            raise ValueError(f"{where}: give either T_base_camera (a fixed camera) or parent and "
                             "T_parent_camera (a camera on a link), not " + ("both" if fixed else "neither"))
        if fixed:
            return cls(width, height, K, T_base_camera=_pose(data["T_base_camera"], f"{where}.T_base_camera"),
                       source=source)
        parent = data.get("parent")
        links = kinematics().link_names
        if not isinstance(parent, str) or parent not in links:
            raise ValueError(f"{where}.parent: expected a URDF link name, found {_shown(parent)}; links: {links}")
        if "T_parent_camera" not in data:
            raise ValueError(f"{where}: missing field 'T_parent_camera'")
        return cls(width, height, K, parent=parent,
                   T_parent_camera=_pose(data["T_parent_camera"], f"{where}.T_parent_camera"), source=source)


def to_camera(points_base: npt.ArrayLike, T_base_camera: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """(..., N, 3) points [m, base frame] -> the camera frame, for (..., 4, 4) camera poses."""
    p = np.asarray(points_base, np.float64)
    T = np.asarray(T_base_camera, np.float64)
    R, t = T[..., :3, :3], T[..., :3, 3]
    # p_cam = R^T (p - t), as (..., N, 3) @ (..., 3, 3)
    return (p - t[..., None, :]) @ R


def intrinsics_from_fovy(fovy_deg: float, width: int, height: int) -> npt.NDArray[np.float64]:
    """(3, 3) K of square pixels with a vertical field of view ``fovy_deg``, centred.

    The principal point is the image centre in OpenCV's pixel-centre convention,
    ``((width - 1) / 2, (height - 1) / 2)``: an OpenGL (MuJoCo) image spans [0, width] in pixel
    edges, its centre at width / 2, which is pixel (width - 1) / 2.
    """
    f = (height / 2.0) / math.tan(math.radians(fovy_deg) / 2.0)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


# A MuJoCo camera looks along its -z with +y up; OpenCV's looks along +z with y down.
_MUJOCO_TO_OPENCV = np.diag([1.0, -1.0, -1.0])


def camera_from_mujoco(pos: Sequence[float], quat_wxyz: Sequence[float], fovy_deg: float, width: int,
                       height: int, parent: str | None = None, source: str = "") -> Camera:
    """A MuJoCo camera (``model.cam_pos``, ``cam_quat``, ``cam_fovy``) as a :class:`Camera`.

    Args:
        pos, quat_wxyz: the camera in its body's frame (the world for a world camera) [m].
        fovy_deg: vertical field of view [deg].
        width, height: the rendered image size [px].
        parent: the URDF link of the MuJoCo body the camera sits in, or None for the world (the
            arm's base frame when the arm's base sits at the world origin, as in the demo).
    """
    T = np.eye(4)
    T[:3, :3] = quat_matrix(quat_wxyz) @ _MUJOCO_TO_OPENCV
    T[:3, 3] = pos
    K = intrinsics_from_fovy(fovy_deg, width, height)
    if parent is None:
        return Camera(width, height, K, T_base_camera=T, source=source)
    return Camera(width, height, K, parent=parent, T_parent_camera=T, source=source)


def quat_matrix(quat_wxyz: Sequence[float]) -> npt.NDArray[np.float64]:
    """(3, 3) rotation of a unit quaternion (w, x, y, z), MuJoCo's order."""
    w, x, y, z = np.asarray(quat_wxyz, np.float64) / np.linalg.norm(quat_wxyz)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def point_names() -> list[str]:
    """Every named point of the arm: the URDF's links, then :data:`GRIPPER_TIP`."""
    return [*kinematics().link_names, GRIPPER_TIP]


def named_points(q_rad: npt.ArrayLike, names: Sequence[str]) -> dict[str, npt.NDArray[np.float64]]:
    """Positions of named points of the arm in the base frame.

    Args:
        q_rad: (T, 6) joint angles [rad], :data:`~inspector.units.JOINT_NAMES` order.
        names: URDF link names (their origins) and/or :data:`GRIPPER_TIP`.

    Returns:
        ``{name: (T, 3)}`` [m].

    Raises:
        ValueError: an unknown name (the message lists the known ones).
    """
    fk = kinematics()
    unknown = [n for n in names if n not in fk.link_names and n != GRIPPER_TIP]
    if unknown:
        raise ValueError(f"unknown point {unknown[0]!r}; points: {point_names()}")
    links = {n for n in names if n != GRIPPER_TIP}
    if GRIPPER_TIP in names:
        links |= {GRIPPER_LINK, JAW_LINK}
    poses = fk.link_poses(q_rad, links=tuple(sorted(links)))
    out = {n: poses[n][:, :3, 3].copy() for n in names if n != GRIPPER_TIP}
    if GRIPPER_TIP in names:
        fixed = _apply(poses[GRIPPER_LINK], FIXED_JAW_TIP)
        moving = _apply(poses[JAW_LINK], MOVING_JAW_TIP)
        out[GRIPPER_TIP] = (fixed + moving) / 2
    return out


def _apply(T: npt.NDArray[np.floating], point: Sequence[float]) -> npt.NDArray[np.float64]:
    return np.asarray(T[:, :3, :3] @ np.asarray(point, np.float64) + T[:, :3, 3], np.float64)


# ---------------------------------------------------------------------------------------------
# Checking a camera's fields


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else f"{text[:57]}..."


def _side(value: object, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_IMAGE_SIDE:
        raise ValueError(f"{where}: expected a whole number of pixels from 1 to {MAX_IMAGE_SIDE}, found {_shown(value)}")
    return value


def _matrix(value: object, rows: int, cols: int, where: str) -> npt.NDArray[np.float64]:
    """A (rows, cols) list of lists of finite numbers (no bools), as float64."""
    ok = (isinstance(value, list) and len(value) == rows
          and all(isinstance(r, list) and len(r) == cols for r in value))
    if not ok:
        raise ValueError(f"{where}: expected {rows} rows of {cols} numbers, found {_shown(value)}")
    assert isinstance(value, list)
    for i, row in enumerate(value):
        for j, x in enumerate(row):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise ValueError(f"{where}[{i}][{j}]: expected a number, found {_shown(x)}")
            if isinstance(x, int) and abs(x) > 1e15 or not math.isfinite(x):
                raise ValueError(f"{where}[{i}][{j}]: expected a finite number of reasonable size, found {_shown(x)}")
    return np.array(value, np.float64)


def _intrinsics(value: object, where: str) -> npt.NDArray[np.float64]:
    K = _matrix(value, 3, 3, where)
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise ValueError(f"{where}: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]], found {K.tolist()}")
    for name, f in (("fx", K[0, 0]), ("fy", K[1, 1])):
        if not 0 < f <= MAX_FOCAL_PX:
            raise ValueError(f"{where}: {name} must be more than 0 and at most {MAX_FOCAL_PX:g} px, found {f:g}")
    if max(abs(K[0, 1]), abs(K[0, 2]), abs(K[1, 2])) > MAX_FOCAL_PX:
        raise ValueError(f"{where}: the skew and principal point must lie within {MAX_FOCAL_PX:g} px")
    return K


def _pose(value: object, where: str) -> npt.NDArray[np.float64]:
    T = _matrix(value, 4, 4, where)
    if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{where}: the last row must be [0, 0, 0, 1], found {T[3].tolist()}")
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
        raise ValueError(f"{where}: the upper-left 3x3 is not a rotation (orthonormal, determinant +1)")
    if np.abs(T[:3, 3]).max() > MAX_OFFSET_M:
        raise ValueError(f"{where}: a translation past {MAX_OFFSET_M:g} m")
    return T


def _rows(M: npt.NDArray[np.float64] | None) -> list[list[float]]:
    assert M is not None
    # 9 significant digits: below a micrometre and a millipixel, and short enough to read
    return [[float(f"{x:.9g}") + 0.0 for x in row] for row in M]


__all__ = ["Camera", "GRIPPER_TIP", "BASE_LINK", "camera_from_mujoco", "intrinsics_from_fovy", "named_points",
           "point_names", "quat_matrix", "to_camera"]
