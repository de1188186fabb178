"""A switch for benchmarks only: with ``INSPECTOR_SANITY_MEASURES=off`` in its environment, a
command computes none of the sanity measures (chunk seams, completion, joint coherence, the
video's no-reference quality and break; their fields are null or empty), so that
``benchmarks/before_after.py --without-sanity`` times the same code with and without them in one
run. Not a user setting: docs/development.md names it beside the benchmark.
"""

from __future__ import annotations

import os

ENV = "INSPECTOR_SANITY_MEASURES"


def sanity_measures_on() -> bool:
    """False when the environment switches the sanity measures off (read at every call: a worker
    process inherits its command's environment)."""
    return os.environ.get(ENV, "on") != "off"
