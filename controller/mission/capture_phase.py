"""The capture's phase logic, pure (Sharma §3): what the capture measures each tick turned into
a report for ``mission.sequence`` (a cue or a failure: the sequence moves the job's phase, which
this module only reads), and what it remembers (contact times, the cage of frozen contact
targets, the hold's displacement, the arrest)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from controller.config import ApproachSection, FleetConfig, configured, from_section
from controller.events import ArrestEvent, ContactLostEvent, EscapeEvent
from controller.mission.sequence import CAPTURING, Cue, Failure
from controller.mission.sequence import Step as SeqStep
from controller.mission.types import Event, Phase, Reason

CLOSED = (Phase.HOLD, Phase.ARRESTED, Phase.DONE)  # robots in contact, preloading
_APPROACH = ApproachSection()  # the config's defaults: the settings' defaults of its keys


@dataclass(frozen=True)
class CaptureSettings:
    """The capture mission's tuning constants, in one place (SI units).

    From ``[approach]``: the tolerances, ``hold_s``, ``preload_depth``, the timeout and the
    interception horizon. Internal: ``settle_s`` (s the arrested fleet keeps holding before a
    capture-only mission is done); ``release_factor`` (a robot in hold whose gap exceeds this
    many contact tolerances lost contact); ``creep_gap`` (m: closer than this estimated gap to
    the surface a robot stops riding on the object's estimated motion and creeps in: the
    estimate of an object being pushed is what the pushing moves); ``station_gap`` (m between a
    contact target and the
    surface while closing in); ``waypoint_reached`` (m at which a detour waypoint counts as
    reached); ``detour_clearance`` (m beyond the robot radius when testing whether the straight
    line to a station crosses an obstacle), ``detour_samples`` (points tested on it),
    ``detour_spacing`` (m between a detour's waypoints); ``speed_margin`` (the share of its
    top speed a robot plans an interception with).
    """

    contact_tolerance: float = configured(_APPROACH, "contact_tolerance")
    envelope_tolerance: float = configured(_APPROACH, "envelope_tolerance")
    hold_s: float = configured(_APPROACH, "hold_s")
    hold_tolerance: float = configured(_APPROACH, "hold_tolerance")
    preload_depth: float = configured(_APPROACH, "preload_depth")
    timeout: float = configured(_APPROACH, "timeout")
    intercept_horizon: float = configured(_APPROACH, "intercept_horizon")
    settle_s: float = 0.5
    release_factor: float = 2.0
    creep_gap: float = 0.03
    station_gap: float = 0.0
    waypoint_reached: float = 0.15
    detour_clearance: float = 0.05
    detour_samples: int = 50
    detour_spacing: float = 0.6
    speed_margin: float = 0.9

    @classmethod
    def from_config(cls, cfg: FleetConfig) -> CaptureSettings:
        return from_section(cls, cfg.approach)


@dataclass(frozen=True)
class Measures:
    """What the phase logic reads each tick (estimates, SI units)."""

    t: float
    dist: np.ndarray  # (M,) each assigned robot to its current target
    preload: np.ndarray  # (M, 2) preload targets at the object's current estimate
    gap: np.ndarray  # (M,) each assigned robot's disc to the object's surface (< 0: overlap)
    polygon: np.ndarray  # (V, 2) the object's estimated polygon, world frame
    detouring: bool


@dataclass(frozen=True)
class CaptureState:
    """What the capture remembers (immutable; :func:`advance` returns a new one). The phase is
    the job's (``sequence.Sequencer``), not the capture's."""

    t0: float | None = None
    contact_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hold_t0: float | None = None
    hold_polygon: np.ndarray | None = None
    cage: np.ndarray | None = None  # (M, 2) world contact targets frozen at contact (NaN: none)
    hold_displacement: float = 0.0
    arrest_t: float | None = None
    arrival_spread: float | None = None
    escapes: int = 0
    releases: int = 0


@dataclass(frozen=True)
class Report:
    """The phase logic's answer for one tick: what it remembers, its events, and what it saw
    for the sequence (at most one cue, or a failure)."""

    state: CaptureState
    events: list[Event]
    cue: Cue | None = None
    failure: Failure | None = None


def advance(st: CaptureState, m: Measures, s: CaptureSettings, phase: Phase) -> Report:
    """The capture's measures in the job's ``phase``, pure: what it saw (a cue or a failure for
    :func:`sequence.next_phase`, which moves the phase), what it remembers, and its events."""
    events: list[Event] = []
    cue: Cue | None = None
    if phase == Phase.APPROACH:
        if np.all(m.dist < s.envelope_tolerance) and not m.detouring:
            cue = Cue.ON_ENVELOPE
    elif phase == Phase.CLOSE_IN:
        touching = m.gap < s.contact_tolerance
        contact_t = st.contact_t.copy()
        contact_t[touching & np.isnan(contact_t)] = m.t
        st = replace(st, contact_t=contact_t, cage=_recage(st.cage, touching, m.preload))
        if np.all(touching):
            st = replace(st, hold_t0=m.t, hold_polygon=m.polygon, hold_displacement=0.0)
            cue = Cue.ALL_TOUCHING
    elif phase in CLOSED:
        st, cue = _hold(st, m, s, events, phase)
    failure = None
    if phase in CAPTURING and m.t - st.t0 > s.timeout:
        reason = Reason.ESCAPED if st.escapes else Reason.TIMEOUT
        failure = Failure(reason, _timeout_detail(st, m, s, phase))
    return Report(st, events, cue, failure)


def entered(st: CaptureState, step: SeqStep, m: Measures) -> tuple[CaptureState, list[Event]]:
    """What the capture remembers of the phase the sequence has just moved the job into (the
    arrest: its time, the arrival spread and its event), and the sequence's events."""
    events = list(step.events)
    if step.fired and step.state.phase == Phase.ARRESTED:
        spread = float(np.nanmax(st.contact_t) - np.nanmin(st.contact_t))
        st = replace(st, arrest_t=m.t, arrival_spread=spread)
        events.append(_arrest_event(st, m))
    return st, events


