"""A stop asked for by a signal, remembered as well as raised.

The command line's SIGTERM handler (and ``serve``'s) raise where the main thread happens to be.
Where that is a callback whose exceptions Python ignores (a weakref callback of the import
system's module locks, a ``__del__``), the exception is printed as "Exception ignored in ..." and
lost, and the process would go on as if never asked to stop: ``inspector serve`` sent SIGTERM
while it was still starting served on. So the handlers also set this flag, and the waits that can
last forever (``serve``'s main loop) check it.
"""

from __future__ import annotations

import threading

_requested = threading.Event()


def note_stop_request() -> None:
    """Called by a signal handler before it raises."""
    _requested.set()


def stop_requested() -> bool:
    return _requested.is_set()


def clear_stop_request() -> None:
    """A new command starts (tests run several in one process)."""
    _requested.clear()
