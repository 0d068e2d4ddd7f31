"""The ROS 2 messages the ROS 2 driver speaks: their definitions, type hashes and CDR codec.

Pure functions, no I/O. One table (:data:`DEFINITIONS`) describes each message's fields; from it
come the ``.msg`` text (the ``ros2msg`` schema an MCAP file carries, and what the codec is built
from), the REP-2011 type description and its hash ``RIHS01_<sha256>`` (rosidl's
``rosidl_generator_type_description.calculate_type_hash``: the type description and its sorted
referenced types as JSON, default values dropped, separators ``", "``/``": "``). The hashes of
``geometry_msgs/msg/Twist``, ``TwistStamped``, ``nav_msgs/msg/Odometry`` are checked in the tests
against the values rosidl publishes (the keys of real rmw_zenoh robots).

CDR: mcap-ros2-support (Foxglove's ``mcap_ros2``), a maintained pure-Python codec driven by
the same ``.msg`` text we write into MCAP, so what the driver encodes and what a log declares
cannot drift apart. Payloads are XCDR1 little endian with the 4-byte encapsulation header
(``00 01 00 00``), as rmw_zenoh (Fast CDR) sends them.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from functools import cache
from typing import Any

from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

# (field name, type): a primitive, a nested type's full name, "float64[36]" (a fixed array) or
# "pkg/msg/T[]" (an unbounded sequence)
DEFINITIONS: dict[str, tuple[tuple[str, str], ...]] = {
    "builtin_interfaces/msg/Time": (("sec", "int32"), ("nanosec", "uint32")),
    "std_msgs/msg/Header": (("stamp", "builtin_interfaces/msg/Time"), ("frame_id", "string")),
    "geometry_msgs/msg/Vector3": (("x", "float64"), ("y", "float64"), ("z", "float64")),
    "geometry_msgs/msg/Point": (("x", "float64"), ("y", "float64"), ("z", "float64")),
    "geometry_msgs/msg/Quaternion": (
        ("x", "float64"),
        ("y", "float64"),
        ("z", "float64"),
        ("w", "float64"),
    ),
    "geometry_msgs/msg/Twist": (
        ("linear", "geometry_msgs/msg/Vector3"),
        ("angular", "geometry_msgs/msg/Vector3"),
    ),
    "geometry_msgs/msg/TwistStamped": (
        ("header", "std_msgs/msg/Header"),
        ("twist", "geometry_msgs/msg/Twist"),
    ),
    "geometry_msgs/msg/Pose": (
        ("position", "geometry_msgs/msg/Point"),
        ("orientation", "geometry_msgs/msg/Quaternion"),
    ),
    "geometry_msgs/msg/PoseStamped": (
        ("header", "std_msgs/msg/Header"),
        ("pose", "geometry_msgs/msg/Pose"),
    ),
    "geometry_msgs/msg/PoseWithCovariance": (
        ("pose", "geometry_msgs/msg/Pose"),
        ("covariance", "float64[36]"),
    ),
    "geometry_msgs/msg/TwistWithCovariance": (
        ("twist", "geometry_msgs/msg/Twist"),
        ("covariance", "float64[36]"),
    ),
    "geometry_msgs/msg/Transform": (
        ("translation", "geometry_msgs/msg/Vector3"),
        ("rotation", "geometry_msgs/msg/Quaternion"),
    ),
    "geometry_msgs/msg/TransformStamped": (
        ("header", "std_msgs/msg/Header"),
        ("child_frame_id", "string"),
        ("transform", "geometry_msgs/msg/Transform"),
    ),
    "tf2_msgs/msg/TFMessage": (("transforms", "geometry_msgs/msg/TransformStamped[]"),),
    "std_msgs/msg/String": (("data", "string"),),
    "nav_msgs/msg/Odometry": (
        ("header", "std_msgs/msg/Header"),
        ("child_frame_id", "string"),
        ("pose", "geometry_msgs/msg/PoseWithCovariance"),
        ("twist", "geometry_msgs/msg/TwistWithCovariance"),
    ),
}

#: config names → ROS types (``[robots.ros2] cmd_type`` and ``pose_type``)
CMD_TYPES = {"twist": "geometry_msgs/msg/Twist", "twist_stamped": "geometry_msgs/msg/TwistStamped"}
POSE_TYPES = {"odometry": "nav_msgs/msg/Odometry", "pose_stamped": "geometry_msgs/msg/PoseStamped"}

# type_description_interfaces/msg/FieldType ids of the types above
_TYPE_IDS = {"int32": 6, "uint32": 7, "float64": 11, "string": 17}
_NESTED, _ARRAY_OFFSET = 1, 48  # FIELD_TYPE_NESTED_TYPE; a fixed array adds 48 (double[] = 59)
_SEQUENCE_OFFSET = 144  # an unbounded sequence adds 144 (NESTED_TYPE_UNBOUNDED_SEQUENCE = 145)
UNBOUNDED = -1  # ``_split_array``'s size of an unbounded sequence
_SEPARATOR = "=" * 80


def _split_array(ftype: str) -> tuple[str, int]:
    """(base type, size): 0 for a single value, ``UNBOUNDED`` for ``T[]``."""
    if ftype.endswith("]"):
        base, n = ftype[:-1].split("[")
        return base, int(n) if n else UNBOUNDED
    return ftype, 0


def _field_description(name: str, ftype: str) -> dict[str, Any]:
    base, n = _split_array(ftype)
    nested = base if base in DEFINITIONS else ""
    type_id = _NESTED if nested else _TYPE_IDS[base]
    if n == UNBOUNDED:
        type_id += _SEQUENCE_OFFSET
    elif n:
        type_id += _ARRAY_OFFSET
    return {
        "name": name,
        "type": {
            "type_id": type_id,
            "capacity": max(n, 0),
            "string_capacity": 0,
            "nested_type_name": nested,
        },
    }


def _referenced(type_name: str) -> list[str]:
    """Every type ``type_name`` refers to, directly or not, sorted by name."""
    out: set[str] = set()
    todo = [type_name]
    while todo:
        for _, ftype in DEFINITIONS[todo.pop()]:
            base, _ = _split_array(ftype)
            if base in DEFINITIONS and base not in out:
                out.add(base)
                todo.append(base)
    return sorted(out)


def type_description(type_name: str) -> dict[str, Any]:
    """The REP-2011 type description of ``type_name`` (what is hashed; no default values)."""

    def one(name: str) -> dict[str, Any]:
        return {
            "type_name": name,
            "fields": [_field_description(f, t) for f, t in DEFINITIONS[name]],
        }

    return {
        "type_description": one(type_name),
        "referenced_type_descriptions": [one(n) for n in _referenced(type_name)],
    }


@cache
def type_hash(type_name: str) -> str:
    """``RIHS01_<64 hex>``: the REP-2011 hash of ``type_name`` (e.g. geometry_msgs/msg/Twist)."""
    text = json.dumps(type_description(type_name), separators=(", ", ": "), ensure_ascii=True)
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def dds_type_name(type_name: str) -> str:
    """rmw_zenoh's type name in keys: ``geometry_msgs::msg::dds_::Twist_``."""
    pkg, sub, name = type_name.split("/")
    return f"{pkg}::{sub}::dds_::{name}_"


