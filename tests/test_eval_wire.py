"""The policy servers' wire format: ``inspector.eval.wire`` packs what openpi-client's own
``msgpack_numpy`` packer packs, to the same bytes (captured once into ``tests/data/openpi_msgpack``
by its ``capture.py``, which says how to capture them again), and reads them back."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from inspector.eval.wire import packb, unpackb

CAPTURED = Path(__file__).resolve().parent / "data" / "openpi_msgpack"


def _captured_messages() -> dict[str, object]:
    spec = importlib.util.spec_from_file_location("openpi_capture", CAPTURED / "capture.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.messages()


MESSAGES = _captured_messages()


def assert_same(found: object, expected: object, where: str = "") -> None:
    """Equal values, arrays with the same dtype and shape (a tuple reads back as a list)."""
    if isinstance(expected, np.ndarray):
        assert isinstance(found, np.ndarray), where
        assert found.dtype == expected.dtype and found.shape == expected.shape, where
        np.testing.assert_array_equal(found, expected)
    elif isinstance(expected, np.float64):  # a float subclass: msgpack packs it as a plain float
        assert type(found) is float and found == expected, where
    elif isinstance(expected, np.generic):
        assert type(found) is type(expected) and found == expected, where
    elif isinstance(expected, dict):
        assert isinstance(found, dict) and sorted(found) == sorted(expected), where
        for key in expected:
            assert_same(found[key], expected[key], f"{where}.{key}")
    elif isinstance(expected, (list, tuple)):
        assert isinstance(found, list) and len(found) == len(expected), where
        for i, (f, e) in enumerate(zip(found, expected)):
            assert_same(f, e, f"{where}[{i}]")
    else:
        assert type(found) is type(expected) and found == expected, where


def test_the_capture_covers_every_message() -> None:
    assert sorted(p.stem for p in CAPTURED.glob("*.msgpack")) == sorted(MESSAGES)
    assert "openpi-client 0.1.2" in (CAPTURED / "versions.txt").read_text()


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_packs_to_openpi_clients_bytes(name: str) -> None:
    assert packb(MESSAGES[name]) == (CAPTURED / f"{name}.msgpack").read_bytes()


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_reads_openpi_clients_bytes(name: str) -> None:
    assert_same(unpackb((CAPTURED / f"{name}.msgpack").read_bytes()), MESSAGES[name], name)


def test_an_array_reads_back_as_sent() -> None:
    chunk = np.random.default_rng(0).normal(size=(24, 6)).astype(np.float32)
    back = unpackb(packb({"action": chunk}))["action"]
    assert back.dtype == np.float32 and np.array_equal(back, chunk)


def test_object_and_complex_arrays_are_refused() -> None:
    for bad in (np.array([object()]), np.array([1 + 2j])):
        with pytest.raises(ValueError, match="Unsupported dtype"):
            packb({"x": bad})


def test_bytes_that_are_not_a_message_are_one_value_error() -> None:
    for bad in (b"\xc1", b"\x92\x01", packb({b"__ndarray__": True, b"data": b"abc", b"dtype": "<f8", b"shape": [2]})):
        with pytest.raises(ValueError, match="not a msgpack_numpy message"):
            unpackb(bad)


# ==============================================================================================
# What a server sends is untrusted: only boolean and numeric arrays whose bytes fit their shape

def _array(dtype: object = "<f8", shape: object = (2,), data: object = bytes(16), **more: object) -> bytes:
    """The encoding of an array as a server could craft it (any dtype, shape and data)."""
    import msgpack

    shape = list(shape) if isinstance(shape, tuple) else shape
    return msgpack.packb({b"__ndarray__": True, b"data": data, b"dtype": dtype, b"shape": shape, **more})


UNSAFE = {
    "object": _array("|O", [2], b"A" * 16),  # read as pointers 0x4141414141414141
    "object bare": _array("O", [1], b"A" * 8),
    "object in a structure": _array("<f8,|O", [1], b"A" * 16),
    "object in a list of fields": _array([["a", "|O"]], [1], b"A" * 8),
    "void": _array("|V8", [1], b"A" * 8),
    "subarray": _array("(2,)<f8", [1], bytes(16)),
    "datetime": _array("<M8[s]", [1], bytes(8)),
    "timedelta": _array("<m8[s]", [1], bytes(8)),
    "unicode": _array("<U2", [1], bytes(8)),
    "bytes": _array("|S3", [1], bytes(3)),
    "complex": _array("<c16", [1], bytes(16)),
    "long double": _array("<f16", [1], bytes(16)),
    "not a dtype": _array("<i16", [1], bytes(16)),
    "dtype not a string": _array(8, [1], bytes(8)),
    "too few bytes": _array("<f8", [24, 6], bytes(8)),
    "too many bytes": _array("<f4", [2], bytes(12)),
    "a shape that lies by wrapping": _array("<f8", [2 ** 61, 8], bytes(0)),  # 2**64 bytes: 0 in uint64
    "a huge shape": _array("<f8", [2 ** 40, 2 ** 20], bytes(16)),
    "a negative size": _array("<f8", [-2], bytes(16)),
    "negative sizes that multiply right": _array("<f8", [-1, -2], bytes(16)),
    "a bool size": _array("<f8", [True, 2], bytes(16)),
    "a float size": _array("<f8", [2.0], bytes(16)),
    "too many dimensions": _array("|u1", [1] * 65, bytes(1)),
    "a shape that is no list": _array("<f8", 2, bytes(16)),
    "data as text": _array("|u1", [3], "abc"),
    "no data": _array("|u1", [0], None),
}


@pytest.mark.parametrize("name", sorted(UNSAFE))
def test_unsafe_arrays_are_refused(name: str) -> None:
    with pytest.raises(ValueError, match="not a msgpack_numpy message") as info:
        unpackb(UNSAFE[name])
    assert "\n" not in str(info.value) and len(str(info.value)) < 400


def test_unsafe_scalars_are_refused() -> None:
    import msgpack

    for dtype, data in (("|O", 5), ("<c16", 1.0), ("<M8[s]", 3), ("<f8", b"x" * 10_000), ("<f8", [1.0]),
                        ("|u1", 300), ("|V8", b"AAAAAAAA")):
        message = msgpack.packb({b"__npgeneric__": True, b"data": data, b"dtype": dtype})
        with pytest.raises(ValueError, match="not a msgpack_numpy message") as info:
            unpackb(message)
        assert len(str(info.value)) < 400


def test_every_kind_a_server_sends_reads_back() -> None:
    """bool, every integer and float size, either byte order, 0-d and empty arrays: as sent."""
    for dtype in ("|b1", "|i1", "|u1", "<i2", ">u2", "<i4", ">i4", "<u4", "<i8", "<u8", "<f2", "<f4", ">f4", "<f8"):
        arr = np.arange(6).astype(dtype).reshape(2, 3)
        for sent in (arr, arr[:0], np.array(arr[0, 0])):
            back = unpackb(packb({"a": sent}))["a"]
            assert back.dtype == sent.dtype and back.shape == sent.shape and np.array_equal(back, sent)


def _walk(value: object) -> list[np.ndarray]:
    """Every array in a decoded message."""
    if isinstance(value, np.ndarray):
        return [value]
    if isinstance(value, dict):
        return [a for k, v in value.items() for a in (*_walk(k), *_walk(v))]
    if isinstance(value, list):
        return [a for v in value for a in _walk(v)]
    return []


def _messages() -> st.SearchStrategy[bytes]:
    """Arbitrary msgpack, and crafted arrays (any dtype string, any shape, any data) anywhere in it."""
    import msgpack

    ints = st.integers(-(2 ** 63), 2 ** 64 - 1)  # what msgpack can carry
    dtypes = (st.sampled_from(["|O", "O", "<f8,|O", "|V8", "|V0", "(2,)<f8", "<M8[s]", "<m8", "<U1", "|S1",
                               "<c8", "<c16", "<f16", "object", "float64", "<f8", "<f4", "|u1", ">i2", "|b1",
                               "", "x", "<f8\x00", "[('a', 'O')]"])
              | st.text(max_size=10) | ints | st.binary(max_size=8) | st.none()
              | st.lists(st.lists(st.text(max_size=3), max_size=2), max_size=2))
    sizes = st.integers(-3, 8) | ints | st.booleans() | st.floats() | st.text(max_size=2)
    shapes = st.lists(sizes, max_size=6) | ints | st.none() | st.lists(st.just(1), min_size=30, max_size=70)
    data = st.binary(max_size=96) | st.text(max_size=8) | ints | st.none()
    crafted = st.builds(lambda ndarray, d, t, s, drop: {k: v for k, v in
                                                        {b"__ndarray__": ndarray, b"data": d, b"dtype": t, b"shape": s}.items()
                                                        if k not in drop},
                        st.booleans() | ints, data, dtypes, shapes,
                        st.sets(st.sampled_from([b"data", b"dtype", b"shape"]), max_size=1))
    # arrays whose bytes do fit their shape and dtype (object ones included: the bytes would be pointers)
    itemsizes = {"|O": 8, "<c8": 8, "<c16": 16, "<M8[s]": 8, "<m8[s]": 8, "|V8": 8, "<U1": 4, "|S4": 4, "<f16": 16,
                 "<f8,|O": 16, "(2,)<f4": 8, "<f8": 8, ">f4": 4, "<f2": 2, "|u1": 1, "|i1": 1, "<i2": 2, ">u4": 4,
                 "<i8": 8, "|b1": 1}
    fitting = st.tuples(st.sampled_from(sorted(itemsizes)), st.lists(st.integers(0, 4), max_size=3),
                        st.randoms(use_true_random=False)).map(
        lambda t: {b"__ndarray__": True, b"dtype": t[0], b"shape": t[1],
                   b"data": t[2].randbytes(int(np.prod(t[1], dtype=np.int64)) * itemsizes[t[0]])})
    scalar = st.builds(lambda d, t: {b"__npgeneric__": True, b"data": d, b"dtype": t},
                       ints | st.floats() | st.booleans() | st.binary(max_size=9)
                       | st.text(max_size=3) | st.none(), dtypes)
    leaves = (st.none() | st.booleans() | ints | st.floats() | st.text(max_size=6)
              | st.binary(max_size=12) | crafted | fitting | scalar)
    values = st.recursive(leaves, lambda inner: st.lists(inner, max_size=4)
                          | st.dictionaries(st.text(max_size=4) | st.binary(max_size=4), inner, max_size=4),
                          max_leaves=12)
    packed = values.map(lambda v: msgpack.packb(v, use_bin_type=True))
    # ... and the same bytes cut short or changed at one place, and bytes that are no msgpack at all
    mangled = st.tuples(packed, st.integers(0, 10 ** 6), st.integers(0, 255)).map(
        lambda t: t[0][:t[1] % (len(t[0]) + 1)] + bytes([t[2]]) + t[0][t[1] % (len(t[0]) + 1) + 1:])
    arrays = st.dictionaries(st.sampled_from(["action", "video", "action.joint_position"]), fitting | crafted,
                             min_size=1, max_size=3).map(lambda v: msgpack.packb(v, use_bin_type=True))
    return packed | arrays | mangled | st.binary(max_size=64)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(_messages())
@pytest.mark.slow
def test_the_decoder_takes_anything(message: bytes) -> None:
    """Whatever a server sends decodes to boolean or numeric arrays whose bytes fit their shape,
    or is one ValueError; never an object array (whose use would read the bytes as pointers and
    take the process down, and this test with it), never another exception."""
    try:
        decoded = unpackb(message)
    except ValueError as exc:
        assert str(exc).startswith("not a msgpack_numpy message") and "\n" not in str(exc)
        assert len(str(exc)) < 400
        return
    for arr in _walk(decoded):
        event(f"array {arr.dtype.kind}")
        assert arr.dtype.kind in "biuf" and not arr.dtype.hasobject and arr.dtype.itemsize <= 8
        assert arr.nbytes == arr.size * arr.dtype.itemsize
        arr.tolist()  # reading every value: an object array from these bytes would crash here
        np.asarray(arr, np.float64)
