"""Shared pytest fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

# The repo sits at <work>/main and the shared fixtures at <work>/shared/fixtures.
FIXTURES_DIR = Path(__file__).resolve().parents[2] / "shared" / "fixtures"


@pytest.fixture(scope="session")
def fixtures_dir() -> Path:
    """``../shared/fixtures``; tests using it are skipped when it is absent."""
    if not FIXTURES_DIR.is_dir():
        pytest.skip(f"shared fixtures not found at {FIXTURES_DIR}")
    return FIXTURES_DIR
