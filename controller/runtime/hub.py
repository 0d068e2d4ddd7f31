"""``fleet hub``: the fleet's meeting point on the lab network, and the e-stop's keeper.

A zenoh session in router mode listening on the config's ``zenoh.listen`` endpoints: agents,
the daemon (which then joins as a client instead of listening) and the tools all connect to it,
so an agent still hears ``fleet estop`` when the daemon is hung or dead. It holds the latched
e-stop: it subscribes to ``estop`` and answers latch queries on ``estop/state/hub/main`` with the
latest ``EStop`` (agents and the controller answer the same query with their own latched state,
so any one survivor suffices). Every few seconds it asks the other holders too, so a restarted
hub learns the latch back from the agents.
"""

from __future__ import annotations

import logging
import sys
import threading
import time

from controller import wire
from controller.config import FleetConfig
from controller.io.bus import Bus, Inbox, Received

log = logging.getLogger(__name__)

RELEARN_EVERY = 2.0  # s between the hub's own latch queries


class HubLatch:
    """The hub's latched e-stop: live messages in arrival order, other holders' answers when
    newer (``wire.newest_estop``). Thread-safe (zenoh's callbacks and the query responder)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.msg: wire.EStop | None = None

    def live(self, msg: wire.EStop) -> None:
        with self._lock:
            changed = self.msg is None or self.msg.engaged != msg.engaged
            self.msg = msg
        if changed:
            state = "engaged" if msg.engaged else "released"
            log.warning("e-stop %s by %s", state, msg.source)

    def answer(self, msg: wire.EStop) -> None:
        if msg.t <= 0.0:
            return  # a holder that never latched anything: nothing to learn
        with self._lock:
            if self.msg is not None and wire.newest_estop([self.msg, msg]) is self.msg:
                return
            self.msg = msg
        log.warning("e-stop latch learnt from a holder: engaged=%s by %s", msg.engaged, msg.source)

    def state(self) -> wire.EStop:
        with self._lock:
            held = self.msg
        return held if held is not None else wire.EStop(t=0.0, engaged=False, source="hub/main")


class _Answers:
    """Where the other holders' latch answers go (zenoh's thread): into the hub's latch."""

    def __init__(self, latch: HubLatch, own_key: str) -> None:
        self.latch, self.own_key = latch, own_key

    def put(self, item: Received) -> None:
        if item.key != self.own_key:
            self.latch.answer(item.msg)


def run_hub(cfg: FleetConfig, stop: threading.Event, duration: float = 0.0) -> int:
    """Serve until ``stop`` (or ``duration`` s). Exit 0; a BusError (endpoints taken) → 1."""
    latch = HubLatch()
    with Bus(
        cfg.zenoh, cfg.fleet.name, mode="router", listen=list(cfg.zenoh.listen), connect=[]
    ) as bus:
        bus.subscribe(
            bus.key("estop"),
            wire.EStop,
            Inbox(maxsize=1),
            on_message=lambda r: latch.live(r.msg),
            lossless=True,  # every e-stop reaches the latch, whatever floods the key
        )
        own = bus.serve_estop("hub", "main", latch.state)

        answers = _Answers(latch, own)
        print(
            f"fleet hub: fleet {cfg.fleet.name!r} on {list(cfg.zenoh.listen)}",
            file=sys.stderr,
            flush=True,
        )
        t0 = time.monotonic()
        while not stop.is_set():
            bus.query_async(bus.estop_wildcard(), wire.EStop, answers, timeout=1.0)
            if duration and time.monotonic() - t0 >= duration:
                break
            stop.wait(RELEARN_EVERY)
    print("fleet hub: stopped", file=sys.stderr)
    return 0
