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


# the end-to-end folders: dry runs, processes, pybullet, zenoh sessions, golden-log replays.
# Their tests carry the ``e2e`` marker, so ``pytest -m "not e2e"`` is the fast tier (the unit
# tests, under a minute); ``make test`` runs everything.
E2E_FOLDERS = ("integration", "scenarios", "replay", "contract")
# the folders whose tests time real processes against the wall clock (watchdogs, rates, e-stop
# delays): ``serial``, run alone (``make test`` runs the rest on both cores first; the dry runs
# are lockstep, their outcome does not depend on the machine's load)
SERIAL_FOLDERS = ("integration", "contract")
LOCKSTEP_FILES = ("test_dry_run.py", "test_run_cli.py")  # dry runs in those folders: not serial


def pytest_collection_modifyitems(config, items):
    for item in items:
        parts = item.path.parts
        folder = parts[parts.index("tests") + 1] if "tests" in parts else ""
        if folder in E2E_FOLDERS:
            item.add_marker(pytest.mark.e2e)
        if folder in SERIAL_FOLDERS and item.path.name not in LOCKSTEP_FILES:
            item.add_marker(pytest.mark.serial)
