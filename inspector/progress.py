"""What a command says while it works, on stderr: progress bars (tqdm, only when stderr is a
terminal), and the warnings it says once per command even when a worker process met them (a
worker holds its warning and hands it back with its results, for the command to say)."""

from __future__ import annotations

import sys
import threading
from typing import Any, TextIO


def progress_bar(total: float, desc: str, unit: str = "it", stream: TextIO | None = None,
                 show: bool | None = None, delay_s: float = 0.5) -> Any:
    """A tqdm bar, or None when it would not be seen.

    Args:
        total: the count the bar fills to.
        desc: what is progressing (shown at the left).
        unit: what is counted.
        stream: where to draw (default stderr).
        show: force on or off (default: when ``stream`` is a terminal).
        delay_s: draw only once the work has taken this long (quick runs stay quiet).
    """
    stream = stream if stream is not None else sys.stderr
    if show is None:
        show = bool(getattr(stream, "isatty", lambda: False)())
    if not show or total <= 0:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=stream, leave=False, delay=delay_s,
                dynamic_ncols=True)


class FractionBar:
    """``bar(fraction, message)`` callbacks (what export reports) drawn on a tqdm bar.

    Args:
        desc: what is progressing.
        stream, show, delay_s: as :func:`progress_bar`.
    """

    def __init__(self, desc: str, stream: TextIO | None = None, show: bool | None = None,
                 delay_s: float = 0.5) -> None:
        self._bar = progress_bar(100, desc, unit="%", stream=stream, show=show, delay_s=delay_s)

    def __call__(self, fraction: float, message: str = "") -> None:
        if self._bar is None:
            return
        self._bar.n = int(round(min(max(fraction, 0.0), 1.0) * 100))
        self._bar.set_postfix_str(message, refresh=False)
        self._bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


# -- one warning per command ------------------------------------------------------------------

_unsaid: str | None = None  # this process's first warning, not yet printed or handed on
_said = False  # this process has printed its warning
_hold = False  # a worker process: hand warnings back instead of printing them
_lock = threading.Lock()  # the app's threads meet them too


def say_once_or_hold(message: str) -> None:
    """Print ``message`` at once (the first warning in this process), or hold it for the command if
    this is a worker process (:func:`take_unsaid` hands it back)."""
    global _unsaid
    with _lock:
        if _said or _unsaid is not None:
            return
        _unsaid = message
    if not _hold:
        warn_once(take_unsaid())


def hold_warnings() -> None:
    """In a worker process: warnings are handed back (:func:`take_unsaid`), never printed."""
    global _hold
    _hold = True


def take_unsaid() -> str | None:
    """The warning this process holds (then no longer), for a worker's results."""
    global _unsaid
    with _lock:
        message, _unsaid = _unsaid, None
    return message


def warn_once(message: str | None) -> None:
    """Print ``message`` (a warning, from this process or a worker's), unless one was printed."""
    global _said
    with _lock:
        if message is None or _said:
            return
        _said = True
    print(message, file=sys.stderr, flush=True)
