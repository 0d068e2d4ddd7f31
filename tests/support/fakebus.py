"""The in-memory bus of the unit tests: ``controller.replay.membus.MemoryBus`` (the regression
replay drives the node with the same one)."""

from __future__ import annotations

from controller.replay.membus import MemoryBus as FakeBus
from controller.replay.membus import MemoryPublisher as FakePublisher

__all__ = ["FakeBus", "FakePublisher"]
