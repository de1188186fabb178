"""Batched forward kinematics of the SO-101, in numpy.

One call computes every link pose for every timestep at once: (T, 6) joint values in -> (T, 4, 4)
transforms per link. A 540x6 rollout takes well under a millisecond, where a per-frame yourdfpy
loop takes ~100 ms. Joints are mapped by name, so the column order of the chain (shoulder_pan ..
gripper) never leaks out.

The chain is read from our URDF with the standard library: a process that only needs FK (export,
report, the app) does not pay for torch (~2 s and ~250 MB to import). Tests check every link
against pytorch-kinematics and yourdfpy, two independent parsers of the same file.
"""

from __future__ import annotations

import functools
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt

from ..units import JOINT_NAMES, Units, to_radians
from .description import BASE_LINK, GRIPPER_FRAME, urdf_path


@dataclass(frozen=True)
class ChainStep:
    """One joint of the chain: ``T_parent_link = T_parent_origin @ Rz(q)`` (Rz only if revolute).

    Attributes:
        link: the child link.
        parent: the parent link.
        column: the joint's column in :data:`JOINT_NAMES` order, or None for a fixed joint.
        T_parent_origin: (4, 4) the joint's origin in the parent link's frame [m].
    """

    link: str
    parent: str
    column: int | None
    T_parent_origin: npt.NDArray[np.float64]


