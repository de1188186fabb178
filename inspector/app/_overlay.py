"""The arms drawn into the frames: the predicted arm (orange) and the GT arm (grey) over each view
with a camera, and the imagined gripper's track beside where the predicted joints put it.

The overlay is a transparent PNG laid over the frame in the page (the frame's JPEG stays as it
is cached): the two arms' silhouettes, half transparent, with their outlines, through the view's
camera scaled to the display size (a camera riding on a link is posed by the joints of the arm it
draws, so the wrist view shows each arm's jaws as its own camera would). Over the imagined frame,
two rings: the projected predicted ``gripper_link`` (orange) and the gripper tracked through the
imagined video (cyan; :mod:`inspector.analysis.gripper_track`), fed by the pass that decodes the
frames for the cache, so the track costs no decode of its own.

Drawing a view's overlay at a step costs two silhouettes and two small PNGs, drawn at half the
display size (the page scales the overlay onto the frame): ~6 ms a step at 320x240 (docs/app.md);
the last few hundred are kept, so scrubbing back and forth draws each once.
"""

from __future__ import annotations

import base64
import io
import threading
from collections import OrderedDict
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from ..analysis.camera_measures import (
    TRACKED_POINT,
    SurfacePoint,
    cameras_of,
    gripper_surface,
    project_point,
    scaled_camera,
)
from ..analysis.gripper_track import GripperTracker
from ..analysis.timeline import RolloutTimeline
from ..robot.camera import Camera
from ..robot.silhouette import arm_masks, arm_mesh, outline
from ..units import to_radians

PRED_RGB = (232, 89, 12)  # the predicted arm's orange, as in the 3D scene and the captions
GT_RGB = (134, 142, 150)  # the GT arm's grey
TRACK_RGB = (21, 170, 191)  # the tracked imagined gripper
FILL_ALPHA = 96  # of 255: the frame shows through the silhouettes
KEPT_OVERLAYS = 512
HALF_SIZE_FROM_ROWS = 160  # frames shown this tall get their overlay drawn at half size


def _png_data_uri(rgba: npt.NDArray[np.uint8]) -> str:
    from PIL import Image

    buf = io.BytesIO()
    # level 1: a mostly transparent image compresses well at once; higher levels cost 3x the time
    Image.fromarray(rgba, "RGBA").save(buf, format="PNG", compress_level=1)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _paint(rgba: npt.NDArray[np.uint8], mask: npt.NDArray[np.bool_], rgb: tuple[int, int, int]) -> None:
    """A half-transparent silhouette with an opaque outline."""
    rgba[mask, :3] = rgb
    rgba[mask, 3] = FILL_ALPHA
    edge = outline(mask)
    rgba[edge, :3] = rgb
    rgba[edge, 3] = 255


def _ring(rgba: npt.NDArray[np.uint8], uv: npt.NDArray[np.float64], rgb: tuple[int, int, int], radius: float) -> None:
    """A ring of ``radius`` px (2 px thick) around ``uv``; nothing for a point off the image."""
    if not np.isfinite(uv).all():
        return
    h, w = rgba.shape[:2]
    r0, r1 = max(0, int(uv[1] - radius - 2)), min(h, int(uv[1] + radius + 3))
    c0, c1 = max(0, int(uv[0] - radius - 2)), min(w, int(uv[0] + radius + 3))
    if r0 >= r1 or c0 >= c1:
        return
    yy, xx = np.mgrid[r0:r1, c0:c1]
    d = np.hypot(xx - uv[0], yy - uv[1])
    on = np.abs(d - radius) <= 1.0
    block = rgba[r0:r1, c0:c1]
    block[on, :3] = rgb
    block[on, 3] = 255


