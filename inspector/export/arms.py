"""The GT and predicted SO-101 arms in a recording: URDF trees, joint transforms, tool-point paths.

Both arms come from our URDF through ``rerun.urdf.UrdfTree``: the visual meshes are swapped for
decimated copies (:mod:`inspector.robot.meshes`) and each copy gets its own robot name, entity
prefix and frame prefix (``gt/``, ``pred/``) so the two trees never share a frame. The tree's
geometry is logged once (static); every revolute joint's transform is then sent for all steps at
once with ``send_columns``, computed by the tree from the joint angles, never clamped (a joint
past its limit is shown past it). The fixed joints are logged once, static, and each tree's root
is tied to the 3D view's frame.
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import cast

import numpy as np
import numpy.typing as npt
import rerun as rr

from ..analysis.timeline import RolloutTimeline
from ..errors import InspectorError
from ..robot.description import resolved_urdf_text, urdf_path
from ..robot.kinematics import kinematics
from ..robot.meshes import decimated_mesh
from ..units import JOINT_NAMES, to_radians
from . import layout as L

_MESH = re.compile(r'<mesh filename="([^"]+)"')
_MATERIAL = re.compile(r'(<material name="([^"]*)">\s*<color rgba=")([^"]+)(")')
_ROBOT = re.compile(r'<robot name="[^"]*"')


def prepare_meshes() -> None:
    """Make (or find) the decimated copies of the arm's meshes, as :func:`arm_urdf_text` will.

    The first export on a machine decimates ~320k triangles (~0.7 s of numpy and C); an export
    runs this beside its video metrics, whose decoder threads leave a core idle part of the time.
    """
    for m in _MESH.finditer(resolved_urdf_text()[0]):
        decimated_mesh(m.group(1))


def arm_urdf_text(arm: str, xml: str | None = None, decimate: bool = True) -> str:
    """Our URDF for one arm: decimated meshes, robot named ``<arm>_arm``, prediction recoloured.

    Args:
        arm: ``"gt"`` or ``"pred"``.
        xml: the resolved URDF (default :func:`inspector.robot.description.resolved_urdf_text`).
        decimate: swap meshes for their decimated cached copies.
    """
    xml = xml if xml is not None else resolved_urdf_text()[0]
    if decimate:
        xml = _MESH.sub(lambda m: f'<mesh filename="{decimated_mesh(m.group(1))}"', xml)
    xml = _ROBOT.sub(f'<robot name="{L.arm_robot_name(arm)}"', xml, count=1)
    if arm == "pred":
        def recolour(m: re.Match[str]) -> str:
            rgba = L.PRED_MESH_RGBA.get(m.group(2), L.PRED_MESH_DEFAULT)
            return m.group(1) + " ".join(f"{c:g}" for c in rgba) + m.group(4)

        xml = _MATERIAL.sub(recolour, xml)
    return xml


def log_arm(rec: rr.RecordingStream, arm: str, q_rad: npt.NDArray[np.float64],
            indexes: Sequence[rr.TimeColumn], work_dir: Path) -> rr.urdf.UrdfTree:
    """Log one arm's geometry (static) and its joint transforms over time.

    Args:
        arm: ``"gt"`` or ``"pred"``.
        q_rad: (T, 6) joint angles [rad] in :data:`JOINT_NAMES` order, one row per index entry.
        indexes: the timeline columns of the T steps.
        work_dir: where the arm's URDF variant is written for the tree to read.
    """
    path = work_dir / f"{L.arm_robot_name(arm)}.urdf"
    path.write_text(arm_urdf_text(arm))
    tree = rr.urdf.UrdfTree.from_file_path(path, entity_path_prefix=L.WORLD,
                                           frame_prefix=L.arm_frame_prefix(arm))
    rec.send_chunks(tree.stream(include_joint_transforms=False))
    root = L.arm_frame_prefix(arm) + tree.root_link().name
    rec.log(L.joint_transform_path(arm, "mount"),
            rr.Transform3D(parent_frame=L.WORLD_FRAME, child_frame=root), static=True)
    for joint in tree.joints():
        entity = L.joint_transform_path(arm, joint.name)
        if joint.joint_type == "fixed":
            rec.log(entity, joint.compute_transform(0.0, clamp=False), static=True)
            continue
        if joint.name not in JOINT_NAMES:
            raise InspectorError(urdf_path(), f"joint {joint.name!r} is not one of {list(JOINT_NAMES)}")
        column = q_rad[:, JOINT_NAMES.index(joint.name)]
        # rerun reads the values with list(values): an array does as well as a sequence
        rec.send_columns(entity, indexes, joint.compute_transform_columns(cast(Sequence[float], column), clamp=False))
    return tree


def log_arms(rec: rr.RecordingStream, tl: RolloutTimeline, indexes: Sequence[rr.TimeColumn]) -> None:
    """Both arms (the GT one only when GT joints exist), their tool-point paths and markers."""
    rec.log(L.WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)  # the URDF's base frame
    with tempfile.TemporaryDirectory(prefix="inspector-urdf-") as tmp:
        log_arm(rec, "pred", to_radians(tl.pred, tl.units), indexes, Path(tmp))
        if tl.gt_aligned is not None:
            log_arm(rec, "gt", to_radians(tl.gt_aligned, tl.units), indexes, Path(tmp))
    log_tool_paths(rec, tl, indexes)
    log_chunk_trails(rec, tl)


def log_tool_paths(rec: rr.RecordingStream, tl: RolloutTimeline, indexes: Sequence[rr.TimeColumn]) -> None:
    """Whole tool-point paths (static), the tool point now, and where joint limits are broken."""
    paths = [("pred", tl.ee_pred, L.PRED_RGBA)]
    if tl.ee_gt is not None:
        paths.append(("gt", tl.ee_gt, L.GT_RGBA))
    for arm, ee, rgba in paths:
        rec.log(L.ee_path(arm), rr.LineStrips3D([ee], colors=[rgba], radii=0.002,
                                                labels=[f"{tl.labels.gt if arm == 'gt' else tl.labels.pred} tool path"]),
                static=True)
        rec.log(L.ee_now(arm), rr.Points3D.from_fields(colors=[rgba], radii=0.008), static=True)
        rec.send_columns(L.ee_now(arm), indexes, rr.Points3D.columns(positions=ee))
    bad = tl.limit_violation.any(axis=1)
    if bad.any():
        rec.log(L.LIMITS_3D, rr.Points3D(tl.ee_pred[bad], colors=[L.LIMIT_RGBA], radii=0.0025), static=True)


def log_chunk_trails(rec: rr.RecordingStream, tl: RolloutTimeline) -> None:
    """Each chunk's full predicted horizon as a line, shown from the chunk's first step on."""
    n, h, _ = tl.chunks.shape
    ee = kinematics().gripper_positions(tl.chunks.reshape(n * h, -1), tl.units).reshape(n, h, 3)
    starts = np.minimum(tl.chunk_start_step, tl.n_steps - 1)
    rec.log(L.CHUNK_TRAIL, rr.LineStrips3D.from_fields(colors=[(120, 200, 255, 255)], radii=0.0015),
            static=True)
    rec.send_columns(L.CHUNK_TRAIL, L.step_indexes(tl, starts, chunks=np.arange(n)),
                     rr.LineStrips3D.columns(strips=list(ee)))

