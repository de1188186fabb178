"""Every rollout the app serves, and what is computed for each, once, shared by all tabs.

The picker shows labels; a label maps to an :class:`Entry` in a dict built at start-up from the
sessions under the served roots. Nothing a browser sends is ever used as a path: a name that is
not a key of that dict is simply not found. A rollout whose directory or files resolve (through
symbolic links) outside its session directory is refused, at start-up and again when opened.

Opening a rollout builds its :class:`~inspector.timeline.RolloutTimeline`, its scene arrays and
its frame store once, behind a per-rollout lock (two tabs opening it at once wait for one build).
A failure is kept and shown on an error card; it is retried on the next open.
"""

from __future__ import annotations

import threading
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path

from ..errors import InspectorError
from ..session import Rollout, Session
from ..sources import Sources, check_confined
from ..timeline import RolloutTimeline, build_timeline
from ._frames import FrameStore
from ._scene import RolloutScene


@dataclass(frozen=True)
class Entry:
    """One rollout of one served session (it may have failed to load: ``error``)."""

    key: str  # unique label shown in the picker: "<session> / <tag>"
    session: Session
    tag: str
    error: InspectorError | None = None

    @property
    def rollout(self) -> Rollout | None:
        return self.session.rollouts.get(self.tag)


@dataclass
class Loaded:
    """A rollout ready to show: the shared timeline plus what the app derives from it."""

    entry: Entry
    timeline: RolloutTimeline
    scene: RolloutScene
    frames: FrameStore


class Catalog:
    """The served rollouts, keyed by picker label, with lazily built shared data.

    Args:
        sources: the opened sessions.
        executor: pool for background video decoding.
        joint_links: joint name -> child link (for limit markers), from the shared robot.
    """

    def __init__(self, sources: Sources, executor: Executor, joint_links: dict[str, str]) -> None:
        self.sources = sources
        self._executor = executor
        self._joint_links = joint_links
        self.entries: dict[str, Entry] = {}
        names = [s.name for s in sources.sessions]
        for i, session in enumerate(sources.sessions):
            # Two sessions may share a name: the label then carries its directory too.
            name = session.name if names.count(session.name) == 1 else f"{session.name} ({session.root.name}#{i})"
            for tag in session.tags():
                key = f"{name} / {tag}"
                self.entries[key] = Entry(key, session, tag, session.errors.get(tag))
        self._lock = threading.Lock()
        self._build_locks: dict[str, threading.Lock] = {}
        self._loaded: dict[str, Loaded] = {}

    def keys(self) -> list[str]:
        return list(self.entries)

    def default_key(self) -> str | None:
        """The first rollout that loaded (autoregressive first: the richest view), else any."""
        good = [e for e in self.entries.values() if e.error is None]
        good.sort(key=lambda e: e.rollout.kind != "autoregressive")  # stable: keeps name order
        return good[0].key if good else next(iter(self.entries), None)

    def get(self, key: str) -> Entry | None:
        return self.entries.get(key)

    def load(self, key: str) -> Loaded:
        """The rollout's shared data, built on first use.

        Raises:
            KeyError: ``key`` is not a served rollout.
            InspectorError: the rollout (or its GT) cannot be read; other exceptions are wrapped
                into one naming the rollout directory.
        """
        entry = self.entries[key]
        if entry.error is not None:
            raise entry.error
        with self._lock:
            done = self._loaded.get(key)
            if done is not None:
                return done
            build_lock = self._build_locks.setdefault(key, threading.Lock())
        with build_lock:
            with self._lock:
                if key in self._loaded:
                    return self._loaded[key]
            loaded = self._build(entry)
            with self._lock:
                self._loaded[key] = loaded
        loaded.frames.start()
        return loaded

    def _build(self, entry: Entry) -> Loaded:
        rollout = entry.rollout
        assert rollout is not None
        try:
            # Refused at start-up already when served; checked again in case a link appeared since.
            check_confined(rollout.root, [entry.session.root])
            tl = build_timeline(rollout)
            scene = RolloutScene.from_timeline(tl, self._joint_links)
        except InspectorError:
            raise
        except Exception as exc:  # any failure becomes an error card naming the rollout
            what = f"cannot build the timeline ({type(exc).__name__}: {exc})"
            raise InspectorError(Path(rollout.root), what) from exc
        return Loaded(entry, tl, scene, FrameStore(tl, self._executor))
