"""Typed plan events: one frozen dataclass per kind of ``plan/<kind>`` event, and their JSON.

The missions build these; the node publishes ``event.to_dict()`` as the ``data`` of a
``wire.PlanEvent`` on ``plan/<event.kind>``; the recorder logs it; replay, the scene, the viz
and the run summaries read it back through :func:`parse_event`. The JSON is a contract read by
tools outside the repo: ``to_dict()`` gives the keys in the order the fields are declared and the
values exactly as the producer gave them (no rounding, no float conversion), so the bytes on the
bus and in the MCAP logs are those of the ``(kind, dict)`` tuples these classes replaced. Extend,
never rename: a new field goes last, with a default, so that older logs still parse.

Reading is forgiving: a field a newer writer added is kept in ``extra`` (written back last);
an unknown kind, or a known one whose fields do not fit (missing, or of the wrong type), is kept
as a :class:`GenericEvent` with its raw data. :func:`parse_event` never raises.

``Phase`` and ``Reason`` live here: they are words of the wire contract (``plan/phase``,
``failure.reason``); ``controller.mission.types`` re-exports them. Pure: stdlib only.
"""

from __future__ import annotations

import dataclasses
import enum
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, ClassVar


class Phase(StrEnum):
    """Mission phases, as they appear on ``plan/phase``, in ``fleet status`` and ``--json``."""

    PLAN = "plan"  # waiting for every robot's and the object's first estimates
    APPROACH = "approach"  # chase the capture points' images on the convex envelope
    CLOSE_IN = "close_in"  # every robot on the envelope: move in to contact
    HOLD = "hold"  # in contact: preload and watch the object stay put
    ARRESTED = "arrested"  # the object held still through the hold
    ROUTE = "route"  # plan the object's route to its goal
    REARRANGE = "rearrange"  # robots move to the pushing contacts
    TRANSPORT = "transport"  # push the object along the route
    DONE = "done"
    FAILED = "failed"
    GOTO = "goto"  # GotoMission (HoldMission, the bring-up check, reports HOLD: every robot
    # stopped; the word on the bus is "hold" either way)


class Reason(StrEnum):
    """Why a run failed (``failure.reason`` in ``fleet run --json``)."""

    TIMEOUT = "timeout"
    PINNED = "pinned"
    ESCAPED = "escaped"
    COLLISION = "collision"
    ROBOTS_LOST = "robots_lost"
    ROBOT_LOST = "robot_lost"
    NO_CAPTURE = "no_capture"
    ESTOP = "estop"
    NO_ROUTE = "no_route"
    STALLED = "stalled"
    TOO_HEAVY = "too_heavy"  # the whole fleet at its force limits cannot push the object
    NOT_DELIVERED = "not_delivered"  # the run ended with the object outside object.goal's tolerance
    # the dry run's lockstep: the controller's answers or its commands stopped arriving (ticks
    # missed in a row); the run is cut short, its outcome unknown
    LOCKSTEP_LOST = "lockstep_lost"


class EventFieldError(ValueError):
    """Data that does not fit an event kind's fields (``parse_event`` keeps it generic)."""


_OMIT = {"omit_none": True}  # a field written only when it has a value (None: no key)
Points = list[list[float]]