class ArmOverlay:
    """The overlays of one rollout's views with a camera (shared by every tab that shows it).

    Args:
        tl: the rollout's timeline.
        cameras: its session's cameras by view.
    """

    def __init__(self, tl: RolloutTimeline, cameras: dict[str, Camera]) -> None:
        self.tl = tl
        self.cameras = cameras
        self._mesh = arm_mesh()
        self._lock = threading.Lock()
        self._kept: OrderedDict[tuple, tuple[str, str]] = OrderedDict()
        self._pred_q = to_radians(tl.pred, tl.units) if tl.has_joints else None
        self._gt_q = to_radians(tl.gt_aligned, tl.units) if tl.gt_aligned is not None else None
        self._trackers: dict[str, GripperTracker] = {}
        self._track_size: dict[str, tuple[int, int]] = {}
        self._points: dict[str, SurfacePoint] = {}

    @classmethod
    def of(cls, tl: RolloutTimeline) -> ArmOverlay | None:
        """The rollout's overlay, or None where its session has no camera (or a bad cameras.json:
        the rollout still opens, without the overlay)."""
        cameras, _ = cameras_of(tl.rollout.session)
        views = set(tl.rollout.views) | set(tl.gt.views)
        cameras = {v: c for v, c in cameras.items() if v in views}
        return cls(tl, cameras) if cameras else None

    # -- the gripper's track, fed by the frame fill ------------------------------------------
    def tracker_feed(self, view: str) -> Callable[[int, npt.NDArray[np.uint8]], None] | None:
        """What the frame fill calls with each imagined frame ``(f, rgb)`` of ``view``, to track
        its gripper (None: nothing to track there: no fixed camera, or no joints to start from)."""
        camera = self.cameras.get(view)
        if camera is None or not camera.is_fixed or self._gt_q is None or self._pred_q is None:
            return None
        gt_q = self._gt_q

        def feed(f: int, rgb: npt.NDArray[np.uint8]) -> None:
            tracker = self._trackers.get(view)
            if tracker is None or f == 0:
                size = (rgb.shape[1], rgb.shape[0])
                start = project_point(scaled_camera(camera, size), gt_q[:1], self._point(view))[0]
                tracker = self._trackers[view] = GripperTracker(start, size)
                self._track_size[view] = size
            tracker.add(rgb)
        return feed

    def _point(self, view: str) -> SurfacePoint:
        """The point on the arm the gripper's track follows in ``view`` (as the report's)."""
        point = self._points.get(view)
        if point is None:
            point = (TRACKED_POINT, np.zeros(3)) if self._gt_q is None else gripper_surface(self.cameras[view], self._gt_q[0])
            self._points[view] = point
        return point

    def track(self, view: str) -> tuple[npt.NDArray[np.float64], tuple[int, int]] | None:
        """(F, 2) the tracked gripper of ``view`` so far [px, at the decoded size] and that size."""
        tracker = self._trackers.get(view)
        return None if tracker is None else (tracker.result(), self._track_size[view])

    def distance_series(self, view: str) -> npt.NDArray[np.float64] | None:
        """(T,) per step, the pixel distance between the tracked and the projected predicted
        gripper (NaN once the track is lost, or where no frame shows the step)."""
        known = self.track(view)
        if known is None or self._pred_q is None:
            return None
        tracked, size = known
        tl = self.tl
        projected = project_point(scaled_camera(self.cameras[view], size), self._pred_q, self._point(view))
        frame_of = np.array([tl.frame_index(s) for s in range(tl.n_steps)])
        out = np.full(tl.n_steps, np.nan)
        ok = frame_of < len(tracked)
        lost = ~np.isfinite(tracked).all(axis=1)
        if lost.any():
            tracked = tracked.copy()
            tracked[int(np.argmax(lost)):] = np.nan  # a lost track has no distance from there on
        out[ok] = np.hypot(*(tracked[frame_of[ok]] - projected[ok]).T)
        return out

    # -- drawing ------------------------------------------------------------------------------
    def uris(self, view: str, step: int, frame: int, size: tuple[int, int]) -> tuple[str, str] | None:
        """(over the imagined frame, over the GT frame) PNG data URIs of ``view`` at ``step``
        (imagined frame ``frame``), ``size`` (width, height); None for a view without a camera."""
        camera = self.cameras.get(view)
        if camera is None or self._mesh is None:
            return None
        key = (view, step, frame, size, len(self._trackers[view].result()) > frame if view in self._trackers else False)
        with self._lock:
            kept = self._kept.get(key)
            if kept is not None:
                self._kept.move_to_end(key)
                return kept
        # drawn at half the display size (the page scales it onto the frame): a quarter of the
        # PNG and half the silhouette's rows, ~6 ms a step for both arms instead of ~16 ms
        half = (max(1, size[0] // 2), max(1, size[1] // 2)) if size[1] >= HALF_SIZE_FROM_ROWS else size
        drawn = self._draw(view, camera, step, frame, half)
        with self._lock:
            self._kept[key] = drawn
            while len(self._kept) > KEPT_OVERLAYS:
                self._kept.popitem(last=False)
        return drawn

    def _draw(self, view: str, camera: Camera, step: int, frame: int, size: tuple[int, int]) -> tuple[str, str]:
        assert self._mesh is not None
        cam = scaled_camera(camera, size)
        rgba = np.zeros((size[1], size[0], 4), np.uint8)
        if self._gt_q is not None:
            _paint(rgba, arm_masks(self._mesh, cam, self._gt_q[step:step + 1])[0], GT_RGB)
        if self._pred_q is not None:
            _paint(rgba, arm_masks(self._mesh, cam, self._pred_q[step:step + 1])[0], PRED_RGB)
        over_gt = _png_data_uri(rgba)
        radius = max(3.0, size[1] / 40)
        if self._pred_q is not None and camera.is_fixed:
            _ring(rgba, project_point(cam, self._pred_q[step:step + 1], self._point(view))[0], PRED_RGB, radius)
        known = self.track(view)
        if known is not None and frame < len(known[0]):
            tracked, track_size = known
            scale = np.array([size[0] / track_size[0], size[1] / track_size[1]])
            _ring(rgba, (tracked[frame] + 0.5) * scale - 0.5, TRACK_RGB, radius + 2)
        return _png_data_uri(rgba), over_gt


__all__ = ["ArmOverlay", "GT_RGB", "PRED_RGB", "TRACKED_POINT", "TRACK_RGB"]
