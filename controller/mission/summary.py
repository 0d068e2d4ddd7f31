"""What a mission reports at the end of a run, typed: the ``mission`` object of ``fleet run
--json`` and the figures the run's summary takes from it (arrival spread, re-arrangements,
relocations). ``to_json()`` gives the keys and order the ``summary()`` dicts always had: a
flat object, the job's own capture-plan figures first, then its capture's, then its transport's.
Extend, never rename (tools outside the repo read these keys)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from controller.events import CaptureEvent
from controller.planning.capture_set import CaptureSet


class _Flat:
    """``to_json()``: the fields in order; a nested summary (or None) merged in flat."""

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            v = getattr(self, f.name)
            if f.metadata.get("nested"):
                out.update(v.to_json() if v is not None else {})
            else:
                out[f.name] = v
        return out


def _nested() -> Any:
    return dataclasses.field(default=None, metadata={"nested": True})


@dataclass(frozen=True)
class CaptureSummary(_Flat):
    """The capture mission's figures (its own estimate: the dry run scores from the truth)."""

    phase: str
    arrival_spread_s: float | None
    arrest_time_s: float | None
    hold_displacement_estimated_m: float | None
    escapes: int
    contacts_lost: int
    infeasible_filter_calls: int


@dataclass(frozen=True)
class TransportSummary(_Flat):
    """The transport mission's figures; ``transport_failure`` ``{reason, t, detail}`` or None."""

    transport_phase: str
    route_length_m: float | None
    route_replans: int
    rearrangements: int
    relocations: int
    local_plans: int
    planned_force_mean_n: float | None
    transport_failure: dict[str, Any] | None
    # serpentine only (else None): local plans, those with both groups manned, group switches
    serpentine_plans: int | None = None
    serpentine_two_group_plans: int | None = None
    serpentine_switches: int | None = None


@dataclass(frozen=True)
class CapturePlanSummary(_Flat):
    """The job's capture set and what became of its robots."""

    capture_points: int
    capture_objective: float
    form_closure: bool
    hold_capacity: float | None
    reinforced_points: int
    assigned: list[str] | None
    reassignments: int
    wall_replans: int
    unreachable_nodes: int
    robots_lost: list[str]
    outages: int
    loss_replans: int
    braces: int = 0  # robots that braced a fast object (approach.brace_share)

    @classmethod
    def of(cls, job) -> CapturePlanSummary:
        """The figures of a ``mission.job.CaptureJob`` that planned a capture."""
        ids = [r.id for r in job.cfg.robots]
        cap, a = job.capture, job.assignment
        return cls(
            capture_points=len(cap.points),
            capture_objective=cap.objective,
            form_closure=cap.form_closure,
            hold_capacity=cap.hold_capacity,
            reinforced_points=cap.reinforced,
            assigned=None if a is None else [ids[i] for i in a],
            reassignments=job.reassigner.count,
            wall_replans=job.reach.replans,
            unreachable_nodes=len(job.reach.unreachable),
            robots_lost=[ids[i] for i in job.roster.lost],
            outages=job.outage.outages,
            loss_replans=job.loss_replans,
            braces=job.braces,
        )


@dataclass(frozen=True)
class JobSummary(_Flat):
    """The whole job: its capture plan (None when entered at ``route``), its capture mission's
    figures, its transport's (None until it carries)."""

    plan: CapturePlanSummary | None = _nested()
    capture: CaptureSummary | None = _nested()
    transport: TransportSummary | None = _nested()

    @property
    def arrival_spread_s(self) -> float | None:
        return None if self.capture is None else self.capture.arrival_spread_s

    @property
    def rearrangements(self) -> int | None:
        return None if self.transport is None else self.transport.rearrangements

    @property
    def relocations(self) -> int | None:
        return None if self.transport is None else self.transport.relocations


def summary_of(mission: Any) -> JobSummary:
    """A mission's summary as the job's (a capture or a transport mission alone fills its part;
    a mission without a summary, the bring-up ones and test doubles, reports nothing)."""
    got = mission.summary() if callable(getattr(mission, "summary", None)) else None
    if isinstance(got, CaptureSummary):
        return JobSummary(capture=got)
    if isinstance(got, TransportSummary):
        return JobSummary(transport=got)
    return got if isinstance(got, JobSummary) else JobSummary()


def capture_event(capture: CaptureSet, robots: list[str], unavailable: list[str], pinned: bool):
    """The ``capture`` event of a capture set assigned to ``robots`` (one per point)."""
    return CaptureEvent(
        points=capture.points.round(4).tolist(),
        normals=capture.normals.round(4).tolist(),
        robots=robots,
        objective=capture.objective,
        form_closure=capture.form_closure,
        robots_needed=len(capture.points),
        hold_capacity=capture.hold_capacity,
        reinforced=capture.reinforced,
        pinned=pinned,
        wall_contacts=capture.walls,
        unavailable=unavailable,
    )
