"""The report page's overlay frames: at a rollout's worst chunk, the arms drawn into each view.

For each rollout row with a worst chunk whose session has cameras, the imagined and the GT frame
of each view with a camera at the chunk's middle executed step, with the predicted arm (orange)
and the GT arm (grey) outlined into them through the view's camera, as small JPEG data URIs
(128 px wide, ~3 kB each). The page stays small: the :data:`MAX_ROLLOUTS` rollouts of highest
chunk RMSE at their worst chunk get frames; the section says how many were left out. A rollout
that cannot be read, or a frame that cannot be decoded, is left out of the section, never the page.
"""

from __future__ import annotations

import base64
from collections.abc import Mapping, Sequence
from html import escape
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..analysis.camera_measures import cameras_of, scaled_camera
from ..analysis.timeline import build_timeline
from ..robot.silhouette import arm_masks, arm_mesh, outline
from ..units import to_radians

MAX_ROLLOUTS = 4
THUMB_WIDTH = 128  # [px]
PRED_RGB = (232, 89, 12)
GT_RGB = (134, 142, 150)
JPEG_QUALITY = 65


def _jpeg_uri(rgb: npt.NDArray[np.uint8]) -> str:
    import simplejpeg

    data = simplejpeg.encode_jpeg(np.ascontiguousarray(rgb), quality=JPEG_QUALITY, colorspace="RGB")
    return "data:image/jpeg;base64," + base64.b64encode(data).decode("ascii")


def _thumb(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    from PIL import Image

    h, w = rgb.shape[:2]
    size = (THUMB_WIDTH, max(1, round(h * THUMB_WIDTH / w)))
    return np.asarray(Image.fromarray(np.ascontiguousarray(rgb)).resize(size, Image.Resampling.BILINEAR))


def _drawn(rgb: npt.NDArray[np.uint8], masks: Sequence[tuple[npt.NDArray[np.bool_], tuple[int, int, int]]]
           ) -> npt.NDArray[np.uint8]:
    """``rgb`` with each mask tinted (a third) and outlined in its colour."""
    out = rgb.astype(np.float32)
    for mask, colour in masks:
        out[mask] = out[mask] * 0.66 + np.asarray(colour, np.float32) * 0.34
        out[outline(mask)] = colour
    return out.astype(np.uint8)


def overlay_frames(tl: Any) -> list[tuple[str, str | None, str | None]]:
    """(view, imagined frame URI, GT frame URI) of each view with a camera at the rollout's worst
    chunk (a URI is None where that frame is not there)."""
    cameras, _ = cameras_of(tl.rollout.session)
    mesh = arm_mesh()
    if not cameras or mesh is None or not tl.has_joints:
        return []
    chunk = min(tl.worst_chunk()[0], tl.n_chunks - 1)
    step = tl.step_of(chunk, tl.rollout.executed_per_chunk // 2)
    f = tl.frame_index(step)
    out: list[tuple[str, str | None, str | None]] = []
    for view in tl.video_views() if tl.video_views() else tl.rollout.views:
        camera = cameras.get(view)
        if camera is None or view not in tl.rollout.views:
            continue
        imagined = tl.rollout.video(view).frame(f)
        if imagined is None:
            continue
        small = _thumb(imagined)
        cam = scaled_camera(camera, (small.shape[1], small.shape[0]))
        masks = []
        if tl.gt_aligned is not None:
            masks.append((arm_masks(mesh, cam, to_radians(tl.gt_aligned[step:step + 1], tl.units))[0], GT_RGB))
        masks.append((arm_masks(mesh, cam, to_radians(tl.pred[step:step + 1], tl.units))[0], PRED_RGB))
        gt_uri = None
        clip = tl.gt.clips.get(view)
        index = tl.gt_index_of_frame(view)(f) if clip is not None else -1
        if clip is not None and index >= 0:
            gt = clip.frame(index)
            if gt is not None:
                gt_uri = _jpeg_uri(_drawn(_thumb(gt), masks))
        out.append((view, _jpeg_uri(_drawn(small, masks)), gt_uri))
    return out


def overlay_section(report: Mapping[str, Any], sources: Sequence[str]) -> str:
    """The page's "Arms in frames" section ("" where no rollout has a camera)."""
    rows = [r for r in report.get("rollouts", []) if r.get("worst_chunk") is not None]
    if not rows or not sources:
        return ""
    from ..data.session import ROLLOUT_FILE, is_session

    # sessions and their rollouts only: another tool's raw output would be imported all over again
    saved = [p for p in sources if is_session(Path(p)) or (Path(p) / ROLLOUT_FILE).is_file()]
    if not saved:
        return ""
    try:
        from ..data.sources import open_sources

        opened = open_sources(saved, lazy=True, keep_going=True)
    except Exception:
        return ""
    by_key = {(s.name, tag): (s, tag) for s in opened.sessions for tag in s.rollouts}

    def worst_rmse(r: Mapping[str, Any]) -> float:
        per_chunk = (r.get("time_aligned_drift") or {}).get("per_chunk") or []
        c = r["worst_chunk"]["chunk"]
        return float(per_chunk[c]) if 0 <= c < len(per_chunk) and per_chunk[c] is not None else 0.0

    candidates = sorted((r for r in rows if (r.get("session"), r["tag"]) in by_key), key=worst_rmse, reverse=True)
    cards = []
    shown = 0
    for r in candidates:
        if shown >= MAX_ROLLOUTS:
            break
        from ..data.session import load_session_rollout

        session, tag = by_key[(r.get("session"), r["tag"])]
        try:
            frames = overlay_frames(build_timeline(load_session_rollout(session, tag)))
        except Exception:  # one unreadable rollout leaves the section, never the page
            continue
        if not frames:
            continue
        shown += 1
        cells = "".join(
            f"<figure><img alt='{escape(view)} {kind}' src='{uri}'><figcaption>{escape(view)} {kind}</figcaption></figure>"
            for view, imagined, gt in frames for kind, uri in (("imagined", imagined), ("GT", gt)) if uri is not None)
        cards.append(f"<div class='overlay-rollout'><h3>{escape(str(r.get('session')))} / {escape(tag)} &middot; "
                     f"chunk {r['worst_chunk']['chunk']} ({escape(str(r['worst_chunk']['by']))})</h3>"
                     f"<div style='display:flex;flex-wrap:wrap;gap:6px'>{cells}</div></div>")
    if not cards:
        return ""
    left = len(candidates) - shown
    more = f" ({left} more rollout(s) with cameras not shown)" if left > 0 and shown >= MAX_ROLLOUTS else ""
    return ("<h2>Arms in frames</h2><p>At each rollout's worst chunk (the middle of its executed steps), the "
            "predicted arm (orange) and the GT arm (grey) drawn into the imagined and GT frames through each "
            f"view's camera; the {shown} rollout(s) of largest drift at their worst chunk{more}.</p>"
            + "".join(cards))


__all__ = ["MAX_ROLLOUTS", "overlay_frames", "overlay_section"]
