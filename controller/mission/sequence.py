"""The job's phase sequence, pure: the one place a phase changes.

    plan → approach → close_in → hold → arrested → route → rearrange ⇄ transport → done
                                                                     any → failed(reason)

The stages (the capture mission, the transport mission, the job's roster) measure and report
what they saw this tick as a :class:`Cue` (at most one: the stage's checks come in their order
of precedence), or a :class:`Failure`; :func:`next_phase` alone decides where that leads from
the job's current :class:`JobState`, and writes the ``phase`` and ``failure`` events. A cue that
leads nowhere from the current phase (a stage's report out of turn) leaves the phase as it is.
A failure wins over a cue of the same tick: the job stops. ``done`` and ``failed`` are final.

The job holds the one :class:`JobState` in a :class:`Sequencer` and hands it to its stages:
they read the phase from it and report into it; none keeps a phase of its own. A capture that
starts again (a re-plan after a loss or a pin) reports ``replanned``: back to ``approach``.
``fleet run --mission transport`` is the same job entered at ``route``: the job's ``carry``
when it starts the transport moves ``plan`` to ``route`` (the object already held).

A timer is a cue the sequence raises itself (``TIMERS``): a job that carries the object on
moves from ``arrested`` to ``route`` once ``transport.start_after`` s have passed since the
arrest, at the first report of a tick whose stage saw nothing that leads anywhere (a contact
lost in that tick wins: back to ``close_in``, and the wait starts again at the next arrest).
The job then runs the stage of the new phase in the same tick.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum

from controller.events import FailureEvent, PhaseEvent
from controller.mission.types import Event, Phase, Reason


class Cue(StrEnum):
    """What a stage saw this tick that may move the phase."""

    READY = "ready"  # plan: the object and the robots the capture needs are seen, assigned
    ON_ENVELOPE = "on_envelope"  # approach: every assigned robot at its station
    ALL_TOUCHING = "all_touching"  # close_in: every assigned robot in contact
    CONTACT_LOST = "contact_lost"  # hold, arrested: a robot's gap opened past the release
    ESCAPED = "escaped"  # hold: the object moved more than hold_tolerance
    HELD = "held"  # hold: contact and stillness kept through hold_s
    SETTLED = "settled"  # arrested, capture alone: settle_s more of holding
    CARRY = "carry"  # arrested: start_after has passed (a timer); plan: entered at route
    CAN_PUSH = "can_push"  # a new route segment the contacts can push along (the LP)
    CANNOT_PUSH = "cannot_push"  # a new route segment the contacts cannot push along: new ones
    ARRANGED = "arranged"  # rearrange: every mover at its new contact
    RESET = "reset"  # rearrange: the set is given up (a mover blocked): another set
    UNPUSHABLE = "unpushable"  # rearrange: no set pushes the (heavy) object this way: a new route
    STUCK = "stuck"  # transport: the local plans keep re-positioning without pushing
    OFF_ROUTE = "off_route"  # transport: the object left the route's corridor
    DELIVERED = "delivered"  # route, rearrange, transport: the object inside the goal tolerance
    REPLANNED = "replanned"  # a capturing phase: a new capture set (a loss, a pin): approach again


@dataclass(frozen=True)
class Failure:
    """A stage's verdict that the job cannot go on: the reason (``failure.reason`` in the run's
    JSON) and the detail a person reads."""

    reason: Reason
    detail: str

    def to_json(self, t: float | None) -> dict:
        """The failure as the run's JSON says it (``reason``, ``t`` s, ``detail``)."""
        return {"reason": str(self.reason), "t": t, "detail": self.detail}


@dataclass(frozen=True)
class JobState:
    """Where the job is: its phase and since when (s), and the failure that ended it."""

    phase: Phase = Phase.PLAN
    since: float | None = None
    failure: Failure | None = None

    @property
    def final(self) -> bool:
        return self.phase in FINAL


@dataclass(frozen=True)
class Measures:
    """One tick's report of the stage in charge: the time (s) and at most one cue or failure."""

    t: float
    cue: Cue | None = None
    failure: Failure | None = None


@dataclass(frozen=True)
class Step:
    """:func:`next_phase`'s answer: the new state and the events of the change (a ``phase``
    event whenever a transition fires, the same phase again included: a new segment pushed
    from the start; a ``failure`` event after the ``failed`` one)."""

    state: JobState
    events: tuple[Event, ...] = ()

    @property
    def fired(self) -> bool:
        return bool(self.events)


FINAL = frozenset({Phase.DONE, Phase.FAILED})
CAPTURING = frozenset({Phase.APPROACH, Phase.CLOSE_IN, Phase.HOLD})

