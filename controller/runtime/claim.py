"""One controller per fleet: the daemon's claim on ``fleet/<fleet>/alive/controller/<id>``.

Each daemon process has its own liveliness id, ``main-<start ms>-<pid>-<host>``; ids order by
their start stamp (then the text), and ``main`` alone (a controller from before these ids) is
the oldest. The rule, which never leaves two controllers commanding once they see each other:

- at start, a daemon that finds another controller's token alive refuses to start (exit 1,
  naming it), unless told to take over (``fleet daemon --take-over``);
- a controller that sees a *newer* controller's token stops commanding at once and exits 1
  naming it (the old side of a take-over, or the older of two started in the same instant);
- the newcomer of a take-over takes a stamp newer than every controller it found, declares
  its token, and commands nothing until all of them are gone (the old one saw the token and
  stopped); if they are not gone within ``wait`` seconds (a hung old daemon, or one from before
  this rule) it gives up, exit 1, and nothing was commanded;
- a "newer" token stamped more than ``FUTURE_LIMIT_MS`` after this clock (and not just one
  above this controller's own stamp, as a take-over of a controller whose clock runs ahead
  takes) is no take-over: forged, or a clock far off. It is logged and ignored, so one such
  token cannot make the running controller yield. On the open profile anyone on the port can
  still declare a plausible one; the lab profile's ACL lets only the controller's user declare
  ``alive/controller/*`` (docs/lab/safety.md).

I/O shell only (the bus); the ordering of ids is pure (``newer``).
"""

from __future__ import annotations

import logging
import os
import re
import socket
import threading
import time
from collections.abc import Callable

log = logging.getLogger(__name__)

ROLE = "controller"
_ID = re.compile(r"^main-(\d+)-(\d+)-(.+)$")
_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-]")
# ms a take-over's stamp may be ahead of this clock: lab clocks under NTP agree within
# milliseconds; a minute leaves room for a host that is not synced yet
FUTURE_LIMIT_MS = 60_000


def stamp_of(ident: str) -> int:
    """The start stamp (ms) in a controller id; 0 for an id without one (``main``)."""
    m = _ID.match(ident)
    return int(m.group(1)) if m else 0


def newer(a: str, b: str) -> bool:
    """Whether controller id ``a`` is newer than ``b`` (start stamp, then the text)."""
    return (stamp_of(a), a) > (stamp_of(b), b)


def make_ident(now_ms: int, others: list[str], pid: int | None = None, host: str = "") -> str:
    """This process's controller id: stamped ``now_ms``, or later than every id in ``others``
    (a newcomer is newer than what it found whatever the clocks say)."""
    stamp = max([now_ms, *(stamp_of(o) + 1 for o in others)])
    host = _UNSAFE.sub("_", host or socket.gethostname()) or "host"
    return f"main-{stamp}-{os.getpid() if pid is None else pid}-{host}"


def far_ahead(ident: str, now_ms: float) -> bool:
    """Whether a controller id is stamped more than ``FUTURE_LIMIT_MS`` after ``now_ms``."""
    return stamp_of(ident) > now_ms + FUTURE_LIMIT_MS


def newest_status(replies: list):
    """Of several ``FleetStatus`` answers, the newest controller's (the one a take-over
    leaves commanding)."""
    best = replies[0]
    for r in replies[1:]:
        if newer(r.controller, best.controller):
            best = r
    return best


class Claim:
    """A daemon's claim: its id, and the newer controller it yielded to (if any).

    ``watch(bus)`` follows the other controllers' tokens (zenoh's thread): a newer one sets
    ``yielded_to`` and ``yielded``; older ones are ``predecessors`` while alive."""

    def __init__(
        self, ident: str, found: list[str], clock_ms: Callable[[], float] | None = None
    ) -> None:
        self.ident = ident
        self.yielded = threading.Event()
        self.yielded_to = ""
        self._lock = threading.Lock()
        self.predecessors: set[str] = {o for o in found if o != ident}
        self._clock_ms = clock_ms if clock_ms is not None else (lambda: time.time() * 1e3)
        self.implausible: set[str] = set()  # "newer" tokens stamped too far ahead: ignored

    def plausible(self, other: str) -> bool:
        """Whether a newer token's stamp could be a take-over's: not further ahead of this
        clock than ``FUTURE_LIMIT_MS``, or just one above this controller's own stamp."""
        return not far_ahead(other, self._clock_ms()) or stamp_of(other) <= stamp_of(self.ident) + 1

    def on_alive(self, other: str, alive: bool) -> None:
        if other == self.ident:
            return
        with self._lock:
            if not alive:
                self.predecessors.discard(other)
                return
            if newer(other, self.ident) and not self.plausible(other):
                if other not in self.implausible:
                    self.implausible.add(other)
                    log.warning(
                        "controller token %s is stamped %.0f s ahead of this clock: no "
                        "take-over (forged, or a clock far off); ignored",
                        other,
                        (stamp_of(other) - self._clock_ms()) / 1e3,
                    )
                return
            if newer(other, self.ident):
                if not self.yielded_to:
                    self.yielded_to = other
                    log.error("a newer controller %s took over: this one stops commanding", other)
                self.yielded.set()
            else:
                self.predecessors.add(other)

    def watch(self, bus) -> None:
        bus.watch_alive(ROLE, self.on_alive)

    def check(self, bus, timeout: float = 0.5) -> None:
        """Ask for the controller tokens now (e.g. after the loop was held up): a newer one
        found sets ``yielded``."""
        for other in bus.alive_ids(ROLE, timeout):
            self.on_alive(other, True)

    def alone(self) -> bool:
        with self._lock:
            return not self.predecessors


def wait_until_alone(
    claim: Claim, wait: float, stop: threading.Event, mono: Callable[[], float] = time.monotonic
) -> bool:
    """Wait (at most ``wait`` s, or until ``stop``) for every older controller to be gone."""
    deadline = mono() + wait
    while not claim.alone():
        if stop.is_set() or mono() >= deadline or claim.yielded.is_set():
            return False
        stop.wait(0.05)  # polling a flag set on zenoh's thread by the liveliness watch
    return True
