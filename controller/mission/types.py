"""What a mission sees and returns each tick: ``FleetView`` in, ``MissionOutput`` out.

The types every mission and the node share (the pure missions never import the I/O node).
Estimates are N×k arrays in config robot order, SI units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np


@dataclass(frozen=True)
class FleetView:
    """What the mission sees each tick: estimates as N×k arrays in config robot order (SI units)."""

    t: float
    ids: tuple[str, ...]
    poses: np.ndarray  # (N, 3) x, y, theta
    velocities: np.ndarray  # (N, 3) world vx, vy, wz
    stale: np.ndarray  # (N,) bool
    present: np.ndarray  # (N,) bool: liveliness token held and link ok
    object_pose: np.ndarray | None  # (3,)
    object_velocity: np.ndarray | None  # (3,)
    object_prediction: np.ndarray | None  # (3,) pose a short horizon ahead
    estop: bool


@dataclass
class MissionOutput:
    """Body-frame commands (N, 3) for every robot, the phase, and events to publish."""

    commands: np.ndarray
    phase: str
    events: list[tuple[str, dict[str, Any]]] = field(default_factory=list)
    done: bool = False
    failed: bool = False
    arrest: bool = False


class Mission(Protocol):
    def step(self, view: FleetView) -> MissionOutput: ...
