"""Callbacks that tabs register on shared data (a rollout's frames, the Overview's rows)."""

from __future__ import annotations

import threading
from collections.abc import Callable


class Listeners:
    """A thread-safe set of ``fn()`` callbacks, called in the order they were added."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._fns: list[Callable[[], None]] = []

    def add(self, fn: Callable[[], None]) -> None:
        with self._lock:
            self._fns.append(fn)

    def __len__(self) -> int:
        with self._lock:
            return len(self._fns)

    def remove(self, fn: Callable[[], None]) -> None:
        with self._lock:
            self._fns = [f for f in self._fns if f != fn]  # bound methods compare equal, not identical

    def notify(self) -> None:
        """Call every callback outside the lock; one that fails (its tab went away) never stops
        the others or the thread that notifies."""
        with self._lock:
            fns = list(self._fns)
        for fn in fns:
            try:
                fn()
            except Exception:
                pass


class Notifying:
    """For shared data that tabs listen to: ``add_listener`` / ``remove_listener``, and
    ``_notify`` when something changed. Subclasses set ``self._listeners = Listeners()``."""

    _listeners: Listeners

    def add_listener(self, fn: Callable[[], None]) -> None:
        """Call ``fn()`` (on the thread that makes the change) whenever it changes."""
        self._listeners.add(fn)

    def remove_listener(self, fn: Callable[[], None]) -> None:
        self._listeners.remove(fn)

    def _notify(self) -> None:
        self._listeners.notify()
