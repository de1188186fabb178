"""What the parts of the app need from each other, as Protocols (viser's handles refer back to
their server the same way): a tab sees the server as an :class:`AppHost`, the overview and the
Label panel see their tab as an :class:`OverviewHost`, and the tab's overview as an
:class:`OverviewView`. The server imports the tab and the tab the overview, never the other way
round, so no import circle forms, and each part names exactly what it uses.
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


class OverviewView(Protocol):
    """What a tab's other parts use of its overview (:class:`._overview.OverviewPanel`)."""

    @property
    def visible(self) -> bool: ...

    @property
    def shown(self) -> list[Any]:
        """The rows the overview's table shows, in its order (each has a ``key``)."""
        ...

    def hide(self, start_frames: bool = True) -> None: ...


class OverviewHost(Protocol):
    """What the overview and the Label panel use of their tab (:class:`inspector.app.TabState`)."""

    app: AppHost
    client: Any  # viser.ClientHandle
    controls: ControlPanel
    right_panel: Any  # a viser GUI panel handle
    key: str | None
    closed: threading.Event
    client_id: int

    @property
    def overview(self) -> OverviewView | None:
        """The tab's overview; None while the tab is being built (the overview comes last)."""
        ...

    def open(self, key: str) -> bool: ...

    def start_frames(self) -> None: ...
