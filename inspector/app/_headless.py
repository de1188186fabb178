"""A browser-less viser client: it makes the app open a tab, for tests and benchmarks.

viser counts a websocket connection as a client once it has sent its first camera message; from
then on the app builds a :class:`~._state.TabState` for it exactly as for a browser tab. This
client sends that one message (plus, optionally, GUI value updates as a browser would) and reads
and discards everything the server sends, so the server's send queue never backs up.

Usage::

    with HeadlessClient(app.port) as client:
        tab = app.wait_for_tabs(1)[0]
        tab.set_step(10)
"""

from __future__ import annotations

import threading
from typing import Any

import msgspec


class HeadlessClient:
    """Connect to a local viser server as one client.

    Args:
        port: the server's port.
        host: the server's host.
    """

    def __init__(self, port: int, host: str = "127.0.0.1") -> None:
        import viser
        from websockets.sync.client import connect

        self._ws = connect(f"ws://{host}:{port}", subprotocols=[f"viser-v{viser.__version__}"],
                           max_size=None, open_timeout=10)
        self.received_bytes = 0
        self._stop = threading.Event()
        self._reader = threading.Thread(target=self._drain, name="headless-viser-client", daemon=True)
        self._reader.start()
        self._send_message("ViewerCameraMessage", wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.6, -0.6, 0.5),
                           fov=1.0, near=0.01, far=100.0, image_height=720, image_width=1280,
                           look_at=(0.15, 0.0, 0.1), up_direction=(0.0, 0.0, 1.0))

    def set_gui_value(self, uuid: str, value: Any) -> None:
        """Send what a browser sends when the user changes a control (e.g. drags a slider)."""
        self._send_message("GuiUpdateMessage", uuid=uuid, updates={"value": value})

    def _send_message(self, type_name: str, **fields: Any) -> None:
        self._ws.send(msgspec.msgpack.encode({"type": type_name, **fields}))

    def _drain(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self._ws.recv(timeout=0.5)
            except TimeoutError:
                continue
            except Exception:
                return  # closed
            self.received_bytes += len(msg)

    def close(self) -> None:
        self._stop.set()
        try:
            self._ws.close()
        finally:
            self._reader.join(timeout=2)

    def __enter__(self) -> HeadlessClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
