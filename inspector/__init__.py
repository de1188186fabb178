"""inspector: rollout inspector for world-action models on the SO-101 arm.

The public API for evaluation scripts and notebooks; the command line is ``inspector --help``.
Names load on first use, so ``inspector info`` never pays for torch.
"""

from __future__ import annotations

import importlib
from typing import Any

# public name -> module that defines it
_EXPORTS = {
    "InspectorError": ".errors",
    "JOINT_NAMES": ".units",
    "Units": ".units",
    "Rollout": ".session",
    "Session": ".session",
    "SessionWriter": ".session",
    "open_session": ".session",
    "open_sources": ".sources",
    "RolloutTimeline": ".timeline",
    "build_timeline": ".timeline",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'inspector' has no attribute {name!r}")
    return getattr(importlib.import_module(_EXPORTS[name], __name__), name)
