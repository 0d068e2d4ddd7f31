"""What a mission sees and returns each tick, and the names of its phases and failures
(``Phase``, ``Reason`` and the typed ``Event``s live in ``controller.events``, re-exported here).

``FleetView`` in; the mission's plan stage returns an ``Intent`` (nominal world velocities and
what the safety stage must know); its safety stage returns the ``MissionOutput`` (body-frame
commands). The types every mission and the node share: the pure missions never import the I/O
node. Estimates are N×k arrays in config robot order, SI units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from controller.events import Event, Phase, Reason  # noqa: F401 - the words of the wire


class MissionError(RuntimeError):
    """The mission cannot be built for this fleet (e.g. no feasible capture plan: the message
    gives the planner's reason). Beside ``Phase`` and ``Reason``: what a mission can answer."""


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
class Intent:
    """The plan stage's answer: nominal world velocities (N, 2) m/s and what the safety stage
    needs to filter them.

    ``object_pose`` places the object's barrier (None: the object is unknown, no barrier);
    ``touch`` (N,) marks robots allowed to touch the object (their contact role; never enter
    it); ``hold`` (N,) robots commanded exactly zero after the filter; ``stop`` every robot
    zero (e-stop, nothing known yet)."""

    velocities: np.ndarray
    phase: str
    events: list[Event] = field(default_factory=list)
    object_pose: np.ndarray | None = None
    touch: np.ndarray | None = None
    overlap: float = 0.0  # m a ``touch`` robot's disc may overlap the object's estimate
    cage: bool = False  # ``touch`` robots hold their ground: they never yield to the object
    steady: np.ndarray | None = None  # (N,) robots that must not turn (a caging diff robot)
    hold: np.ndarray | None = None
    stop: bool = False
    done: bool = False
    failed: bool = False
    reason: str = ""
    arrest: bool = False
    progress: dict[str, Any] = field(default_factory=dict)  # for the progress line
    # the world twist (vx, vy, wz of the object frame's origin) the robots push the object with
    object_push: np.ndarray | None = None


@dataclass
class MissionOutput:
    """Body-frame commands (N, 3) for every robot, the phase, and events to publish."""

    commands: np.ndarray
    phase: str
    events: list[Event] = field(default_factory=list)
    done: bool = False
    failed: bool = False
    arrest: bool = False
    reason: str = ""
    progress: dict[str, Any] = field(default_factory=dict)
    object_push: np.ndarray | None = None


class Mission(Protocol):
    """A per-tick mission in two stages the node runs (and times) in order."""

    def plan(self, view: FleetView) -> Intent: ...

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput: ...


def step(mission: Mission, view: FleetView) -> MissionOutput:
    """Both stages at once (tests, benchmarks)."""
    return mission.safety(view, mission.plan(view))