def _msg_line(name: str, ftype: str) -> str:
    base, n = _split_array(ftype)
    if base in DEFINITIONS:
        pkg, _, short = base.split("/")
        base = f"{pkg}/{short}"
    size = "[]" if n == UNBOUNDED else f"[{n}]" if n else ""
    return f"{base}{size} {name}"


@cache
def msg_definition(type_name: str) -> str:
    """The ``ros2msg`` schema text: the type's ``.msg`` then each referenced type's, separated
    as rosbag2 writes them (``====…`` and ``MSG: pkg/Name``)."""
    parts = ["\n".join(_msg_line(f, t) for f, t in DEFINITIONS[type_name])]
    for ref in _referenced(type_name):
        pkg, _, short = ref.split("/")
        body = "\n".join(_msg_line(f, t) for f, t in DEFINITIONS[ref])
        parts.append(f"{_SEPARATOR}\nMSG: {pkg}/{short}\n{body}")
    return "\n".join(parts) + "\n"


# --------------------------------------------------------------------------- codec


@cache
def _encoder(type_name: str):
    return serialize_dynamic(type_name, msg_definition(type_name))[type_name]


@cache
def _decoder(type_name: str):
    return generate_dynamic(type_name, msg_definition(type_name))[type_name]


def encode(type_name: str, msg: dict[str, Any]) -> bytes:
    """A message (nested dicts with every field) as a CDR payload."""
    return _encoder(type_name)(msg)