def _arrest_event(st: CaptureState, m: Measures) -> Event:
    return ArrestEvent(
        t=m.t,
        arrival_spread_s=st.arrival_spread,
        hold_s=m.t - st.hold_t0,
        hold_displacement_m=st.hold_displacement,
        gaps_m=m.gap.round(4).tolist(),
    )


def _recage(cage: np.ndarray | None, touching: np.ndarray, preload: np.ndarray) -> np.ndarray:
    """A touching robot holds still where it touched; one the object has left closes in again."""
    out = np.full_like(preload, np.nan) if cage is None else cage.copy()
    new = touching & np.isnan(out[:, 0])
    out[new] = preload[new]
    out[~touching] = np.nan
    return out


def _hold(st: CaptureState, m: Measures, s: CaptureSettings, events, phase: Phase) -> tuple:
    """Hold, arrested, done: contact kept and the object still (``held`` after ``hold_s``,
    ``settled`` ``settle_s`` after the arrest), or contact lost or the object escaped."""
    moved = float(np.max(np.linalg.norm(m.polygon - st.hold_polygon, axis=1)))
    touching = m.gap < s.contact_tolerance
    st = replace(
        st,
        hold_displacement=max(st.hold_displacement, moved),
        cage=_recage(st.cage, touching, m.preload),
    )
    if np.any(m.gap > s.release_factor * s.contact_tolerance):
        events.append(ContactLostEvent(t=m.t, gaps_m=m.gap.round(4).tolist()))
        return replace(st, releases=st.releases + 1, cage=None), Cue.CONTACT_LOST
    if moved > s.hold_tolerance and phase == Phase.HOLD:
        events.append(EscapeEvent(t=m.t, displacement_m=moved))
        return replace(st, escapes=st.escapes + 1, cage=None), Cue.ESCAPED
    if phase == Phase.HOLD and m.t - st.hold_t0 >= s.hold_s and np.all(touching):
        return st, Cue.HELD
    if phase == Phase.ARRESTED and m.t - st.arrest_t >= s.settle_s:
        return st, Cue.SETTLED
    return st, None


def _timeout_detail(st: CaptureState, m: Measures, s: CaptureSettings, phase: Phase) -> str:
    if phase == Phase.APPROACH:
        far = int(np.sum(m.dist >= s.envelope_tolerance))
        return f"{far} robots still {np.max(m.dist):.2f} m from their stations after {s.timeout} s"
    if phase == Phase.CLOSE_IN:
        return (
            f"{int(np.sum(m.gap >= s.contact_tolerance))} robots not in contact (gaps up to "
            f"{np.max(m.gap):.3f} m); {st.escapes} escapes, {st.releases} contacts lost"
        )
    return f"hold never completed: {st.escapes} escapes, {st.releases} contacts lost"
