"""One row per rollout (or dataset episode, or neural trajectory): the layer between the measures
(:mod:`inspector.analysis`) and the front ends that show them (the report's text, HTML and
decisions; the app's Overview and catalog; the Rerun export).

``tasks`` runs the rows' work in worker processes (or Ray tasks), a rollout at a time, through
the metrics cache (``entries``: a rollout's cache entry, read and written); ``rollout`` builds a
rollout's row and the aggregates; ``outcomes`` puts every outcome source's record on the rows and
the success rates beside them; ``trajectories`` is a neural trajectory's row.

Every module, one line each, is on the map in docs/development.md ("Layout of the code"),
which tests/test_layout.py checks against the package.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "rollout_summary": ".rollout",
    "episode_summary": ".rollout",
    "aggregate": ".rollout",
    "Task": ".tasks",
    "EpisodeTask": ".tasks",
    "Outcome": ".tasks",
    "plan_tasks": ".tasks",
    "run_task": ".tasks",
    "run_tasks": ".tasks",
})

if TYPE_CHECKING:
    from .rollout import aggregate as aggregate
    from .rollout import episode_summary as episode_summary
    from .rollout import rollout_summary as rollout_summary
    from .tasks import EpisodeTask as EpisodeTask
    from .tasks import Outcome as Outcome
    from .tasks import Task as Task
    from .tasks import plan_tasks as plan_tasks
    from .tasks import run_task as run_task
    from .tasks import run_tasks as run_tasks
