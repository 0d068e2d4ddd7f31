"""The controller node's latch plumbing: its copy of the latched e-stop, learnt from the other
holders (hub, agents) and the operators' e-stops, served to whoever asks.

Part of ``ControllerNode`` (``controller/runtime/node.py``): the node's sample stage calls
``sample``; ``stopped`` holds every command at zero.
"""

from __future__ import annotations

import logging
import math

from controller import wire
from controller.io.bus import Inbox
from controller.latch import Latch, note_latch, role_of

log = logging.getLogger("controller.runtime.node")  # the node's own log, whichever part


class NodeLatch:
    """The latched e-stop as the controller holds it, and the bus plumbing that keeps it."""

    def __init__(self, bus, fleet: str, at_start: wire.EStop | None, second=None) -> None:
        """``second``: the e-stop's second path (the daemon's own listener,
        ``zenoh.estop_listen``): the operators' e-stops are taken from it too, and the latch
        answered there (a hung hub then delays neither)."""
        self.bus = bus
        self.fleet = fleet
        self.latch = Latch("controller/main", at_start)
        # True from ``expect`` until a holder answers: every command is zero meanwhile
        self.pending = False
        # s: an operator's release stamped further than this from the tick's time is refused
        # (a replayed old resume); the daemon sets fleet.max_clock_skew, the dry run none
        self.release_max_age = math.inf
        # never drop an e-stop, whichever path it comes by
        self._estops = [
            b.subscribe_topic("estop", lossless=True) for b in (bus, second) if b is not None
        ]
        self._replies = Inbox()
        self.paths = [b for b in (bus, second) if b is not None]
        self._key = bus.serve_estop("controller", "main", self.answer)
        if second is not None:
            second.serve_estop("controller", "main", self.answer)

    def serve_status(self, responder) -> None:
        """``fleet status`` answered on every path the latch is answered on (with the hub hung
        an operator still sees the fleet, by the second path)."""
        for b in self.paths:
            b.serve("status", responder)

    @property
    def stopped(self) -> bool:
        """Whether the robots are held stopped: an e-stop latched, or the latch unknown."""
        return self.latch.stopped

    def answer(self) -> wire.EStop | None:
        """The latched e-stop, answered on ``estop/state/controller/main`` (zenoh's thread);
        None (no answer) while unknown."""
        return self.latch.answer()

    def expect(self, timeout: float = 1.0) -> None:
        """Ask every holder and command zero until one answers (a start, or a resume after the
        loop was hung): the controller must not command robots on a state it may have missed.
        ``release`` ends the wait unanswered."""
        self.pending = True
        self.ask(timeout)

    def ask(self, timeout: float = 1.0) -> None:
        """Ask every holder without holding the commands (an unknown latch holds them anyway);
        the answers are applied in the next tick's sample stage."""
        self.bus.query_async(self.bus.estop_wildcard(), wire.EStop, self._replies, timeout=timeout)

    def release(self) -> None:
        """Nobody answered the latch query (no hub, no agent): go on with what this node holds
        (an unknown latch stays stopped until an operator's release)."""
        if self.pending:  # a fresh lab: nobody knows the latch yet (fail closed)
            state = (
                "unknown: stopped until an operator's resume"
                if not self.latch.known
                else ("engaged" if self.stopped else "released")
            )
            log.info("no holder answered the e-stop latch query; the e-stop is %s", state)
        self.pending = False

    def sample(self, now: float | None) -> None:
        """The other holders' answers and the operators' e-stops into the latch."""
        replies = [
            (role_of(i.key, self.fleet), i.msg) for i in self._replies.drain() if i.key != self._key
        ]
        if replies:
            self.pending = False
            note_latch("controller", self.latch.answers(replies))
        age = self.release_max_age  # the lab's wall clock only (see drivers.agent.AgentParams)
        for inbox in self._estops:
            for item in inbox.drain():
                stamp = now if math.isfinite(age) else None
                note_latch("controller", self.latch.operator(item.msg, stamp, age))

    def counters(self) -> dict[str, int]:
        """The latch in ``fleet status``: its epoch, 1 while unknown, refusals so far."""
        c = self.latch.counters
        return {
            "estop_epoch": self.latch.epoch,
            "estop_unknown": int(not self.latch.known),
            "estop_replays_refused": c.replays_refused,
            "estop_answers_refused": c.answers_refused,
            # 0 while the daemon's latch is not in its file (a failed write: full disk...)
            "estop_durable": int(self.latch.durable),
            "estop_implausible_epochs": c.implausible_epochs,
            "estop_releases_refused_not_durable": c.releases_refused_not_durable,
            "estop_stale_releases": c.stale_releases,
        }
