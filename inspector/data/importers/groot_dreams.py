"""GR00T-Dreams (DreamGen) neural trajectories: what ``inspector info`` says of a dump, and
``inspector import groot-dreams`` (every episode a rollout of a new session). The dump's layout
and how an episode becomes a rollout: :mod:`.groot_dreams_reader`.

``report``, ``serve`` and ``export`` open a dump as a dataset (:func:`open_trajectories`), never
as a temporary session: :func:`load_in_memory` says to import it first.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ...errors import InspectorError, require
from ...units import JOINT_NAMES
from ..session import SessionWriter, check_apart
from ..video import probe
from .groot_dreams_reader import (
    EPISODES_PATH,
    INFO_PATH,
    JOINT_PREFIX,
    LAYOUT,
    LAYOUT_HINT,
    LAYOUT_TITLE,
    MODEL_NAME,
    NeuralTrajectories,
    is_groot_dreams,
    rates_differ,
    rollout_args,
    rollout_tag,
    steps_past_limits,
)
from .in_memory import InMemory

# The format's name, as a rollout's ``extra.source.format`` says it.
GROOT_DREAMS = LAYOUT

__all__ = ["GROOT_DREAMS", "LAYOUT", "NeuralTrajectories", "describe", "format_description", "import_command", "import_groot_dreams",
           "is_groot_dreams", "load_in_memory", "open_trajectories", "recognises"]


def recognises(path: Path) -> bool:
    """A dump's directory (see :func:`is_groot_dreams`)."""
    return path.is_dir() and is_groot_dreams(path)


def load_in_memory(src: Path, dataset: str | Path | None = None) -> InMemory:
    """Never: a dump is opened as a dataset of trajectories (:func:`open_trajectories`), so a
    command that wants a session says how to make one.

    Raises:
        InspectorError: always.
    """
    raise InspectorError(src, "a GR00T-Dreams dump is not a session here; import it first: "
                              "inspector import groot-dreams PATH -o SESSION")


_open: OrderedDict[tuple, NeuralTrajectories] = OrderedDict()
_open_lock = threading.Lock()


def open_trajectories(root: str | Path, calibration: str | None = None) -> NeuralTrajectories:
    """A :class:`NeuralTrajectories`, shared in this process while its ``meta/info.json`` is unchanged."""
    path = Path(root).resolve()
    try:
        st = (path / INFO_PATH).stat()
    except OSError:
        return NeuralTrajectories(path, calibration)  # raises the reader's own error
    key = (str(path), st.st_mtime_ns, st.st_size, calibration)
    with _open_lock:
        if key in _open:
            _open.move_to_end(key)
            return _open[key]
    ds = NeuralTrajectories(path, calibration)
    with _open_lock:
        _open[key] = ds
        while len(_open) > 8:
            _open.popitem(last=False)
    return ds


# ----------------------------------------------------------------------------------------------
# inspector info


def describe(src: Path, calibration: str | None = None) -> dict[str, Any]:
    """``inspector info``'s JSON for the dump at ``src``, mapped with ``calibration``
    (``--calibration``; None: the dump's default)."""
    return describe_layout(NeuralTrajectories(src, calibration))


