"""Shared fixtures: seeded hypothesis profile and free loopback ports (helpers: tests/support)."""

from __future__ import annotations

import pytest
from hypothesis import settings

from tests.support.config import free_port

# property tests draw the same examples on every run (seeded CI); a new profile explores
settings.register_profile("seeded", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile("seeded")


@pytest.fixture
def port() -> int:
    return free_port()
