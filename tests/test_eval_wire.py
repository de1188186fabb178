"""The policy servers' wire format: ``inspector.eval.wire`` packs what openpi-client's own
``msgpack_numpy`` packer packs, to the same bytes (captured once into ``tests/data/openpi_msgpack``
by its ``capture.py``, which says how to capture them again), and reads them back."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

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
