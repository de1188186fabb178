"""What the parts of the app need from each other, as Protocols (viser's handles refer back to
their server the same way): a tab sees the server as an :class:`AppHost`, the overview sees its
tab as an :class:`OverviewHost`. The server imports the tab and the tab the overview, never the
other way round, so no import circle forms, and each part names exactly what it uses.
"""

from __future__ import annotations

import threading
from typing import Any, Protocol

from ..data.sources import Sources
from ._catalog import Catalog
from ._overview_rows import OverviewRows
from ._panels import ControlPanel
from ._robot import SharedRobot


class AppHost(Protocol):
    """What a tab uses of the server (:class:`inspector.app.InspectorApp`)."""

    sources: Sources
    catalog: Catalog
    overview_rows: OverviewRows
    server: Any  # viser.ViserServer (viser is imported only by the server)

    def robot(self) -> SharedRobot:
        """The shared robot (blocks until its meshes are loaded)."""
        ...


class OverviewHost(Protocol):
    """What the overview uses of its tab (:class:`inspector.app.TabState`)."""

    app: AppHost
    client: Any  # viser.ClientHandle
    controls: ControlPanel
    right_panel: Any  # a viser GUI panel handle
    key: str | None
    closed: threading.Event
    client_id: int

    def open(self, key: str) -> bool: ...

    def start_frames(self) -> None: ...
