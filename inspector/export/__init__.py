"""Rerun ``.rrd`` recordings: one rollout's recording (``recording``, its parts in modules of their
own and the blueprint in ``layout``), several written by workers (``jobs``), and the
``inspector export`` command (``command``).

Every module, one line each, is on the map in docs/development.md ("Layout of the code"),
which tests/test_layout.py checks against the package.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from .._lazy import attach

# Rerun's native logger reads RUST_LOG once, when rerun is first imported (by this package's
# modules): unless the user set it, only its errors reach stderr, so a failed export stays the one
# ``error:`` line of the contract rather than being followed by rerun's coloured warnings.
os.environ.setdefault("RUST_LOG", "error")

__getattr__, __dir__, __all__ = attach(__name__, {
    "write_recording": ".recording",
    "export_rollout": ".recording",
    "export_cli": ".command",
    "ExportJob": ".jobs",
    "ExportOutcome": ".jobs",
    "run_export_jobs": ".jobs",
})

if TYPE_CHECKING:
    from .command import export_cli as export_cli
    from .jobs import ExportJob as ExportJob
    from .jobs import ExportOutcome as ExportOutcome
    from .jobs import run_export_jobs as run_export_jobs
    from .recording import export_rollout as export_rollout
    from .recording import write_recording as write_recording
