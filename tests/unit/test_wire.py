"""The wire codec: every message round-trips; anything malformed is refused with WireError."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller import wire

finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)
nonneg = st.floats(min_value=0, max_value=10, allow_nan=False, allow_infinity=False)
text = st.text(max_size=20)
seq = st.integers(min_value=0, max_value=2**62)
times = st.floats(min_value=0, max_value=1e9, allow_nan=False)
json_leaf = st.one_of(st.none(), st.booleans(), st.integers(-1000, 1000), finite, text)
json_value = st.recursive(
    json_leaf,
    lambda c: st.one_of(st.lists(c, max_size=3), st.dictionaries(text, c, max_size=3)),
    max_leaves=8,
)

STRATEGIES = {
    wire.Twist2D: st.builds(
        wire.Twist2D,
        t=times,
        seq=seq,
        vx=finite.map(lambda v: v / 20),
        vy=finite.map(lambda v: v / 20),
        wz=finite.map(lambda v: v / 20),
        ttl=nonneg,
    ),
    wire.PoseMeasurement: st.builds(
        wire.PoseMeasurement,
        t=times,
        seq=seq,
        x=finite,
        y=finite,
        theta=st.floats(-7, 7),
        sigma_xy=nonneg,
        sigma_theta=nonneg,
        source=text,
    ),
    wire.RobotState: st.builds(
        wire.RobotState,
        t=times,
        seq=seq,
        id=text,
        x=finite,
        y=finite,
        theta=st.floats(-7, 7),
        vx=finite.map(lambda v: v / 20),
        stale=st.booleans(),
        rejected=st.integers(0, 10**6),
    ),
    wire.ObjectState: st.builds(
        wire.ObjectState,
        t=times,
        seq=seq,
        x=finite,
        y=finite,
        theta=st.floats(-7, 7),
        arrested=st.booleans(),
    ),
    wire.PlanEvent: st.builds(
        wire.PlanEvent,
        t=times,
        seq=seq,
        kind=text,
        phase=text,
        data=st.dictionaries(text, json_value, max_size=4),
    ),
    wire.EStop: st.builds(
        wire.EStop, t=times, seq=seq, engaged=st.booleans(), source=text, reason=text
    ),
    wire.FleetStatus: st.builds(
        wire.FleetStatus,
        t=times,
        seq=seq,
        fleet=text,
        phase=text,
        estop=st.booleans(),
        robots=st.lists(st.dictionaries(text, json_value, max_size=3), max_size=3),
    ),
    wire.SimTick: st.builds(
        wire.SimTick, t=times, seq=seq, step=st.integers(0, 10**9), dt=st.floats(0, 1)
    ),
    wire.TickDone: st.builds(wire.TickDone, t=times, seq=seq, step=st.integers(0, 10**9)),
}


def test_every_message_type_has_a_strategy():
    assert set(STRATEGIES) == set(wire.MESSAGE_TYPES.values())


@pytest.mark.parametrize("cls", list(STRATEGIES), ids=lambda c: c.__name__)
def test_round_trip(cls):
    @settings(max_examples=60, deadline=None)
    @given(STRATEGIES[cls])
    def check(msg):
        assert wire.decode(cls, wire.encode(msg)) == msg

    check()


@pytest.mark.parametrize("cls", list(STRATEGIES), ids=lambda c: c.__name__)
def test_schema_names_every_field(cls):
    schema = wire.json_schema(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    assert list(schema["properties"]) == names
    # every field is required but one added later and sent only when not its default
    # (EStop.durable: old receivers refuse unknown fields)
    late = [f.name for f in dataclasses.fields(cls) if f.metadata.get("omit_default")]
    assert schema["required"] == [n for n in names if n not in late]
    assert late == (["durable"] if cls is wire.EStop else [])
    assert schema["title"] == cls.TYPE
    assert schema["additionalProperties"] is False


def good_twist() -> dict:
    return {"t": 1.0, "seq": 1, "vx": 0.1, "vy": 0.0, "wz": 0.0, "ttl": 0.3}


@pytest.mark.parametrize(
    "patch,words",
    [
        ({"vx": "fast"}, "expected a number"),
        ({"vx": True}, "expected a number"),
        ({"seq": 1.5}, "integer"),
        ({"vx": 1e9}, "exceeds"),
        ({"t": -1e12}, "exceeds"),
        ({"ttl": -1.0}, "below"),
        ({"bogus": 1}, "unknown field"),
    ],
)
def test_decode_rejects_bad_fields(patch, words):
    obj = good_twist() | patch
    with pytest.raises(wire.WireError, match=words):
        wire.decode(wire.Twist2D, json.dumps(obj).encode())


def test_decode_rejects_missing_required_field():
    with pytest.raises(wire.WireError, match="x: missing"):
        wire.decode(wire.PoseMeasurement, b'{"t": 0.0, "y": 1.0, "theta": 0.0}')


@pytest.mark.parametrize("const", ["NaN", "Infinity", "-Infinity"])
def test_decode_rejects_non_finite(const):
    payload = f'{{"t": 1.0, "seq": 0, "vx": {const}}}'.encode()
    with pytest.raises(wire.WireError):
        wire.decode(wire.Twist2D, payload)


@pytest.mark.parametrize("payload", [b"", b"\xff\xfe", b"[1, 2]", b"null", b"{" * 5000, b'"str"'])
def test_decode_rejects_garbage(payload):
    with pytest.raises(wire.WireError):
        wire.decode(wire.Twist2D, payload)


def test_encode_refuses_nan():
    with pytest.raises(wire.WireError):
        wire.encode(wire.Twist2D(t=0.0, vx=math.nan))


def test_topic_registry_keys():
    assert wire.key("robot_cmd", "lab", id="r1") == "fleet/lab/robot/r1/cmd"
    assert wire.key("object_pose", "lab") == "fleet/lab/object/pose"
    assert wire.TOPICS["robot_pose"].wildcard("lab") == "fleet/lab/robot/*/pose"
    assert wire.topic_for_key("lab", "fleet/lab/robot/r7/state").name == "robot_state"
    assert wire.topic_for_key("lab", "fleet/lab/plan/capture").name == "plan"
    assert wire.topic_for_key("lab", "fleet/other/robot/r7/state") is None
    # every key in the design card's table is registered
    for k in ("cmd", "pose", "state"):
        assert wire.topic_for_key("lab", f"fleet/lab/robot/x/{k}") is not None
    for k in ("object/pose", "object/state", "estop", "status", "sim/clock"):
        assert wire.topic_for_key("lab", f"fleet/lab/{k}") is not None


def test_parse_key_takes_keys_apart_through_the_registry():
    k = wire.parse_key("fleet/lab/robot/r7/pose")
    assert k.topic.name == "robot_pose" and k.fleet == "lab" and k.id == "r7"
    assert wire.parse_key("fleet/lab/plan/arrest", "lab").what == "arrest"
    assert wire.parse_key("fleet/lab/sim/truth/robot/r2").topic.name == "truth_robot"
    assert wire.parse_key("fleet/lab/alive/robot/r3").parts == {"role": "robot", "id": "r3"}
    # another fleet, a key of nobody's, an empty id segment: not ours
    assert wire.parse_key("fleet/lab/robot/r7/pose", "other") is None
    assert wire.parse_key("fleet/lab/robot/r7/odometry") is None
    assert wire.parse_key("fleet/lab/robot//pose") is None
    # every template builds keys that parse back to the same parts
    for t in wire.TOPICS.values():
        parts = {p: "x1" for p in ("id", "what", "role") if "{" + p + "}" in t.template}
        back = wire.parse_key(t.key("f", **parts), "f")
        assert back is not None and back.topic is t and back.parts == parts
