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

Numbers a reader takes from a file (any layout's JSON metadata: a count, an index, a length, a
size) go through :func:`whole_number` / :func:`finite_number` where they are read: JSON integers have
no limit (``2**70``, ``10**400``), and one past what numpy, a float or an allocation can hold is a
traceback (``OverflowError``) or an allocation far from where it was read. Every integer is
checked against a bound (:data:`MAX_WHOLE` unless the field has a smaller one), every number is
checked finite without converting an integer to a float first.

JSON the project writes (every command's ``--json``, ``session.json``, ``rollout.json``, outcome and
vote files, cache entries) goes through :func:`json_text`: strict JSON (RFC 8259), which has no
``NaN`` or ``Infinity`` (Python's ``json`` writes both as bare tokens that Node, ``jq`` and most
parsers reject). What is not measured is ``null``; a non-finite number that reaches the writer is
a measure that ran on what was not there, so it is refused naming where it sits, never printed.
"""

from __future__ import annotations

import functools
import json
import math
import types
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin, get_type_hints, is_typeddict

from .errors import InspectorError


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


Check = Callable[[Any, str], "str | None"]


def mismatch(value: Any, tp: Any, where: str = "") -> str | None:
    """Where and how ``value`` (parsed JSON) departs from ``tp``, or None when it conforms."""
    return _checker(tp)(value, where)


@functools.cache
def _checker(tp: Any) -> Check:
    """The check of ``tp``, built once per type (an entry is checked in one pass, no type lookups)."""
    if tp is Any:
        return lambda value, where: None
    origin = get_origin(tp)
    if origin is Annotated:
        inner_type, *constraints = get_args(tp)
        inner = _checker(inner_type)
        return lambda value, where: inner(value, where) or _constraint_mismatch(value, constraints, where)
    if origin in (Union, types.UnionType):
        return _union_checker(get_args(tp))
    if origin is Literal:
        allowed = get_args(tp)
        return lambda value, where: (None if type(value) in (str, int, bool) and value in allowed
                                     else _say(where, f"one of {allowed}", value))
    if is_typeddict(tp):
        return _typeddict_checker(tp)
    if origin is list:
        return _list_checker(get_args(tp)[0])
    if origin is dict:
        key_type, item_type = get_args(tp)
        assert key_type is str, "JSON keys are strings"
        item = _checker(item_type)

        def check_dict(value: Any, where: str) -> str | None:
            if not isinstance(value, dict):
                return _say(where, "an object", value)
            return next((m for k, v in value.items() if (m := item(v, _join(where, k)))), None)
        return check_dict
    if tp is float:
        return lambda value, where: (None if type(value) is float and math.isfinite(value)
                                     else _say(where, "a finite float", value))
    if tp is int:
        return lambda value, where: (None if type(value) is int and -MAX_WHOLE <= value <= MAX_WHOLE
                                     else _say(where, f"an integer within +-{MAX_WHOLE}" if type(value) is int
                                               else "an integer", value))
    if tp in (str, bool):
        return lambda value, where: None if type(value) is tp else _say(where, _name(tp), value)
    if tp is None or tp is type(None):
        return lambda value, where: None if value is None else _say(where, "null", value)
    raise TypeError(f"mismatch() cannot check {tp!r}")


def _union_checker(alternatives: tuple[Any, ...]) -> Check:
    expected = " or ".join(_name(alt) for alt in alternatives)
    checks = [_checker(alt) for alt in alternatives if alt is not type(None)]
    nullable = type(None) in alternatives

    def check_union(value: Any, where: str) -> str | None:
        if value is None and nullable or any(c(value, where) is None for c in checks):
            return None
        # X | None: what is wrong inside X says more than "X or null"
        return checks[0](value, where) if len(checks) == 1 else _say(where, expected, value)
    return check_union


def _list_checker(item_type: Any) -> Check:
    item = _checker(item_type)
    nullable_floats = item_type == float | None  # per-frame series: thousands of numbers, one pass

    def check_list(value: Any, where: str) -> str | None:
        if not isinstance(value, list):
            return _say(where, "a list", value)
        if item_type is float or nullable_floats:
            if all(type(v) is float and math.isfinite(v) or nullable_floats and v is None for v in value):
                return None
        elif item_type in (str, bool) and all(type(v) is item_type for v in value):
            return None
        elif item_type is int and all(type(v) is int and -MAX_WHOLE <= v <= MAX_WHOLE for v in value):
            return None  # a frame match's runs: thousands of short lists of indexes
        return next((m for i, v in enumerate(value) if (m := item(v, f"{where}[{i}]"))), None)
    return check_list


def _typeddict_checker(tp: Any) -> Check:
    fields = get_type_hints(tp, include_extras=True)
    keys = list(fields)
    checks = [(k, _checker(field)) for k, field in fields.items()]

    def check_record(value: Any, where: str) -> str | None:
        if not isinstance(value, dict):
            return _say(where, f"an object ({tp.__name__})", value)
        if list(value) != keys:
            missing = [k for k in keys if k not in value]
            extra = [k for k in value if k not in fields]
            what = (f"no {missing[0]!r}" if missing else f"an unknown key {extra[0]!r}" if extra
                    else "its keys out of order")
            return f"{where or 'the record'}: {what}"
        return next((m for k, check in checks if (m := check(value[k], _join(where, k)))), None)
    return check_record


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
    return f"{where or 'the record'}: {expected} expected, got {shown(value)}"


# ----------------------------------------------------------------------------------------------
# Numbers read from a file

# The largest whole number a file may give for a count, an index, a length or a size: the largest
# integer a float64 holds exactly (a frame index becomes a time as index / fps), and far enough
# inside int64 (numpy's indexes) that a sum or a product with a small factor cannot wrap. No
# dataset has that many frames; a field with a tighter natural bound passes its own ``maximum``.
MAX_WHOLE = 2**53 - 1


def shown(value: Any, limit: int = 40) -> str:
    """``value`` as an error message shows it: its repr cut to ``limit`` characters, an integer
    of many digits by its size (``an integer of 22 digits``), never the whole of a long value."""
    if type(value) is int and not -10**15 < value < 10**15:
        return f"an integer of {len(str(abs(value)))} digits"
    if isinstance(value, (str, list, dict)) and len(value) > limit:
        value = value[:limit] if not isinstance(value, dict) else dict(list(value.items())[:4])
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _whole_words(minimum: int) -> str:
    return {0: "a non-negative integer", 1: "a positive integer"}.get(minimum, f"an integer >= {minimum}")


def whole_problem(value: Any, minimum: int = 0, maximum: int = MAX_WHOLE) -> str | None:
    """What is wrong with ``value`` (parsed JSON) as a whole number in [minimum, maximum], or None:
    an ``int`` (not a bool, not a float) within the bounds."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        return f"expected {_whole_words(minimum)}, found {shown(value)}"
    if value > maximum:
        return f"expected {_whole_words(minimum)} no larger than {maximum}, found {shown(value)}"
    return None


