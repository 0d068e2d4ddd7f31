"""The wire contract: bus keys, message types and their JSON codec. Both sides import this.

This module is the only place a bus key is spelled. ``TOPICS`` is the registry: each entry names
a key template, the message type on it, its expected rate and whether the recorder logs it.
Messages are frozen dataclasses; ``encode`` writes compact JSON, ``decode`` checks types, finite
values and magnitudes and raises ``WireError`` (a ``ValueError``) on anything else. Every message
carries ``t`` (s, the sender's clock; sim time in the dry run) and ``seq``.

Frames: world ENU (x east, y north, theta CCW from x, rad); commands are body frame like ROS
``cmd_vel`` (vx forward, vy left, wz CCW).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import typing
from dataclasses import dataclass, field
from typing import Any, ClassVar

from controller.geometry import wrap_angle  # noqa: F401 - the one angle wrap, for the robot side

# Magnitude bounds: a value beyond these is not a plausible lab quantity.
MAX_ABS_POSITION = 1.0e4  # m
MAX_ABS_SPEED = 1.0e2  # m/s or rad/s
MAX_ABS_TIME = 1.0e10  # s (wall-clock epoch seconds fit)
MAX_SEQ = 2**63 - 1
MAX_STRING = 4096


class WireError(ValueError):
    """A payload that does not decode into the expected message type."""


@dataclass(frozen=True, kw_only=True)
class Message:
    """Base of every bus message: sender time ``t`` (s) and sequence number ``seq``."""

    t: float = field(metadata={"limit": MAX_ABS_TIME})
    seq: int = 0

    TYPE: ClassVar[str] = "Message"


@dataclass(frozen=True, kw_only=True)
class Twist2D(Message):
    """Velocity command in the robot's body frame: vx forward, vy left (m/s), wz CCW (rad/s).

    ``ttl`` (s) is how long the command stays valid; an agent stops the robot after it.
    """

    vx: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    vy: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    wz: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    ttl: float = field(default=0.3, metadata={"limit": 3600.0, "min": 0.0})

    TYPE: ClassVar[str] = "fleet.Twist2D"


@dataclass(frozen=True, kw_only=True)
class PoseMeasurement(Message):
    """A measured pose in the world frame (m, m, rad) with its standard deviations."""

    x: float = field(metadata={"limit": MAX_ABS_POSITION})
    y: float = field(metadata={"limit": MAX_ABS_POSITION})
    theta: float = field(metadata={"limit": 100.0})
    sigma_xy: float = field(default=0.01, metadata={"limit": 100.0, "min": 0.0})
    sigma_theta: float = field(default=0.0175, metadata={"limit": 100.0, "min": 0.0})
    source: str = ""

    TYPE: ClassVar[str] = "fleet.PoseMeasurement"


@dataclass(frozen=True, kw_only=True)
class RobotState(Message):
    """The controller's filtered estimate of one robot (world frame, velocities in world frame)."""

    id: str
    x: float = field(metadata={"limit": MAX_ABS_POSITION})
    y: float = field(metadata={"limit": MAX_ABS_POSITION})
    theta: float = field(metadata={"limit": 100.0})
    vx: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    vy: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    wz: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    sigma_xy: float = field(default=0.0, metadata={"limit": 1e3, "min": 0.0})
    sigma_theta: float = field(default=0.0, metadata={"limit": 1e3, "min": 0.0})
    stale: bool = False
    rejected: int = field(default=0, metadata={"min": 0})

    TYPE: ClassVar[str] = "fleet.RobotState"


@dataclass(frozen=True, kw_only=True)
class ObjectState(Message):
    """The controller's filtered estimate of the object (pose of its frame, world velocities)."""

    x: float = field(metadata={"limit": MAX_ABS_POSITION})
    y: float = field(metadata={"limit": MAX_ABS_POSITION})
    theta: float = field(metadata={"limit": 100.0})
    vx: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    vy: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    wz: float = field(default=0.0, metadata={"limit": MAX_ABS_SPEED})
    sigma_xy: float = field(default=0.0, metadata={"limit": 1e3, "min": 0.0})
    stale: bool = False
    arrested: bool = False

    TYPE: ClassVar[str] = "fleet.ObjectState"


