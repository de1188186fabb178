"""``inspector calibrate``: a fixed view's camera from clicked points of the arm in GT frames.

A points file names, for steps of a rollout's GT episode, a point of the arm and the pixel it was
seen at in that step's GT frame of the view::

    {"view": "front", "rollout": "prompt_train",
     "points": [{"step": 120, "point": "gripper_frame_link", "u": 311.5, "v": 202.0}, ...]}

``rollout`` (optional, at the top or per point) names the rollout whose GT episode the steps are
of; ``point`` is a URDF link's origin (its URDF name) or ``gripper_tip``
(:mod:`inspector.robot.camera`). The 3D points are the forward kinematics of the GT joints at those
steps: the measured joints (``observation.state``) where the GT comes from a dataset, since a
frame shows the arm where it was, not where it was commanded; else the GT carried with the
rollout. The camera is solved (:mod:`inspector.analysis.calibration_solve`) and written into the
session's ``cameras.json`` (a raw directory's sidecar), atomically; a solve above ``max_error_px``
is refused and nothing is written.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .._files import read_regular_file
from ..errors import InspectorError, require
from ..robot.camera import named_points, point_names
from ..units import Units, to_radians
from .calibration_solve import DEFAULT_FOVY_DEG, MIN_POINTS, CalibrationFailed, solve_fixed_camera

MAX_POINTS_BYTES = 4 * 1024 * 1024  # a points file of 10,000 clicks is under 1 MB
MAX_POINTS = 10_000
DEFAULT_MAX_ERROR_PX = 5.0  # refused above this RMS reprojection error [px]
_POINT_FIELDS = ("step", "point", "u", "v", "rollout")
_TAG = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")  # a rollout's tag, as sessions name them


@dataclass(frozen=True)
class Click:
    """One clicked point: ``point`` of the arm seen at pixel (u, v) in ``rollout``'s GT frame ``step``."""

    rollout: str
    step: int
    point: str
    u: float
    v: float


def read_points(path: Path, view: str) -> tuple[list[Click], str | None]:
    """(clicks, top-level rollout) of a points file; every field checked, one line naming it.

    Raises:
        InspectorError: not a regular file, larger than :data:`MAX_POINTS_BYTES`, not JSON (nested
            too deep, a NaN), or a field out of place (another view, an unknown point name, a
            step that is not a whole number, ...).
    """
    from ..data.session import parse_json

    data = parse_json(path, read_regular_file(path, MAX_POINTS_BYTES, "points file"))
    require(isinstance(data, dict), path, f"expected a JSON object, found {type(data).__name__}")
    unknown = sorted(str(k) for k in data if k not in ("view", "rollout", "points"))
    require(not unknown, path, f"unknown field {unknown[0][:80]!r} (fields: view, rollout, points)" if unknown else "")
    require(data.get("view", view) == view, path, f"view: the file's points are of {str(data.get('view'))[:80]!r}, "
                                                  f"not of --view {view!r}")
    top = data.get("rollout")
    require(top is None or (isinstance(top, str) and bool(_TAG.match(top))), path,
            f"rollout: expected a rollout's tag, found {_shown(top)}")
    points = data.get("points")
    require(isinstance(points, list), path, f"points: expected a list, found {type(points).__name__}")
    assert isinstance(points, list)
    require(len(points) <= MAX_POINTS, path, f"points: {len(points):,} points, more than the {MAX_POINTS:,} read")
    names = point_names()
    clicks = []
    for i, p in enumerate(points):
        where = f"points[{i}]"
        require(isinstance(p, dict), path, f"{where}: expected an object, found {type(p).__name__}")
        extra = sorted(str(k) for k in p if k not in _POINT_FIELDS)
        require(not extra, path, f"{where}: unknown field {extra[0][:80]!r} (fields: {', '.join(_POINT_FIELDS)})"
                if extra else "")
        step = p.get("step")
        require(isinstance(step, int) and not isinstance(step, bool) and 0 <= step < 2**53, path,
                f"{where}.step: expected a whole number of steps from 0, found {_shown(step)}")
        point = p.get("point")
        require(isinstance(point, str) and point in names, path,
                f"{where}.point: unknown point {_shown(point)}; points: {', '.join(names)}")
        u, v = (_pixel(path, f"{where}.{axis}", p.get(axis)) for axis in ("u", "v"))
        rollout = p.get("rollout", top)
        require(rollout is None or (isinstance(rollout, str) and bool(_TAG.match(rollout))), path,
                f"{where}.rollout: expected a rollout's tag, found {_shown(rollout)}")
        clicks.append(Click(rollout or "", step, point, u, v))
    return clicks, top


