"""Fixtures of the planner tests."""

from __future__ import annotations

import pytest
from planning import kairos


@pytest.fixture(scope="session", autouse=True)
def _kairos_installed() -> None:
    """Fail early and clearly when the independent validator is missing."""
    kairos()
