"""A browser-less viser client: it makes the app open a tab, for tests and benchmarks.

viser counts a websocket connection as a client once it has sent its first camera message; from
then on the app builds a :class:`~._state.TabState` for it exactly as for a browser tab. This
client sends that one message (plus, optionally, GUI value updates as a browser would) and reads
everything the server sends, so the server's send queue never backs up. With ``observe=True`` it
also decodes the GUI messages, so a client of a server in another process can find a control by
its label, set it, and wait for what the page shows (e.g. the video panel's frames).

Usage::

    with HeadlessClient(app.port) as client:
        tab = app.wait_for_tabs(1)[0]
        tab.set_step(10)

    with HeadlessClient(port, observe=True) as client:      # a server started by `inspector serve`
        picker = client.wait_for_control("Rollout")
        client.set_gui_value(picker, client.control(picker)["props"]["options"][3])
        client.wait_until(lambda: "loading" not in client.html_containing("<div class='inspector-video'"))
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec


class HeadlessClient:
    """Connect to a local viser server as one client.

    Args:
        port: the server's port.
        host: the server's host.
        observe: decode the GUI messages the server sends (see :meth:`control`).
    """

    def __init__(self, port: int, host: str = "127.0.0.1", observe: bool = False) -> None:
        import viser
        from websockets.sync.client import connect
        from websockets.typing import Subprotocol

        self._ws = connect(f"ws://{host}:{port}", subprotocols=[Subprotocol(f"viser-v{viser.__version__}")],
                           max_size=None, open_timeout=10)
        self.received_bytes = 0
        self._observe = observe
        self._controls: dict[str, dict[str, Any]] = {}
        # with observe: every scene node created (name -> its message type and props), and how many
        # pose updates each node got
        self.scene_nodes: dict[str, dict[str, Any]] = {}
        self.pose_updates: dict[str, int] = {}
        self._changed = threading.Condition()
        self._stop = threading.Event()
        self._reader = threading.Thread(target=self._drain, name="headless-viser-client", daemon=True)
        self._reader.start()
        self._send_message("ViewerCameraMessage", wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.6, -0.6, 0.5),
                           fov=1.0, near=0.01, far=100.0, image_height=720, image_width=1280,
                           look_at=(0.15, 0.0, 0.1), up_direction=(0.0, 0.0, 1.0))

    def set_gui_value(self, uuid: str, value: Any) -> None:
        """Send what a browser sends when the user changes a control (e.g. drags a slider)."""
        self._send_message("GuiUpdateMessage", uuid=uuid, updates={"value": value})

    # -- observing (observe=True) ------------------------------------------------------------
    def control(self, uuid: str) -> dict[str, Any]:
        """The last known state of a GUI control: ``type``, ``value``, ``props`` (label, options,
        content, ...)."""
        with self._changed:
            return dict(self._controls[uuid])

    def find_control(self, label: str) -> str | None:
        """The uuid of the control labelled ``label`` (None if the page has none yet)."""
        with self._changed:
            for uuid, c in self._controls.items():
                if c["props"].get("label") == label:
                    return uuid
        return None

    def wait_for_control(self, label: str, timeout: float = 60.0) -> str:
        """The uuid of the control labelled ``label``, waiting for the page to create it."""
        found: list[str] = []

        def present() -> bool:
            uuid = self.find_control(label)
            if uuid is not None:
                found.append(uuid)
            return uuid is not None

        self.wait_until(present, timeout, f"a control labelled {label!r}")
        return found[0]

    def html_containing(self, marker: str) -> str:
        """The content of the HTML element whose content contains ``marker`` ("" if none)."""
        with self._changed:
            for c in self._controls.values():
                content = c["props"].get("content")
                if isinstance(content, str) and marker in content:
                    return content
        return ""

    def wait_until(self, condition: Callable[[], bool], timeout: float = 60.0, what: str = "the page") -> None:
        """Wait (re-checking whenever the server sends something) until ``condition()`` holds."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while not condition():
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"waited {timeout:g} s for {what}")
                self._changed.wait(min(left, 0.5))

    # -- the connection ----------------------------------------------------------------------
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
            if self._observe and isinstance(msg, bytes):
                self._read_gui(msg)

    def _read_gui(self, raw: bytes) -> None:
        """Keep the GUI messages (and the scene nodes' names, props and pose update counts) of one window of viser's wire format: two little-endian sizes,
        the zstd-compressed msgpack of the messages, then raw binary buffers (not needed here)."""
        import zstandard

        size = int.from_bytes(raw[:8], "little")
        compressed = int.from_bytes(raw[8:16], "little")
        inner = zstandard.ZstdDecompressor().decompress(raw[16:16 + compressed], max_output_size=size)
        window = msgspec.msgpack.decode(inner)
        with self._changed:
            for m in window.get("messages", ()):
                kind = m.get("type", "")
                if kind.startswith("Gui") and "props" in m and "uuid" in m:
                    self._controls[m["uuid"]] = {"type": kind, "value": m.get("value"), "props": dict(m["props"])}
                elif kind == "GuiUpdateMessage" and m.get("uuid") in self._controls:
                    control = self._controls[m["uuid"]]
                    for key, value in (m.get("updates") or {}).items():
                        if key == "value":
                            control["value"] = value
                        else:
                            control["props"][key] = value
                elif kind == "GuiRemoveMessage":
                    self._controls.pop(m.get("uuid"), None)
                elif kind in ("SetOrientationMessage", "SetPositionMessage") and "name" in m:
                    self.pose_updates[m["name"]] = self.pose_updates.get(m["name"], 0) + 1
                elif "name" in m and "props" in m and not kind.startswith("Gui"):
                    self.scene_nodes[m["name"]] = {"type": kind, "props": dict(m["props"])}
            self._changed.notify_all()

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