def _pixel(path: Path, where: str, value: object) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and abs(value) < 1e9  # NaN too
    require(ok, path, f"{where}: expected a pixel coordinate, found {_shown(value)}")
    assert isinstance(value, (int, float))
    return float(value)


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else f"{text[:57]}..."


def calibrate(path: str | Path, view: str, points_file: str | Path | None = None, rollout: str | None = None,
              fovy_guess_deg: float = DEFAULT_FOVY_DEG, max_error_px: float = DEFAULT_MAX_ERROR_PX,
              fit_principal_point: bool = False, write: bool = True) -> dict[str, Any]:
    """Solve ``view``'s fixed camera of the session at ``path`` from a points file, and store it.

    Args:
        path: a session, one rollout of it, or a raw directory a session is opened from.
        view: the camera view (its GT frames are what the points were clicked on).
        points_file: the points (default: the clicks saved for ``view``, ``inspector.data.cameras.points_path``).
        rollout: the rollout whose GT episode the steps are of, where the file does not say.
        fovy_guess_deg: the vertical field of view the solve starts from [deg].
        max_error_px: refuse a solve whose RMS reprojection error is above this [px]; points past
            twice it are rejected as bad clicks.
        fit_principal_point: fit the principal point too (default: the image centre).
        write: store the camera in the session's cameras file.

    Returns:
        ``{"view", "camera": {"width", "height", "K", "T_base_camera"}, "reprojection_error_px",
        "points_used", "points_rejected", "residuals_px", "written"}``.

    Raises:
        InspectorError: bad points, no GT joints or frames for the view, fewer than 6 usable points,
            or an error above ``max_error_px`` (one line naming the file).
    """
    from ..data.cameras import cameras_path, points_path, read_cameras, write_camera
    from ..data.sources import open_sources

    sources = open_sources([path])
    try:
        session = sources.sessions[0]
        pfile = Path(points_file) if points_file is not None else points_path(session, view)
        known = read_cameras(cameras_path(session)).get(view)
        require(known is None or known.is_fixed, cameras_path(session),
                f"cameras.{view}: rides on {known.parent if known else ''}; calibrate solves fixed cameras only")
        clicks, _ = read_points(pfile, view)
        require(len(clicks) >= MIN_POINTS, pfile, f"points: {len(clicks)} points; at least {MIN_POINTS} are needed "
                                                  "(spread over the episode)")
        default = rollout or _only_rollout(session, pfile, clicks)
        clicks = [c if c.rollout else Click(default, c.step, c.point, c.u, c.v) for c in clicks]
        size: tuple[int, int] | None = None
        X = np.empty((len(clicks), 3))
        for tag in sorted({c.rollout for c in clicks}):
            joints, units, frame_size = _gt_of(session, tag, view, pfile)
            require(size is None or frame_size == size, pfile,
                    f"rollout {tag!r}: its {view} frames are {frame_size[0]}x{frame_size[1]}, others' {size}")
            size = frame_size
            mine = [i for i, c in enumerate(clicks) if c.rollout == tag]
            for i in mine:
                c = clicks[i]
                require(c.step < len(joints), pfile, f"points[{i}].step: {c.step} is past the GT episode of "
                                                     f"rollout {tag!r} (steps 0 to {len(joints) - 1})")
            q = to_radians(joints[[clicks[i].step for i in mine]], units)
            names = sorted({clicks[i].point for i in mine})
            at = named_points(q, names)
            for k, i in enumerate(mine):
                X[i] = at[clicks[i].point][k]
        assert size is not None
        width, height = size
        uv = np.array([[c.u, c.v] for c in clicks])
        outside = np.flatnonzero((uv[:, 0] < -0.5) | (uv[:, 0] > width - 0.5) | (uv[:, 1] < -0.5)
                                 | (uv[:, 1] > height - 0.5))
        require(not len(outside), pfile, f"points[{outside[0] if len(outside) else 0}]: ({uv[outside[0]][0]:g}, "
                                         f"{uv[outside[0]][1]:g}) lies outside the {width}x{height} frame"
                if len(outside) else "")
        try:
            result = solve_fixed_camera(X, uv, width, height, fovy_guess_deg, reject_px=2 * max_error_px,
                                        fit_principal_point=fit_principal_point)
        except CalibrationFailed as exc:
            raise InspectorError(pfile, f"no camera solved: {exc}") from None
        require(result.reprojection_error_px <= max_error_px, pfile,
                f"reprojection error {result.reprojection_error_px:.2f} px is above {max_error_px:g} px "
                f"(--max-error): check the clicks (worst: points {_worst(result.residuals_px)})")
        camera = result.camera
        source = (f"inspector calibrate: {len(result.used)} points of {', '.join(sorted({c.rollout for c in clicks}))}, "
                  f"reprojection error {result.reprojection_error_px:.2f} px")
        camera = replace(camera, source=source)
        written = None
        if write:
            written = cameras_path(session)
            write_camera(written, view, camera)
        shown = camera.to_dict()
        return {
            "view": view,
            "camera": {key: shown[key] for key in ("width", "height", "K", "T_base_camera")},
            "reprojection_error_px": round(result.reprojection_error_px, 4),
            "points_used": len(result.used),
            "points_rejected": result.rejected,
            "residuals_px": [None if not np.isfinite(r) else round(float(r), 3) for r in result.residuals_px],
            "written": None if written is None else str(written),
        }
    finally:
        sources.close()


