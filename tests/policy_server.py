"""A real policy server for the tests: the DreamZero / RoboArena websocket protocol (the same
handshake, endpoints, msgpack_numpy encoding and error behaviour as DreamZero's
``eval_utils/policy_server.py``) on 127.0.0.1, answering known chunks and recording what it got.

Each ``infer`` is answered with the received state plus :func:`ramp` (so the chunk's error
against the dataset is known exactly), as an array (N, 6) or as the SO-101 map
``{"action.joint_position": (N, 5), "action.gripper_position": (N, 1)}``. Faults are planted by
the index of the ``infer`` request they answer (0, 1, ...).

It misbehaves on purpose too: a handshake of any bytes (``handshake``), and replies a client must
refuse: an object array (``"object"``: its bytes would be read as pointers), a chunk of
``long_rows`` steps (``"long"``), or one of ``huge_rows`` steps (``"huge"``, 8.3 million by
default: 400 MB, streamed in 1 MiB fragments so that the server never holds it).
"""

from __future__ import annotations

import struct
import threading
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from inspector.eval.wire import packb, unpackb

FAULTS = ("traceback", "close", "slow", "shape", "nan", "object", "long", "huge")
HUGE_ROWS = 8_300_000  # a chunk of 400 MB in float64


def object_array(shape: tuple[int, ...]) -> dict[bytes, Any]:
    """The wire encoding of an array of dtype object, its bytes 0x41...: read as an array they
    are pointers to nowhere (openpi-client's packer refuses to send one; a hostile server may)."""
    return {b"__ndarray__": True, b"data": b"A" * 8 * int(np.prod(shape)), b"dtype": "|O", b"shape": list(shape)}


def streamed_chunk(rows: int, piece: int = 1 << 20) -> Iterator[bytes]:
    """A reply (rows, 6) float64 of zeros in pieces of ``piece`` bytes: a websocket message sent as
    fragments, never whole in memory."""
    size = rows * 6 * 8
    yield (b"\x84" + packb(b"__ndarray__") + packb(True) + packb(b"dtype") + packb("<f8") + packb(b"shape")
           + packb([rows, 6]) + packb(b"data") + b"\xc6" + struct.pack(">I", size))
    zeros = bytes(piece)
    for start in range(0, size, piece):
        yield zeros if start + piece <= size else zeros[:size - start]


def ramp(horizon: int) -> np.ndarray:
    """(horizon, 6): step k, joint j -> 0.5 * (k + 1) * (j + 1) [data units]."""
    return 0.5 * np.outer(np.arange(1, horizon + 1), np.arange(1, 7)).astype(np.float64)


@dataclass
class Received:
    """One ``infer`` request as the server saw it."""

    session_id: str
    prompt: str
    image_shapes: dict[str, tuple[int, ...]]
    joint_position: np.ndarray
    gripper_position: np.ndarray
    keys: list[str]
    images: dict[str, np.ndarray]


