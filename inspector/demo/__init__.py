"""The bundled demo session and its generator (MuJoCo, imported only when rebuilding)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

__all__ = ["rebuild_demo", "write_checkpoints"]


def rebuild_demo(out: Path | None = None, quick: bool = False, log: Callable[[str], None] = print) -> Path:
    """Regenerate the demo session (see :mod:`inspector.demo.generate`)."""
    from .generate import rebuild_demo as _rebuild  # deferred: MuJoCo loads only to rebuild

    return _rebuild(out, quick=quick, log=log)


def write_checkpoints(root: Path, overwrite: bool = False, log: Callable[[str], None] = print) -> list[Path]:
    """Checkpoint-like sessions derived from the demo (see :mod:`inspector.demo.checkpoints`)."""
    from .checkpoints import write_checkpoints as _write

    return _write(root, overwrite=overwrite, log=log)
