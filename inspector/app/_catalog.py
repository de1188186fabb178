"""Every rollout the app serves, and what is computed for each, once, shared by all tabs.

The picker shows labels; a label maps to an :class:`Entry` in a dict built at start-up from the
sessions under the served roots. Nothing a browser sends is ever used as a path: a name that is
not a key of that dict is simply not found. A rollout whose directory or files resolve (through
symbolic links) outside its session directory is refused, at start-up and again when opened.

Opening a rollout builds its :class:`~inspector.analysis.timeline.RolloutTimeline`, its scene arrays and
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

from ..analysis.measure_settings import DEFAULT_MEASURES, MeasureSettings
from ..analysis.timeline import RolloutTimeline, build_timeline
from ..analysis.video_metrics import VideoMetrics
from ..cache import rollout_key
from ..data.episodes import EpisodeRef, episode_refs, episode_rollout
from ..data.lerobot_dataset import dataset_name
from ..data.session import Rollout, Session
from ..data.sources import Sources, check_confined
from ..errors import InspectorError, one_line
from ..rows.entries import read_entry, write_entry
from ._frames import FrameCache, FrameStore
from ._scene import RolloutScene
from ._served_outcomes import ServedOutcomes

# Built rollouts kept for reopening (the tabs hold on to the ones they show).
KEEP_LOADED = 16


@dataclass(frozen=True)
class Entry:
    """One rollout of one served session (it may have failed to load: ``error``), or one episode
    of a served dataset (``episode``).
    """

    key: str  # unique label shown in the picker: "<session> / <tag>", "<dataset> / episode <i> ..."
    session: Session | None
    tag: str
    error: InspectorError | None = None
    episode: EpisodeRef | None = None

    @property
    def rollout(self) -> Rollout | None:
        return self.session.rollouts.get(self.tag) if self.session is not None else None

    @property
    def kind(self) -> str:
        if self.episode is not None:
            return "episode"
        r = self.rollout
        return r.kind if r is not None else "unreadable"


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
        matcher: where rollouts' frame matches run, after their frames (default: ``executor``).
        outcome_source: the outcome source the tables and the Label panel show
            (``--outcome-source``; None: the precedence rule).

    Attributes:
        outcomes: the served rollouts' outcome sources (:class:`~._served_outcomes.ServedOutcomes`).
    """

    def __init__(self, sources: Sources, executor: Executor, joint_links: dict[str, str],
                 frame_cache: FrameCache | None = None, metrics_cache=None,
                 matcher: Executor | None = None, outcome_source: str | None = None,
                 measures: MeasureSettings = DEFAULT_MEASURES) -> None:
        self.sources = sources
        self.outcomes = ServedOutcomes(outcome_source)
        self.measures = measures  # the sanity measures' tolerances (--completion-tol-deg, ...)
        self._executor = executor
        self._matcher = matcher
        self._joint_links = joint_links
        self.frame_cache = frame_cache if frame_cache is not None else FrameCache()
        self.metrics_cache = metrics_cache
        self.entries: dict[str, Entry] = {}
        names = _unique_names([(s.name, s.root) for s in sources.sessions]
                              + [(dataset_name(d), d.root) for d in sources.datasets])
        for session, name in zip(sources.sessions, names):
            for tag in session.tags():
                key = f"{name} / {tag}"
                self.entries[key] = Entry(key, session, tag, session.errors.get(tag))
        for ds, name in zip(sources.datasets, names[len(sources.sessions):]):
            for ref in episode_refs(ds):
                key = f"{name} / episode {ref.index} · {ref.length} frames ({ref.duration_s:.1f} s) · {ref.task}"
                self.entries[key] = Entry(key, None, ref.tag, episode=ref)
        for path, error in sources.unusable:  # a path given that could not be opened: its error card
            label = one_line(path)
            key = f"{label} (cannot be read)"
            self.entries[key] = Entry(key, None, label, error)
        self._lock = threading.Lock()
        self._build_locks: dict[str, threading.Lock] = {}
        self._loaded: OrderedDict[str, Loaded] = OrderedDict()

    def keys(self) -> list[str]:
        return list(self.entries)

    def default_key(self) -> str | None:
        """The first entry in the picker's order that loaded, else the first one."""
        return next((e.key for e in self.entries.values() if e.error is None), next(iter(self.entries), None))

    def get(self, key: str) -> Entry | None:
        return self.entries.get(key)

    def load(self, key: str, start_frames: bool = True) -> Loaded:
        """The rollout's shared data, built on first use.

        Args:
            start_frames: start decoding its videos now (else the caller starts them with
                ``loaded.frames.start()`` when it shows them; another tab's load may first).

        Raises:
            KeyError: ``key`` is not a served rollout.
            InspectorError: the rollout (or its GT) cannot be read; other exceptions are wrapped
                into one naming the rollout directory.
        """
        entry = self.entries[key]
        if entry.error is not None:
            raise entry.error
        with self._lock:
            loaded = self._loaded.get(key)
            if loaded is not None:
                self._loaded.move_to_end(key)
            build_lock = self._build_locks.setdefault(key, threading.Lock())
        if loaded is None:
            with build_lock:
                with self._lock:
                    loaded = self._loaded.get(key)
                if loaded is None:
                    loaded = self._build(entry)
                    with self._lock:
                        self._loaded[key] = loaded
                        while len(self._loaded) > KEEP_LOADED:
                            self._loaded.popitem(last=False)
        if start_frames:
            loaded.frames.start()  # nothing where they started already
        return loaded

    def loaded_count(self) -> int:
        with self._lock:
            return len(self._loaded)

    def _build(self, entry: Entry) -> Loaded:
        if entry.episode is not None:
            return self._build_episode(entry)
        rollout = entry.rollout
        assert rollout is not None and entry.session is not None
        try:
            # Refused at start-up already when served; checked again in case a link appeared since.
            check_confined(rollout.root, [entry.session.root])
            tl = build_timeline(rollout, measures=self.measures)
            remember = self._video_metrics_cache(tl)
            scene = RolloutScene.from_timeline(tl, self._joint_links)
        except InspectorError:
            raise
        except Exception as exc:  # any failure becomes an error card naming the rollout
            what = f"cannot build the timeline ({type(exc).__name__}: {exc})"
            raise InspectorError(Path(rollout.root), what) from exc
        return Loaded(entry, tl, scene, FrameStore(tl, self._executor, self.frame_cache, remember, self._matcher))

    def _build_episode(self, entry: Entry) -> Loaded:
        ref = entry.episode
        assert ref is not None
        try:
            rollout, gt = episode_rollout(ref.dataset, ref.index)
            tl = build_timeline(rollout, gt=gt)
            scene = RolloutScene.from_timeline(tl, self._joint_links)
        except InspectorError:
            raise
        except Exception as exc:
            raise InspectorError(ref.dataset.root, f"cannot read episode {ref.index} "
                                                   f"({type(exc).__name__}: {exc})") from exc
        return Loaded(entry, tl, scene, FrameStore(tl, self._executor, self.frame_cache))

    def _video_metrics_cache(self, tl: RolloutTimeline):
        """Put the metrics cache's video metrics into ``tl``; returns what stores new ones there."""
        cache = self.metrics_cache
        if cache is None:
            return None

        key = rollout_key(tl.rollout, tl.gt, tl.limit_margin_deg, tl.measures)
        for view, vm in read_entry(cache, key).video.items():
            if view in tl.video_views():
                tl.set_video_metrics(vm)
        lock = threading.Lock()

        def remember(vm: VideoMetrics) -> None:
            with lock:  # views finish on different threads: merge into one entry
                current = read_entry(cache, key)
                write_entry(cache, key, current.row, {**current.video, vm.view: vm})

        return remember


def _unique_names(named: list[tuple[str, Path]]) -> list[str]:
    """Picker names of served sessions and datasets: their own name, or their directory where
    two share a name, or the directory with its parent where those clash too."""
    names = [n for n, _ in named]
    out = []
    for name, root in named:
        if names.count(name) == 1:
            out.append(name)
            continue
        dirs = [r.name for n, r in named if n == name]
        out.append(f"{name} ({root.name})" if dirs.count(root.name) == 1 else f"{name} ({root.parent.name}/{root.name})")
    return out
