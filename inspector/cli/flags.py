"""The values of the command line's flags, each checked where argparse parses it.

Every number a flag takes has a range, named in its one-line error (``error: --bootstrap: must be
at most 20000 (got 1000000000)``): a number nobody means (a billion bootstrap replicates, a frame
rate of 1e308) ends the command before it allocates, overflows or loops on it. Each flag's type
carries its range (:class:`Bounded`), so a test can walk the parser and find every one; the ranges
are listed in docs/reliability.md.
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable

# The largest index or count a file or a flag may hold: every such integer is exact in a double
# (JSON readers, the browser) [the same bound as ``inspector.schema.MAX_WHOLE``].
MAX_INDEX = 2**53 - 1
# Frame and control rates (``inspector.data.session.MIN_FPS`` / ``MAX_FPS``) [frames/s].
MIN_RATE_HZ, MAX_RATE_HZ = 0.001, 1000.0
# The most indexes one list flag (``--episodes``, ``--frames``) names, ranges counted in full.
MAX_LISTED = 1_000_000


class Bounded:
    """An argparse type: a whole number (``kind=int``) or a finite number (``kind=float``) from
    ``low`` to ``high``; ``low_open`` / ``high_open`` leave the bound itself out.

    Args:
        words: the range as the error says it, in place of "at least" / "at most"
            (``"a TCP port from 0 to 65535"``); ``note`` is added after the value given.
    """

    def __init__(self, kind: type[int] | type[float], low: float, high: float, *, low_open: bool = False,
                 high_open: bool = False, words: str | None = None, note: str = "") -> None:
        self.kind, self.low, self.high = kind, low, high
        self.low_open, self.high_open = low_open, high_open
        self.words, self.note = words, note
        self.__name__ = "whole number" if kind is int else "number"  # argparse's name for the type

    def contains(self, value: float) -> bool:
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def describe(self) -> str:
        """The range in words, for the docs and the tests: ``1 to 20000``, ``more than 0 to 4096``."""
        low = f"more than {_num(self.low)}" if self.low_open else _num(self.low)
        high = f"less than {_num(self.high)}" if self.high_open else _num(self.high)
        return f"{low} to {high}"

    def __call__(self, text: str) -> int | float:
        value = self._parse(text)
        if self.contains(value):
            return value
        got = f"(got {_shown(value, text)}{f'; {self.note}' if self.note else ''})"
        if self.words is not None:
            raise argparse.ArgumentTypeError(f"must be {self.words} {got}")
        if value < self.low or (self.low_open and value == self.low):
            raise argparse.ArgumentTypeError(f"must be {self._low_words()} {got}")
        raise argparse.ArgumentTypeError(f"must be {'less than' if self.high_open else 'at most'} "
                                         f"{_num(self.high)} {got}")

    def _low_words(self) -> str:
        if self.low_open:
            return f"more than {_num(self.low)}"
        if self.kind is float and self.low == 0:
            return "0 or more"
        return f"at least {_num(self.low)}"

    def _parse(self, text: str) -> int | float:
        stripped = text.strip()
        if self.kind is int:
            if re.fullmatch(r"[+-]?[0-9_]+", stripped) and len(stripped.lstrip("+-0_")) > 30:
                # past any range here, and past int()'s digit limit at 4300: said by its length
                raise argparse.ArgumentTypeError(f"must be {self.words or f'at most {_num(self.high)}'} (got an "
                                                 f"integer of {len(stripped.lstrip('+-0_'))} digits)")
            try:
                return int(stripped)
            except ValueError:
                raise argparse.ArgumentTypeError(f"must be a whole number (got {_quoted(text)})") from None
        try:
            value = float(stripped)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number (got {_quoted(text)})") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number (got {_cut(text)})")
        return value


def _num(bound: float) -> str:
    """A bound as the errors write it: ``20000``, ``9007199254740991``, ``0.001``."""
    return str(int(bound)) if float(bound).is_integer() and abs(bound) <= MAX_INDEX else f"{bound:g}"


def _cut(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else f"{text[:limit - 3]}..."


def _quoted(text: str) -> str:
    return repr(_cut(text))


def _shown(value: float, text: str) -> str:
    return str(value) if isinstance(value, int) else _cut(text.strip())


def whole(low: int, high: int = MAX_INDEX) -> Bounded:
    """A whole number from ``low`` to ``high``."""
    return Bounded(int, low, high)


def positive(high: float) -> Bounded:
    """A number more than 0, at most ``high``."""
    return Bounded(float, 0.0, high, low_open=True)


def non_negative(high: float) -> Bounded:
    """A number from 0 to ``high``."""
    return Bounded(float, 0.0, high)


def rate_hz() -> Bounded:
    """A frame or control rate [Hz], as a rollout's ``fps`` is checked."""
    return Bounded(float, MIN_RATE_HZ, MAX_RATE_HZ,
                   words=f"a rate from {MIN_RATE_HZ:g} to {MAX_RATE_HZ:g} per second")


port = Bounded(int, 0, 65535, words="a TCP port from 0 to 65535", note="0 picks a free one")
index = whole(0)  # --episode, --start-frame, --seed
margin_deg = Bounded(float, 0.0, 360.0, high_open=True, words="a number of degrees in [0, 360)")


class IndexList:
    """An argparse type: ``0,3,10-20`` -> [0, 3, 10, 11, ..., 20], each index at most
    :data:`MAX_INDEX`, at most :data:`MAX_LISTED` of them in all."""

    __name__ = "index list"
    low, high = 0, MAX_INDEX

    def __call__(self, text: str) -> list[int]:
        out: set[int] = set()
        for part in text.split(","):
            match = re.fullmatch(r"\s*(\d{1,16})\s*(?:-\s*(\d{1,16})\s*)?", part)
            if not match or (match[2] is not None and int(match[2]) < int(match[1])):
                raise argparse.ArgumentTypeError(f"expected indexes like 0,3,10-20 (got {_quoted(text)})")
            first = int(match[1])
            last = first if match[2] is None else int(match[2])
            if last > MAX_INDEX:
                raise argparse.ArgumentTypeError(f"an index past {MAX_INDEX} (got {_quoted(part)})")
            if last - first >= MAX_LISTED or len(out) + last - first >= MAX_LISTED:
                raise argparse.ArgumentTypeError(f"more than {MAX_LISTED:,} indexes in all (got {_quoted(text)})")
            out.update(range(first, last + 1))
        return sorted(out)


index_list = IndexList()


def key_value(what: str) -> Callable[[str], tuple[str, str]]:
    """An argparse type: ``KEY=VALUE``, both non-empty."""
    def parse(text: str) -> tuple[str, str]:
        key, sep, value = text.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise argparse.ArgumentTypeError(f"expected {what} (got {text!r})")
        return key.strip(), value.strip()
    return parse
