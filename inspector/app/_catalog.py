"""Every rollout the app serves, and what is computed for each, once, shared by all tabs.

The picker shows labels; a label maps to an :class:`Entry` in a dict built at start-up from the
sessions under the served roots. Nothing a browser sends is ever used as a path: a name that is
not a key of that dict is simply not found. A rollout whose directory or files resolve (through
symbolic links) outside its session directory is refused, at start-up and again when opened.

Opening a rollout builds its :class:`~inspector.timeline.RolloutTimeline`, its scene arrays and
its frame store once, behind a per-rollout lock (two tabs opening it at once wait for one build).
The most recently opened rollouts stay built (:data:`KEEP_LOADED`, a few MB each: their frames
live in the server's frame cache); older ones are dropped and rebuilt when opened again. Video
metrics come from, and go to, the on-disk metrics cache. A failure is shown on an error card; it
is retried on the next open.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path

from ..errors import InspectorError
from ..session import Rollout, Session
from ..sources import Sources, check_confined
from ..timeline import RolloutTimeline, build_timeline
from ._frames import FrameCache, FrameStore
from ._scene import RolloutScene

# Built rollouts kept for reopening (the tabs hold on to the ones they show).
KEEP_LOADED = 16


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

    def __init__(self, sources: Sources, executor: Executor, joint_links: dict[str, str],
                 frame_cache: FrameCache | None = None, metrics_cache=None) -> None:
        self.sources = sources
        self._executor = executor
        self._joint_links = joint_links
        self.frame_cache = frame_cache if frame_cache is not None else FrameCache()
        self.metrics_cache = metrics_cache
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
        self._loaded: OrderedDict[str, Loaded] = OrderedDict()

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
                self._loaded.move_to_end(key)
                return done
            build_lock = self._build_locks.setdefault(key, threading.Lock())
        with build_lock:
            with self._lock:
                if key in self._loaded:
                    return self._loaded[key]
            loaded = self._build(entry)
            with self._lock:
                self._loaded[key] = loaded
                while len(self._loaded) > KEEP_LOADED:
                    self._loaded.popitem(last=False)
        loaded.frames.start()
        return loaded

    def loaded_count(self) -> int:
        with self._lock:
            return len(self._loaded)

    def _build(self, entry: Entry) -> Loaded:
        rollout = entry.rollout
        assert rollout is not None
        try:
            # Refused at start-up already when served; checked again in case a link appeared since.
            check_confined(rollout.root, [entry.session.root])
            tl = build_timeline(rollout)
            remember = self._video_metrics_cache(tl)
            scene = RolloutScene.from_timeline(tl, self._joint_links)
        except InspectorError:
            raise
        except Exception as exc:  # any failure becomes an error card naming the rollout
            what = f"cannot build the timeline ({type(exc).__name__}: {exc})"
            raise InspectorError(Path(rollout.root), what) from exc
        return Loaded(entry, tl, scene, FrameStore(tl, self._executor, self.frame_cache, remember))

    def _video_metrics_cache(self, tl: RolloutTimeline):
        """Put the metrics cache's video metrics into ``tl``; returns what stores new ones there."""
        cache = self.metrics_cache
        if cache is None:
            return None
        from ..cache import rollout_key
        from ..video_metrics import VideoMetrics

        key = rollout_key(tl.rollout, tl.gt, tl.limit_margin_deg)
        record = cache.get(key) or {}
        for data in (record.get("video") or {}).values():
            tl.set_video_metrics(VideoMetrics.from_json(data))
        lock = threading.Lock()

        def remember(vm: VideoMetrics) -> None:
            with lock:  # views finish on different threads: merge into one record
                current = cache.get(key) or {}
                video = dict(current.get("video") or {})
                video[vm.view] = vm.to_json()
                cache.put(key, {"row": current.get("row"), "video": video})

        return remember