class So101Kinematics:
    """Forward kinematics for the SO-101 URDF.

    Every SO-101 joint is revolute about its local z: ``T_parent_child = T_origin @ Rz(q)``, and
    right-multiplying by ``Rz(q)`` only mixes two columns, so composing the chain ourselves keeps
    a 1 M-configuration batch well under a second.

    Usage::

        fk = So101Kinematics()
        T_base_links = fk.link_poses(q_rad)           # {link: (T, 4, 4)}
        p = fk.gripper_positions(actions, Units())   # (T, 3) [m], dataset units in
    """

    def __init__(self, urdf_xml: str | None = None) -> None:
        self._steps = _parse_chain(urdf_xml if urdf_xml is not None else urdf_path().read_text())
        self.link_names: list[str] = [BASE_LINK] + [s.link for s in self._steps]
        self._root = BASE_LINK

    def link_poses(self, q_rad: npt.ArrayLike, links: tuple[str, ...] | None = None,
                   dtype: type = np.float64) -> dict[str, npt.NDArray[np.floating]]:
        """Link poses in the base frame.

        Args:
            q_rad: (T, 6) joint angles [rad] in :data:`~inspector.units.JOINT_NAMES` order.
            links: the links wanted (default: all of them); only their chains are computed.
            dtype: float64 (default, ~1e-15 m) or float32 (~1e-7 m, less memory).

        Returns:
            ``{link_name: T_base_link}``, (T, 4, 4) homogeneous transforms [m].
        """
        q: npt.NDArray[np.floating] = self._check(q_rad).astype(dtype, copy=False)
        n = q.shape[0]
        wanted = tuple(self.link_names) if links is None else links
        needed = self._ancestors(wanted)
        poses: dict[str, np.ndarray] = {self._root: np.broadcast_to(np.eye(4, dtype=dtype), (n, 4, 4))}
        for step in self._steps:
            if step.link not in needed:
                continue
            T = poses[step.parent] @ step.T_parent_origin.astype(dtype)
            if step.column is not None:
                T = _post_multiply_rz(T, q[:, step.column])
            poses[step.link] = T
        return {name: np.ascontiguousarray(poses[name]) for name in wanted}

    def gripper_frame_poses(self, q_rad: npt.ArrayLike, dtype: type = np.float64
                            ) -> npt.NDArray[np.floating]:
        """(T, 4, 4) pose of ``gripper_frame_link`` (the tool point) in the base frame [m]."""
        return self.link_poses(q_rad, links=(GRIPPER_FRAME,), dtype=dtype)[GRIPPER_FRAME]

    def gripper_positions(self, values: npt.ArrayLike, units: Units, dtype: type = np.float64
                          ) -> npt.NDArray[np.floating]:
        """(..., 3) tool-point positions [m] for (..., 6) joint values in dataset units."""
        v = np.asarray(values, np.float64)
        flat = to_radians(v.reshape(-1, v.shape[-1]), units)
        return self.link_origins(flat, GRIPPER_FRAME, dtype=dtype).reshape(*v.shape[:-1], 3)

    def link_origins(self, q_rad: npt.ArrayLike, link: str, dtype: type = np.float64
                     ) -> npt.NDArray[np.floating]:
        """(T, 3) position of ``link``'s origin in the base frame [m], without whole poses.

        The point is carried from the link back to the base: each joint is then a rotation of
        (T, 3) points about z and one constant rigid transform, a fraction of composing (T, 4, 4)
        transforms down the chain.
        """
        # (6, T) and (3, T): every per-joint operation runs over contiguous rows
        q: npt.NDArray[np.floating] = np.ascontiguousarray(self._check(q_rad).T, dtype=dtype)
        chain = self._chain_to(link)
        v: npt.NDArray[np.floating] = np.zeros((3, q.shape[1]), dtype=dtype)
        for step in reversed(chain):
            if step.column is not None:  # v <- Rz(q) v
                c, s = np.cos(q[step.column]), np.sin(q[step.column])
                x = v[0].copy()
                v[0] = c * x - s * v[1]
                v[1] = s * x + c * v[1]
            T: npt.NDArray[np.floating] = step.T_parent_origin.astype(dtype)
            v = T[:3, :3] @ v  # v <- T_origin v
            v += T[:3, 3:]
        return np.ascontiguousarray(v.T)

    def _chain_to(self, link: str) -> list[ChainStep]:
        """The steps from the base to ``link``, in order."""
        by_link = {step.link: step for step in self._steps}
        if link not in by_link:
            raise ValueError(f"link {link!r} not in the SO-101 URDF; links: {self.link_names}")
        chain = []
        while link in by_link:
            chain.append(by_link[link])
            link = by_link[link].parent
        return chain[::-1]

    def _ancestors(self, links: tuple[str, ...]) -> set[str]:
        parent = {step.link: step.parent for step in self._steps}
        out: set[str] = set()
        for link in links:
            if link not in parent and link != self._root:
                raise ValueError(f"link {link!r} not in the SO-101 URDF; links: {self.link_names}")
            while link in parent and link not in out:
                out.add(link)
                link = parent[link]
        return out

    @staticmethod
    def _check(q_rad: npt.ArrayLike) -> npt.NDArray[np.float64]:
        q = np.ascontiguousarray(q_rad, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != len(JOINT_NAMES):
            raise ValueError(f"joint angles must be (T, {len(JOINT_NAMES)}), got {q.shape}")
        return q


def _parse_chain(xml: str) -> list[ChainStep]:
    """The URDF's joints as chain steps, parents before children.

    Raises:
        ValueError: a joint type or axis this composition does not handle (our URDF has revolute
            joints about z and fixed ones only).
    """
    root = ET.fromstring(xml)
    steps: dict[str, ChainStep] = {}
    for joint in root.iter("joint"):
        name, kind = joint.get("name", ""), joint.get("type")
        parent = cast(str, joint.find("parent").get("link"))  # type: ignore[union-attr]
        child = cast(str, joint.find("child").get("link"))  # type: ignore[union-attr]
        origin = joint.find("origin")
        xyz = _floats(origin.get("xyz") if origin is not None else None)
        rpy = _floats(origin.get("rpy") if origin is not None else None)
        if kind == "fixed":
            column = None
        elif kind == "revolute":
            axis_el = joint.find("axis")
            axis = _floats(axis_el.get("xyz") if axis_el is not None else None, "1 0 0")  # URDF default x
            if not np.allclose(axis, [0, 0, 1]):
                raise ValueError(f"joint {name!r}: axis {axis.tolist()} is not z; only z axes are composed")
            column = JOINT_NAMES.index(name)
        else:
            raise ValueError(f"joint {name!r}: type {kind!r} is not handled (revolute or fixed)")
        T = np.eye(4)
        T[:3, :3] = _rpy_matrix(*rpy)
        T[:3, 3] = xyz
        steps[child] = ChainStep(child, parent, column, T)
    ordered: list[ChainStep] = []
    placed = {BASE_LINK}
    while len(ordered) < len(steps):
        ready = [s for s in steps.values() if s.parent in placed and s.link not in placed]
        if not ready:
            raise ValueError(f"links not connected to {BASE_LINK!r}: "
                             f"{sorted(set(steps) - placed)}")
        for s in ready:
            ordered.append(s)
            placed.add(s.link)
    return ordered


def _floats(text: str | None, default: str = "0 0 0") -> npt.NDArray[np.float64]:
    return np.array([float(v) for v in (text or default).split()])


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> npt.NDArray[np.float64]:
    """URDF fixed-axis roll/pitch/yaw [rad]: ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def _post_multiply_rz(T: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``T @ Rz(angle)`` for (N, 4, 4) T and (N,) angles [rad]: only columns 0 and 1 change."""
    c = np.cos(angle)[:, None]
    s = np.sin(angle)[:, None]
    out = np.array(T, copy=True)
    x, y = T[:, :, 0], T[:, :, 1]
    out[:, :, 0] = c * x + s * y
    out[:, :, 1] = c * y - s * x
    return out


@functools.lru_cache(maxsize=1)
def kinematics() -> So101Kinematics:
    """The shared :class:`So101Kinematics`."""
    return So101Kinematics()


__all__ = ["So101Kinematics", "kinematics", "BASE_LINK", "GRIPPER_FRAME"]
