"""Every number a flag takes has a range, checked where argparse parses it: any number given (a
billion bootstrap replicates, 1e308, NaN, 5000 digits) is a value within its flag's range or one
line ``error: --flag: ...`` and exit 2, before the command allocates or computes anything."""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from inspector.cli import MAX_BOOTSTRAP, build_parser, main
from inspector.cli import flags as flag
from inspector.data.session import MAX_FPS, MIN_FPS
from inspector.schema import MAX_WHOLE


def _numeric_flags() -> list[tuple[tuple[str, ...], str, flag.Bounded | flag.IndexList]]:
    """(the command's words, the flag, its type) of every flag of every command that takes a
    number, found by walking the parser."""
    found = []

    def walk(parser: argparse.ArgumentParser, words: tuple[str, ...]) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, (*words, name))
            elif isinstance(action.type, (flag.Bounded, flag.IndexList)):
                found.append((words, action.option_strings[0], action.type))
    walk(build_parser(), ())
    return found


NUMERIC_FLAGS = _numeric_flags()


@functools.lru_cache(maxsize=1)
def _parser() -> argparse.ArgumentParser:
    return build_parser()  # (parsing leaves a parser as it was: one serves every example)


def test_every_typed_flag_is_range_checked() -> None:
    """No flag converts with a bare int / float: each number has a range."""
    plain = []

    def walk(parser: argparse.ArgumentParser, words: tuple[str, ...]) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, (*words, name))
            elif action.type in (int, float) or (action.type is not None and not isinstance(
                    action.type, (flag.Bounded, flag.IndexList)) and "key_value" not in repr(action.type)
                    and "calibration" not in repr(action.type)):
                plain.append((words, action.option_strings, action.type))
    walk(build_parser(), ())
    assert plain == []
    flags = {f for _, f, _ in NUMERIC_FLAGS}
    assert {"--jobs", "--cache-mb", "--bootstrap", "--seed", "--steps-per-frame", "--episode", "--start-frame",
            "--port", "--fps", "--control-hz", "--timeout", "--max-reply-mb", "--episodes"} <= flags


def test_the_ranges_are_those_of_the_data() -> None:
    assert (flag.MIN_RATE_HZ, flag.MAX_RATE_HZ) == (MIN_FPS, MAX_FPS)
    assert flag.MAX_INDEX == MAX_WHOLE


def _parse(words: tuple[str, ...], option: str, text: str) -> tuple[int, object, str]:
    """(exit code, the parsed value, stderr) of the command ``words`` with ``option=text``."""
    positional = {"import": ["SRC", "-o", "DEST"], "eval": ["ws://h:1", "D", "-o", "O"], "compare": ["A", "B"],
                  "agreement": ["--imagined", "I", "--real", "R"], "outcomes": ["F", "P"], "rank": ["A", "B"],
                  "report": ["S"], "export": ["S"], "info": ["S"],
                  "calibrate": ["S", "--view", "front"]}.get(words[0], [])
    err = io.StringIO()
    dest = option.lstrip("-").replace("-", "_")
    with contextlib.redirect_stderr(err):
        try:
            args = _parser().parse_args([*words, *positional, f"{option}={text}"])
        except SystemExit as exc:
            return int(exc.code or 0), None, err.getvalue()
    return 0, getattr(args, dest), err.getvalue()


_numbers = st.one_of(
    st.integers(-10**6, 10**6).map(str), st.integers().map(str), st.integers(-2**70, 2**70).map(str),
    st.just("9" * 5000), st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(-1e6, 1e6).map(str), st.sampled_from(["nan", "inf", "-inf", "1e308", "-0", "1e-300", "0x10", "1_000",
                                                    " 7 ", "", "two", "1,2", "3-1", "0-99999999999999999"]),
    st.text(max_size=12))


@settings(max_examples=500, deadline=None)
@given(which=st.integers(0, len(NUMERIC_FLAGS) - 1), text=_numbers)
def test_any_number_for_any_flag_parses_in_range_or_is_one_line(which: int, text: str) -> None:
    words, option, kind = NUMERIC_FLAGS[which]
    code, value, stderr = _parse(words, option, text)
    if code == 0:
        if isinstance(kind, flag.IndexList):
            values = value if isinstance(value, list) else [v for vs in value for v in vs]
            assert len(values) <= flag.MAX_LISTED and all(0 <= v <= flag.MAX_INDEX for v in values)
        else:
            got = value[-1] if isinstance(value, list) else value  # an appended flag (--episode N ...)
            assert isinstance(got, kind.kind) and math.isfinite(got) and kind.contains(got), (option, text, got)
        return
    assert code == 2
    assert stderr.count("\n") == 1 and stderr.startswith(f"error: {option}: "), (option, text, stderr)


@pytest.mark.parametrize(("args", "expected"), [
    (("rank", "A", "B", "--bootstrap", "1000000000"), f"error: --bootstrap: must be at most {MAX_BOOTSTRAP} "
                                                      "(got 1000000000)"),
    (("agreement", "--imagined", "A", "--real", "B", "--bootstrap", "1000000000"), "error: --bootstrap: must be at most"),
    (("import", "dreamzero-served", "SRC", "-o", "D", "--steps-per-frame", "1e308"),
     "error: --steps-per-frame: must be at most 1000 (got 1e308)"),
    (("import", "dreamzero-offline", "SRC", "-o", "D", "--fps", "1e-300"), "error: --fps: must be a rate from 0.001 "
                                                                            "to 1000 per second (got 1e-300)"),
    (("serve", "--cache-mb", "1e300"), "error: --cache-mb: must be at most 1048576 (got 1e300)"),
    (("rank", "A", "B", "--seed", "9" * 5000), "error: --seed: must be at most 9007199254740991 (got an integer of "
                                               "5000 digits)"),
    (("eval", "h:1", "D", "-o", "O", "--frames", "0-999999,2000000-2999999"),
     "error: --frames: more than 1,000,000 indexes in all"),
    (("eval", "h:1", "D", "-o", "O", "--max-reply-mb", "1e308"), "error: --max-reply-mb: must be at most 4096"),
])
def test_a_number_out_of_range_is_one_line_before_any_work(capsys: pytest.CaptureFixture[str], args: tuple[str, ...],
                                                           expected: str) -> None:
    with pytest.raises(SystemExit) as exc:
        main(list(args))
    out = capsys.readouterr()
    assert exc.value.code == 2 and out.out == ""
    assert out.err.count("\n") == 1 and out.err.startswith(expected), out.err


def test_the_bounds_themselves_are_accepted() -> None:
    for words, option, kind in NUMERIC_FLAGS:
        if isinstance(kind, flag.IndexList):
            continue
        for bound, is_open in ((kind.low, kind.low_open), (kind.high, kind.high_open)):
            text = str(int(bound)) if kind.kind is int else repr(float(bound))
            code, value, stderr = _parse(words, option, text)
            assert (code != 0) == is_open, (option, text, stderr)
