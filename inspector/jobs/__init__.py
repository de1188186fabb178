"""Where work runs: spawned worker processes that stop on Ctrl-C (``pool``) and Ray tasks (``ray``).
They run any picklable job; the report and the export bring their own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "local_pool": ".pool",
    "interruptible": ".pool",
    "init_worker": ".pool",
    "default_jobs": ".pool",
    "RayWorkers": ".ray",
    "ray_workers": ".ray",
    "check_address": ".ray",
    "import_ray": ".ray",
})

if TYPE_CHECKING:
    from .pool import default_jobs as default_jobs
    from .pool import init_worker as init_worker
    from .pool import interruptible as interruptible
    from .pool import local_pool as local_pool
    from .ray import RayWorkers as RayWorkers
    from .ray import check_address as check_address
    from .ray import import_ray as import_ray
    from .ray import ray_workers as ray_workers