#: (phase, cue) → the next phase: every way out of every phase but by failure
TRANSITIONS: dict[tuple[Phase, Cue], Phase] = {
    (Phase.PLAN, Cue.READY): Phase.APPROACH,
    (Phase.APPROACH, Cue.ON_ENVELOPE): Phase.CLOSE_IN,
    (Phase.CLOSE_IN, Cue.ALL_TOUCHING): Phase.HOLD,
    (Phase.HOLD, Cue.CONTACT_LOST): Phase.CLOSE_IN,
    (Phase.HOLD, Cue.ESCAPED): Phase.CLOSE_IN,
    (Phase.HOLD, Cue.HELD): Phase.ARRESTED,
    (Phase.ARRESTED, Cue.CONTACT_LOST): Phase.CLOSE_IN,
    (Phase.ARRESTED, Cue.SETTLED): Phase.DONE,
    (Phase.ARRESTED, Cue.CARRY): Phase.ROUTE,
    (Phase.PLAN, Cue.CARRY): Phase.ROUTE,  # entered at route (--mission transport): held already
    (Phase.APPROACH, Cue.REPLANNED): Phase.APPROACH,  # a new set: the approach starts over
    (Phase.CLOSE_IN, Cue.REPLANNED): Phase.APPROACH,
    (Phase.HOLD, Cue.REPLANNED): Phase.APPROACH,
    (Phase.ARRESTED, Cue.REPLANNED): Phase.APPROACH,  # a re-plan asked before the arrest came
    (Phase.ROUTE, Cue.CAN_PUSH): Phase.TRANSPORT,
    (Phase.ROUTE, Cue.CANNOT_PUSH): Phase.REARRANGE,
    (Phase.REARRANGE, Cue.ARRANGED): Phase.TRANSPORT,
    (Phase.REARRANGE, Cue.RESET): Phase.REARRANGE,
    (Phase.REARRANGE, Cue.UNPUSHABLE): Phase.ROUTE,
    (Phase.REARRANGE, Cue.DELIVERED): Phase.DONE,
    (Phase.TRANSPORT, Cue.CAN_PUSH): Phase.TRANSPORT,  # the next segment, pushed as they are
    (Phase.TRANSPORT, Cue.CANNOT_PUSH): Phase.REARRANGE,  # the next segment, new contacts
    (Phase.TRANSPORT, Cue.STUCK): Phase.REARRANGE,
    (Phase.TRANSPORT, Cue.OFF_ROUTE): Phase.ROUTE,
    (Phase.TRANSPORT, Cue.DELIVERED): Phase.DONE,
}


@dataclass(frozen=True)
class SequenceSettings:
    """What the sequence itself is configured by: whether the job carries the object on after
    the arrest (``object.goal`` given) or ends holding it, and how long it holds the arrested
    object before it carries it (``transport.start_after``, s)."""

    carry: bool = False
    start_after: float = 0.0


#: phase → (the cue its timer raises, the setting that says after how many s in the phase)
TIMERS: dict[Phase, tuple[Cue, str]] = {Phase.ARRESTED: (Cue.CARRY, "start_after")}


def _timer(state: JobState, t: float, s: SequenceSettings) -> Cue | None:
    """The cue of the phase's timer when it has run out at ``t``, else None."""
    timer = TIMERS.get(state.phase)
    if timer is None or state.since is None:
        return None
    cue, setting = timer
    return cue if t - state.since >= getattr(s, setting) - 1e-9 else None


def next_phase(state: JobState, m: Measures, s: SequenceSettings | None = None) -> Step:
    """The job's next state from one tick's report (pure). ``s`` None: a capture alone."""
    s = s if s is not None else SequenceSettings()
    if state.final:
        return Step(state)
    if m.failure is not None:
        new = JobState(Phase.FAILED, m.t, m.failure)
        failure = FailureEvent(reason=m.failure.reason, t=m.t, detail=m.failure.detail)
        return Step(new, (PhaseEvent(phase=Phase.FAILED, t=m.t), failure))
    nxt = _leads_to(state.phase, m.cue, s)
    if nxt is None:  # nothing the stage saw leads anywhere: the phase's timer may
        nxt = _leads_to(state.phase, _timer(state, m.t, s), s)
    if nxt is None:
        return Step(state)
    return Step(replace(state, phase=nxt, since=m.t), (PhaseEvent(phase=nxt, t=m.t),))


def _leads_to(phase: Phase, cue: Cue | None, s: SequenceSettings) -> Phase | None:
    """Where ``cue`` leads from ``phase`` (None: nowhere)."""
    if cue is None:
        return None
    nxt = TRANSITIONS.get((phase, cue))
    if nxt is None or (cue == Cue.CARRY and not s.carry):
        return None
    if cue == Cue.SETTLED and s.carry:
        return None  # a job with a goal holds on until it carries the object
    return nxt


class Sequencer:
    """The job's one phase: a :class:`JobState` moved by :func:`next_phase` alone. The job makes
    it and hands it to its stages, which read ``phase`` and ``report`` what they saw; a stage
    used on its own (a capture alone, a test) makes its own at its first phase."""

    def __init__(self, first: Phase = Phase.PLAN, settings: SequenceSettings | None = None):
        self.state = JobState(first)
        self.settings = settings

    @property
    def phase(self) -> Phase:
        return self.state.phase

    def wait(self, dt: float) -> None:
        """``dt`` s the job was held (an e-stop): the phase's timers do not count them."""
        if self.state.since is not None and not self.state.final:
            self.state = replace(self.state, since=self.state.since + dt)

    def report(self, t: float, cue: Cue | None = None, failure: Failure | None = None) -> Step:
        """One stage's report of this tick: the new state (kept here) and its events."""
        step = next_phase(self.state, Measures(t, cue, failure), self.settings)
        self.state = step.state
        return step