def describe_layout(ds: NeuralTrajectories) -> dict[str, Any]:
    """``inspector info``'s JSON for a GR00T-Dreams dump: layout, episodes, views, fps, units and
    calibration, warnings (the first episode is read to check the calibration)."""
    warnings = []
    fps, why = ds.timing
    if rates_differ(fps, ds.info_fps):
        warnings.append(f"meta/info.json says fps {ds.info_fps:g}, the timestamps {fps:g}: the timestamps are trusted")
    if not ds.actions_absolute:
        warnings.append("meta/modality.json marks the actions relative (absolute: false); read as joint "
                        "positions, which is what stats.json's action means are")
    mean = ds.stats_action_mean
    if mean is not None and steps_past_limits(ds.calibration.apply(mean)[None]) > 0:
        warnings.append(f"stats.json's mean action is past a joint limit after calibration {ds.calibration.spec}")
    first = ds.episodes[0].index if ds.episodes else None
    if first is not None:
        try:
            warnings += [f"episode {first}: {w}" for w in ds.trajectory(first).warnings]
        except InspectorError as exc:
            warnings.append(f"episode {first}: {exc}")
    views = {}
    for cam, seg in (ds.episodes[0].videos.items() if ds.episodes else []):
        try:
            v = probe(seg.path)
            views[cam] = {"width": v.width, "height": v.height, "fps": v.fps, "codec": v.codec}
        except InspectorError as exc:
            views[cam] = {"error": str(exc)}
    return {
        "format": LAYOUT, "layout": LAYOUT_TITLE, "robot_type": ds.robot_type,
        "fps": fps, "fps_source": why, "info_fps": ds.info_fps,
        "views": views, "units": "arm degrees, gripper 0..100, after calibration",
        "calibration": {**ds.calibration.to_json(), "text": ds.calibration.describe()},
        "action_columns": {f"{JOINT_PREFIX}{j}": int(c) for j, c in zip(JOINT_NAMES, ds.action_columns)},
        "episodes": [{"index": e.index, "length": e.length, "task": e.task, "dream": ds.is_dream(e)}
                     for e in ds.episodes],
        "warnings": warnings,
    }


def format_description(info: dict[str, Any]) -> str:
    """:func:`describe`'s output as lines."""
    views = ", ".join(f"{k} {v['width']}x{v['height']} @ {v['fps']:g} fps" if "width" in v else f"{k} ({v['error']})"
                      for k, v in info["views"].items()) or "none"
    n_dream = sum(e["dream"] for e in info["episodes"])
    lines = [f"{info['layout']}: {len(info['episodes'])} episode(s) ({n_dream} marked <DREAM>), "
             f"robot_type {info['robot_type']}",
             f"fps: {info['fps_source']}",
             f"views: {views}",
             f"units: {info['units']}; calibration {info['calibration']['text']}",
             f"{'episode':>7}  {'length':>6}  task"]
    lines += [f"{e['index']:>7}  {e['length']:>6}  {e['task']}" for e in info["episodes"]]
    lines += [f"warning: {w}" for w in info["warnings"]]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# inspector import groot-dreams


def import_command(src: str | Path, dest: str | Path, *, overwrite: bool = False,
                   calibration: str | None = None) -> Path:
    """``inspector import groot-dreams SRC -o DEST [--calibration SPEC]``."""
    return import_groot_dreams(src, dest, calibration=calibration, overwrite=overwrite)


def import_groot_dreams(src: str | Path, dest: str | Path, *, calibration: str | None = None,
                        overwrite: bool = False, log: Callable[[str], None] = print) -> Path:
    """Write every episode of the dump at ``src`` as a rollout of a new session at ``dest``
    (``episode_NNNNNN``: the calibrated IDM actions, every camera's generated video as its view).

    All or nothing: an episode that cannot be read stops the import and nothing is written.
    """
    src = Path(src)
    if not src.exists():
        raise InspectorError(src, "not found")
    require(is_groot_dreams(src), src, f"not a {LAYOUT_TITLE} directory ({LAYOUT_HINT})")
    check_apart(dest, src)
    ds = NeuralTrajectories(src, calibration)
    require(bool(ds.episodes), src / EPISODES_PATH, "no episodes")
    with SessionWriter.create(dest, name=Path(dest).name, units=ds.session.units, model={"name": MODEL_NAME},
                              overwrite=overwrite) as writer:
        for info in ds.episodes:
            tr = ds.trajectory(info.index)
            writer.add_rollout(rollout_tag(info.index), **rollout_args(tr, ds))
            log(f"{rollout_tag(info.index)}: {tr.length} steps at {tr.fps:g} fps, "
                f"{', '.join(tr.videos) or 'no video'}, {tr.task!r}"
                + "".join(f"; warning: {w}" for w in tr.warnings))
    return Path(dest)
