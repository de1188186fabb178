"""Copies of the bundled demo that hold only some of its rollouts (its dataset and session file
whole): smaller inputs for tests whose point needs a few rollouts, not all of them."""

from __future__ import annotations

import shutil
from collections.abc import Collection
from pathlib import Path

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"


def demo_copy(where: Path, tags: Collection[str]) -> Path:
    """``where/demo``: a copy of the demo with only the rollouts ``tags``."""
    session = where / "demo"
    shutil.copytree(DEMO, session, ignore=lambda folder, names: [
        n for n in names if Path(folder).name == "rollouts" and n not in tags])
    return session