def decode(type_name: str, payload: bytes) -> Any:
    """A CDR payload as a message object (attributes named as the fields); ValueError if the
    payload does not decode as ``type_name``."""
    try:
        return _decoder(type_name)(bytes(payload))
    except (ValueError, IndexError, KeyError, TypeError, EOFError) as exc:
        raise ValueError(f"not a {type_name} CDR payload: {exc}") from exc
    except Exception as exc:  # noqa: BLE001 - the codec's own errors (struct.error, ...)
        raise ValueError(f"not a {type_name} CDR payload: {exc}") from exc


# --------------------------------------------------------------------------- our messages


def stamp(t: float) -> dict[str, int]:
    """A ``builtin_interfaces/Time`` for ``t`` seconds (floor to the nanosecond)."""
    ns = int(round(t * 1e9))
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def stamp_seconds(s: Any) -> float:
    return float(s.sec) + float(s.nanosec) * 1e-9


def _vec(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> dict[str, float]:
    return {"x": float(x), "y": float(y), "z": float(z)}


def twist_message(
    cmd_type: str, vx: float, vy: float, wz: float, t: float, frame_id: str
) -> dict[str, Any]:
    """A body-frame velocity (REP 103: x forward, y left, z up) as ``cmd_type`` (a key of
    :data:`CMD_TYPES`)."""
    twist = {"linear": _vec(vx, vy), "angular": _vec(0.0, 0.0, wz)}
    if cmd_type == "twist":
        return twist
    return {"header": {"stamp": stamp(t), "frame_id": frame_id}, "twist": twist}


def quaternion_yaw(q: Any) -> float:
    """The yaw (rotation about z, CCW, rad) of a quaternion with ``x y z w`` attributes."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def yaw_quaternion(yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2.0), "w": math.cos(yaw / 2.0)}


@dataclass(frozen=True)
class PlanarPose:
    """A planar pose read from a ROS pose message, in the message's own frame: ``t`` (s, the
    header stamp), ``x``, ``y`` (m), ``yaw`` (rad, CCW), ``frame_id``; ``var_xy``/``var_yaw``
    the covariance's diagonal where the message has one (m², rad²; 0 when not given)."""

    t: float
    x: float
    y: float
    yaw: float
    frame_id: str
    var_xy: float = 0.0
    var_yaw: float = 0.0


def read_pose(pose_type: str, msg: Any) -> PlanarPose:
    """The planar pose of a decoded ``nav_msgs/Odometry`` or ``geometry_msgs/PoseStamped``."""
    if pose_type == "odometry":
        pose, cov = msg.pose.pose, list(msg.pose.covariance)
        var_xy, var_yaw = max(cov[0], cov[7], 0.0), max(cov[35], 0.0)
    else:
        pose, var_xy, var_yaw = msg.pose, 0.0, 0.0
    return PlanarPose(
        t=stamp_seconds(msg.header.stamp),
        x=float(pose.position.x),
        y=float(pose.position.y),
        yaw=quaternion_yaw(pose.orientation),
        frame_id=str(msg.header.frame_id),
        var_xy=float(var_xy),
        var_yaw=float(var_yaw),
    )


def pose_message(
    pose_type: str,
    t: float,
    x: float,
    y: float,
    yaw: float,
    frame_id: str = "odom",
    child_frame_id: str = "base_link",
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0),
    var_xy: float = 0.0,
    var_yaw: float = 0.0,
) -> dict[str, Any]:
    """A planar pose as ``nav_msgs/Odometry`` (twist in the child frame, REP 105) or
    ``geometry_msgs/PoseStamped``: what a ROS 2 robot (or our stand-in) publishes."""
    header = {"stamp": stamp(t), "frame_id": frame_id}
    pose = {"position": _vec(x, y), "orientation": yaw_quaternion(yaw)}
    if pose_type == "pose_stamped":
        return {"header": header, "pose": pose}
    cov = [0.0] * 36
    cov[0] = cov[7] = var_xy
    cov[35] = var_yaw
    vx, vy, wz = velocity
    return {
        "header": header,
        "child_frame_id": child_frame_id,
        "pose": {"pose": pose, "covariance": cov},
        "twist": {
            "twist": {"linear": _vec(vx, vy), "angular": _vec(0.0, 0.0, wz)},
            "covariance": [0.0] * 36,
        },
    }
