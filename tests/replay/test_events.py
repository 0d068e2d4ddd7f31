"""Typed plan events (controller/events.py, issue 21 item 6): the JSON on the bus and in the
MCAP logs is the contract external tools read. Today's controller, replayed on both golden logs,
publishes every plan event byte for byte as logged; every logged event reads back as its typed
class and writes back the same bytes; an unknown kind, or a known one that does not fit, is kept
as a generic event and never raises."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import pytest

from controller import wire
from controller.events import (
    EVENT_TYPES,
    ArrestEvent,
    FailureEvent,
    GenericEvent,
    LinkLostEvent,
    LinkRestoredEvent,
    PhaseEvent,
    Reason,
    RobotLostEvent,
    RouteEvent,
    TransportEvent,
    link_event,
    parse_event,
)
from controller.io.recorder import read_log
from controller.replay.check import replay

DATA = Path(__file__).resolve().parent / "data"
GOLDEN = [("capture", DATA / "capture.mcap"), ("transport", DATA / "transport.mcap")]


def logged_plan_events(path: Path) -> dict[str, list[bytes]]:
    """The raw payloads of every ``plan/<what>`` message of a log, by key, in log order."""
    out: dict[str, list[bytes]] = defaultdict(list)
    for rec in read_log(path):
        parsed = wire.parse_key(rec.topic)
        if parsed is not None and parsed.topic.name == "plan":
            out[rec.topic].append(bytes(rec.data))
    return dict(out)


@pytest.fixture(scope="module", params=GOLDEN, ids=[k for k, _ in GOLDEN])
def golden(request):
    mission, path = request.param
    return mission, path, logged_plan_events(path)


def test_every_logged_event_reads_typed_and_writes_back_the_same_bytes(golden):
    _, _, logged = golden
    kinds = set()
    for payloads in logged.values():
        for raw in payloads:
            msg = wire.decode(wire.PlanEvent, raw)
            ev = parse_event(msg.kind, msg.data)
            assert not isinstance(ev, GenericEvent), (msg.kind, msg.data)
            assert type(ev) is EVENT_TYPES[msg.kind] and ev.extra == {}
            again = wire.PlanEvent(t=msg.t, seq=msg.seq, kind=ev.kind, phase=msg.phase)
            again = wire.PlanEvent(**{**wire.to_dict(again), "data": ev.to_dict()})
            assert wire.encode(again) == raw
            kinds.add(msg.kind)
    assert {"phase", "route", "rearrange", "transport", "delivered"} <= kinds or {
        "capture",
        "phase",
        "arrest",
    } <= kinds


def data_bytes(raw: bytes) -> bytes:
    """The ``data`` object of an encoded PlanEvent, as the bytes on the wire."""
    return raw[raw.index(b',"data":') + len(b',"data":') : -1]


def test_todays_controller_publishes_the_logged_events_byte_for_byte(golden):
    """The producers build dataclasses now; what goes on the bus is what the golden logs hold
    (keys, key order, float formatting), event by event. (The replay's first tick publishes a
    ``phase`` event at t = 0 the recorder of the transport run had not yet heard: the events
    are compared from the first logged one on.)"""
    mission, path, logged = golden
    res, _run, bus, _ = replay(path, mission=mission)
    assert res.first is None
    t0 = min(wire.decode(wire.PlanEvent, raw).t for ps in logged.values() for raw in ps)
    sent: dict[str, list[bytes]] = {}
    for k, msgs in bus.sent.items():
        if "/plan/" in k:
            sent[k] = [data_bytes(wire.encode(m)) for m in msgs if m.t >= t0]
    assert sent.keys() == logged.keys()
    for k, payloads in logged.items():
        assert sent[k] == [data_bytes(raw) for raw in payloads], k


def test_the_failure_reason_stays_a_reason():
    ev = parse_event("failure", {"reason": "no_route", "t": 3.0, "detail": "walled in"})
    assert isinstance(ev, FailureEvent) and ev.reason is Reason.NO_ROUTE
    assert ev.to_dict() == {"reason": "no_route", "t": 3.0, "detail": "walled in"}
    assert json.dumps(FailureEvent(reason=Reason.STALLED, t=1, detail="").to_dict()) == (
        '{"reason": "stalled", "t": 1, "detail": ""}'
    )


@pytest.mark.parametrize(
    ("kind", "data"),
    [
        ("brand_new_kind", {"t": 1.0, "what": [1, 2]}),  # a newer writer's kind
        ("phase", {"t": 1.0}),  # a field missing
        ("phase", {"phase": "levitate", "t": 1.0}),  # a phase this version does not know
        ("failure", {"reason": "gremlins", "t": 1.0, "detail": ""}),  # nor this reason
        ("route", {"t": "soon", "waypoints": [], "subgoals": [], "length_m": 0.0}),
        ("arrest", "not an object"),
    ],
)
def test_what_does_not_fit_is_kept_generic_and_never_raises(kind, data):
    ev = parse_event(kind, data)
    assert isinstance(ev, GenericEvent) and ev.kind == kind
    assert ev.to_dict() == (data if isinstance(data, dict) else {})


def test_a_newer_field_is_kept_and_written_back_last():
    data = {"t": 2.0, "robot": "r1", "phase": "transport", "why": "battery"}
    ev = parse_event("robot_lost", data)
    assert isinstance(ev, RobotLostEvent) and ev.robot == "r1" and ev.assigned is None
    assert ev.extra == {"why": "battery"} and list(ev.to_dict()) == list(data)


def test_optional_fields_are_written_only_when_given():
    lost = RobotLostEvent(t=1.0, robot="r2", phase="approach")
    assert lost.to_dict() == {"t": 1.0, "robot": "r2", "phase": "approach"}
    assert "assigned" in RobotLostEvent(t=1.0, robot="r2", phase="x", assigned=False).to_dict()
    arrest = ArrestEvent(t=1.0, arrival_spread_s=0.5, hold_s=2.0, hold_displacement_m=0.01,
                         gaps_m=[0.0])  # fmt: skip
    assert "contacts" not in arrest.to_dict() and arrest.contact_robots == []


def test_the_transport_plan_keys_sit_between_robots_and_relocating():
    data = {"t": 1.0, "robots": ["r1"], "strategy": "sa", "forces": [[1.5]], "relocating": {}}
    data["plan_age_s"] = 0.05
    ev = parse_event("transport", data)
    assert isinstance(ev, TransportEvent) and ev.plan == {"strategy": "sa", "forces": [[1.5]]}
    assert ev.forces == [[1.5]] and list(ev.to_dict()) == list(data)


def test_every_kind_is_registered_once_and_typed_fields_read_back():
    assert all(k == cls.KIND for k, cls in EVENT_TYPES.items())
    route = RouteEvent(t=0.5, waypoints=[[0.0, 0.0, 0.0]], subgoals=[], length_m=1.0,
                       cost_s=None, replans=0)  # fmt: skip
    assert parse_event("route", json.loads(json.dumps(route.to_dict()))) == route
    assert parse_event("phase", {"phase": "hold", "t": 2}) == PhaseEvent(phase="hold", t=2)


def test_a_robots_link_events_are_typed_and_a_misshapen_one_keeps_its_kind():
    lost = link_event("link_lost", {"detail": "no heartbeat"})
    assert isinstance(lost, LinkLostEvent) and lost.detail == "no heartbeat"
    assert lost.to_dict() == {"detail": "no heartbeat"}  # what drivers/agent.py writes
    assert isinstance(link_event("link_restored", {}), LinkRestoredEvent)
    # a detail that is not a string: the kind still counts (the robot's link is lost)
    assert link_event("link_lost", {"detail": 7}) == LinkLostEvent()
    assert link_event("battery_low", {"detail": "x"}) is None
