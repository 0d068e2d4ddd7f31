"""A ROS 2 node as rmw_zenoh puts it on zenoh: its session, its liveliness tokens, publishers
whose samples carry rmw_zenoh's attachment, and raw subscriptions. Both sides use it: the
driver (our node on the robot's ROS graph) and the stand-in robot of the tests. What goes in the
payloads (CDR) is the caller's business; keys and tokens are :mod:`drivers.ros2.keys`.

A callback runs on zenoh's thread: it gets ``(payload, attachment or None)`` and must only
enqueue.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Sequence
from typing import Any

import zenoh

from drivers.ros2 import keys

log = logging.getLogger(__name__)


def open_session(
    connect: Sequence[str] = (), listen: Sequence[str] = (), mode: str = "client"
) -> zenoh.Session:
    """A zenoh session as rmw_zenoh would open one (router at ``connect``), without multicast
    scouting; ``mode`` "client" routes everything through the router or peer it connects to."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if mode != "client":
        conf.insert_json5("scouting/gossip/enabled", "false")
    return zenoh.open(conf)


class RmwPublisher:
    """A publisher of one topic: each ``put`` carries (sequence from 1, source time, GID)."""

    def __init__(self, session: zenoh.Session, key: str, token: str, express: bool) -> None:
        self.key = key
        self.token_key = token
        self.gid = keys.gid(token)
        self.seq = 0
        self._pub = session.declare_publisher(
            key,
            congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.REAL_TIME if express else zenoh.Priority.DATA,
            express=express,
        )
        self._token = session.liveliness().declare_token(token)

    def put(self, payload: bytes, source_time_ns: int) -> None:
        self.seq += 1
        self._pub.put(payload, attachment=keys.attachment(self.seq, source_time_ns, self.gid))

    def matching(self) -> bool:
        """Whether a subscriber of this key is known (its declaration arrived)."""
        return bool(self._pub.matching_status.matching)

    def undeclare(self) -> None:
        for h in (self._token, self._pub):
            try:
                h.undeclare()
            except Exception:  # noqa: BLE001 - already gone with the session
                pass


class RmwNode:
    """A node ``namespace``/``name`` on ``domain_id`` over an open ``session`` (not owned)."""

    def __init__(self, session: zenoh.Session, domain_id: int, namespace: str, name: str) -> None:
        self.session = session
        self.domain_id = domain_id
        self.namespace = namespace or "/"
        self.name = name
        self.zid = str(session.zid())
        self.node_id = 0
        self._next_entity = 1
        self._handles: list[Any] = []
        self.token_key = keys.node_token(domain_id, self.zid, 0, self.namespace, name)
        self._handles.append(session.liveliness().declare_token(self.token_key))

    def _entity(self, kind: str, topic: str, type_name: str) -> tuple[str, str]:
        eid = self._next_entity
        self._next_entity += 1
        token = keys.entity_token(
            kind, self.domain_id, self.zid, self.node_id, eid, self.namespace, self.name,
            topic, type_name,
        )  # fmt: skip
        return keys.topic_key(self.domain_id, topic, type_name), token

    def publisher(self, topic: str, type_name: str, express: bool = False) -> RmwPublisher:
        """Publish ``type_name`` on the fully qualified ``topic`` (declares its ``MP`` token)."""
        key, token = self._entity(keys.PUBLISHER, topic, type_name)
        pub = RmwPublisher(self.session, key, token, express)
        self._handles.append(pub)
        return pub

    def subscribe(
        self, topic: str, type_name: str, callback: Callable[[bytes, bytes | None], None]
    ) -> str:
        """Subscribe to ``topic`` (declares its ``MS`` token); returns the data key."""
        key, token = self._entity(keys.SUBSCRIPTION, topic, type_name)

        def cb(sample: zenoh.Sample) -> None:
            att = sample.attachment
            try:
                callback(sample.payload.to_bytes(), None if att is None else att.to_bytes())
            except Exception:  # noqa: BLE001 - never raise out of zenoh's thread
                log.exception("subscription callback failed on %s", key)

        self._handles.append(self.session.declare_subscriber(key, cb))
        self._handles.append(self.session.liveliness().declare_token(token))
        return key

    def close(self) -> None:
        """Undeclare every entity and the node's token (the session stays open)."""
        for h in reversed(self._handles):
            try:
                h.undeclare()
            except Exception:  # noqa: BLE001 - already gone with the session
                pass
        self._handles.clear()
