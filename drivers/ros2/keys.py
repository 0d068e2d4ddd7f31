"""rmw_zenoh's conventions on the zenoh bus, as pure functions: key expressions, liveliness
tokens, the attachment of every sample, the entity GID, and REP 103/105 frames.

Implemented from ros2/rmw_zenoh 0.2.5 (jazzy branch, CHANGELOG of 2025-06-18; the attachment
format of 0.2.4, "Change serialization format in attachment_helpers.cpp" #605), read in
``rmw_zenoh_cpp/src/detail/``: ``liveliness_utils.cpp`` @3411fdec1 (keys and tokens),
``attachment_helpers.cpp`` @534747dca (attachment), ``rmw_publisher_data.cpp`` @3e19ec730
(publish), ``type_support_common.hpp`` (the ``dds_`` type name) and ``docs/design.md``. (The
fetched snapshot, bfc065f8 of 2024-10, is the zenoh 0.11 era: a key-value attachment with
string numbers and tokens without node ids or type hashes; a Zenoh 1.x peer like ours cannot
talk to that version at all.)

- data key: ``<domain_id>/<topic without leading or trailing '/'>/<dds type>/<RIHS01 hash>``,
  e.g. ``0/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45…``;
- liveliness token: ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS>/<enclave>/
  <namespace>/<node>[/<topic>/<dds type>/<type hash>/<qos>]`` with every ``/`` inside a part
  mangled to ``%`` (the root namespace and enclave are ``%``); ``<qos>`` lists only what
  differs from rmw_zenoh's default profile (``::,:,:,:,,`` is all defaults: reliability,
  durability, history,depth, deadline s,ns, lifespan s,ns, liveliness,lease s,ns). Our
  entities are RELIABLE, VOLATILE, KEEP_LAST 10: rmw_zenoh's defaults since jazzy 0.2.3 /
  rolling 0.5.0, when the durability default became VOLATILE (TRANSIENT_LOCAL before, so an
  empty durability there would claim a late-joiner cache we do not keep). Those older robots
  are below the supported releases anyway (``SUPPORTED_RMW_ZENOH``: the attachment);
- attachment (zenoh-ext serialization): int64 sequence number (from 1), int64 source timestamp
  (ns since the epoch, the publisher's clock), the 16-byte GID as a sequence (LEB128 length 16
  then the bytes): 33 bytes, little endian;
- GID: XXH3-128 of the entity's liveliness key expression, its ``low64`` then its ``high64``
  word, each in the host's (little-endian) byte order, as ``Entity::Entity`` memcpy's them
  (``liveliness_utils.cpp``): what ``ros2 topic info -v`` lists and what a receiver's
  ``publisher_gid`` (``rmw_message_info_t``) carries.

Frames (REP 103, REP 105): a ROS body frame is x forward, y left, z up, like our command's
body frame, so a twist maps one to one; a pose arrives in the robot's ``odom`` (or a mocap
``map``) frame, which the configured ``odom_to_world`` [x, y, yaw] places in our ENU world.
"""

from __future__ import annotations

import math
import re
import struct

import xxhash

from drivers.ros2.msgs import dds_type_name, type_hash

ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION = "NN", "MP", "MS"
DEFAULT_QOS = "::,:,:,:,,"
GID_SIZE = 16
_ATTACHMENT = struct.Struct("<qqB16s")  # seq, source timestamp, LEB128(16), gid
ATTACHMENT_SIZE = _ATTACHMENT.size  # 33
#: the rmw_zenoh releases of this attachment (and of zenoh 1.x); older robots read ours as
#: malformed (the config's ``ros2.rmw_zenoh`` refuses them: RMW_ZENOH_MIN there)
SUPPORTED_RMW_ZENOH = "jazzy 0.2.4, rolling 0.6.0, humble 0.1.2"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def valid_name(name: str, absolute_ok: bool = True) -> bool:
    """Whether ``name`` is a ROS name: ``/``-separated tokens of letters, digits and ``_``, not
    starting with a digit (``""`` is not; ``/`` alone is the root)."""
    if name == "/":
        return absolute_ok
    if name.startswith("/"):
        if not absolute_ok:
            return False
        name = name[1:]
    return bool(name) and all(_NAME.match(p) for p in name.split("/"))


def qualify(namespace: str, topic: str) -> str:
    """The fully qualified topic name: an absolute ``topic`` as is, a relative one under
    ``namespace`` (``"" `` or ``/`` is the root)."""
    if topic.startswith("/"):
        return topic
    ns = namespace.strip("/")
    return f"/{ns}/{topic}" if ns else f"/{topic}"