@dataclass(frozen=True, kw_only=True)
class PlanEvent(Message):
    """A planner decision or phase event: ``kind`` names it, ``data`` holds its JSON fields."""

    kind: str
    phase: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    TYPE: ClassVar[str] = "fleet.PlanEvent"


@dataclass(frozen=True, kw_only=True)
class EStop(Message):
    """Latched emergency stop (``engaged`` true) or its explicit release (``engaged`` false).

    ``source`` names who set it (the operator's identity); ``epoch`` orders operators' actions:
    a counter only they advance (the latch, ``controller.latch``, refuses a release at or below
    the epoch it holds). ``t`` is the sender's clock, logged and never used to order e-stops.

    ``durable`` (a holder's answer on ``estop/state/<role>/<id>`` only): false when the holder
    keeps its latch in a file and this state is not (yet) in it - a failed write (full disk,
    unwritable folder) or a write still to come. Sent only when false: receivers older than the
    field refuse such an answer, as they refuse anything they cannot decode (they stay stopped).
    """

    engaged: bool
    source: str = ""
    reason: str = ""
    epoch: int = field(default=0, metadata={"min": 0})
    durable: bool = field(default=True, metadata={"omit_default": True})

    TYPE: ClassVar[str] = "fleet.EStop"


@dataclass(frozen=True, kw_only=True)
class FleetStatus(Message):
    """What a running controller reports when queried: phase, robots and counters."""

    fleet: str
    phase: str
    estop: bool = False
    robots: list[dict[str, Any]] = field(default_factory=list)
    counters: dict[str, Any] = field(default_factory=dict)
    # per planner (transport, route, rearrange, capture): wall latency p50/p99/max s, late...
    plan_latency_s: dict[str, Any] = field(default_factory=dict)
    tick_ms: dict[str, Any] = field(default_factory=dict)  # the tick's p50/p99/max, ms
    controller: str = ""  # the answering controller's liveliness id (alive/controller/<id>)

    TYPE: ClassVar[str] = "fleet.FleetStatus"


@dataclass(frozen=True, kw_only=True)
class SimTick(Message):
    """Lockstep clock: the sim announces tick ``step`` at sim time ``t``; ``measurements`` is how
    many pose measurements (robots and object) it has published in all before this tick, so the
    controller can wait until it has taken in every one of them."""

    step: int = field(default=0, metadata={"min": 0})
    dt: float = field(default=0.05, metadata={"limit": 10.0, "min": 0.0})
    measurements: int = field(default=0, metadata={"min": 0})

    TYPE: ClassVar[str] = "fleet.SimTick"


@dataclass(frozen=True, kw_only=True)
class TickDone(Message):
    """Lockstep answer: the controller has published every command for tick ``step``;
    ``commands`` is how many commands it has published in all so far. (The sim learns nothing
    else from the controller: no "arrest" switch, the physics decides whether it holds.)"""

    step: int = field(default=0, metadata={"min": 0})
    commands: int = field(default=0, metadata={"min": 0})

    TYPE: ClassVar[str] = "fleet.TickDone"


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.TYPE: cls
    for cls in (
        Twist2D,
        PoseMeasurement,
        RobotState,
        ObjectState,
        PlanEvent,
        EStop,
        FleetStatus,
        SimTick,
        TickDone,
    )
}


# --------------------------------------------------------------------------- codec


@functools.cache
def _omittable(cls: type) -> tuple[tuple[str, bool, Any], ...]:
    """A message type's fields as (name, omitted while default, default), computed once."""
    return tuple(
        (f.name, bool(f.metadata.get("omit_default")), f.default) for f in dataclasses.fields(cls)
    )


def to_dict(msg: Message) -> dict[str, Any]:
    """The message as plain JSON-ready data. A field marked ``omit_default`` (added to a type
    after receivers were deployed) is left out while it holds its default, so a receiver that
    predates it still decodes every message that does not use it."""
    out = {}
    for name, omit, default in _omittable(type(msg)):
        v = getattr(msg, name)
        if not (omit and v == default):
            out[name] = v
    return out


