"""Per-rollout metrics kept on disk, so a second ``report`` (or opening a rollout in the app, or
exporting it) does not decode its videos again.

Entries live in the user's cache directory (``$INSPECTOR_CACHE_DIR``, else
``$XDG_CACHE_HOME/inspector``, else ``~/.cache/inspector``), never in the session, so read-only
sessions work. An entry's key covers everything its numbers depend on: every file of the rollout
and of its GT (path, size, modification time), the joint-limit margin, the sanity measures'
tolerances (completion's, the seam flag's), and the code that computes
them (the package version and the metric modules' source), so a changed input or a new release
never reads a stale entry.

Another tool's output (an offline-inference run, a DreamZero-SO101 or lerobot-eval output) is
imported into a temporary session each time a command reads it, whose files are new every time:
its rollouts are keyed by the source files instead (path, size, modification time of every file
of the rollout's source directory, else of the whole source; :func:`record_import_sources`), with
the importers' code, the content of what the import derived from them (``session.json``,
``rollout.json``, the arrays; the videos by name), and the GT as above. So a second report of an
unchanged output reads its rows from the cache, and an edited or touched source file is a miss.

An entry is written atomically and read back only when it is whole and is what was written: a
header line names its key and the SHA-256 of the record that follows, and the record must match
the type its writer declares (a ``TypedDict``, checked by :func:`inspector.schema.mismatch`).
Anything else (truncated, edited, another key's file, wrong types) is a miss, computed again and
written anew.

The cache is optional. One that cannot be written (a file where its directory should be, a
read-only file system, a full disk) is said once per command, in one ``warning:`` line, and the
command goes on without it: :func:`note_unusable` keeps the first failure of a process, printed
at once in a command's own process; a worker process holds it and hands it back with its results,
for the command to print (the warnings channel of :mod:`inspector.progress`).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import os
from pathlib import Path
from typing import Any

from ._files import mkstemp_sibling
from .errors import one_line
from .progress import say_once_or_hold
from .schema import json_text, mismatch

ENV_DIR = "INSPECTOR_CACHE_DIR"
SCHEMA = "inspector.metrics-cache/2"
# What a file written next to ``session.json`` of a session imported in memory is called: the
# state of each of its rollouts' source files (see :func:`record_import_sources`).
IMPORTED_FROM = ".inspector-imported-from.json"
# The modules whose code decides what an import derives from its source, by import name (a
# package stands for every module in it: a new importer joins by itself). Each must exist: one
# renamed or removed fails the fingerprint (:func:`fingerprinted_files`), never drops out of it.
IMPORT_MODULES = ("inspector.data.importers", "inspector.data.session", "inspector.data.session_model",
                  "inspector.data.session_arrays", "inspector.data.session_reader", "inspector.data.session_writer",
                  "inspector._files")
# The modules whose code decides the cached numbers (the same way).
METRIC_MODULES = ("inspector.analysis.metrics", "inspector.analysis.sweep", "inspector.analysis.video_metrics",
                  "inspector.analysis.timeline", "inspector.analysis.video_action", "inspector.robot.kinematics",
                  "inspector.units", "inspector.data.ground_truth", "inspector.rows.rollout", "inspector.data.video",
                  "inspector.rows.tasks",  # tasks: which rollouts get SSIM
                  "inspector.analysis.seams", "inspector.analysis.completion", "inspector.analysis.coherence",
                  "inspector.analysis.video_break", "inspector.analysis.sanity", "inspector.analysis.measure_settings",
                  "inspector.analysis.masked_psnr", "inspector.analysis.gripper_track",
                  "inspector.analysis.camera_measures")


def default_dir() -> Path:
    """Where entries live (see the module docstring)."""
    if os.environ.get(ENV_DIR):
        return Path(os.path.expanduser(os.environ[ENV_DIR]))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "inspector"


@functools.lru_cache(maxsize=4)
def code_fingerprint(modules: tuple[str, ...] = METRIC_MODULES) -> str:
    """Package version + the source of ``modules`` (import names; default the metric modules),
    hashed: entries of other code never match.

    Raises:
        ModuleNotFoundError: a module of ``modules`` does not exist (see :func:`fingerprinted_files`).
    """
    from importlib import metadata

    h = hashlib.sha256(SCHEMA.encode())
    try:
        h.update(metadata.version("inspector").encode())
    except metadata.PackageNotFoundError:
        pass
    for name, path in fingerprinted_files(modules):
        h.update(f"{name}\0".encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def fingerprinted_files(modules: tuple[str, ...]) -> list[tuple[str, Path]]:
    """(name, source file) of each of ``modules`` (import names), found by the import system
    without running them; a package: each ``.py`` file under it, by path.

    Raises:
        ModuleNotFoundError: one of them does not exist (renamed, moved or removed): the list
            must name the module that now holds its code, or a change there would leave stale
            entries readable.
    """
    files: list[tuple[str, Path]] = []
    for name in modules:
        try:
            spec = importlib.util.find_spec(name)
        except ModuleNotFoundError:  # its package is gone too
            spec = None
        if spec is None or spec.origin is None:
            raise ModuleNotFoundError(f"the metrics cache's code fingerprint names {name}, which does not exist: "
                                      "name the module that holds its code now (inspector/cache.py)", name=name)
        if spec.submodule_search_locations:  # a package: all of it
            root = Path(spec.origin).parent
            files += [(f"{name}/{p.relative_to(root).as_posix()}", p) for p in sorted(root.rglob("*.py"))]
        else:
            files.append((name, Path(spec.origin)))
    return files


def _file_state(path: Path) -> list[Any]:
    try:
        st = path.stat()
        return [str(path), st.st_size, st.st_mtime_ns]
    except OSError:
        return [str(path), None, None]


def rollout_key(rollout, gt, limit_margin_deg: float, measures) -> str:
    """The cache key of a rollout's metrics (see the module docstring).

    Args:
        rollout: a :class:`inspector.data.session.Rollout`.
        gt: its :class:`inspector.data.ground_truth.GroundTruth`.
        limit_margin_deg: the joint-limit margin the numbers were computed with [deg].
        measures: the :class:`inspector.analysis.measure_settings.MeasureSettings` they were
            computed with (its ``cache_key()``).
    """
    root = Path(rollout.root).resolve()
    files = sorted(p for p in root.rglob("*") if p.is_file())
    imported = _imported_from(rollout)
    clips = {v: list(c.key) for v, c in sorted(gt.clips.items())}
    if imported is None:
        identity: dict[str, Any] = {"rollout": str(root), "files": [_file_state(p) for p in files]}
    else:  # a temporary import: its own paths and times are new each time, its source's are not
        session_json = Path(rollout.session.root) / "session.json"
        identity = {"imported_from": imported, "tag": rollout.tag, "session": _content(session_json),
                    "files": [_derived_state(p, root) for p in files]}
        clips = {v: [_relative(Path(k[0]).resolve(), root), *k[1:]] for v, k in clips.items()}
    state = {
        "code": code_fingerprint(),
        **identity,
        "units": rollout.units.to_json(),
        "gt": {"source": gt.source, "dataset_key": list(gt.dataset_key) if gt.dataset_key else None,
               "files": [_file_state(Path(p)) for p in gt.files],
               "clips": clips},
        "limit_margin_deg": float(limit_margin_deg),
        "measures": measures.cache_key(),
    }
    session = getattr(rollout, "session", None)
    if session is not None:  # the cameras the arm-masked PSNR and the gripper track were measured through
        # by content: a temporary import's root (and so its path) is new on every run
        cameras = getattr(session, "cameras_file", None) or Path(session.root) / "cameras.json"
        state["cameras"] = _content(Path(cameras))
    return hashlib.sha256(json.dumps(state, sort_keys=True, default=str).encode()).hexdigest()


def record_import_sources(session, source: str | Path, dataset: str | Path | None = None) -> None:
    """Write into ``session`` (:class:`inspector.data.session.Session`), just imported in memory
    from ``source``, what keys its rollouts' cache entries (:func:`rollout_key`): per rollout, the
    state (path, size, modification time) of every file of its source directory
    (``extra.source.path``, when that is a directory under ``source``, and ``extra.source.also_read``),
    else of every file under ``source``; with ``source``, ``dataset`` and the importers' code."""
    source = Path(source).resolve()
    whole: list[list[Any]] | None = None
    states = {}
    for tag, rollout in sorted(session.rollouts.items()):
        own = rollout.extra.get("source") if isinstance(rollout.extra, dict) else None
        where = Path(own["path"]).resolve() if isinstance(own, dict) and isinstance(own.get("path"), str) else None
        if where is not None and where.is_dir() and where.is_relative_to(source):
            # and the files beside it that the import also read (a list of samples lending its episode)
            also = own.get("also_read") if isinstance(own, dict) else None
            files = _tree_state(where) + [_file_state(Path(p)) for p in (also if isinstance(also, list) else [])
                                          if isinstance(p, str)]
        else:
            whole = _tree_state(source) if whole is None else whole
            files = whole
        state = {"code": code_fingerprint(IMPORT_MODULES), "source": str(source),
                 "dataset": None if dataset is None else str(dataset), "files": files}
        states[tag] = hashlib.sha256(json.dumps(state, sort_keys=True).encode()).hexdigest()
    data = json_text({"schema": SCHEMA, "rollouts": states}).encode()
    try:
        (Path(session.root) / IMPORTED_FROM).write_bytes(data)
    except OSError:  # the cache is optional: without the record (or with a cut one, not JSON), its
        pass  # entries are keyed as any session's


