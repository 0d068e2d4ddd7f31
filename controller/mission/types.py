"""What a mission sees and returns each tick, and the names of its phases and failures
(``Phase``, ``Reason`` and the typed ``Event``s live in ``controller.events``, re-exported here).

``FleetView`` in; the mission's plan stage returns an ``Intent`` (nominal world velocities and
what the safety stage must know); its safety stage returns the ``MissionOutput`` (body-frame
commands). The types every mission and the node share: the pure missions never import the I/O
node. Estimates are N×k arrays in config robot order, SI units.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
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


@dataclass(frozen=True)
class Command:
    """What the plan stage asks of the safety stage: nominal world velocities (N, 2) m/s and
    what the filter must know. ``object_pose`` places the object's barrier (None: the object is
    unknown, no barrier); ``touch`` (N,) marks robots allowed to touch the object (their contact
    role; never enter it); ``hold`` (N,) robots commanded exactly zero after the filter;
    ``stop`` every robot zero (e-stop, nothing known yet)."""

    velocities: np.ndarray
    object_pose: np.ndarray | None = None
    touch: np.ndarray | None = None
    overlap: float = 0.0  # m a ``touch`` robot's disc may overlap the object's estimate
    cage: bool = False  # ``touch`` robots hold their ground: they never yield to the object
    steady: np.ndarray | None = None  # (N,) robots that must not turn (a caging diff robot)
    hold: np.ndarray | None = None
    stop: bool = False
    # the world twist (vx, vy, wz of the object frame's origin) the robots push the object with
    object_push: np.ndarray | None = None


@dataclass(frozen=True)
class Outcome:
    """How the job stands after this tick: done, failed (with its ``reason``), or arrested now."""

    done: bool = False
    failed: bool = False
    reason: Reason | None = None
    arrest: bool = False


@dataclass(frozen=True)
class Report:
    """What the plan stage reports: the job's phase, the events of this tick, the figures of
    the progress line and the outcome."""

    phase: Phase
    events: tuple[Event, ...] = ()
    progress: dict[str, Any] = field(default_factory=dict)
    outcome: Outcome = Outcome()


@dataclass(frozen=True)
class Intent:
    """The plan stage's answer (immutable): the command part the safety stage filters and the
    report part the node publishes. Build one with :meth:`of`."""

    command: Command
    report: Report

    @classmethod
    def of(
        cls,
        velocities: np.ndarray,
        phase: str,
        events: Sequence[Event] = (),
        *,
        done: bool = False,
        failed: bool = False,
        reason: str | None = None,
        arrest: bool = False,
        progress: dict[str, Any] | None = None,
        **command: Any,
    ) -> Intent:
        """An intent from the velocities, the phase, the events, the outcome's flags and the
        command's other fields (``object_pose``, ``touch``, ``hold``, ``stop``, ...)."""
        outcome = Outcome(done, failed, Reason(reason) if reason else None, arrest)
        report = Report(Phase(phase), tuple(events), dict(progress or {}), outcome)
        return cls(Command(velocities, **command), report)

    def after(self, events: Sequence[Event]) -> Intent:
        """The same intent with ``events`` before its own (what the job saw first)."""
        return replace(self, report=replace(self.report, events=(*events, *self.report.events)))

    def ending(self, done: bool) -> Intent:
        """The same intent, done or not."""
        return replace(
            self, report=replace(self.report, outcome=replace(self.report.outcome, done=done))
        )


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

    @classmethod
    def of(cls, commands: np.ndarray, intent: Intent) -> MissionOutput:
        """The output for ``commands`` (N, 3) carrying ``intent``'s report (and its push)."""
        r, o = intent.report, intent.report.outcome
        return cls(
            commands,
            r.phase,
            list(r.events),
            done=o.done,
            failed=o.failed,
            arrest=o.arrest,
            reason=str(o.reason) if o.reason else "",
            progress=dict(r.progress),
            object_push=intent.command.object_push,
        )


class Mission(Protocol):
    """A per-tick mission in two stages the node runs (and times) in order."""

    def plan(self, view: FleetView) -> Intent: ...

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput: ...


def step(mission: Mission, view: FleetView) -> MissionOutput:
    """Both stages at once (tests, benchmarks)."""
    return mission.safety(view, mission.plan(view))