@dataclass(frozen=True, kw_only=True)
class Event:
    """Base of the typed plan events: ``KIND`` names the kind (the ``<what>`` of ``plan/<what>``);
    ``extra`` keeps the fields a newer writer added (written back after the declared ones)."""

    KIND: ClassVar[str] = ""
    extra: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def kind(self) -> str:
        return self.KIND

    def to_dict(self) -> dict[str, Any]:
        """The event's JSON object, key order and values as the producers always wrote them."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name == "extra" or (v is None and f.metadata.get("omit_none")):
                continue
            out[f.name] = v.value if isinstance(v, enum.Enum) else v
        out.update(self.extra)
        return out

    @classmethod
    def from_dict(cls, data: Any) -> Event:
        """The typed event from its JSON object (raises :class:`EventFieldError` if it does not
        fit: a missing field, a value of the wrong type, an unknown enum word)."""
        if not isinstance(data, dict):
            raise EventFieldError(f"{cls.KIND}: expected an object, got {type(data).__name__}")
        rules = _rules(cls)
        kwargs: dict[str, Any] = {}
        names = set()
        for f in dataclasses.fields(cls):
            if f.name == "extra":
                continue
            names.add(f.name)
            if f.name not in data:
                if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                    raise EventFieldError(f"{cls.KIND}.{f.name}: missing")
                continue
            kwargs[f.name] = _fit(rules[f.name], data[f.name])
        extra = {k: v for k, v in data.items() if k not in names}
        return cls(**kwargs, extra=extra)


@dataclass(frozen=True, kw_only=True)
class GenericEvent(Event):
    """An event of a kind this version does not know (or whose fields do not fit its kind):
    kept as read, written back as read."""

    name: str
    data: dict[str, Any] = field(default_factory=dict)

    @property
    def kind(self) -> str:
        return self.name

    def to_dict(self) -> dict[str, Any]:
        return dict(self.data)


# --------------------------------------------------------------------------- the kinds
# Field order is the JSON key order: never reorder; add new fields last, with a default.


@dataclass(frozen=True, kw_only=True)
class PhaseEvent(Event):
    """The job entered ``phase`` at ``t`` (s)."""

    KIND: ClassVar[str] = "phase"
    phase: Phase
    t: float


@dataclass(frozen=True, kw_only=True)
class FailureEvent(Event):
    """The job failed: the reason (``failure.reason`` of ``fleet run --json``) and a detail."""

    KIND: ClassVar[str] = "failure"
    reason: Reason
    t: float
    detail: str


@dataclass(frozen=True, kw_only=True)
class CaptureEvent(Event):
    """The capture set (object-frame points and inward normals, m) and who goes where."""

    KIND: ClassVar[str] = "capture"
    points: Points
    normals: Points
    robots: list[str]
    objective: float
    form_closure: bool
    robots_needed: int
    hold_capacity: float | None
    reinforced: int  # points added to the GA's set so that it holds
    pinned: bool
    wall_contacts: int
    # the robots the plan could not use (lost or not yet seen); older logs lack it
    unavailable: list[str] | None = field(default=None, metadata=_OMIT)


@dataclass(frozen=True, kw_only=True)
class ArrestEvent(Event):
    """The object held still through the hold: timing, the hold's displacement (m), the gaps
    (m, per assigned robot) and, from the capture mission, each robot's world contact point."""

    KIND: ClassVar[str] = "arrest"
    t: float
    arrival_spread_s: float | None
    hold_s: float
    hold_displacement_m: float | None
    gaps_m: list[float]
    contacts: list[dict[str, Any]] | None = field(default=None, metadata=_OMIT)

    @property
    def contact_robots(self) -> list[str]:
        """The robots at the contacts (none when the event came without them)."""
        return [str(c.get("robot")) for c in self.contacts or [] if isinstance(c, dict)]


@dataclass(frozen=True, kw_only=True)
class ContactLostEvent(Event):
    """A robot's gap (m) opened past the release during the hold or after the arrest."""

    KIND: ClassVar[str] = "contact_lost"
    t: float
    gaps_m: list[float]


@dataclass(frozen=True, kw_only=True)
class EscapeEvent(Event):
    """The object moved more than the hold tolerance (m) during the hold."""

    KIND: ClassVar[str] = "escape"
    t: float
    displacement_m: float


@dataclass(frozen=True, kw_only=True)
class ReassignEvent(Event):
    """A better assignment of robots to capture points; ``eta_s`` (now, better)."""

    KIND: ClassVar[str] = "reassign"
    robots: list[str]
    t: float
    eta_s: list[float]


@dataclass(frozen=True, kw_only=True)
class RobotLostEvent(Event):
    """A robot left the job (liveliness or link lost); ``assigned``: it held a capture point
    (the capture's roster says; the transport does not)."""

    KIND: ClassVar[str] = "robot_lost"
    t: float
    robot: str
    phase: str
    assigned: bool | None = field(default=None, metadata=_OMIT)


