"""The browser app (viser): ``inspector serve [PATH...]``.

Modules: ``_server`` (serve, InspectorApp), ``_state`` (TabState: one browser tab, and the scrub
step ``TabState.set_step``), ``_catalog`` (served rollouts and shared per-rollout data),
``_scene`` (arms, paths, trail), ``_frames`` (background video decoding, JPEG cache),
``_plots`` (uPlot charts with a cursor), ``_panels`` / ``_cards`` (GUI layout and HTML),
``_annotations`` (annotations.json under a file lock), ``_robot`` (shared decimated URDF),
``_headless`` (a browser-less client for tests and benchmarks).
"""

from ._headless import HeadlessClient as HeadlessClient
from ._server import InspectorApp as InspectorApp
from ._server import serve as serve
from ._state import TabState as TabState
