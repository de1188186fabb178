"""A session's cameras (``cameras.json``): read hostile-safe, written atomically.

A session may hold a camera per view (docs/formats.md#camerasjson)::

    {"schema": "inspector.cameras/1",
     "cameras": {"front": {"width": 320, "height": 240, "K": [[...]], "T_base_camera": [[...]]},
                 "wrist": {"width": 320, "height": 240, "K": [[...]], "parent": "gripper_link",
                           "T_parent_camera": [[...]]}}}

A raw directory opened in memory (another tool's output) keeps its cameras in a sidecar beside it,
``<dir>.inspector-cameras.json``, as its outcomes are kept (``Session.cameras_file``). A missing
file is no cameras; a bad one is one line naming the file and the field, and is never overwritten.
Calibration clicks saved for ``inspector calibrate`` live beside it (:func:`points_path`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import InspectorError, require
from ..robot.camera import Camera
from .session import _VIEW, Session, read_json_object, write_json_atomic

CAMERAS_FILE = "cameras.json"
CAMERAS_SIDECAR_SUFFIX = ".inspector-cameras.json"
CAMERAS_SCHEMA = "inspector.cameras/1"
POINTS_DIR = "calibration_points"  # in a session: <view>.json, clicks saved for `inspector calibrate`
POINTS_SIDECAR_SUFFIX = ".inspector-calibration-{view}.json"
MAX_VIEWS = 64


def cameras_path(session: Session) -> Path:
    """Where ``session``'s cameras live: its ``cameras.json``, or a raw directory's sidecar."""
    return session.cameras_file if session.cameras_file is not None else session.root / CAMERAS_FILE


def sidecar_path(raw_dir: str | Path) -> Path:
    """``<dir>.inspector-cameras.json`` beside a raw directory opened in memory."""
    raw = Path(raw_dir).resolve()
    return raw.parent / f"{raw.name}{CAMERAS_SIDECAR_SUFFIX}"


def points_path(session: Session, view: str) -> Path:
    """Where saved calibration clicks of ``view`` live (what ``calibrate`` reads without ``--points``)."""
    if session.cameras_file is not None:
        return session.cameras_file.parent / (session.cameras_file.name[: -len(CAMERAS_SIDECAR_SUFFIX)]
                                              + POINTS_SIDECAR_SUFFIX.format(view=view))
    return session.root / POINTS_DIR / f"{view}.json"


def session_cameras(session: Session) -> dict[str, Camera]:
    """``session``'s cameras by view ({} when it has none).

    Raises:
        InspectorError: the file is not a valid ``cameras.json`` (naming the field).
    """
    return read_cameras(cameras_path(session))


def read_cameras(path: Path) -> dict[str, Camera]:
    """The cameras a ``cameras.json`` holds, by view; {} when the file does not exist.

    Raises:
        InspectorError: not a regular file, too large, not JSON, or a field out of place.
    """
    try:
        present = path.exists() or path.is_symlink()
    except OSError:  # a raw directory's sidecar name past the file system's limit: no such file can be
        return {}
    if not present:
        return {}
    data = read_json_object(path)
    return parse_cameras(path, data)


def parse_cameras(path: Path, data: dict[str, Any]) -> dict[str, Camera]:
    """:func:`read_cameras` of a parsed document (``path`` named in the errors)."""
    require(data.get("schema") == CAMERAS_SCHEMA, path,
            f"schema: expected {CAMERAS_SCHEMA!r}, found {str(data.get('schema'))[:80]!r}")
    unknown = sorted(str(k) for k in data if k not in ("schema", "cameras"))
    require(not unknown, path, f"unknown field {unknown[0][:80]!r} (fields: schema, cameras)" if unknown else "")
    cameras = data.get("cameras")
    require(isinstance(cameras, dict), path, f"cameras: expected an object of views, found {type(cameras).__name__}")
    assert isinstance(cameras, dict)
    require(len(cameras) <= MAX_VIEWS, path, f"cameras: {len(cameras)} views, more than the {MAX_VIEWS} read")
    out = {}
    for view, entry in cameras.items():
        require(bool(_VIEW.match(view)), path, f"cameras: view {view[:80]!r} is not a name like 'front'")
        try:
            out[view] = Camera.from_dict(entry, f"cameras.{view}")
        except ValueError as exc:
            raise InspectorError(path, str(exc)) from None
    return out


def write_camera(path: Path, view: str, camera: Camera) -> None:
    """Put ``camera`` in ``path`` as ``view``'s, keeping the other views; atomically.

    Raises:
        InspectorError: ``path`` exists but is not a valid ``cameras.json`` (it is left as it is:
            what a user wrote is never replaced by a file that drops it).
    """
    cameras = read_cameras(path)
    cameras[view] = camera
    write_cameras(path, cameras)


def write_cameras(path: Path, cameras: dict[str, Camera]) -> None:
    """Write ``cameras`` (view -> camera) as ``path``, atomically (views in name order)."""
    write_json_atomic(path, {"schema": CAMERAS_SCHEMA,
                             "cameras": {view: cameras[view].to_dict() for view in sorted(cameras)}})


__all__ = ["CAMERAS_FILE", "CAMERAS_SCHEMA", "CAMERAS_SIDECAR_SUFFIX", "cameras_path", "parse_cameras",
           "points_path", "read_cameras", "session_cameras", "sidecar_path", "write_camera", "write_cameras"]
