"""Progress bars of the command line (tqdm, on stderr, only when stderr is a terminal)."""

from __future__ import annotations

import sys
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