def _imported_from(rollout) -> str | None:
    """The source state :func:`record_import_sources` wrote for ``rollout``, or None (a session
    of its own, or no such record)."""
    session = getattr(rollout, "session", None)
    if session is None:
        return None
    try:
        data = json.loads((Path(session.root) / IMPORTED_FROM).read_bytes())
    except (OSError, ValueError):
        return None
    states = data.get("rollouts") if isinstance(data, dict) and data.get("schema") == SCHEMA else None
    state = states.get(rollout.tag) if isinstance(states, dict) else None
    return state if isinstance(state, str) else None


def _tree_state(root: Path) -> list[list[Any]]:
    """(path, size, modification time) of every file under ``root``, by path."""
    return [_file_state(p) for p in sorted(p for p in root.rglob("*") if p.is_file())]


def _content(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _derived_state(path: Path, root: Path) -> list[Any]:
    """A file a temporary import wrote: its path in the rollout, and its content's hash (a video's
    is left out: it is cut from the source files the key holds)."""
    return [_relative(path, root), None if path.suffix == ".mp4" else _content(path)]


def _relative(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix() if path.is_relative_to(root) else str(path)


class MetricsCache:
    """Get and put per-rollout records (JSON objects of a declared shape) by key.

    Args:
        root: the cache directory (default :func:`default_dir`).
        enabled: False makes every get a miss and every put a no-op (``--no-cache``).
    """

    def __init__(self, root: str | Path | None = None, enabled: bool = True) -> None:
        self.root = Path(root) if root is not None else default_dir()
        self.enabled = enabled
        self._dir = self.root / "metrics"

    def _path(self, key: str) -> Path:
        return self._dir / key[:2] / f"{key}.json"

    def get(self, key: str, shape: Any) -> dict[str, Any] | None:
        """The record stored under ``key`` if it is whole, is ``key``'s, and matches ``shape`` (a
        ``TypedDict``); None otherwise (missing, unreadable, edited, of another shape)."""
        if not self.enabled:
            return None
        try:
            data = self._path(key).read_bytes()
        except OSError:
            return None
        return decode_entry(data, key, shape)

    def put(self, key: str, record: dict[str, Any], shape: Any) -> None:
        """Store ``record`` under ``key`` (atomically). A record that does not match ``shape`` (a
        NaN among its numbers, say) is not kept; a failure to write is noted (:func:`note_unusable`)."""
        if not self.enabled or mismatch(record, shape) is not None:
            return
        path = self._path(key)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = mkstemp_sibling(path, prefix=".")
            try:
                with os.fdopen(fd, "wb") as fh:
                    fh.write(encode_entry(key, record))
                os.replace(tmp, path)
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
        except OSError as exc:
            note_unusable(self.root, exc)


def encode_entry(key: str, record: dict[str, Any]) -> bytes:
    """An entry file's bytes: a header line (schema, key, SHA-256 of the rest), then the record."""
    # dumps, not dump: dump streams through the pure-Python encoder (5x slower)
    body = json_text(record).encode()
    header = json_text({"schema": SCHEMA, "key": key, "sha256": hashlib.sha256(body).hexdigest()})
    return header.encode() + b"\n" + body


def decode_entry(data: bytes, key: str, shape: Any) -> dict[str, Any] | None:
    """The record in an entry file's bytes, or None unless it is whole, ``key``'s and of ``shape``."""
    head, _, body = data.partition(b"\n")
    try:
        header = json.loads(head)
        if not (isinstance(header, dict) and header.get("schema") == SCHEMA and header.get("key") == key
                and header.get("sha256") == hashlib.sha256(body).hexdigest()):
            return None
        record = json.loads(body, parse_constant=_no_constants)
    except (ValueError, RecursionError):  # not JSON (or NaN, Infinity), nested past the stack
        return None
    return record if mismatch(record, shape) is None else None


def _no_constants(name: str) -> None:
    raise ValueError(f"{name} is not JSON")


# -- one warning per command ------------------------------------------------------------------


def note_unusable(where: str | Path, exc: OSError) -> None:
    """A cache at ``where`` could not be written: said once per command
    (:func:`inspector.progress.say_once_or_hold`), by the command even when a worker met it."""
    say_once_or_hold(f"warning: cache {one_line(where)} cannot be written ({one_line(exc.strerror or exc)}); "
                     "continuing without it")
