"""A served checkpoint evaluated against a LeRobot dataset, open loop, over the DreamZero /
RoboArena websocket policy-server protocol: the wire format (``wire``), the client (``client``),
what a request holds (``observation``), what a reply must be (``replies``) and the run that writes
a session (``run``). Needs the ``eval`` extra (``msgpack``, ``websockets``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "EvalPlan": ".run",
    "EvalResult": ".run",
    "evaluate": ".run",
    "format_result": ".run",
    "plan_samples": ".run",
    "PolicyClient": ".client",
    "ServerConfig": ".client",
    "SampleError": ".client",
    "server_url": ".client",
    "map_cameras": ".observation",
    "chunk_from_reply": ".replies",
    "packb": ".wire",
    "unpackb": ".wire",
})

if TYPE_CHECKING:
    from .client import PolicyClient as PolicyClient
    from .client import SampleError as SampleError
    from .client import ServerConfig as ServerConfig
    from .client import server_url as server_url
    from .observation import map_cameras as map_cameras
    from .replies import chunk_from_reply as chunk_from_reply
    from .run import EvalPlan as EvalPlan
    from .run import EvalResult as EvalResult
    from .run import evaluate as evaluate
    from .run import format_result as format_result
    from .run import plan_samples as plan_samples
    from .wire import packb as packb
    from .wire import unpackb as unpackb
