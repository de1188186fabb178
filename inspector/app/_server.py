"""``inspector serve``: the viser server, shared caches, and one :class:`TabState` per browser tab."""

from __future__ import annotations

import functools
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

from .._signals import note_stop_request, stop_requested
from ..analysis.measure_settings import DEFAULT_MEASURES, MeasureSettings
from ..cache import MetricsCache
from ..data.cameras import cameras_path
from ..data.session import is_session
from ..data.sources import BUNDLED_DEMO, Sources, open_sources
from ..errors import InspectorError
from ..jobs.pool import stop_pool
from ..robot.kinematics import kinematics
from . import DEFAULT_FRAME_CACHE_MB
from ._ab_mode import ABTab, served_sessions
from ._catalog import Catalog
from ._frames import FrameCache
from ._overview_rows import OverviewRows, start_workers
from ._robot import SharedRobot, joint_child_links
from ._state import TabState
from ._stop_watchdog import exit_if_stopping_hangs

# Background frame loaders, one per camera view of an opening rollout (up to four): decoding and
# JPEG encoding run outside the GIL, so views fill side by side and the cores stay busy.
DECODE_WORKERS = 4
# How long ``inspector serve`` waits for the app to stop after Ctrl-C before it exits anyway.
STOP_GRACE_S = 30.0


class InspectorApp:
    """A running inspector: the viser server, the served rollouts, and the open tabs.

    Args:
        sources: opened sessions (kept open, closed by :meth:`stop`).
        host, port: where to listen (port 0 picks a free port; a busy port moves up by one).
        cache_mb: the budget of the frame cache shared by every tab [MiB].
        metrics_cache: where video metrics are read and kept (default: the user's cache).
        ab: blind A/B mode: every tab compares pairs of sessions' rollouts (see ``._ab_mode``)
            instead of browsing them.
        outcome_source: the outcome source the Overview and the Label panel show
            (``--outcome-source``; None: a label over a file over sim/recording).
        overview_workers: the Overview's workers, started before the sessions were read
            (:func:`~._overview_rows.start_workers`); the app owns them from here.

    Attributes:
        catalog: the served rollouts and their shared data.
        overview_rows: the overview's summary row of every served rollout.
        tabs: ``{client_id: TabState}`` of the connected tabs.
        ab_tabs: ``{client_id: ABTab}`` of the connected tabs in A/B mode.
    """

    def __init__(self, sources: Sources, host: str = "127.0.0.1", port: int = 8080,
                 cache_mb: float = DEFAULT_FRAME_CACHE_MB, metrics_cache: MetricsCache | None = None,
                 ab: bool = False, outcome_source: str | None = None,
                 measures: MeasureSettings = DEFAULT_MEASURES,
                 overview_workers: ProcessPoolExecutor | None = None) -> None:
        import viser

        self.sources = sources
        self.ab = ab
        self.tabs: dict[int, TabState] = {}
        self.ab_tabs: dict[int, ABTab] = {}
        self._tabs_changed = threading.Condition()
        self._decoder = ThreadPoolExecutor(DECODE_WORKERS, thread_name_prefix="inspector-decode")
        # video-action frame matches, after a rollout's frames: one at a time, beside the decoders
        self._matcher = ThreadPoolExecutor(1, thread_name_prefix="inspector-match")
        # Meshes and the FK chain take ~1 s to load: start now, wait only where they are needed.
        loader = ThreadPoolExecutor(1, thread_name_prefix="inspector-robot")
        self._robot: Future[SharedRobot] = loader.submit(_load_robot)
        if any(cameras_path(session).is_file() for session in sources.sessions):
            loader.submit(_warm_overlay)  # the first rollout with a camera opens without waiting on them
        loader.shutdown(wait=False)  # the jobs still run; the thread exits after them
        self.frame_cache = FrameCache(int(cache_mb * 2**20))
        self.joint_links = joint_child_links()
        self.catalog = Catalog(sources, self._decoder, self.joint_links, self.frame_cache,
                               metrics_cache if metrics_cache is not None else MetricsCache(), self._matcher,
                               outcome_source=outcome_source, measures=measures)
        # Summary rows of every rollout for the overview, computed once for every tab. Where a tab
        # opens on the overview (more than one rollout), computing starts with the server: the
        # workers start and read their rollouts while the first tab is built, rather than after.
        self.overview_rows = OverviewRows(self.catalog, workers=overview_workers)
        self.server = viser.ViserServer(host=host, port=port, label="inspector", verbose=False)
        self.server.initial_camera.position = (0.40, -0.32, 0.28)
        self.server.initial_camera.look_at = (0.10, 0.0, 0.10)
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)
        if not ab and len(self.overview_rows) > 1:  # once the server is up: nothing below can fail
            self.overview_rows.start()
        else:
            self.overview_rows.drop_started_workers()

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def host(self) -> str:
        return self.server.get_host()

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def robot(self) -> SharedRobot:
        """The shared robot (blocks until its meshes are loaded)."""
        return self._robot.result()

    def _connect(self, client) -> None:
        if self.ab:
            try:
                robot: SharedRobot | None = self.robot()  # waits for the shared meshes on the first tab
            except Exception:  # the pair still compares by its videos and joint plots
                robot = None
            ab_tab = ABTab(served_sessions(self.sources.sessions), client, robot=robot,
                           joint_links=self.joint_links)
            with self._tabs_changed:
                self.ab_tabs[client.client_id] = ab_tab
                self._tabs_changed.notify_all()
            return
        tab = TabState(self, client)
        with tab.lock:  # whoever finds the tab in ``tabs`` waits on its lock for the first open
            with self._tabs_changed:
                self.tabs[client.client_id] = tab
                self._tabs_changed.notify_all()
            key = self.catalog.default_key()
            if key is not None and not tab.closed.is_set():
                tab.open(key)

    def _disconnect(self, client) -> None:
        with self._tabs_changed:
            tab = self.tabs.pop(client.client_id, None)
            ab_tab = self.ab_tabs.pop(client.client_id, None)
            self._tabs_changed.notify_all()
        for closing in (tab, ab_tab):
            if closing is not None:
                closing.close()

    def wait_for_tabs(self, n: int = 1, timeout: float = 60.0) -> list[TabState]:
        """Wait until ``n`` tabs are connected (and have opened their first rollout)."""
        deadline = time.monotonic() + timeout
        with self._tabs_changed:
            while len(self.tabs) < n:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"{len(self.tabs)} of {n} tabs connected after {timeout} s")
                self._tabs_changed.wait(left)
            tabs = list(self.tabs.values())
        for tab in tabs:  # a tab registers holding its lock until its first rollout is open
            with tab.lock:
                pass
        return tabs

    def stop(self) -> None:
        """Close every tab, stop the server and drop temporary sessions."""
        for tab in list(self.tabs.values()):
            tab.close()
        for ab_tab in list(self.ab_tabs.values()):
            ab_tab.close()
        self.overview_rows.stop()
        self.server.stop()
        self._decoder.shutdown(wait=False, cancel_futures=True)
        self._matcher.shutdown(wait=False, cancel_futures=True)
        self.sources.close()