# one encoder and one decoder for every message (json.dumps/loads with options build one a call)
_ENCODER = json.JSONEncoder(separators=(",", ":"), allow_nan=False)


def encode(msg: Message) -> bytes:
    """Compact JSON bytes of a message (NaN/inf are refused)."""
    try:
        return _ENCODER.encode(to_dict(msg)).encode()
    except ValueError as exc:
        raise WireError(f"{type(msg).__name__}: not encodable: {exc}") from exc


def _check_number(cls_name: str, name: str, value: Any, meta: typing.Mapping[str, Any]) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise WireError(f"{cls_name}.{name}: expected a number, got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v):
        raise WireError(f"{cls_name}.{name}: not finite ({value!r})")
    limit = meta.get("limit", MAX_ABS_POSITION)
    if abs(v) > limit:
        raise WireError(f"{cls_name}.{name}: |{v}| exceeds {limit}")
    if "min" in meta and v < meta["min"]:
        raise WireError(f"{cls_name}.{name}: {v} is below {meta['min']}")
    return v


def _check_json(cls_name: str, name: str, value: Any, depth: int = 0) -> None:
    if depth > 8:
        raise WireError(f"{cls_name}.{name}: nested too deep")
    if isinstance(value, float) and not math.isfinite(value):
        raise WireError(f"{cls_name}.{name}: not finite")
    if isinstance(value, dict):
        for k, v in value.items():
            _check_json(cls_name, f"{name}.{k}", v, depth + 1)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_json(cls_name, f"{name}[{i}]", v, depth + 1)


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    if cls not in _HINTS:
        _HINTS[cls] = typing.get_type_hints(cls)
    return _HINTS[cls]


def _check_field(
    cls_name: str, name: str, tp: Any, value: Any, meta: typing.Mapping[str, Any]
) -> Any:
    """One field's value checked against its declared type and metadata (raises WireError)."""
    where = f"{cls_name}.{name}"
    origin = typing.get_origin(tp) or tp
    if tp is float:
        return _check_number(cls_name, name, value, meta)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise WireError(f"{where}: expected an integer")
        if not (-MAX_SEQ <= value <= MAX_SEQ) or value < meta.get("min", -MAX_SEQ):
            raise WireError(f"{where}: integer out of range")
    elif tp is bool:
        if not isinstance(value, bool):
            raise WireError(f"{where}: expected true or false")
    elif tp is str:
        if not isinstance(value, str) or len(value) > MAX_STRING:
            raise WireError(f"{where}: expected a string of at most {MAX_STRING}")
    elif origin in (dict, list):
        if not isinstance(value, origin):
            raise WireError(f"{where}: expected an {'object' if origin is dict else 'array'}")
        _check_json(cls_name, name, value)
    else:  # pragma: no cover - a new field type without a rule
        raise WireError(f"{where}: unsupported type {tp}")
    return value


@functools.cache
def _spec(cls: type) -> tuple[frozenset[str], tuple[tuple[str, Any, Any, bool, float | None], ...]]:
    """A message type's field names, and per field (name, type, metadata, required, the
    number's limit or None), computed once."""
    hints = _hints(cls)
    fields = dataclasses.fields(cls)
    return frozenset(f.name for f in fields), tuple(
        (
            f.name,
            hints[f.name],
            f.metadata,
            f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING,
            f.metadata.get("limit", MAX_ABS_POSITION) if hints[f.name] is float else None,
        )
        for f in fields
    )


def from_dict(cls: type[Message], obj: Any) -> Message:
    """Validate plain data into a message of type ``cls`` (raises WireError)."""
    name = cls.__name__
    if not isinstance(obj, dict):
        raise WireError(f"{name}: expected a JSON object, got {type(obj).__name__}")
    names, spec = _spec(cls)
    if not names.issuperset(obj):
        raise WireError(f"{name}: unknown field(s) {sorted(set(obj) - names)}")
    kwargs: dict[str, Any] = {}
    for fname, tp, meta, required, limit in spec:
        if fname not in obj:
            if required:
                raise WireError(f"{name}.{fname}: missing")
            continue
        v = obj[fname]
        # a number within its limit (NaN fails the comparison) and no minimum: the common case;
        # anything else takes the full check, which names what is wrong
        if limit is not None and type(v) in (float, int) and abs(v) <= limit and "min" not in meta:
            kwargs[fname] = float(v)
        else:
            kwargs[fname] = _check_field(name, fname, tp, v, meta)
    return cls(**kwargs)


def decode(cls: type[Message], payload: bytes | bytearray | memoryview | str) -> Message:
    """Decode JSON bytes into a message of type ``cls`` (raises WireError on anything wrong)."""
    try:
        if isinstance(payload, str):
            text = payload
        else:
            raw = bytes(payload)
            text = raw.decode(json.detect_encoding(raw), "surrogatepass")  # as json.loads does
        obj = _DECODER.decode(text)
    except WireError:
        raise
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise WireError(f"{cls.__name__}: not JSON: {exc}") from exc
    return from_dict(cls, obj)


def _refuse_constant(name: str) -> Any:
    raise WireError(f"non-finite constant {name} in payload")


_DECODER = json.JSONDecoder(parse_constant=_refuse_constant)


def json_schema(cls: type[Message]) -> dict[str, Any]:
    """JSON Schema (draft 2020-12) of a message type; every field is required, as Foxglove likes."""
    hints = _hints(cls)
    props: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        origin = typing.get_origin(tp) or tp
        if tp is float:
            lim = f.metadata.get("limit", MAX_ABS_POSITION)
            props[f.name] = {
                "type": "number",
                "minimum": f.metadata.get("min", -lim),
                "maximum": lim,
            }
        elif tp is int:
            props[f.name] = {"type": "integer", "minimum": f.metadata.get("min", -MAX_SEQ)}
        elif tp is bool:
            props[f.name] = {"type": "boolean"}
        elif tp is str:
            props[f.name] = {"type": "string", "maxLength": MAX_STRING}
        elif origin is dict:
            props[f.name] = {"type": "object"}
        elif origin is list:
            props[f.name] = {"type": "array"}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": cls.TYPE,
        "description": (cls.__doc__ or "").strip().splitlines()[0],
        "type": "object",
        "properties": props,
        # a field left out while default (``omit_default``) is not required
        "required": [
            f.name
            for f in dataclasses.fields(cls)
            if f.name in props and not f.metadata.get("omit_default")
        ],
        "additionalProperties": False,
    }


