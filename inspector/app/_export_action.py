"""The Export button: the open rollout's Rerun recording (``.rrd``) written in a thread and sent to
the tab as a download, its progress in a notification; the ``export`` extra missing, or a failed
export, is said there too, and never takes the tab down.

A part of :class:`~._state.TabState` (which inherits it): it meets the rest of the tab only
through the attributes declared below.
"""

from __future__ import annotations

import tempfile
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._catalog import Loaded
from ._host import AppHost


class TabExport:
    """Export the open rollout (see the module docstring).

    Attributes:
        export_result: what the last export did (for tests and logs).
    """

    # What the export uses of its tab (:class:`~._state.TabState` sets them).
    app: AppHost
    client: Any  # viser.ClientHandle
    client_id: int
    lock: threading.RLock
    loaded: Loaded | None
    export_result: str | None

    if TYPE_CHECKING:
        def _notify(self, title: str, body: str, color: str | None = None) -> None: ...

    def export(self) -> threading.Thread | None:
        """Write the open rollout's .rrd in a thread and send it to this tab as a download."""
        with self.lock:
            loaded = self.loaded
        if loaded is None:
            self._notify("Nothing to export", "Open a rollout first.", color="yellow")
            return None
        try:
            from ..export.recording import write_recording  # deferred: rerun takes ~0.6 s to import
        except ImportError as exc:
            hint = " Install it: pip install 'inspector[export]'." if getattr(exc, "name", "") == "rerun" else ""
            self._notify("Export unavailable", f"inspector.export.recording could not be imported ({exc}).{hint}",
                         color="red")
            return None
        tag = loaded.timeline.tag
        note = self.client.add_notification("Exporting", f"{tag}.rrd …", loading=True, with_close_button=False)
        self.export_result = None

        def progress(fraction: float, message: str) -> None:
            note.body = f"{tag}.rrd: {message} ({fraction:.0%})"

        def work() -> None:
            try:
                with tempfile.TemporaryDirectory(prefix="inspector-export-") as tmp:
                    path = Path(tmp) / f"{tag}.rrd"
                    write_recording(loaded.timeline, path, progress=progress,
                                    outcome_source=self.app.catalog.outcomes.prefer)
                    data = path.read_bytes()
                self.client.send_file_download(f"{tag}.rrd", data, save_immediately=True)
                note.title, note.body = "Exported", f"{tag}.rrd ({len(data) / 1e6:.1f} MB)"
                note.color = "green"
                self.export_result = f"sent {len(data)} bytes"
            except Exception as exc:  # report, never crash the tab
                message = " ".join(str(exc).split()) or type(exc).__name__
                note.title, note.body, note.color = "Export failed", message, "red"
                self.export_result = f"failed: {message}"
            note.loading = False
            note.with_close_button = True

        thread = threading.Thread(target=work, name=f"inspector-export-{self.client_id}", daemon=True)
        thread.start()
        return thread
