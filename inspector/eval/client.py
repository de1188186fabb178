"""A client of the DreamZero / RoboArena websocket policy server, one request at a time.

The protocol (``eval_utils/policy_server.py`` of DreamZero, derived from RoboArena's):

1. The client connects; the server sends its config, one msgpack map (:class:`ServerConfig`).
2. Each request is one binary msgpack map (:mod:`inspector.eval.wire`) with ``"endpoint"``:
   ``"reset"`` (answered with a text frame, ``"reset successful"``) or ``"infer"`` (answered with
   a binary frame: the action chunk).
3. A request the server fails on is answered with the traceback as a text frame, then a close
   (code 1011).

Nothing here retries: a failure is a :class:`SampleError` with one line saying what happened, and
the connection it happened on is closed (a late reply must never be read as the next one's).

A message from the server (the config, a reply) larger than ``max_reply_bytes`` is refused as it
arrives, from the size in its frame header: the connection is closed (code 1009) before the rest
is read, so a server cannot make the client hold more than that. Its arrays are decoded as
:mod:`inspector.eval.wire` allows (numeric only, their bytes checked against their shapes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

from ..errors import InspectorError, one_line
from .wire import packb, unpackb

ACTION_SPACE = "joint_position"  # the only action space compared against joints
RESET_OK = "reset successful"
# The largest message accepted from a server by default [MB, 10**6 bytes]. DreamZero-SO101's
# reply is 1.5 MB (24 x 6 actions and 9 predicted frames of 176 x 320 in each of three views);
# this holds 80 of those, or about 140 predicted frames at 640 x 480. ``--max-reply-mb`` raises it.
DEFAULT_MAX_REPLY_MB = 128.0
SHOWN_CHARS = 300  # a server's text (a traceback's last line, a config value) shown up to this


def shorten(text: object, limit: int = SHOWN_CHARS) -> str:
    """``text`` on one line (control characters escaped), cut to ``limit`` characters with the
    number left out said: a server's message may be megabytes long."""
    line = one_line(" ".join(str(text).split()))
    return line if len(line) <= limit else f"{line[:limit]}... ({len(line) - limit} more characters)"


class SampleError(Exception):
    """One sample failed (an error reply, a timeout, a closed socket, a bad reply): one line."""


@dataclass(frozen=True)
class ServerConfig:
    """What the server sends on connect.

    Attributes:
        image_resolution: (height, width) the images are resized to, or None (sent as they are).
        n_external_cameras: external cameras it needs (``observation/exterior_image_{i}_left``).
        needs_wrist_camera: it needs ``observation/wrist_image_left``.
        needs_stereo_camera: it needs the ``_right`` image of each camera too.
        needs_session_id: it keeps history per ``session_id``.
        action_space: ``joint_position`` (others are not joint chunks and are refused).
        raw: the config as received.
    """

    image_resolution: tuple[int, int] | None
    n_external_cameras: int
    needs_wrist_camera: bool
    needs_stereo_camera: bool
    needs_session_id: bool
    action_space: str
    raw: dict[str, Any]

    @classmethod
    def parse(cls, message: Any, where: str) -> ServerConfig:
        """Validate a handshake message.

        Raises:
            InspectorError: naming ``where`` (the server) and the field at fault.
        """
        if not isinstance(message, dict):
            raise InspectorError(where, "handshake: expected the server's config (a map), found "
                                        f"{type(message).__name__}")
        res = message.get("image_resolution")
        if res is not None:
            ok = (isinstance(res, (list, tuple)) and len(res) == 2
                  and all(isinstance(v, int) and not isinstance(v, bool) and 0 < v <= 8192 for v in res))
            if not ok:
                raise InspectorError(where, f"handshake: image_resolution: expected [height, width], found {shorten(repr(res), 80)}")
            res = (int(res[0]), int(res[1]))
        n_ext = message.get("n_external_cameras", 1)
        if not isinstance(n_ext, int) or isinstance(n_ext, bool) or not 0 <= n_ext <= 16:
            raise InspectorError(where, f"handshake: n_external_cameras: expected 0..16, found {shorten(repr(n_ext), 80)}")
        flags = {}
        for key, default in (("needs_wrist_camera", True), ("needs_stereo_camera", False), ("needs_session_id", False)):
            value = message.get(key, default)
            if not isinstance(value, bool):
                raise InspectorError(where, f"handshake: {key}: expected true or false, found {shorten(repr(value), 80)}")
            flags[key] = value
        space = message.get("action_space", ACTION_SPACE)
        if space != ACTION_SPACE:
            raise InspectorError(where, f"handshake: action_space {shorten(repr(space), 80)}: only {ACTION_SPACE!r} chunks can be "
                                        "compared with the dataset's joints")
        return cls(image_resolution=res, n_external_cameras=n_ext, action_space=space,
                   raw={str(k): v for k, v in message.items()}, **flags)