@functools.lru_cache(maxsize=1)
def _load_robot() -> SharedRobot:
    """The FK chain and the arm's meshes, loaded once a process: apps served one after another
    in a process (a notebook's, a test run's) share them; every use of its URDF takes its lock."""
    kinematics()  # build the FK chain now rather than on the first rollout open
    return SharedRobot()


def _warm_overlay() -> None:
    """What drawing the arms into the frames and tracking the gripper load once a process (the
    coarse meshes, ~0.5 s; the FFTs' module, ~0.4 s), ready before a rollout needs them."""
    from ..analysis import gripper_track  # noqa: F401  (scipy.fft, on the tracker's first frame otherwise)
    from ..robot.silhouette import arm_mesh

    arm_mesh()


def serve(paths: Sequence[str | Path] | None = None, host: str = "127.0.0.1", port: int = 8080,
          share: bool = False, dataset: str | Path | None = None, block: bool = True,
          cache_mb: float = DEFAULT_FRAME_CACHE_MB, use_cache: bool = True,
          exit_when_stopped: bool = False, calibration: str | None = None, ab: bool = False,
          outcome_source: str | None = None, measures: MeasureSettings = DEFAULT_MEASURES) -> InspectorApp:
    """Serve sessions in the browser (the bundled demo when ``paths`` is empty).

    Args:
        paths: sessions, rollout directories, DreamZero-SO101 outputs or LeRobot datasets
            (directories, or ``org/name`` in the local LeRobot cache; see ``open_sources``).
        host: interface to bind; 127.0.0.1 unless the user asks otherwise.
        port: TCP port (0 = any free port).
        share: also request a public viser share URL.
        dataset: LeRobot dataset with the GT episodes, for sessions that name none.
        block: serve until Ctrl-C (then stop); False returns the running app at once.
        cache_mb: frame cache budget [MiB] (JPEGs sent to browsers, shared by all tabs).
        use_cache: read and keep video metrics in the on-disk metrics cache.
        exit_when_stopped: with ``block``, end the process as soon as the app has stopped (what
            the command line wants): the interpreter would otherwise wait for background work
            that no one needs any more (a rollout's videos still decoding, meshes loading),
            many seconds on a busy machine.
        calibration: a GR00T-Dreams dump's calibration (``--calibration``; None: its default).
        ab: blind A/B comparison of the sessions (``--ab``; see ``._ab_mode``).
        outcome_source: the outcome source the Overview's columns and the Label panel show
            (``--outcome-source``: label, file, sim or recording; None: the precedence rule).
            Labels made in the app are saved as source ``label`` either way.
        measures: the sanity measures' tolerances (completion's, the seam flag's).

    Returns:
        The :class:`InspectorApp` (``.port``, ``.url``, ``.stop()``, ``.tabs``).

    Raises:
        InspectorError: no path given and the bundled demo is not built, or a path is unreadable;
            with ``ab``, fewer than two sessions with rollouts.
    """
    paths = list(paths or [])
    if not paths:
        if not is_session(BUNDLED_DEMO):
            raise InspectorError(BUNDLED_DEMO, "the bundled demo session is not built yet; build it with "
                                 "`inspector demo --rebuild`, or serve a session: `inspector serve PATH`")
        paths = [BUNDLED_DEMO]
    # The Overview's workers start first: they import the report's modules while this process
    # reads the sessions, on a core that would otherwise wait.
    workers = None if ab else start_workers(paths)
    try:
        # no link leads out of a root; datasets are browsed episode by episode; a path that cannot
        # be opened is an error card, and the others are served
        sources = open_sources(paths, dataset=dataset, confine=True, datasets=True, keep_going=True,
                               calibration=calibration)
    except BaseException:
        if workers is not None:
            stop_pool(workers, grace_s=0)
        raise
    if ab and len(served_sessions(sources.sessions)) < 2:
        sources.close()
        raise InspectorError("--ab", f"blind comparison needs two or more sessions with rollouts "
                                     f"(got {len(served_sessions(sources.sessions))})")
    try:
        app = InspectorApp(sources, host=host, port=port, cache_mb=cache_mb,
                           metrics_cache=MetricsCache(enabled=use_cache), ab=ab, outcome_source=outcome_source,
                           measures=measures, overview_workers=workers)
    except BaseException:  # Ctrl-C while starting included: drop temporary sessions
        if workers is not None:
            stop_pool(workers, grace_s=0)
        sources.close()
        raise
    if not block:
        try:
            _announce(app, share)
        except BaseException:
            app.stop()
            raise
        return app
    restore_sigterm = _stop_on_sigterm()
    try:
        _announce(app, share)
        while not stop_requested():  # a SIGTERM whose exception was lost while starting
            # Short sleeps: a signal the kernel hands to another thread interrupts no sleep here,
            # and Python runs its handler only when this thread next wakes.
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        if exit_when_stopped:
            exit_if_stopping_hangs(STOP_GRACE_S)
        app.stop()
        restore_sigterm()
    if exit_when_stopped:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)  # the app and its temporary sessions are gone: nothing is left to clean up
    return app


