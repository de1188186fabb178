"""JSON read back checked against the type that describes it, so that what was written is the
only thing ever read.

A record's shape is written once, as a ``TypedDict`` (the writer's return type, which mypy checks
against the code that builds it), and :func:`mismatch` checks a parsed JSON value against that very
type at run time. What it accepts: ``TypedDict`` (exactly its keys, in their declared order: a JSON
document's key order shows in what is printed from it), ``list[X]``, ``dict[str, X]``, ``X | None``,
``Literal[...]``, ``str``, ``bool``, ``int`` (not a bool), ``float`` (finite, not an int: a written
``1.0`` reads back as a float), ``Any``, and ``Annotated[X, Length(n)]`` / ``Annotated[X, Keys(names)]``
for a list of ``n`` items and a mapping with exactly ``names`` as keys, in order.

Example::

    class Drift(TypedDict):
        mean: float
        per_joint: Annotated[list[float], Length(6)]

    mismatch({"mean": 1.0, "per_joint": [0.0] * 6}, Drift)    # None: it conforms
    mismatch({"mean": "1.0", "per_joint": []}, Drift)         # "mean: a float expected, got '1.0'"
"""

from __future__ import annotations

import functools
import math
import types
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Literal, Union, get_args, get_origin, get_type_hints, is_typeddict


@dataclass(frozen=True)
class Length:
    """``Annotated[list[X], Length(n)]``: exactly ``n`` items."""

    n: int


@dataclass(frozen=True)
class Keys:
    """``Annotated[dict[str, X], Keys(names)]``: exactly these keys, in this order."""

    names: tuple[str, ...]

    def __init__(self, names: Sequence[str]) -> None:
        object.__setattr__(self, "names", tuple(names))


def mismatch(value: Any, tp: Any, where: str = "") -> str | None:
    """Where and how ``value`` (parsed JSON) departs from ``tp``, or None when it conforms."""
    if tp is Any:
        return None
    origin = get_origin(tp)
    if origin is Annotated:
        inner, *constraints = get_args(tp)
        return mismatch(value, inner, where) or _constraint_mismatch(value, constraints, where)
    if origin in (Union, types.UnionType):
        alternatives = get_args(tp)
        if any(mismatch(value, alt, where) is None for alt in alternatives):
            return None
        return _say(where, " or ".join(_name(alt) for alt in alternatives), value)
    if origin is Literal:
        return None if value in get_args(tp) and type(value) in (str, int, bool) else _say(where, f"one of {get_args(tp)}", value)
    if is_typeddict(tp):
        return _typeddict_mismatch(value, tp, where)
    if origin is list:
        if not isinstance(value, list):
            return _say(where, "a list", value)
        (item,) = get_args(tp)
        if item in _FAST_ITEMS and all(type(v) is float and math.isfinite(v) or v is None and item is not float
                                       for v in value):
            return None  # per-frame series: thousands of numbers, checked in one pass
        return next((m for i, v in enumerate(value) if (m := mismatch(v, item, f"{where}[{i}]"))), None)
    if origin is dict:
        if not isinstance(value, dict):
            return _say(where, "an object", value)
        key_type, item = get_args(tp)
        assert key_type is str, "JSON keys are strings"
        return next((m for k, v in value.items() if (m := mismatch(v, item, _join(where, k)))), None)
    if tp is float:
        ok = type(value) is float and math.isfinite(value)
        return None if ok else _say(where, "a finite float", value)
    if tp is int:
        return None if type(value) is int else _say(where, "an integer", value)
    if tp in (str, bool):
        return None if type(value) is tp else _say(where, _name(tp), value)
    if tp is None or tp is type(None):
        return None if value is None else _say(where, "null", value)
    raise TypeError(f"mismatch() cannot check {tp!r}")


_FAST_ITEMS = (float, float | None)


def _typeddict_mismatch(value: Any, tp: Any, where: str) -> str | None:
    if not isinstance(value, dict):
        return _say(where, f"an object ({tp.__name__})", value)
    fields = _fields(tp)
    if list(value) != list(fields):
        missing = [k for k in fields if k not in value]
        extra = [k for k in value if k not in fields]
        what = (f"no {missing[0]!r}" if missing else f"an unknown key {extra[0]!r}" if extra
                else "its keys out of order")
        return f"{where or 'the record'}: {what}"
    return next((m for k, field in fields.items() if (m := mismatch(value[k], field, _join(where, k)))), None)


@functools.cache
def _fields(tp: Any) -> dict[str, Any]:
    """A TypedDict's fields and their types, in declaration order (resolved once)."""
    return get_type_hints(tp, include_extras=True)


def _constraint_mismatch(value: Any, constraints: list[Any], where: str) -> str | None:
    for c in constraints:
        if isinstance(c, Length) and len(value) != c.n:
            return f"{where}: {c.n} items expected, got {len(value)}"
        if isinstance(c, Keys) and tuple(value) != c.names:
            return f"{where}: the keys {list(c.names)} expected, got {list(value)[:8]}"
    return None


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _name(tp: Any) -> str:
    if tp is type(None):
        return "null"
    if is_typeddict(tp):
        return f"an object ({tp.__name__})"
    origin = get_origin(tp)
    if origin is Annotated:
        return _name(get_args(tp)[0])
    return {list: "a list", dict: "an object", float: "a finite float", int: "an integer", str: "a string",
            bool: "a boolean"}.get(origin or tp, str(tp))


def _say(where: str, expected: str, value: Any) -> str:
    shown = repr(value)
    return f"{where or 'the record'}: {expected} expected, got {shown if len(shown) <= 40 else shown[:37] + '...'}"