def server_url(address: str) -> str:
    """``ws://host:port`` from ``ws://host:port``, ``wss://...`` or ``host:port``.

    Raises:
        InspectorError: not a websocket address with a host and a port.
    """
    url = address if "://" in address else f"ws://{address}"
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise InspectorError(address, f"not a server address ({exc}); expected ws://HOST:PORT or HOST:PORT") from None
    if parts.scheme not in ("ws", "wss") or not parts.hostname or port is None:
        raise InspectorError(address, "not a server address; expected ws://HOST:PORT or HOST:PORT")
    return url


def last_line(text: str) -> str:
    """The line of a traceback that says what went wrong (its last non-empty line), shortened."""
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return shorten(lines[-1]) if lines else "(empty message)"


class PolicyClient:
    """One connection to a policy server.

    Args:
        url: ``ws://host:port`` (see :func:`server_url`).
        timeout_s: how long to wait for the connection, the handshake and each reply [s].
        max_reply_bytes: the largest message accepted from the server (its config, a reply).

    Raises:
        SampleError: the server cannot be reached or its handshake does not arrive in time.
        InspectorError: the handshake is not a valid config.
    """

    def __init__(self, url: str, timeout_s: float, max_reply_bytes: int = int(DEFAULT_MAX_REPLY_MB * 1e6)) -> None:
        from websockets.sync.client import connect

        self.url = url
        self.timeout_s = timeout_s
        self.max_reply_bytes = max_reply_bytes
        try:
            # No keep-alive pings: a server busy in inference may not answer them (its event loop
            # is blocked), and each reply is bounded by timeout_s anyway. A message past
            # max_reply_bytes is refused from its header; at most a few frames wait in the queue
            # (a server sending what was not asked for cannot fill memory).
            self._ws = connect(url, open_timeout=timeout_s, close_timeout=1.0, compression=None,
                               max_size=max_reply_bytes, max_queue=4, ping_interval=None, ping_timeout=None)
        except TimeoutError:
            raise SampleError(f"cannot connect to {url}: no answer within {timeout_s:g} s") from None
        except OSError as exc:  # refused, unreachable, a name that does not resolve
            raise SampleError(f"cannot connect to {url} ({exc.strerror or exc})") from None
        except Exception as exc:  # websockets' handshake errors (not a websocket server, ...)
            raise SampleError(f"cannot connect to {url} ({type(exc).__name__}: {shorten(exc)})") from None
        message = self._receive("the server's config")
        if isinstance(message, str):
            self.close()
            raise SampleError(f"handshake: the server sent text instead of its config: {last_line(message)}")
        try:
            decoded = unpackb(message)
        except ValueError as exc:
            self.close()
            raise InspectorError(url, f"handshake: {exc}") from None
        try:
            self.config = ServerConfig.parse(decoded, url)
        except InspectorError:
            self.close()
            raise

    def reset(self, session_id: str) -> None:
        """The ``reset`` endpoint (a fresh history for ``session_id``)."""
        reply = self._request({"session_id": session_id, "endpoint": "reset"}, "the reset")
        if isinstance(reply, bytes) or reply.lstrip().startswith("Traceback"):
            text = "a binary frame" if isinstance(reply, bytes) else last_line(reply)
            self.close()
            raise SampleError(f"reset failed: {text}")

    def infer(self, observation: dict[str, Any]) -> Any:
        """The ``infer`` endpoint: the decoded reply (an array or a map)."""
        reply = self._request({**observation, "endpoint": "infer"}, "the reply")
        if isinstance(reply, str):
            self.close()
            raise SampleError(f"server error: {last_line(reply)}")
        try:
            return unpackb(reply)
        except ValueError as exc:
            self.close()
            raise SampleError(f"reply: {exc}") from None

    def close(self) -> None:
        self._ws.close()

    def _request(self, message: dict[str, Any], what: str) -> str | bytes:
        from websockets.exceptions import ConnectionClosed

        try:
            self._ws.send(packb(message))
        except ConnectionClosed as exc:
            raise SampleError(f"the server closed the connection ({_close_reason(exc)})") from None
        return self._receive(what)

    def _receive(self, what: str) -> str | bytes:
        from websockets.exceptions import ConnectionClosed

        try:
            return self._ws.recv(timeout=self.timeout_s)
        except TimeoutError:
            self.close()
            raise SampleError(f"no {what} within {self.timeout_s:g} s (--timeout)") from None
        except ConnectionClosed as exc:
            sent = getattr(exc, "sent", None)
            if sent is not None and sent.code == MESSAGE_TOO_BIG:
                raise SampleError(f"{what} is larger than {self.max_reply_bytes / 1e6:g} MB, refused unread "
                                  "(--max-reply-mb raises the limit)") from None
            raise SampleError(f"the server closed the connection before {what} ({_close_reason(exc)})") from None


MESSAGE_TOO_BIG = 1009  # the close code of a message past max_size (RFC 6455)


def _close_reason(exc: Exception) -> str:
    rcvd = getattr(exc, "rcvd", None)
    if rcvd is None:
        return "no close frame"
    return f"code {rcvd.code}" + (f": {shorten(rcvd.reason, 125)}" if rcvd.reason else "")