@dataclass(frozen=True, kw_only=True)
class RobotJoinedEvent(Event):
    """A robot is back (present with a fresh estimate)."""

    KIND: ClassVar[str] = "robot_joined"
    t: float
    robot: str


@dataclass(frozen=True, kw_only=True)
class OutageEvent(Event):
    """Several robots silent at once: one outage, the mission pauses up to ``grace_s``."""

    KIND: ClassVar[str] = "outage"
    t: float
    robots: list[str]
    grace_s: float


@dataclass(frozen=True, kw_only=True)
class OutageEndEvent(Event):
    """The outage ended after ``duration_s``; ``lost``: the robots still gone then."""

    KIND: ClassVar[str] = "outage_end"
    t: float
    duration_s: float
    lost: list[str]


@dataclass(frozen=True, kw_only=True)
class SafetyStopEvent(Event):
    """The safety filter was infeasible for these robots: they were stopped this tick."""

    KIND: ClassVar[str] = "safety_stop"
    robots: list[str]


@dataclass(frozen=True, kw_only=True)
class RouteEvent(Event):
    """The object's route (x, y, theta waypoints and subgoals), its length (m) and cost."""

    KIND: ClassVar[str] = "route"
    t: float
    waypoints: Points
    subgoals: Points
    length_m: float
    cost_s: float | None
    replans: int


@dataclass(frozen=True, kw_only=True)
class RearrangeEvent(Event):
    """A new set of pushing contacts (GA of Eq. 5): who moves, and each robot's contact."""

    KIND: ClassVar[str] = "rearrange"
    t: float
    direction: list[float]
    pushers: int
    basis: str
    eq5_value: float
    moving: list[str]
    contacts: dict[str, list[float]]


@dataclass(frozen=True, kw_only=True)
class TransportEvent(Event):
    """One local plan: its rows' robots, the plan (``LocalPlan.to_dict()``'s keys, written
    between ``robots`` and ``relocating``), the robots relocating (path length, m), its age."""

    KIND: ClassVar[str] = "transport"
    t: float
    robots: list[str]
    plan: dict[str, Any]
    relocating: dict[str, float]
    plan_age_s: float

    @property
    def forces(self) -> list[list[float | None]]:
        """The plan's contact normal forces (N), (intervals, robots) (empty if not given)."""
        got = self.plan.get("forces")
        return got if isinstance(got, list) else []

    def to_dict(self) -> dict[str, Any]:
        return {
            "t": self.t,
            "robots": self.robots,
            **self.plan,
            "relocating": self.relocating,
            "plan_age_s": self.plan_age_s,
            **self.extra,
        }

    @classmethod
    def from_dict(cls, data: Any) -> Event:
        if not isinstance(data, dict):
            raise EventFieldError("transport: expected an object")
        own = ("t", "robots", "relocating", "plan_age_s")
        plan = {k: v for k, v in data.items() if k not in own}
        return super().from_dict({**{k: data[k] for k in own if k in data}, "plan": plan})


@dataclass(frozen=True, kw_only=True)
class DeliveredEvent(Event):
    """The object is at its goal: its pose (x, y, theta) then."""

    KIND: ClassVar[str] = "delivered"
    t: float
    pose: list[float]


@dataclass(frozen=True, kw_only=True)
class LinkLostEvent(Event):
    """On ``robot/<id>/event``: the robot's agent lost its link to the robot. The agent writes
    it (``drivers/`` speaks only the wire contract: the same JSON, ``{"detail": ...}``)."""

    KIND: ClassVar[str] = "link_lost"
    detail: str = ""


@dataclass(frozen=True, kw_only=True)
class LinkRestoredEvent(Event):
    """On ``robot/<id>/event``: the link is back, or a new agent started."""

    KIND: ClassVar[str] = "link_restored"
    detail: str = ""


