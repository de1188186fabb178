"""A rollout's arrays: ``.npy`` files whose headers are checked on load and values read (and
checked: finite, not absurd) on first use, and arrays held in memory read the same way."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ..errors import InspectorError, require

# Joint values beyond this are no angle or gripper reading; it also keeps every squared distance
# the metrics take far below float64's overflow (~1e154 per value).
ABSURD_VALUE = 1e100


class ArrayValue:
    """An array held in memory, read like an :class:`NpyFile` (for rollouts made in memory)."""

    def __init__(self, values: npt.ArrayLike) -> None:
        self._values = np.asarray(values, np.float64)
        self.shape: tuple[int, ...] = tuple(self._values.shape)

    def load(self) -> npt.NDArray[np.float64]:
        return self._values

    def release(self) -> None:
        pass  # nothing to read again


class NoJoints(ArrayValue):
    """The actions of a video-only rollout: NaN of the shape its rollout.json gives, made when
    first read (a long rollout's steps cost nothing until then)."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.shape = tuple(shape)
        self._nan: npt.NDArray[np.float64] | None = None

    def load(self) -> npt.NDArray[np.float64]:
        if self._nan is None:
            self._nan = np.full(self.shape, np.nan)
        return self._nan

    def release(self) -> None:
        self._nan = None


class NpyFile:
    """A numeric ``.npy`` file: its header checked now, its values read (and checked) on first use.

    Args:
        path: the file.
        shape: expected shape; a string entry (e.g. ``"n_chunks"``) matches any size.

    Raises:
        InspectorError: unreadable, not numeric, or another shape (naming the file).
    """

    def __init__(self, path: Path, shape: tuple[int | str, ...]) -> None:
        self.path = path
        self.shape: tuple[int, ...] = _read_npy_header(path, shape)
        self._values: npt.NDArray[np.float64] | None = None
        self._lock = threading.Lock()

    def load(self) -> npt.NDArray[np.float64]:
        """The values as float64, checked (finite, not absurd); kept until :meth:`release`."""
        with self._lock:
            if self._values is None:
                self._values = load_array(self.path, self.shape)
            return self._values

    def release(self) -> None:
        with self._lock:
            self._values = None


def _read_npy_header(path: Path, shape: tuple[int | str, ...]) -> tuple[int, ...]:
    """The shape in a ``.npy`` header, checked against ``shape`` and a numeric dtype."""
    if not path.is_file():
        raise InspectorError(path, "file not found")
    try:
        # reads the header, maps the rest; a header whose shape overflows the size fails here
        # (numpy would only warn and go on)
        with np.errstate(over="raise"):
            mapped = np.load(path, mmap_mode="r", allow_pickle=False)
        found, dtype = mapped.shape, mapped.dtype
        del mapped
    except FloatingPointError:
        raise InspectorError(path, "the shape in its header is too large for any array") from None
    except Exception as exc:
        raise InspectorError(path, f"not a readable .npy array ({type(exc).__name__}: {exc})") from None
    require(dtype.kind in "fiu", path, f"expected a numeric array, found dtype {dtype}")
    _check_shape(path, shape, found)
    return tuple(int(n) for n in found)


def _check_shape(path: Path, expected: tuple[int | str, ...], found: tuple[int, ...]) -> None:
    pattern = "(" + ", ".join(str(s) for s in expected) + ")"
    require(len(found) == len(expected) and all(isinstance(e, str) or e == a for e, a in zip(expected, found)),
            path, f"shape: expected {pattern}, found {tuple(found)}")


def load_array(path: Path, shape: tuple[int | str, ...]) -> npt.NDArray[np.float64]:
    """Load a numeric ``.npy`` and check its shape and values.

    Args:
        path: the file.
        shape: expected shape; a string entry (e.g. ``"n_chunks"``) matches any size.

    Returns:
        float64 array.
    """
    if not path.is_file():
        raise InspectorError(path, "file not found")
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise InspectorError(path, f"not a readable .npy array ({type(exc).__name__}: {exc})") from None
    require(isinstance(arr, np.ndarray) and arr.dtype.kind in "fiu", path,
            f"expected a numeric array, found dtype {getattr(arr, 'dtype', type(arr).__name__)}")
    _check_shape(path, shape, arr.shape)
    arr = arr.astype(np.float64, copy=False)
    check_values(arr, path)
    return arr


def check_values(arr: npt.NDArray[np.float64], file: str | Path, what: str = "") -> None:
    """Raise unless every value is finite and no larger than :data:`ABSURD_VALUE` in magnitude.

    Args:
        what: prefix naming the field (e.g. ``"actions_pred: "``), empty for a whole file.
    """
    bad = ~np.isfinite(arr)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InspectorError(file, f"{what}non-finite value {arr[where]} at index {list(where)}")
    huge = np.abs(arr) > ABSURD_VALUE
    if huge.any():
        where = tuple(int(i) for i in np.argwhere(huge)[0])
        raise InspectorError(file, f"{what}absurd value {arr[where]:g} at index {list(where)} "
                                   f"(joint values must lie within +-{ABSURD_VALUE:g})")

