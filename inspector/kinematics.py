"""Batched forward kinematics of the SO-101 (chain parsed by pytorch-kinematics).

One call computes every link pose for every timestep at once: (T, 6) joint values in -> (T, 4, 4)
transforms per link. A 540x6 rollout takes about a millisecond on a CPU, where a per-frame yourdfpy
loop takes ~100x longer. Joints are mapped by name, so the column order of the chain (shoulder_pan
.. gripper) never leaks out.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt
import torch

from .robot import BASE_LINK, GRIPPER_FRAME, resolved_urdf_text
from .units import JOINT_NAMES, Units, to_radians


class So101Kinematics:
    """Forward kinematics for the SO-101 URDF.

    pytorch-kinematics parses the URDF into a chain; we then compose that chain ourselves, because
    every SO-101 joint is revolute about its local z: ``T_parent_child = T_origin @ Rz(q)``, and
    right-multiplying by ``Rz(q)`` only mixes two columns. That keeps a 1 M-configuration batch
    well under a second, where the generic per-frame transform objects take ~10 s.

    Usage::

        fk = So101Kinematics()
        T_base_links = fk.link_poses(q_rad)           # {link: (T, 4, 4)}
        p = fk.gripper_positions(actions, Units())   # (T, 3) [m], dataset units in
    """

    def __init__(self) -> None:
        import pytorch_kinematics as pk

        xml, _ = resolved_urdf_text()
        chain = pk.build_chain_from_urdf(xml.encode()).to(dtype=torch.float64)
        # (link, parent link, joint column in JOINT_NAMES order or None if fixed, T_parent_origin)
        self._steps: list[tuple[str, str, int | None, torch.Tensor]] = []

        def walk(frame, parent: str | None) -> None:
            if parent is not None:
                T_origin = frame.joint.offset.get_matrix()[0] if frame.joint.offset else torch.eye(4)
                if frame.link.offset is not None:
                    T_origin = T_origin @ frame.link.offset.get_matrix()[0]
                column = JOINT_NAMES.index(frame.joint.name) if frame.joint.joint_type != "fixed" else None
                self._steps.append((frame.link.name, parent, column, T_origin.to(torch.float64)))
            for child in frame.children:
                walk(child, frame.link.name)

        walk(chain._root, None)
        self.link_names: list[str] = [BASE_LINK] + [s[0] for s in self._steps]
        self._root = chain._root.link.name

    def link_poses(self, q_rad: npt.ArrayLike, links: tuple[str, ...] | None = None,
                   dtype: torch.dtype = torch.float64) -> dict[str, npt.NDArray[np.floating]]:
        """Link poses in the base frame.

        Args:
            q_rad: (T, 6) joint angles [rad] in :data:`~inspector.units.JOINT_NAMES` order.
            links: the links wanted (default: all of them); only their chains are computed.
            dtype: float64 (default, ~1e-15 m) or float32 (~1e-7 m, twice the throughput).

        Returns:
            ``{link_name: T_base_link}``, (T, 4, 4) homogeneous transforms [m].
        """
        q = self._check(q_rad)
        th = torch.from_numpy(q).to(dtype)
        n = th.shape[0]
        wanted = tuple(self.link_names) if links is None else links
        needed = self._ancestors(wanted)
        poses: dict[str, torch.Tensor] = {self._root: torch.eye(4, dtype=dtype).expand(n, 4, 4)}
        for link, parent, column, T_origin in self._steps:
            if link not in needed:
                continue
            T = poses[parent] @ T_origin.to(dtype)
            if column is not None:
                T = _post_multiply_rz(T, th[:, column])
            poses[link] = T
        return {name: poses[name].numpy() for name in wanted}

    def gripper_frame_poses(self, q_rad: npt.ArrayLike, dtype: torch.dtype = torch.float64
                            ) -> npt.NDArray[np.floating]:
        """(T, 4, 4) pose of ``gripper_frame_link`` (the tool point) in the base frame [m]."""
        return self.link_poses(q_rad, links=(GRIPPER_FRAME,), dtype=dtype)[GRIPPER_FRAME]

    def gripper_positions(self, values: npt.ArrayLike, units: Units, dtype: torch.dtype = torch.float64
                          ) -> npt.NDArray[np.floating]:
        """(T, 3) tool-point positions [m] for (T, 6) joint values in dataset units."""
        return self.link_origins(to_radians(values, units), GRIPPER_FRAME, dtype=dtype)

    def link_origins(self, q_rad: npt.ArrayLike, link: str, dtype: torch.dtype = torch.float64
                     ) -> npt.NDArray[np.floating]:
        """(T, 3) position of ``link``'s origin in the base frame [m], without whole poses.

        The point is carried from the link back to the base: each joint is then a rotation of
        (T, 4) vectors about z and one constant 4x4 product, a fraction of composing (T, 4, 4)
        transforms down the chain.
        """
        q = torch.from_numpy(self._check(q_rad)).to(dtype)
        chain = self._chain_to(link)
        v = torch.zeros((q.shape[0], 4), dtype=dtype)
        v[:, 3] = 1.0
        for _, _, column, T_origin in reversed(chain):
            if column is not None:  # v <- Rz(q) v
                c, s = torch.cos(q[:, column]), torch.sin(q[:, column])
                x, y = v[:, 0].clone(), v[:, 1]
                v[:, 0] = c * x - s * y
                v[:, 1] = s * x + c * y
            v = v @ T_origin.to(dtype).T  # v <- T_origin v
        return v[:, :3].numpy()

    def _chain_to(self, link: str) -> list[tuple[str, str, int | None, torch.Tensor]]:
        """The steps from the base to ``link``, in order."""
        by_link = {step[0]: step for step in self._steps}
        if link not in by_link:
            raise ValueError(f"link {link!r} not in the SO-101 URDF; links: {self.link_names}")
        chain = []
        while link in by_link:
            chain.append(by_link[link])
            link = by_link[link][1]
        return chain[::-1]

    def _ancestors(self, links: tuple[str, ...]) -> set[str]:
        parent = {link: par for link, par, _, _ in self._steps}
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


def _post_multiply_rz(T: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """``T @ Rz(angle)`` for (N, 4, 4) T and (N,) angles [rad]: only columns 0 and 1 change."""
    c = torch.cos(angle)[:, None]
    s = torch.sin(angle)[:, None]
    x, y = T[:, :, 0], T[:, :, 1]
    return torch.stack([c * x + s * y, c * y - s * x, T[:, :, 2], T[:, :, 3]], dim=2)


@functools.lru_cache(maxsize=1)
def kinematics() -> So101Kinematics:
    """The shared :class:`So101Kinematics` (building the chain takes ~50 ms)."""
    return So101Kinematics()


__all__ = ["So101Kinematics", "kinematics", "BASE_LINK", "GRIPPER_FRAME"]
