"""The policy servers' wire format: msgpack with NumPy arrays as openpi-client's ``msgpack_numpy``
encodes them, byte for byte (``tests/data/openpi_msgpack/`` holds bytes made by openpi-client's
own packer, and the tests compare).

An array travels as a map with *binary* keys::

    {b"__ndarray__": True, b"data": <C-order bytes>, b"dtype": "<f4", b"shape": [24, 6]}

and a NumPy scalar as ``{b"__npgeneric__": True, b"data": <item>, b"dtype": "<f8"}``. Object,
void and complex arrays are refused (openpi-client refuses them too: never pickle).

openpi-client itself pins ``numpy<2``, so this module speaks the format over ``msgpack`` alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np

# The keys of an encoded array, as openpi-client writes them (bytes, packed as msgpack bin).
NDARRAY = b"__ndarray__"
NPGENERIC = b"__npgeneric__"


def _encode(obj: Any) -> Any:
    """msgpack's ``default`` hook: what it cannot pack itself (arrays, NumPy scalars)."""
    if isinstance(obj, (np.ndarray, np.generic)) and obj.dtype.kind in ("V", "O", "c"):
        raise ValueError(f"Unsupported dtype: {obj.dtype}")
    if isinstance(obj, np.ndarray):
        return {NDARRAY: True, b"data": obj.tobytes(), b"dtype": obj.dtype.str, b"shape": obj.shape}
    if isinstance(obj, np.generic):
        return {NPGENERIC: True, b"data": obj.item(), b"dtype": obj.dtype.str}
    raise TypeError(f"cannot serialize {type(obj).__name__}")


def _decode(obj: dict) -> Any:
    """msgpack's ``object_hook``: an encoded array or scalar back to NumPy, any other map as is."""
    if NDARRAY in obj:
        return np.ndarray(buffer=obj[b"data"], dtype=np.dtype(obj[b"dtype"]), shape=obj[b"shape"])
    if NPGENERIC in obj:
        return np.dtype(obj[b"dtype"]).type(obj[b"data"])
    return obj


def packb(obj: Any) -> bytes:
    """``obj`` (maps, lists, strings, numbers, arrays) as one msgpack message."""
    import msgpack

    return msgpack.packb(obj, default=_encode)


def unpackb(data: bytes) -> Any:
    """One msgpack message back to Python; arrays come back read-only, viewing ``data``.

    Raises:
        ValueError: not a msgpack message, or an array whose bytes do not fit its shape and dtype.
    """
    import msgpack

    try:
        return msgpack.unpackb(data, object_hook=_decode)
    except (msgpack.UnpackException, ValueError, TypeError, KeyError) as exc:
        raise ValueError(f"not a msgpack_numpy message ({type(exc).__name__}: {exc})") from None
