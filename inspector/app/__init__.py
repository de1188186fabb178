"""The browser app (viser): ``inspector serve [PATH...]``.

The server (``_server``) serves a catalog of rollouts (``_catalog``), each computed once and shared
by every tab; each browser tab is a ``TabState`` (``_state``: open a rollout, the scrub step
``TabState.set_step``), with its playback, notes, export and readout in modules of their own, the
Overview of every rollout (``_overview*``), and ``serve --ab``'s blind A/B tab (``_ab_mode``). The
parts see each other through the Protocols in ``_host``.

Every module, one line each, is on the map in docs/development.md ("Layout of the code"),
which tests/test_layout.py checks against the package.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ._headless import HeadlessClient
    from ._server import InspectorApp, serve
    from ._state import TabState

__all__ = ["DEFAULT_FRAME_CACHE_MB", "HeadlessClient", "InspectorApp", "TabState", "serve"]

# The in-memory frame cache (JPEGs sent to browsers, shared by every tab) [MiB]: here, in the
# package's face, so that the command line's --cache-mb default costs no import of viser.
DEFAULT_FRAME_CACHE_MB = 256

# Imported when first asked for: a module of the app that needs none of viser (the annotations
# file, the Overview's table) is then imported without it, in a second instead of two.
_WHERE = {"HeadlessClient": "._headless", "InspectorApp": "._server", "serve": "._server", "TabState": "._state"}


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(_WHERE[name], __name__), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
