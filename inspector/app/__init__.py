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

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ._headless import HeadlessClient
    from ._server import InspectorApp, serve
    from ._state import TabState

__all__ = ["HeadlessClient", "InspectorApp", "TabState", "serve"]

# Imported when first asked for: a module of the app that needs none of viser (the annotations
# file, the Overview's table) is then imported without it, in a second instead of two.
_WHERE = {"HeadlessClient": "._headless", "InspectorApp": "._server", "serve": "._server", "TabState": "._state"}


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(_WHERE[name], __name__), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