def whole_number(value: Any, file: str | Path, field: str, minimum: int = 0, maximum: int = MAX_WHOLE) -> int:
    """``value`` read from ``file``'s ``field`` as a whole number in [minimum, maximum].

    Raises:
        InspectorError: ``<file>: <field>: expected a non-negative integer..., found ...``.
    """
    problem = whole_problem(value, minimum, maximum)
    if problem is not None:
        raise InspectorError(file, f"{field}: {problem}")
    return int(value)


_FLOAT_MAX = 1.7976931348623157e308


def number_problem(value: Any, minimum: float = -math.inf, maximum: float = math.inf) -> str | None:
    """What is wrong with ``value`` (parsed JSON) as a finite number in [minimum, maximum], or None.
    An integer is compared as it is (``10**400`` has no float: ``float()`` and ``math.isfinite``
    of it raise)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"expected a finite number, found {shown(value)}"
    if isinstance(value, float) and not math.isfinite(value) or abs(value) > _FLOAT_MAX:
        return f"expected a finite number, found {shown(value)}"
    if not minimum <= value <= maximum:
        bounds = (f"in [{minimum:g}, {maximum:g}]" if math.isfinite(minimum) and math.isfinite(maximum)
                  else f">= {minimum:g}" if math.isfinite(minimum) else f"<= {maximum:g}")
        return f"expected a finite number {bounds}, found {shown(value)}"
    return None


def finite_number(value: Any, file: str | Path, field: str, minimum: float = -math.inf,
                  maximum: float = math.inf) -> float:
    """``value`` read from ``file``'s ``field`` as a finite float in [minimum, maximum].

    Raises:
        InspectorError: naming the file and the field.
    """
    problem = number_problem(value, minimum, maximum)
    if problem is not None:
        raise InspectorError(file, f"{field}: {problem}")
    return float(value)



# ----------------------------------------------------------------------------------------------
# JSON written


class NotJsonError(ValueError):
    """A value that strict JSON cannot hold (NaN, an infinity) reached :func:`json_text`: a bug in
    the code that built the document (a figure not measured is None), named by where it sits."""


def json_text(value: Any, indent: int | None = None, sort_keys: bool = False) -> str:
    """``value`` as strict JSON text: ``allow_nan=False``, the one place the project writes JSON.

    Raises:
        NotJsonError: a non-finite float in ``value``, naming its place (``rollouts[3].seams.worst``).
    """
    try:
        return json.dumps(value, indent=indent, sort_keys=sort_keys, allow_nan=False)
    except ValueError:
        where = _non_finite_place(value, "")
        if where is None:
            raise
        raise NotJsonError(f"{where or 'the document'}: a non-finite number is not JSON "
                           "(what is not measured is null)") from None


def _non_finite_place(value: Any, where: str) -> str | None:
    """Where the first non-finite float in ``value`` sits, or None (only run once writing failed)."""
    if isinstance(value, float):
        return None if math.isfinite(value) else where
    if isinstance(value, dict):
        return next((w for k, v in value.items() if (w := _non_finite_place(v, _join(where, str(k)))) is not None),
                    None)
    if isinstance(value, (list, tuple)):
        return next((w for i, v in enumerate(value) if (w := _non_finite_place(v, f"{where}[{i}]")) is not None),
                    None)
    return None
