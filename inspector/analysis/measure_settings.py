"""The tolerances the sanity measures are computed with: completion's (how near the GT's final
pose, for how long) and the chunk seams' flag (a multiple of the GT's typical step, and a floor).

The defaults are the documented ones (docs/metrics.md); ``report``, ``serve`` and ``export`` take
flags to change them. The cache key of a rollout's metrics holds them (:meth:`cache_key`), so a
row computed with other tolerances is never read back as this one's.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from .completion import COMPLETION_HOLD_S, COMPLETION_TOL_DEG, COMPLETION_TOL_MM
from .measures_switch import sanity_measures_on
from .seams import SEAM_FLOOR, SEAM_STEP_MULTIPLE


@dataclass(frozen=True)
class MeasureSettings:
    """Attributes:
        completion_tol_deg: joints within this of the GT's final pose (6-joint norm, data units).
        completion_tol_mm: the tool point within this of the final pose's [mm].
        completion_hold_s: ... staying there this long [s].
        seam_multiple: a seam is flagged past this multiple of the GT's typical step ...
        seam_floor_deg: ... and past this floor (data units).
    """

    completion_tol_deg: float = COMPLETION_TOL_DEG
    completion_tol_mm: float = COMPLETION_TOL_MM
    completion_hold_s: float = COMPLETION_HOLD_S
    seam_multiple: float = SEAM_STEP_MULTIPLE
    seam_floor_deg: float = SEAM_FLOOR

    def cache_key(self) -> dict[str, Any]:
        """What of these settings the numbers depend on (with the benchmarks' switch)."""
        return {**{k: float(v) for k, v in asdict(self).items()}, "on": sanity_measures_on()}


DEFAULT_MEASURES = MeasureSettings()