@dataclass
class PolicyServer:
    """Settings and what was received (read them after the run)."""

    config: dict[str, Any]
    form: str = "array"  # or "map"
    horizon: int = 24
    faults: dict[int, str] = field(default_factory=dict)
    slow_s: float = 3.0
    scale: float = 1.0  # the ramp's scale (a "worse checkpoint" answers a steeper one)
    delay_s: float = 0.0  # every infer waits this long first
    video: tuple[int, int, int] | None = None  # (T, H, W) predicted frames under "video" (map form)
    echo: bool = False  # answer a fixed chunk at once, nothing recorded (benchmark)
    handshake: bytes | None = None  # sent on connect instead of the packed config
    long_rows: int = 5000  # steps of a "long" reply
    huge_rows: int = HUGE_ROWS  # steps of a "huge" reply
    infers: list[Received] = field(default_factory=list)
    resets: list[str] = field(default_factory=list)
    connections: int = 0
    port: int = 0
    _n_infer: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    def reply(self, obs: dict[str, Any], fault: str | None) -> Any:
        state = np.concatenate([np.asarray(obs["observation/joint_position"], np.float64),
                                np.asarray(obs["observation/gripper_position"], np.float64)])
        chunk = (state + self.scale * ramp(self.horizon)).astype(np.float32)
        if fault == "shape":
            chunk = np.zeros((self.horizon, 8), np.float32)
        if fault == "nan":
            chunk[3, 2] = np.nan
        if fault == "long":
            chunk = np.resize(chunk, (self.long_rows, 6))
        if self.form == "array":
            return chunk
        out: dict[str, Any] = {"action.joint_position": chunk[:, :-1], "action.gripper_position": chunk[:, -1:]}
        if self.video is not None:
            t, h, w = self.video
            out["video"] = np.full((t, h, w, 3), 128, np.uint8)
        return out

    def handle(self, ws) -> None:
        from websockets.exceptions import ConnectionClosed

        with self._lock:
            self.connections += 1
        ws.send(self.handshake if self.handshake is not None else packb(self.config))
        while True:
            try:
                obs = unpackb(ws.recv())
            except ConnectionClosed:
                return
            try:
                endpoint = obs.pop("endpoint")
                if endpoint == "reset":
                    with self._lock:
                        self.resets.append(str(obs.get("session_id")))
                    ws.send("reset successful")
                    continue
                if self.echo:
                    ws.send(self._echo_reply)
                    continue
                with self._lock:
                    index, self._n_infer = self._n_infer, self._n_infer + 1
                    self.infers.append(Received(
                        session_id=obs.get("session_id"), prompt=obs.get("prompt"),
                        image_shapes={k: tuple(v.shape) for k, v in obs.items() if isinstance(v, np.ndarray)
                                      and v.dtype == np.uint8},
                        joint_position=np.array(obs["observation/joint_position"]),
                        gripper_position=np.array(obs["observation/gripper_position"]), keys=sorted(obs),
                        images={k: np.array(v) for k, v in obs.items() if isinstance(v, np.ndarray) and v.ndim == 3}))
                fault = self.faults.get(index)
                if fault == "traceback":
                    raise ValueError("Expected 5 joint values, got shape (7,)")
                if fault == "close":
                    ws.close()
                    return
                if fault == "slow":
                    time.sleep(self.slow_s)
                if self.delay_s:
                    time.sleep(self.delay_s)
                if fault == "object":
                    ws.send(packb(object_array((self.horizon, 6))))
                elif fault == "huge":
                    ws.send(streamed_chunk(self.huge_rows))
                else:
                    ws.send(packb(self.reply(obs, fault)))
            except ConnectionClosed:
                return
            except Exception:
                # what DreamZero's server does: the traceback as text, then close with 1011
                try:
                    ws.send(traceback.format_exc())
                    ws.close(1011, "Internal server error. Traceback included in previous frame.")
                except ConnectionClosed:
                    pass
                return

    @property
    def _echo_reply(self) -> bytes:
        if not hasattr(self, "_echo_bytes"):
            self._echo_bytes = packb(np.zeros((self.horizon, 6), np.float32))
        return self._echo_bytes


DEFAULT_CONFIG = {"image_resolution": (96, 128), "n_external_cameras": 1, "needs_wrist_camera": True,
                  "needs_stereo_camera": False, "needs_session_id": True, "action_space": "joint_position"}


@contextmanager
def policy_server(**settings: Any) -> Iterator[PolicyServer]:
    """A running server on 127.0.0.1 (a free port), stopped on exit."""
    from websockets.sync.server import serve

    state = PolicyServer(config=settings.pop("config", dict(DEFAULT_CONFIG)), **settings)
    with serve(state.handle, "127.0.0.1", 0, compression=None, max_size=None, ping_interval=None) as server:
        state.port = server.socket.getsockname()[1]
        thread = threading.Thread(target=server.serve_forever, daemon=True)
        thread.start()
        try:
            yield state
        finally:
            server.shutdown()
            thread.join(timeout=10)
