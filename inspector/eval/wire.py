"""The policy servers' wire format: msgpack with NumPy arrays as openpi-client's ``msgpack_numpy``
encodes them, byte for byte (``tests/data/openpi_msgpack/`` holds bytes made by openpi-client's
own packer, and the tests compare).

An array travels as a map with *binary* keys::

    {b"__ndarray__": True, b"data": <C-order bytes>, b"dtype": "<f4", b"shape": [24, 6]}

and a NumPy scalar as ``{b"__npgeneric__": True, b"data": <item>, b"dtype": "<f8"}``. Object,
void and complex arrays are refused (openpi-client refuses them too: never pickle).

What arrives is untrusted (a server's bytes): it becomes boolean or numeric arrays only
(:data:`ALLOWED_KINDS`, items of at most 8 bytes, any byte order), whose shape is a list of
:data:`MAX_NDIM` or fewer non-negative sizes that multiply, with the item size, to exactly the
bytes sent. An object array built from a server's bytes would read them as pointers (a crash or
worse); a structured, void, string, datetime or complex array is nothing a policy server sends.
Anything else is refused as a ``ValueError``.

openpi-client itself pins ``numpy<2``, so this module speaks the format over ``msgpack`` alone.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

# The keys of an encoded array, as openpi-client writes them (bytes, packed as msgpack bin).
NDARRAY = b"__ndarray__"
NPGENERIC = b"__npgeneric__"

# Array kinds accepted from the wire: bool, signed and unsigned integers, floats (what
# openpi-client's packer sends for actions, states and images; it refuses object, void and complex).
ALLOWED_KINDS = "biuf"
MAX_ITEMSIZE = 8  # float16..float64, (u)int8..(u)int64, bool; no long double
MAX_NDIM = 32  # NumPy 1's limit (2's is 64)


def _encode(obj: Any) -> Any:
    """msgpack's ``default`` hook: what it cannot pack itself (arrays, NumPy scalars)."""
    if isinstance(obj, (np.ndarray, np.generic)) and obj.dtype.kind in ("V", "O", "c"):
        raise ValueError(f"Unsupported dtype: {obj.dtype}")
    if isinstance(obj, np.ndarray):
        return {NDARRAY: True, b"data": obj.tobytes(), b"dtype": obj.dtype.str, b"shape": obj.shape}
    if isinstance(obj, np.generic):
        return {NPGENERIC: True, b"data": obj.item(), b"dtype": obj.dtype.str}
    raise TypeError(f"cannot serialize {type(obj).__name__}")


def _dtype(value: Any) -> np.dtype:
    """An encoded dtype (its ``.str``, e.g. ``"<f4"``), if it is one of the allowed kinds."""
    if not isinstance(value, str) or len(value) > 16:
        raise ValueError(f"dtype: expected a NumPy type string such as '<f4', found {_show(value)}")
    try:
        dtype = np.dtype(value)
    except Exception:  # TypeError (not understood), SyntaxError and others for odd strings
        raise ValueError(f"dtype {_show(value)} is not a NumPy type") from None
    if dtype.kind not in ALLOWED_KINDS or dtype.itemsize > MAX_ITEMSIZE or dtype.hasobject:
        raise ValueError(f"dtype {_show(value)} ({dtype}) refused: only boolean, integer and float "
                         "arrays are accepted")
    return dtype


def _shape(value: Any) -> tuple[int, ...]:
    if not isinstance(value, list) or len(value) > MAX_NDIM or not all(
            type(n) is int and n >= 0 for n in value):
        raise ValueError(f"shape: expected a list of at most {MAX_NDIM} sizes >= 0, found {_show(value)}")
    return tuple(value)


def _decode(obj: dict) -> Any:
    """msgpack's ``object_hook``: an encoded array or scalar back to NumPy, any other map as is.

    Raises:
        ValueError: an array or scalar that is not a numeric one as described (module docstring).
    """
    if NDARRAY in obj:
        dtype, shape, data = _dtype(obj.get(b"dtype")), _shape(obj.get(b"shape")), obj.get(b"data")
        if not isinstance(data, bytes):
            raise ValueError(f"data: expected bytes, found {type(data).__name__}")
        size = math.prod(shape) * dtype.itemsize  # Python ints: no overflow
        if size != len(data):
            raise ValueError(f"an array {shape} {dtype} needs {size} bytes, {len(data)} sent")
        try:
            return np.ndarray(buffer=data, dtype=dtype, shape=shape)
        except Exception as exc:  # a zero-size shape past the address space, say
            raise ValueError(f"an array {_show(shape)} {dtype}: {exc}") from None
    if NPGENERIC in obj:
        dtype, data = _dtype(obj.get(b"dtype")), obj.get(b"data")
        if type(data) not in (bool, int, float):
            raise ValueError(f"a scalar {dtype}: expected a number, found {type(data).__name__}")
        try:
            with np.errstate(all="ignore"):
                return dtype.type(data)
        except Exception as exc:  # an int out of the type's range
            raise ValueError(f"a scalar {dtype}: {exc}") from None
    return obj


def _show(value: Any, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters (a server may send megabytes)."""
    text = repr(value) if not isinstance(value, (bytes, str)) or len(value) <= limit else repr(value[:limit])
    return text if len(text) <= limit else text[:limit] + "..."


def packb(obj: Any) -> bytes:
    """``obj`` (maps, lists, strings, numbers, arrays) as one msgpack message."""
    import msgpack

    return msgpack.packb(obj, default=_encode)


def unpackb(data: bytes) -> Any:
    """One msgpack message back to Python; arrays come back read-only, viewing ``data``.

    Raises:
        ValueError: not a msgpack message, or an array that is not a boolean or numeric one whose
            bytes fit its shape and dtype (one line).
    """
    import msgpack

    try:
        return msgpack.unpackb(data, object_hook=_decode)
    except (msgpack.UnpackException, ValueError, TypeError, KeyError, RecursionError) as exc:
        raise ValueError(f"not a msgpack_numpy message ({type(exc).__name__}: {_cut(str(exc))})") from None


def _cut(text: str, limit: int = 200) -> str:
    return text if len(text) <= limit else text[:limit] + "..."
