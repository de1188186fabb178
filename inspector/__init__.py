"""inspector: rollout inspector for world-action models on the SO-101 arm.

The public API for evaluation scripts and notebooks; the command line is ``inspector --help``.
Names load on first use, so ``inspector info`` never pays for rerun or viser.

The package, one subpackage per layer (each imports only from those above it in this list):
``errors``, ``units``, ``cache``, ``progress`` (shared by all); :mod:`~inspector.robot` (URDF,
forward kinematics, meshes); :mod:`~inspector.data` (sessions, LeRobot datasets, video, importers,
what a PATH means); :mod:`~inspector.analysis` (metrics and the per-rollout timeline);
:mod:`~inspector.jobs` (worker processes, Ray); :mod:`~inspector.report` and
:mod:`~inspector.export` (the commands' work); :mod:`~inspector.app` (the viser app);
:mod:`~inspector.demo`; ``cli``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "InspectorError": ".errors",
    "JOINT_NAMES": ".units",
    "Units": ".units",
    "Rollout": ".data.session",
    "Session": ".data.session",
    "SessionWriter": ".data.session",
    "open_session": ".data.session",
    "open_sources": ".data.sources",
    "RolloutTimeline": ".analysis.timeline",
    "build_timeline": ".analysis.timeline",
})

if TYPE_CHECKING:
    from .analysis.timeline import RolloutTimeline as RolloutTimeline
    from .analysis.timeline import build_timeline as build_timeline
    from .data.session import Rollout as Rollout
    from .data.session import Session as Session
    from .data.session import SessionWriter as SessionWriter
    from .data.session import open_session as open_session
    from .data.sources import open_sources as open_sources
    from .errors import InspectorError as InspectorError
    from .units import JOINT_NAMES as JOINT_NAMES
    from .units import Units as Units