def _worst(residuals: npt.NDArray[np.float64]) -> str:
    order = np.argsort(-np.nan_to_num(residuals, nan=np.inf))[:3]
    return ", ".join(f"{i} ({'behind the camera' if not np.isfinite(residuals[i]) else f'{residuals[i]:.1f} px'})"
                     for i in order)


def _only_rollout(session: Any, pfile: Path, clicks: list[Click]) -> str:
    """The rollout the clicks without one are of: the session's only rollout (else one must be named)."""
    if all(c.rollout for c in clicks):
        return ""
    tags = sorted(session.rollouts)
    require(len(tags) == 1, pfile, f"rollout: which rollout's GT episode are the steps of? name it "
                                   f"(--rollout or \"rollout\" in the file); rollouts: {', '.join(tags[:20])}"
                                   f"{' ...' if len(tags) > 20 else ''}")
    return tags[0]


def _gt_of(session: Any, tag: str, view: str, pfile: Path
           ) -> tuple[npt.NDArray[np.float64], Units, tuple[int, int]]:
    """(joints (S, 6) by rollout step, their units, (width, height) of the view's GT frames)."""
    from ..data.ground_truth import resolve_ground_truth
    from ..data.lerobot_dataset import open_dataset
    from ..data.video import probe

    rollout = session.rollouts.get(tag)
    if rollout is None:
        problem = session.errors.get(tag)
        raise InspectorError(pfile, f"rollout: {tag!r} " + (f"could not be read ({problem})" if problem else
                                                            f"is not in the session; rollouts: {', '.join(sorted(session.rollouts)[:20])}"))
    gt = resolve_ground_truth(rollout)
    require(view in gt.clips, pfile, f"rollout {tag!r} has no GT frames of view {view!r} (GT views: {gt.views})")
    info = probe(gt.clips[view].path)
    if gt.dataset_key is not None:  # a dataset episode: the measured joints, what the frames show
        episode = open_dataset(Path(gt.dataset_key[0])).episode(rollout.episode_index)
        return episode.state[rollout.start_frame:], episode.units, (info.width, info.height)
    require(gt.actions is not None, pfile, f"rollout {tag!r} has no GT joints ({gt.source}): nothing to project")
    assert gt.actions is not None
    return gt.actions[gt.offset:], rollout.units, (info.width, info.height)


def format_calibration(result: dict[str, Any]) -> str:
    """The text ``inspector calibrate`` prints."""
    cam = result["camera"]
    K, T = np.array(cam["K"]), np.array(cam["T_base_camera"])
    fovy = math.degrees(2 * math.atan(cam["height"] / 2 / K[1, 1]))
    rejected = result["points_rejected"]
    lines = [
        f"{result['view']}: camera solved from {result['points_used']} points"
        f"{f' ({len(rejected)} rejected as bad clicks: {rejected})' if rejected else ''}, "
        f"reprojection error {result['reprojection_error_px']:.2f} px (RMS)",
        f"  image {cam['width']}x{cam['height']} px, focal length {K[0, 0]:.1f} px (vertical field of view "
        f"{fovy:.1f} deg), principal point ({K[0, 2]:.1f}, {K[1, 2]:.1f})",
        f"  camera at ({T[0, 3]:.3f}, {T[1, 3]:.3f}, {T[2, 3]:.3f}) m in the arm's base frame, looking along "
        f"({T[0, 2]:.2f}, {T[1, 2]:.2f}, {T[2, 2]:.2f})",
    ]
    if result.get("written"):
        lines.append(f"wrote {result['written']}")
    return "\n".join(lines)


__all__ = ["Click", "calibrate", "format_calibration", "read_points"]