# --------------------------------------------------------------------------- topic registry

_PLACEHOLDERS = ("id", "what", "role")


@dataclass(frozen=True)
class Topic:
    """One bus key: its template (``{fleet}``, ``{id}``, ``{what}``, ``{role}`` placeholders),
    message type, expected rate (Hz, 0 for events: ``fleet replay`` compares the logged rate with
    it) and whether the recorder logs it."""

    name: str
    template: str
    msg: type[Message]
    rate_hz: float
    logged: bool = True

    def key(self, fleet: str, **parts: str) -> str:
        return self.template.format(fleet=fleet, **parts)

    def wildcard(self, fleet: str) -> str:
        """The key expression matching every instance of this topic in a fleet."""
        parts = {p: "*" for p in _PLACEHOLDERS if "{" + p + "}" in self.template}
        return self.template.format(fleet=fleet, **parts)


TOPICS: dict[str, Topic] = {
    t.name: t
    for t in (
        Topic("robot_cmd", "fleet/{fleet}/robot/{id}/cmd", Twist2D, 20.0),
        Topic("robot_pose", "fleet/{fleet}/robot/{id}/pose", PoseMeasurement, 30.0),
        Topic("robot_state", "fleet/{fleet}/robot/{id}/state", RobotState, 20.0),
        Topic("object_pose", "fleet/{fleet}/object/pose", PoseMeasurement, 30.0),
        Topic("object_state", "fleet/{fleet}/object/state", ObjectState, 20.0),
        Topic("robot_event", "fleet/{fleet}/robot/{id}/event", PlanEvent, 0.0),
        Topic("plan", "fleet/{fleet}/plan/{what}", PlanEvent, 0.0),
        Topic("estop", "fleet/{fleet}/estop", EStop, 0.0),
        # the latched e-stop as each holder (hub, controller, every agent) knows it: a queryable
        # per holder, so a late agent or a restarted daemon asks them all (QueryTarget.ALL); an
        # answer can only engage another holder's latch (``controller.latch``)
        Topic("estop_state", "fleet/{fleet}/estop/state/{role}/{id}", EStop, 0.0, logged=False),
        Topic("status", "fleet/{fleet}/status", FleetStatus, 0.0, logged=False),
        Topic("sim_clock", "fleet/{fleet}/sim/clock", SimTick, 20.0),
        Topic("sim_done", "fleet/{fleet}/sim/done", TickDone, 20.0),
        Topic("truth_robot", "fleet/{fleet}/sim/truth/robot/{id}", PoseMeasurement, 20.0),
        Topic("truth_object", "fleet/{fleet}/sim/truth/object", PoseMeasurement, 20.0),
        # the shared stand-in world process (``fleet world``) and the ``sim`` agents attached to
        # it: the velocity each agent applies to its robot, and that robot's sensor samples
        Topic("world_cmd", "fleet/{fleet}/sim/world/{id}/cmd", Twist2D, 20.0),
        Topic("world_pose", "fleet/{fleet}/sim/world/{id}/pose", PoseMeasurement, 30.0),
        Topic("alive", "fleet/{fleet}/alive/{role}/{id}", Message, 0.0, logged=False),
    )
}


