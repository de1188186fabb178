"""One error type for bad input: it names the file and says what is wrong with it.

The CLI prints it as ``error: <file>: <what>`` and exits 2; the app shows it on an error card.
The message is always one line: control characters in a path (a newline, an escape sequence)
are written as escapes, never as themselves. It is also of a readable length wherever it is
printed: a message past :data:`MAX_WHAT_CHARS` keeps its start and says how much was cut, a path
past :data:`MAX_FILE_CHARS` keeps its start and its end (the file's name).
"""

from __future__ import annotations

import unicodedata
from pathlib import Path

# Characters shown as escapes: controls (Cc), format characters such as bidi overrides (Cf),
# undecodable bytes of a file name (Cs, surrogate escapes) and the Unicode line/paragraph breaks.
_ESCAPED_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})
_SHORT_ESCAPES = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}
# What an error line keeps of what is wrong, and of the file's path [characters]. A value quoted
# from a file (a template, a list) can be megabytes long; the line names the field before it.
MAX_WHAT_CHARS = 400
MAX_FILE_CHARS = 1000


def one_line(text: object) -> str:
    """``text`` with every control character escaped (``\\n``, ``\\x1b``, ``\\u2028``), so it
    prints as one line and cannot drive a terminal."""
    s = str(text)
    if s.isprintable():  # the usual case, fast
        return s
    out = []
    for c in s:
        if c in _SHORT_ESCAPES:
            out.append(_SHORT_ESCAPES[c])
        elif unicodedata.category(c) in _ESCAPED_CATEGORIES:
            code = ord(c)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000
                       else f"\\U{code:08x}")
        else:
            out.append(c)
    return "".join(out)


class InspectorError(Exception):
    """Bad input that a user can fix: a missing file, a wrong shape, a value out of place.

    Args:
        file: the file (or directory) at fault; kept as given in ``file``, escaped in the message.
        what: one line saying what is wrong, naming the field where there is one.
    """

    def __init__(self, file: str | Path, what: str) -> None:
        self.file = str(file)
        self.what = _cut(str(what))
        super().__init__(f"{_cut_path(self.file)}: {self.what}")


def _cut(what: str) -> str:
    """``what`` as one line (line breaks become spaces, controls escapes) of at most
    :data:`MAX_WHAT_CHARS` characters: its start, then how much was left out. Only the start of a
    long text is looked at."""
    head = one_line(" ".join(what[:4 * MAX_WHAT_CHARS].split()))
    if len(head) <= MAX_WHAT_CHARS and len(what) <= 4 * MAX_WHAT_CHARS:
        return head
    return f"{head[:MAX_WHAT_CHARS]}... ({len(what):,} characters in all)"


def _cut_path(file: str) -> str:
    """``file`` escaped as one line, at most about :data:`MAX_FILE_CHARS` characters: a longer path
    keeps its start and its end (the file's name, its last directories), the middle written as ``...``."""
    if len(file) <= MAX_FILE_CHARS:
        return one_line(file)
    return one_line(f"{file[:MAX_FILE_CHARS // 3]}...{file[-(2 * MAX_FILE_CHARS // 3):]}")


def require(condition: bool, file: str | Path, what: str) -> None:
    """Raise :class:`InspectorError` unless ``condition`` holds."""
    if not condition:
        raise InspectorError(file, what)
