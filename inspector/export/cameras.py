"""Each view with a camera as a Pinhole in the recording's 3D scene, its videos under it.

Rerun draws what a pinhole sees: with a view's imagined and GT frames logged under its camera,
a 2D view of the camera shows the arms of the 3D scene projected into those frames by the viewer
itself, and the 3D view shows the camera's frustum with the frame in it::

    /world/cameras/<view>             Transform3D (the camera in the base frame) + Pinhole
    /world/cameras/<view>/imagined    VideoFrameReference -> /video/<view>/imagined
    /world/cameras/<view>/gt          VideoFrameReference -> /video/<view>/gt

A fixed camera's pose is static; a camera riding on a link (the SO-101 wrist camera) follows the
predicted arm's link, one pose a step (the imagined video is what the predicted arm's camera
would see). The references point at the video assets the recording already holds
(:mod:`inspector.export.video`): nothing is encoded twice.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import rerun as rr

from ..analysis.camera_measures import cameras_of
from ..analysis.timeline import RolloutTimeline
from ..robot.camera import Camera
from ..robot.kinematics import kinematics
from ..units import to_radians
from . import layout as L

CAMERAS = f"{L.WORLD}/cameras"
IMAGE_PLANE_M = 0.08  # how far from the lens the 3D view draws a camera's frame [m]


def camera_path(view: str) -> str:
    """The entity of ``view``'s camera (its Transform3D and Pinhole)."""
    return f"{CAMERAS}/{view}"


def camera_video_path(view: str, source: str) -> str:
    """The frame references of ``view``'s ``imagined`` or ``gt`` video under its camera."""
    return f"{camera_path(view)}/{source}"


def recording_cameras(tl: RolloutTimeline, views: Sequence[str]) -> dict[str, Camera]:
    """The cameras of the exported views (none where the session has no ``cameras.json``, or a bad
    one: the recording is written without them)."""
    cameras, _ = cameras_of(tl.rollout.session)
    return {v: cameras[v] for v in views if v in cameras}


def log_camera(rec: rr.RecordingStream, tl: RolloutTimeline, view: str, camera: Camera,
               steps_indexes: Callable[[np.ndarray], list[rr.TimeColumn]]) -> None:
    """``view``'s camera: its pose (static, or per step for a riding camera) and its pinhole."""
    entity = camera_path(view)
    rec.log(entity, rr.Pinhole(image_from_camera=camera.K, resolution=[camera.width, camera.height],
                               camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=IMAGE_PLANE_M), static=True)
    if camera.T_base_camera is not None:
        T = camera.T_base_camera
        rec.log(entity, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=True)
        return
    assert camera.parent is not None
    q = to_radians(tl.pred, tl.units)
    poses = camera.poses(kinematics().link_poses(q, links=(camera.parent,)), len(q))
    rec.send_columns(entity, steps_indexes(np.arange(tl.n_steps)),
                     rr.Transform3D.columns(translation=poses[:, :3, 3], mat3x3=poses[:, :3, :3]))


def log_camera_frames(rec: rr.RecordingStream, view: str, source: str, indexes: Sequence[rr.TimeColumn],
                      timestamps_ns: np.ndarray) -> None:
    """References to the frames of the ``source`` video asset of ``view``, under its camera."""
    entity = camera_video_path(view, source)
    rec.log(entity, rr.VideoFrameReference.from_fields(video_reference=L.video_path(view, source)), static=True)
    rec.send_columns(entity, indexes, rr.VideoFrameReference.columns_nanos(timestamps_ns))


__all__ = ["CAMERAS", "camera_path", "camera_video_path", "log_camera", "log_camera_frames", "recording_cameras"]