@dataclass(frozen=True)
class KeyParts:
    """A concrete key taken apart: its topic, fleet and placeholder values (e.g. ``id``)."""

    topic: Topic
    fleet: str
    parts: dict[str, str]

    @property
    def id(self) -> str:
        return self.parts.get("id", "")

    @property
    def what(self) -> str:
        return self.parts.get("what", "")


def key(topic: str, fleet: str, **parts: str) -> str:
    """The concrete key of a registered topic, e.g. ``key("robot_cmd", "lab", id="r1")``."""
    return TOPICS[topic].key(fleet, **parts)


def alive_key(fleet: str, role: str, ident: str) -> str:
    """Liveliness token key for a robot agent or the controller."""
    return TOPICS["alive"].key(fleet, role=role, id=ident)


def fleet_prefix(fleet: str) -> str:
    """The key expression of everything a fleet puts on the bus."""
    return f"fleet/{fleet}/**"


def _match(template: str, k: list[str]) -> dict[str, str] | None:
    tparts = template.split("/")
    if len(tparts) != len(k):
        return None
    out: dict[str, str] = {}
    for a, b in zip(tparts, k, strict=True):
        if a.startswith("{") and a.endswith("}"):
            if not b:
                return None
            out[a[1:-1]] = b
        elif a != b:
            return None
    return out


def parse_key(k: str, fleet: str | None = None) -> KeyParts | None:
    """Take a concrete key apart through the registry (None if it is not one of ours, or not of
    ``fleet`` when given): ``parse_key("fleet/lab/robot/r1/pose").id == "r1"``."""
    got = _parse_key(k, fleet)
    return None if got is None else KeyParts(got[0], got[1], dict(got[2]))


@functools.lru_cache(maxsize=4096)  # a fleet's keys repeat: every sample of a log, every pose
def _parse_key(k: str, fleet: str | None) -> tuple[Topic, str, tuple[tuple[str, str], ...]] | None:
    segs = k.split("/")
    for t in TOPICS.values():
        got = _match(t.template, segs)
        if got is not None and (fleet is None or got["fleet"] == fleet):
            f = got.pop("fleet")
            return t, f, tuple(got.items())
    return None


def topic_for_key(fleet: str, k: str) -> Topic | None:
    """The registered topic a concrete key of ``fleet`` belongs to (None if it is not ours)."""
    parsed = parse_key(k, fleet)
    return None if parsed is None else parsed.topic