LINK_EVENTS: dict[str, type[Event]] = {c.KIND: c for c in (LinkLostEvent, LinkRestoredEvent)}


def link_event(kind: str, data: Any) -> LinkLostEvent | LinkRestoredEvent | None:
    """A robot event as the controller takes it: typed by its kind (a malformed ``detail`` is
    dropped: the kind is what counts), None for any other kind."""
    if kind not in LINK_EVENTS:
        return None
    ev = parse_event(kind, data)
    if isinstance(ev, LinkLostEvent | LinkRestoredEvent):
        return ev
    return LinkLostEvent() if kind == LinkLostEvent.KIND else LinkRestoredEvent()


EVENT_TYPES: dict[str, type[Event]] = {
    cls.KIND: cls
    for cls in (
        PhaseEvent,
        FailureEvent,
        CaptureEvent,
        ArrestEvent,
        ContactLostEvent,
        EscapeEvent,
        ReassignEvent,
        RobotLostEvent,
        RobotJoinedEvent,
        OutageEvent,
        OutageEndEvent,
        SafetyStopEvent,
        RouteEvent,
        RearrangeEvent,
        TransportEvent,
        DeliveredEvent,
        LinkLostEvent,
        LinkRestoredEvent,
    )
}


def parse_event(kind: str, data: Any) -> Event:
    """The typed event of ``kind`` from its JSON data; a :class:`GenericEvent` for an unknown
    kind or data that does not fit (never raises)."""
    cls = EVENT_TYPES.get(kind)
    if cls is not None:
        try:
            return cls.from_dict(data)
        except EventFieldError:
            pass
    return GenericEvent(name=str(kind), data=dict(data) if isinstance(data, dict) else {})


# --------------------------------------------------------------------------- field checks

_TYPE_CHECKS: dict[Any, Callable[[Any], bool]] = {
    float: lambda v: isinstance(v, int | float) and not isinstance(v, bool),
    int: lambda v: isinstance(v, int) and not isinstance(v, bool),
    bool: lambda v: isinstance(v, bool),
    str: lambda v: isinstance(v, str),
    list: lambda v: isinstance(v, list),
    dict: lambda v: isinstance(v, dict),
}


@dataclass(frozen=True)
class _Rule:
    """How one field of a kind is read: its declared type (top level), optional or not."""

    where: str
    tp: Any
    nullable: bool
    check: Callable[[Any], bool]


_RULES: dict[type, dict[str, _Rule]] = {}


def _rules(cls: type) -> dict[str, _Rule]:
    """Per field of ``cls``, its reading rule (resolved once per class)."""
    if cls not in _RULES:
        out = {}
        for name, tp in typing.get_type_hints(cls).items():
            if name in ("KIND", "extra"):
                continue
            nullable = False
            if typing.get_origin(tp) in (typing.Union, types.UnionType):
                nullable = type(None) in typing.get_args(tp)
                (tp,) = [a for a in typing.get_args(tp) if a is not type(None)]
            check = _TYPE_CHECKS.get(typing.get_origin(tp) or tp, lambda v: True)
            out[name] = _Rule(f"{cls.KIND}.{name}", tp, nullable, check)  # type: ignore[attr-defined]
        _RULES[cls] = out
    return _RULES[cls]


def _fit(rule: _Rule, value: Any) -> Any:
    """``value`` checked against the field's declared type (top level only); enum words become
    members. Raises EventFieldError."""
    if value is None and rule.nullable:
        return None
    if isinstance(rule.tp, type) and issubclass(rule.tp, enum.Enum):
        try:
            return rule.tp(value)
        except ValueError as exc:
            raise EventFieldError(f"{rule.where}: {value!r} is not a {rule.tp.__name__}") from exc
    if not rule.check(value):
        raise EventFieldError(f"{rule.where}: {type(value).__name__} does not fit {rule.tp}")
    return value


def by_kind(events: typing.Iterable[Event]) -> dict[str, Event]:
    """The events of a tick by kind (the last of each kind)."""
    return {e.kind: e for e in events}
