"""The ``fleet run`` summary, typed: what the dry run measured (:class:`RunFigures`), the
hardware contract's figures (:class:`Checks`), the verdict and the outcome (:class:`RunSummary`).

``RunSummary.to_json()`` is the ``fleet run --json`` object (a contract: tools outside the repo
and ``tests/contract`` read it; docs/reference/run-json.md lists its fields): the same keys in
the same order as the dict it replaced. Extend, never rename: a new figure is a new field,
written by ``to_json``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from controller.config import FleetConfig
from controller.mission.summary import JobSummary


def _fields(obj: Any, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.name not in skip}


@dataclass(frozen=True)
class TransportFigures:
    """The transport scored from ground truth. ``carried`` False (no goal, or the transport
    never began): only ``transported`` is reported (None without a goal, else False)."""

    transported: bool | None = None
    goal_error_m: float | None = None
    goal_error_deg: float | None = None
    transport_time_s: float | None = None
    route_length_m: float | None = None
    object_path_length_m: float | None = None
    lateral_deviation_rms_m: float | None = None
    max_lateral_deviation_m: float | None = None
    contact_force_mean_n: float | None = None
    contact_force_max_n: float | None = None
    contact_impulse_ns: float | None = None
    transport_object_min_clearance_m: float | None = None
    # m: the object's centroid (its CG, uniform density) from the centroid it has at the goal
    # pose, at the end; Sharma et al.'s criterion judges the CG, not the polygon's frame origin
    goal_centroid_error_m: float | None = None
    # s from the transport's start to the centroid's first arrival within transport.tolerance
    # of the goal's centroid (Sharma §5's stopping rule; null if it never came that near)
    goal_centroid_reached_s: float | None = None
    # the robots the plan had pushing: the share of their ticks they truly touched the object,
    # and how often one was off it for half a second while still pushing (a contact lost)
    push_contact_share: float | None = None
    push_contact_losses: int | None = None
    carried: bool = False

    def to_json(self) -> dict[str, Any]:
        if not self.carried:
            return {"transported": self.transported}
        return _fields(self, skip=("carried",))


@dataclass(frozen=True)
class RunFigures:
    """What the run measured: the mission's end, the arrest scored from the truth, the loop's
    health, the transport's figures and the mission's own summary (with its stage timings)."""

    mission_phase: str
    done: bool
    failed: bool
    estop: bool
    arrest_declared: bool
    arrest_time_s: float | None
    arrival_spread_s: float | None
    contact_gaps_at_arrest_m: dict[str, float] | None
    hold_displacement_m: float | None
    phases: list[dict[str, Any]]
    object_gave_up_at_s: float | None
    sim_time_s: float
    ticks: int
    input_timeouts: int
    node: dict[str, Any]
    bad_payloads: int
    drops: dict[str, int]
    estimator: dict[str, Any]
    final_object_pose: list[float]
    rearrangements: int | None
    relocations: int | None
    plan_latency_s: dict[str, Any]
    transport: TransportFigures
    mission: JobSummary
    timing: dict[str, Any] = field(default_factory=dict)  # the node's stage timings (ms)

    def to_json(self) -> dict[str, Any]:
        out = _fields(self, skip=("transport", "mission", "timing"))
        out.update(self.transport.to_json())
        out["mission"] = {**self.mission.to_json(), **self.timing}
        return out


@dataclass(frozen=True)
class Checks:
    """The hardware contract's figures over the run (the verdict judges these)."""

    min_clearance_m: float | None
    max_object_penetration_m: float
    obstacle_contacts: list[str]
    object_min_clearance_m: float | None
    missed_ticks: int
    watchdog_stops: int
    clamped_commands: int
    vy_dropped: int
    wall_time_s: float
    log: str
    messages_logged: int
    # the limits the figures are read against (the config's): approach.safety_margin, the
    # goal's transport.tolerance and heading_tolerance_deg (None without object.goal)
    safety_margin_m: float | None = None
    goal_tolerance_m: float | None = None
    goal_tolerance_deg: float | None = None

    def to_json(self) -> dict[str, Any]:
        return _fields(self)


def limits_of(cfg: FleetConfig) -> dict[str, float | None]:
    """The config's limits a run's figures are read against (``Checks``' last fields; the
    daemon's outcome has them too): the safety filter's margin, the goal's tolerances (None
    without ``object.goal``)."""
    goal = cfg.object.goal is not None
    return {
        "safety_margin_m": cfg.approach.safety_margin,
        "goal_tolerance_m": cfg.transport.tolerance if goal else None,
        "goal_tolerance_deg": cfg.transport.heading_tolerance_deg if goal else None,
    }


@dataclass(frozen=True)
class RunFailure:
    """Why the run failed: a ``Reason`` word (or a verdict rule's), when (sim s), a detail."""

    reason: str
    t: float | None
    detail: str = ""

    def to_json(self) -> dict[str, Any]:
        return _fields(self)


@dataclass(frozen=True)
class RunSummary:
    """The whole ``fleet run`` answer: figures, checks, the verdict (each failed rule
    ``{reason, detail}``), whether the object was arrested (declared and not escaped by the
    truth), the failure (None: the run is ok) and the phase the run ended in."""

    figures: RunFigures
    checks: Checks
    verdict: list[dict[str, Any]]
    arrested: bool
    failure: RunFailure | None

    @property
    def ok(self) -> bool:
        return self.failure is None

    @property
    def status(self) -> str:
        return "ok" if self.ok else "failed"

    @property
    def reason(self) -> str | None:
        return None if self.failure is None else self.failure.reason

    @property
    def phase(self) -> str:
        return "failed" if self.failure is not None else self.figures.mission_phase

    def to_json(self) -> dict[str, Any]:
        """The ``fleet run --json`` object."""
        return {
            **self.figures.to_json(),
            **self.checks.to_json(),
            "verdict": self.verdict,
            "arrested": self.arrested,
            "failure": None if self.failure is None else self.failure.to_json(),
            "reason": self.reason,
            "status": self.status,
            "phase": self.phase,
        }
