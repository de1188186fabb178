"""The bundled demo session and its generator (MuJoCo, imported only when rebuilding)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

__all__ = ["rebuild_demo"]


def rebuild_demo(out: Path | None = None, quick: bool = False, log: Callable[[str], None] = print) -> Path:
    """Regenerate the demo session (see :mod:`inspector.demo.generate`)."""
    from .generate import rebuild_demo as _rebuild  # deferred: MuJoCo loads only to rebuild

    return _rebuild(out, quick=quick, log=log)
