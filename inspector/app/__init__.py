"""The browser app (viser): ``inspector serve [PATH...]``.

Modules: ``_server`` (serve, InspectorApp), ``_state`` (TabState: one browser tab, and the scrub
step ``TabState.set_step``), ``_catalog`` (served rollouts and shared per-rollout data),
``_scene`` (arms, paths, trail), ``_frames`` (background video decoding, JPEG cache),
``_plots`` (uPlot charts with a cursor), ``_panels`` / ``_cards`` (GUI layout and HTML),
``_annotations`` (annotations.json under a file lock), ``_ab_mode`` (``serve --ab``: blind A/B
votes between sessions), ``_robot`` (shared decimated URDF),
``_headless`` (a browser-less client for tests and benchmarks), ``_host`` (what a tab needs from
the server and the overview from a tab, as Protocols).
"""

from ._headless import HeadlessClient
from ._server import InspectorApp, serve
from ._state import TabState

__all__ = ["HeadlessClient", "InspectorApp", "TabState", "serve"]
