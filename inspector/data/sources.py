"""Open whatever a user points at: a session, one rollout of it, or another tool's raw output.

``report``, ``serve`` and ``export`` all take such paths; they share this one function so a path
means the same thing everywhere. Raw output, in any format of the importer registry
(:data:`.importers.FORMATS`), is imported into a temporary session that lives as long as the
returned :class:`Sources`.

``open_sources(..., confine=True)`` (what ``inspector serve`` uses) also refuses, before reading
them, ``session.json`` and every rollout whose directory or any file in it resolves (through
symbolic links) outside its session's directory: see :func:`check_confined`.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..cache import record_import_sources
from ..errors import InspectorError
from .cameras import sidecar_path as cameras_sidecar
from .importers import GROOT_DREAMS, format_named, no_layout_fits, open_trajectories, recognised
from .lerobot_dataset import INFO_PATH, REPO_ID, dataset_file_roots, find_dataset, is_lerobot_dataset, open_dataset
from .session import OUTCOMES_SIDECAR_SUFFIX, Rollout, Session, is_rollout, is_session, open_session

BUNDLED_DEMO = Path(__file__).resolve().parents[2] / "sessions" / "demo"


@dataclass
class Sources:
    """Sessions (and LeRobot datasets) opened from user paths. ``roots`` are the directories the
    app may read under."""

    sessions: list[Session] = field(default_factory=list)
    roots: list[Path] = field(default_factory=list)
    datasets: list = field(default_factory=list)  # LeRobotDataset, their episodes browsed on their own
    # (path as given, why) of the paths that could not be opened (``open_sources(keep_going=True)``)
    unusable: list[tuple[str, InspectorError]] = field(default_factory=list)
    _temps: list[tempfile.TemporaryDirectory] = field(default_factory=list, repr=False)

    def rollouts(self) -> Iterator[tuple[Session, Rollout]]:
        for session in self.sessions:
            for tag in sorted(session.rollouts):
                yield session, session.rollouts[tag]

    def serves(self, path: str | Path) -> bool:
        """True when ``path`` resolves to one of ``roots`` or to something under one."""
        return _under(Path(path).resolve(), self.roots)

    def close(self) -> None:
        for t in self._temps:
            t.cleanup()
        self._temps.clear()


def open_sources(paths: Sequence[str | Path], dataset: str | Path | None = None,
                 confine: bool = False, lazy: bool = False, datasets: bool = False,
                 calibration: str | None = None, keep_going: bool = False) -> Sources:
    """Open each path as a session (a rollout path opens its session filtered to that rollout).

    A session named more than once (itself, or several of its rollouts) is opened once, holding
    every rollout named.

    Args:
        paths: sessions, rollout directories, or DreamZero-SO101 source directories.
        dataset: a LeRobot dataset to take GT from when a session names none.
        confine: refuse (as rollout errors, before reading them) rollouts whose directory or any
            file in it resolves outside the session directory; the app serves with this on.
        lazy: read rollouts' arrays on first use (``open_session(..., lazy=True)``).
        datasets: also take LeRobot datasets (a directory, or ``org/name`` in the local LeRobot
            cache) and GR00T-Dreams neural trajectories into ``Sources.datasets`` (only their
            metadata and episode index are read).
        calibration: a GR00T-Dreams dump's calibration (``--calibration``; None: its default).
        keep_going: a path that cannot be opened goes to ``Sources.unusable`` and the others
            open (the app serves what it can); only when none opens is its error raised.

    Raises:
        InspectorError: a path is missing or is none of the above (or, confined, its
            ``session.json`` resolves outside the session directory); with ``keep_going``, only
            when every path is.
    """
    out = Sources()
    try:
        for raw in paths:
            try:
                if datasets and _open_dataset(out, raw, confine, calibration):
                    continue
                _open_one(out, raw, dataset, confine, lazy)
            except InspectorError as exc:
                if not keep_going:
                    raise
                out.unusable.append((str(raw), exc))
        if out.unusable and not out.sessions and not out.datasets:
            raise out.unusable[0][1]
    except BaseException:
        out.close()  # temporary sessions of the paths already opened
        raise
    return out


def _open_one(out: Sources, raw: str | Path, dataset: str | Path | None, confine: bool = False,
              lazy: bool = False) -> None:
    """Open one path of :func:`open_sources` into ``out``."""
    path = Path(os.path.expanduser(raw))  # '~nosuchuser' stays as it is: not found
    if not path.exists():
        raise InspectorError(path, "not found")
    path = path.resolve()

    def opened(root: Path) -> Session:
        root = root.resolve()
        return open_session(root, check=(lambda p: check_confined(p, [root])) if confine else None, lazy=lazy)

    if is_session(path):
        session = opened(path)
    elif is_rollout(path) and is_session(path.parent.parent):
        session = opened(path.parent.parent)
        keep = path.name
        session.rollouts = {k: v for k, v in session.rollouts.items() if k == keep}
        session.errors = {k: v for k, v in session.errors.items() if k == keep}
    else:
        session_path, handle, errors = _import_raw(path, dataset)
        out._temps.append(handle)
        session = opened(session_path)
        record_import_sources(session, path, dataset)  # its cache entries are keyed by the source's files
        session.outcomes_file = path.resolve().parent / f"{path.resolve().name}{OUTCOMES_SIDECAR_SUFFIX}"
        session.cameras_file = cameras_sidecar(path)
        session.errors.update(errors)
        out.roots.append(Path(handle.name))
    if dataset is not None and session.dataset_root is None:

        session.gt_source["dataset"] = str(find_dataset(dataset, download=True))
    same = next((s for s in out.sessions if s.root.resolve() == session.root.resolve()), None)
    if same is not None:  # named twice (or two of its rollouts named): one session, their union
        same.rollouts.update(session.rollouts)
        same.errors.update(session.errors)
        return
    out.sessions.append(session)
    out.roots.append(session.root.resolve())


def _import_raw(path: Path, dataset: str | Path | None
                ) -> tuple[Path, tempfile.TemporaryDirectory, dict[str, InspectorError]]:
    """Import another tool's output at ``path`` into a temporary session, by the first format of
    the registry (:data:`.importers.FORMATS`) it is in: (session path, handle to keep alive,
    {tag: error} of the runs left out). A GR00T-Dreams dump is refused: it opens as a dataset."""
    fmt = recognised(path)
    if fmt is None:
        raise no_layout_fits(path)
    return fmt.importer.load_in_memory(path, dataset=dataset)


def _open_dataset(out: Sources, raw: str | Path, confine: bool, calibration: str | None = None) -> bool:
    """Open ``raw`` into ``out.datasets`` when it names a LeRobot dataset (or a GR00T-Dreams dump);
    False when it does not."""
    path = Path(os.path.expanduser(raw))
    if _is_trajectories(path):
        root = path.resolve()
        if confine:
            check_confined(root / INFO_PATH, [root])
        trajectories = open_trajectories(root, calibration)
        _ = trajectories.episodes, trajectories.fps  # the index: read now, so a broken one is refused now
        if all(d.root != trajectories.root for d in out.datasets):
            out.datasets.append(trajectories)
            out.roots.append(root)
        return True
    if path.exists():
        if not (is_lerobot_dataset(path) or ((path / INFO_PATH).is_file() and not is_session(path))):
            return False
        root = path.resolve()
    elif REPO_ID.match(str(raw)):
        try:
            root = find_dataset(str(raw), download=True).resolve()
        except InspectorError as exc:  # neither a path nor a dataset here: say how to get one
            raise InspectorError(path, f"not found: no such path, and {exc.what}") from None
    else:
        return False
    # a hub cache snapshot's files are symlinks into the repository's blobs/: read there too
    allowed = dataset_file_roots(root)
    if confine:
        check_confined(root / INFO_PATH, allowed)
    ds = open_dataset(root)
    _ = ds.episodes  # the index: read now, so a broken one is refused now
    if all(d.root != ds.root for d in out.datasets):
        out.datasets.append(ds)
        out.roots.extend(allowed)
    return True


def _is_trajectories(path: Path) -> bool:
    """A GR00T-Dreams dump: opened as a dataset of trajectories, never imported in memory."""
    fmt = format_named(GROOT_DREAMS)
    return fmt is not None and fmt.importer.recognises(path)


def check_confined(path: str | Path, roots: Iterable[str | Path]) -> None:
    """Refuse ``path`` when it, or anything under it, resolves outside every one of ``roots``.

    Every entry is resolved through its symbolic links, and the walk follows the links that stay
    inside (each directory once), so no file reachable under ``path`` leads elsewhere. Nothing is
    read but directory listings.

    Raises:
        InspectorError: naming the first entry at fault, e.g. ``rollouts/ep0/video/front.mp4:
            resolves outside the served roots (to /elsewhere/front.mp4) ...``.
    """
    allowed = [Path(r).resolve() for r in roots]
    seen: set[Path] = set()
    stack = [Path(path)]
    while stack:
        entry = stack.pop()
        try:
            target = entry.resolve()
        except (RuntimeError, OSError):  # a link loop (RuntimeError before Python 3.13): leads nowhere
            continue
        if not _under(target, allowed):
            raise InspectorError(entry, f"resolves outside the served roots (to {target}); only files under "
                                        f"{', '.join(map(str, allowed))} are served, so it is not read")
        if target in seen or not target.is_dir():
            continue
        seen.add(target)
        try:
            names = sorted(os.listdir(entry))
        except OSError:
            continue  # unreadable: whoever reads it reports that
        stack.extend(entry / name for name in reversed(names))


def _under(path: Path, roots: Iterable[Path]) -> bool:
    return any(path == r or path.is_relative_to(r) for r in roots)
