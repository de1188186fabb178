"""A LeRobot dataset's on-disk layout (codebase v3.0 and v2.1): its paths, keys and column names as
constants, and the checks its files need (path templates, JSON lines, the v3.0 episode index's
column types). Kept apart from the readers so the reader and the writer
(:mod:`inspector.data.lerobot_writer`) name every file and key from one place. The two layouts::

    v3.0 (LeRobot >= 0.4): many episodes per file
    <root>/
      meta/
        info.json                          codebase_version, fps, features, path templates
        stats.json                         (not read here)
        tasks.parquet                      one row per task: task_index, task string as the index
        episodes/chunk-000/file-000.parquet  one row per episode: episode_index, tasks, length,
                                           dataset_from_index, dataset_to_index, data/chunk_index,
                                           data/file_index, videos/<key>/chunk_index|file_index|
                                           from_timestamp|to_timestamp, stats/...
      data/chunk-000/file-000.parquet      rows of many episodes; select by episode_index
      videos/<video_key>/chunk-000/file-000.mp4   many episodes back to back; an episode is the
                                           window [from_timestamp, to_timestamp) of the file

    v2.1 (LeRobot 0.1 - 0.3): one file per episode, chunk = episode_index // chunks_size
    <root>/
      meta/
        info.json
        episodes.jsonl                     {"episode_index", "tasks", "length"} per line
        tasks.jsonl                        {"task_index", "task"} per line
        episodes_stats.jsonl               (not read here)
      data/chunk-000/episode_000000.parquet
      videos/chunk-000/<video_key>/episode_000000.mp4

v2.0 has the v2.1 layout (they differ only in their stats files, which this reader does not use),
so it is read the same way.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

from ..errors import InspectorError
from ..schema import shown, whole_number

# --- versions -------------------------------------------------------------------------------------
V30 = "v3.0"
V21 = "v2.1"
V20 = "v2.0"
SUPPORTED_VERSIONS: tuple[str, ...] = (V30, V21, V20)

# --- paths (relative to the dataset root) ---------------------------------------------------------
INFO_PATH = "meta/info.json"
V30_EPISODES_DIR = "meta/episodes"
V30_EPISODES_GLOB = "chunk-*/file-*.parquet"  # under V30_EPISODES_DIR
V30_TASKS_PATH = "meta/tasks.parquet"
V30_DEFAULT_DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
V30_DEFAULT_VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
V21_EPISODES_PATH = "meta/episodes.jsonl"
V21_TASKS_PATH = "meta/tasks.jsonl"
V21_DEFAULT_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V21_DEFAULT_VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
DEFAULT_CHUNKS_SIZE = 1000

# --- info.json keys -------------------------------------------------------------------------------
CODEBASE_VERSION_KEY = "codebase_version"
FPS_KEY = "fps"
ROBOT_TYPE_KEY = "robot_type"
FEATURES_KEY = "features"
TOTAL_EPISODES_KEY = "total_episodes"
CHUNKS_SIZE_KEY = "chunks_size"
DATA_PATH_KEY = "data_path"
VIDEO_PATH_KEY = "video_path"
# Not a LeRobot key: our writer states the joint units here ({"arm": "degrees", "gripper": "0..100"}).
UNITS_KEY = "units"

# --- feature / column names -----------------------------------------------------------------------
STATE_KEY = "observation.state"
ACTION_KEY = "action"
IMAGE_PREFIX = "observation.images."
TIMESTAMP_KEY = "timestamp"
FRAME_INDEX_KEY = "frame_index"
EPISODE_INDEX_KEY = "episode_index"
INDEX_KEY = "index"
TASK_INDEX_KEY = "task_index"

# --- v3.0 meta/episodes columns -------------------------------------------------------------------
EP_TASKS = "tasks"
EP_LENGTH = "length"
EP_FROM_INDEX = "dataset_from_index"
EP_TO_INDEX = "dataset_to_index"
EP_DATA_CHUNK = "data/chunk_index"
EP_DATA_FILE = "data/file_index"


def ep_video_column(video_key: str, field_name: str) -> str:
    """``videos/<video_key>/<field>`` with field one of chunk_index, file_index, from_timestamp,
    to_timestamp (v3.0 meta/episodes)."""
    return f"videos/{video_key}/{field_name}"


# What a path template may be filled from, with a value of each field's type (checked on it).
V30_TEMPLATE_FIELDS: dict[str, Any] = {"chunk_index": 0, "file_index": 0}
V21_TEMPLATE_FIELDS: dict[str, Any] = {"episode_chunk": 0, "episode_index": 0}
# The widest format a template field may ask for (``{episode_index:06d}`` asks for 6), and the
# longest template: a path longer than a file system takes is no path [characters].
MAX_TEMPLATE_WIDTH = 32
MAX_TEMPLATE_CHARS = 1024
_FORMAT_SPEC = re.compile(r"(?:.?[<>=^])?[+\- ]?z?#?0?(?P<width>\d*)[,_]?(?:\.(?P<precision>\d+))?[bcdeEfFgGnosxX%]?")


def template_problem(template: str, fields: dict[str, Any]) -> str | None:
    """What is wrong with ``template`` as a path template filled from ``fields`` (their names and
    example values), or None: only those names (no attribute or index lookups, no positional
    ``{}``), each formatted with a plain spec of width and precision at most
    :data:`MAX_TEMPLATE_WIDTH` (``{episode_index:>300000000}`` would be a 300 MB path), at most
    :data:`MAX_TEMPLATE_CHARS` long, filled without error from the example values, and inside the
    dataset (no ``..``, not absolute)."""
    import string

    if len(template) > MAX_TEMPLATE_CHARS:
        return f"a template of {len(template):,} characters (at most {MAX_TEMPLATE_CHARS})"
    known = sorted(fields)
    try:
        parts = list(string.Formatter().parse(template))
    except ValueError as exc:
        return f"template {shown(template)} is not a format string ({exc})"
    for _, name, spec, conversion in parts:
        if name is None:
            continue
        if name not in fields:
            return f"template {shown(template)}: unknown field {shown(name)}; known: {known}"
        match = _FORMAT_SPEC.fullmatch(spec or "")
        if match is None or conversion not in (None, "s"):
            return f"template {shown(template)}: field {name!r} has an unsupported format {shown(spec)}"
        widths = [int(w) for w in (match["width"], match["precision"]) if w]
        if any(w > MAX_TEMPLATE_WIDTH for w in widths):
            return (f"template {shown(template)}: field {name!r} asks for a width of {max(widths)} "
                    f"(at most {MAX_TEMPLATE_WIDTH})")
    try:
        template.format(**fields)
    except (KeyError, IndexError, ValueError, AttributeError, TypeError) as exc:
        return f"template {shown(template)} cannot be filled from {known} ({exc})"
    if ".." in Path(template).parts or Path(template).is_absolute():
        return f"template {shown(template)} leaves the dataset"
    return None


def _expand(path: str | Path) -> Path:
    """``~`` expanded; an unknown ``~user`` stays as written (``Path.expanduser`` would raise)."""
    return Path(os.path.expanduser(path))


def _camera_name(video_key: str) -> str:
    """``observation.images.front`` -> ``front``."""
    return video_key[len(IMAGE_PREFIX):] if video_key.startswith(IMAGE_PREFIX) else video_key


def _feature_names(feature: dict[str, Any]) -> list[str] | None:
    """``features[key]["names"]`` as a list; v2.0-era datasets nest it as ``{"motors": [...]}``."""
    names = feature.get("names")
    if isinstance(names, dict) and len(names) == 1:
        names = next(iter(names.values()))
    if isinstance(names, list) and all(isinstance(n, str) for n in names):
        return names
    return None


def read_jsonl(f: Path) -> list[tuple[int, dict[str, Any]]]:
    """(line number, object) for every non-empty line of a JSON-lines file."""
    if not f.is_file():
        raise InspectorError(f, "file not found")
    try:
        text = f.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InspectorError(f, f"cannot read: {exc}") from None
    out = []
    for line_no, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except (ValueError, RecursionError) as exc:
            raise InspectorError(f, f"line {line_no}: invalid JSON ({exc})") from None
        if not isinstance(row, dict):
            raise InspectorError(f, f"line {line_no}: expected a JSON object")
        out.append((line_no, row))
    return out


def _check_index_columns(f: Path, schema: Any, needed: list[str]) -> None:
    """The v3.0 episode index holds every column it needs, each of its expected type: whole
    numbers for indexes and lengths, numbers for timestamps, lists of strings for tasks. Checked
    on the file's schema, once for all its rows, so a wrong-typed column (an episode index
    written as strings) is one line naming it, not a comparison failing deep in the reader.

    Raises:
        InspectorError: naming ``f`` and the first column missing or of the wrong type.
    """
    import pyarrow as pa

    missing = [c for c in needed if c not in schema.names]
    if missing:
        raise InspectorError(f, f"missing column(s) {missing}")
    for name in needed:
        typ = schema.field(name).type
        if name == EP_TASKS:
            ok = pa.types.is_null(typ) or ((pa.types.is_list(typ) or pa.types.is_large_list(typ))
                                           and (pa.types.is_string(typ.value_type)
                                                or pa.types.is_large_string(typ.value_type)))
            expected = "a list of task strings"
        elif name.endswith(("from_timestamp", "to_timestamp")):
            ok, expected = pa.types.is_floating(typ) or pa.types.is_integer(typ), "numbers [s]"
        else:
            ok, expected = pa.types.is_integer(typ), "whole numbers"
        if not ok:
            raise InspectorError(f, f"column '{name}': expected {expected}, found {typ}")


def _is_whole(value: Any) -> bool:
    """An integer, and not a bool (JSON's ``true`` is no episode index)."""
    return isinstance(value, int) and not isinstance(value, bool)


def _check_episode(f: Path, where: str, index: Any, length: Any) -> None:
    """An episode's metadata row names a non-negative index and a positive length (both no
    larger than :data:`MAX_WHOLE`)."""
    if not index >= 0 or not length >= 1:
        raise InspectorError(f, f"{where}: '{EPISODE_INDEX_KEY}' must be >= 0 and '{EP_LENGTH}' >= 1, "
                                f"found {shown(index)} and {shown(length)}")
    whole_number(index, f, f"{where}: '{EPISODE_INDEX_KEY}'")
    whole_number(length, f, f"{where}: '{EP_LENGTH}'", minimum=1)


def _describe_indices(indices: list[int]) -> str:
    """``[0, 1, 2]`` -> ``"0..2"``; gaps are listed (shortened when long)."""
    if not indices:
        return "none"
    idx = sorted(indices)
    if idx == list(range(idx[0], idx[-1] + 1)):
        return f"{idx[0]}..{idx[-1]}"
    return str(idx) if len(idx) <= 12 else f"{idx[:5]} ... {idx[-5:]} ({len(idx)} episodes)"