def _stop_on_sigterm():
    """Make SIGTERM (``kill``, ``docker stop``, systemd) stop the app as Ctrl-C does, so imported
    sessions' temporary directories go with it rather than staying behind in the temp folder.
    Returns what puts the previous handler back. Signal handlers belong to the main thread: a
    server blocking in another thread leaves SIGTERM as it is."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def interrupt(signum, frame):
        note_stop_request()
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    return lambda: signal.signal(signal.SIGTERM, previous)


def _announce(app: InspectorApp, share: bool) -> None:
    """Say what is served where (and the share URL when asked for)."""
    sources = app.sources
    n_ok = sum(len(s.rollouts) for s in sources.sessions)
    n_bad = sum(len(s.errors) for s in sources.sessions) + len(sources.unusable)
    for _, error in sources.unusable:
        print(f"error: {error}", file=sys.stderr, flush=True)
    served = [f"{n_ok} rollout(s) from {len(sources.sessions)} session(s)"] if sources.sessions else []
    if sources.datasets:
        n_eps = sum(len(d.episodes) for d in sources.datasets)
        served.append(f"{n_eps} episode(s) of {len(sources.datasets)} dataset(s)")
    print(f"inspector: serving {' and '.join(served) or 'nothing'}"
          + (f" ({n_bad} could not be read; see the app)" if n_bad else "") + f" at {app.url}", flush=True)
    if share:
        url = app.server.request_share_url(verbose=False)
        print(f"inspector: share URL {url}" if url else "inspector: no share URL could be obtained", flush=True)
