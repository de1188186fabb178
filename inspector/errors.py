"""One error type for bad input: it names the file and says what is wrong with it.

The CLI prints it as ``error: <file>: <what>`` and exits 2; the app shows it on an error card.
"""

from __future__ import annotations

from pathlib import Path


class InspectorError(Exception):
    """Bad input that a user can fix: a missing file, a wrong shape, a value out of place.

    Args:
        file: the file (or directory) at fault.
        what: one line saying what is wrong, naming the field where there is one.
    """

    def __init__(self, file: str | Path, what: str) -> None:
        self.file = str(file)
        self.what = " ".join(str(what).split())  # always one line
        super().__init__(f"{self.file}: {self.what}")


def require(condition: bool, file: str | Path, what: str) -> None:
    """Raise :class:`InspectorError` unless ``condition`` holds."""
    if not condition:
        raise InspectorError(file, what)
