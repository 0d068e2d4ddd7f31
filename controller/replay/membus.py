"""An in-memory stand-in for ``controller.io.bus.Bus``: the controller node's I/O without zenoh.

It hands out real ``Inbox`` objects (so the node's draining is the real code) and records every
publication, so the regression replay (and unit tests) can feed a tick's inputs and read its
outputs synchronously.
"""

from __future__ import annotations

import time
from collections import defaultdict
from typing import Any

from controller import wire
from controller.io.bus import Inbox, Received


class MemoryPublisher:
    def __init__(self, bus: MemoryBus, key: str) -> None:
        self.bus, self.key = bus, key

    def put(self, msg: wire.Message) -> None:
        self.bus.sent[self.key].append(msg)

    def matching(self) -> bool:
        return True


class MemoryBus:
    """The parts of ``Bus`` the controller node uses, in memory."""

    def __init__(self, fleet: str) -> None:
        self.fleet = fleet
        self.sent: dict[str, list[wire.Message]] = defaultdict(list)
        self.inboxes: dict[str, Inbox] = {}
        self.alive_cb: dict[str, Any] = {}
        self.served: dict[str, Any] = {}
        self.queries: list[tuple[str, Inbox]] = []
        self.bad = 0

    def key(self, topic: str, **parts: str) -> str:
        return wire.key(topic, self.fleet, **parts)

    def subscribe_topic(
        self, topic: str, inbox=None, waker=None, lossless: bool = False, **parts: str
    ) -> Inbox:
        box = inbox if inbox is not None else Inbox(waker=waker)
        self.inboxes[topic] = box
        return box

    def publisher(self, topic: str, *, command: bool = False, lossless: bool = False, **parts):
        return MemoryPublisher(self, self.key(topic, **parts))

    def put(self, topic: str, msg: wire.Message, **parts: str) -> None:
        self.sent[self.key(topic, **parts)].append(msg)

    def watch_alive(self, role: str, callback) -> None:
        self.alive_cb[role] = callback

    def serve(self, topic: str, responder, **parts: str) -> None:
        self.served[self.key(topic, **parts) if parts else topic] = responder

    def serve_estop(self, role: str, ident: str, responder) -> str:
        self.serve("estop_state", responder, role=role, id=ident)
        return self.key("estop_state", role=role, id=ident)

    def estop_wildcard(self) -> str:
        return wire.TOPICS["estop_state"].wildcard(self.fleet)

    def query_async(self, key_expr: str, msg_type, inbox, timeout: float) -> None:
        """Nothing answers on the in-memory bus (a test puts replies in ``inbox`` itself)."""
        self.queries.append((key_expr, inbox))

    def declare_alive(self, role: str, ident: str) -> None:
        pass

    def drops(self) -> dict[str, int]:
        return {"bad_payloads": self.bad, "inbox_overflow": 0, "rate_limited": 0}

    # -- the feeding side
    def deliver(self, topic: str, msg: wire.Message, **parts: str) -> None:
        """A message arrives on ``topic`` (as a zenoh callback would enqueue it)."""
        self.inboxes[topic].put(Received(time.time(), self.key(topic, **parts), msg))

    def deliver_key(self, key: str, msg: wire.Message, recv_time: float = 0.0) -> bool:
        """A message arrives on a concrete key; False if nothing subscribed to its topic."""
        parsed = wire.parse_key(key, self.fleet)
        box = None if parsed is None else self.inboxes.get(parsed.topic.name)
        if box is None:
            return False
        box.put(Received(recv_time, key, msg))
        return True

    def last(self, topic: str, **parts: str) -> wire.Message:
        return self.sent[self.key(topic, **parts)][-1]