def topic_key(domain_id: int, topic: str, type_name: str) -> str:
    """The data key expression of a fully qualified ``topic`` carrying ``type_name``."""
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(type_name)}/{type_hash(type_name)}"


def mangle(name: str) -> str:
    return name.replace("/", "%")


def node_token(domain_id: int, zid: str, node_id: int, namespace: str, node: str) -> str:
    """The liveliness token of a node (``NN``)."""
    ns = namespace if namespace.startswith("/") else "/" + namespace
    return "/".join(
        (ADMIN_SPACE, str(domain_id), zid, str(node_id), str(node_id), NODE, "%", mangle(ns), node)
    )


def entity_token(
    kind: str,
    domain_id: int,
    zid: str,
    node_id: int,
    entity_id: int,
    namespace: str,
    node: str,
    topic: str,
    type_name: str,
    qos: str = DEFAULT_QOS,
) -> str:
    """The liveliness token of a publisher (``MP``) or subscription (``MS``) of ``topic``."""
    ns = namespace if namespace.startswith("/") else "/" + namespace
    return "/".join(
        (
            ADMIN_SPACE,
            str(domain_id),
            zid,
            str(node_id),
            str(entity_id),
            kind,
            "%",
            mangle(ns),
            node,
            mangle(topic),
            mangle(dds_type_name(type_name)),
            type_hash(type_name),
            qos,
        )
    )


def parse_token(token: str) -> dict[str, str] | None:
    """A liveliness token's parts (``kind``, ``domain``, ``namespace``, ``node``, and for an
    endpoint ``topic``, ``type``, ``hash``), or None if it is not an rmw_zenoh token."""
    parts = token.split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE or parts[5] not in (NODE, PUBLISHER, SUBSCRIPTION):
        return None
    out = {
        "domain": parts[1],
        "zid": parts[2],
        "kind": parts[5],
        "namespace": parts[7].replace("%", "/"),
        "node": parts[8].replace("%", "/"),
    }
    if parts[5] != NODE:
        if len(parts) < 13:
            return None
        out.update(topic=parts[9].replace("%", "/"), type=parts[10], hash=parts[11])
    return out


def gid(token: str) -> bytes:
    """The entity's 16-byte GID as rmw_zenoh computes it from its liveliness token: XXH3-128
    of the token's text, ``low64`` then ``high64``, little endian. (xxhash's ``digest()`` is
    the canonical big-endian ``high64 || low64``: the same bytes in the other order.)"""
    h = xxhash.xxh3_128_intdigest(token.encode())
    return struct.pack("<QQ", h & 0xFFFF_FFFF_FFFF_FFFF, h >> 64)


def attachment(seq: int, source_timestamp_ns: int, source_gid: bytes) -> bytes:
    """rmw_zenoh's sample attachment (sequence number, source timestamp in ns, GID)."""
    if len(source_gid) != GID_SIZE:
        raise ValueError(f"a GID has {GID_SIZE} bytes, got {len(source_gid)}")
    return _ATTACHMENT.pack(seq, source_timestamp_ns, GID_SIZE, source_gid)


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp ns, GID) of an attachment; ValueError if malformed."""
    if len(data) != _ATTACHMENT.size:
        raise ValueError(f"an rmw_zenoh attachment has {_ATTACHMENT.size} bytes, got {len(data)}")
    seq, ts, n, g = _ATTACHMENT.unpack(data)
    if n != GID_SIZE:
        raise ValueError(f"the GID's length is {n}, expected {GID_SIZE}")
    return seq, ts, g


# --------------------------------------------------------------------------- frames


def odom_to_world(
    x: float, y: float, yaw: float, transform: tuple[float, float, float]
) -> tuple[float, float, float]:
    """A pose in the robot's odom frame (REP 105) in our world frame: ``transform`` is the odom
    frame's pose in the world (x, y in m, yaw in rad CCW); the heading is wrapped to (-π, π]."""
    tx, ty, tyaw = transform
    c, s = math.cos(tyaw), math.sin(tyaw)
    return tx + c * x - s * y, ty + s * x + c * y, math.remainder(yaw + tyaw, 2 * math.pi)


def world_to_odom(
    x: float, y: float, yaw: float, transform: tuple[float, float, float]
) -> tuple[float, float, float]:
    """The inverse of :func:`odom_to_world`."""
    tx, ty, tyaw = transform
    c, s = math.cos(tyaw), math.sin(tyaw)
    dx, dy = x - tx, y - ty
    return c * dx + s * dy, -s * dx + c * dy, math.remainder(yaw - tyaw, 2 * math.pi)
