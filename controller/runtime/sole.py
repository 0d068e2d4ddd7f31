"""One agent per robot, one world per fleet: a part about to declare its liveliness token first
looks for the same token on the bus. A crashed predecessor's token goes with its lease, so the
look lasts the lease and a second; a token still there after that is a second, live part (two
agents driving one robot, or two worlds serving one fleet's robots), and the newcomer refuses."""

from __future__ import annotations

import threading
import time

LOOK = 0.3  # s one liveliness query waits for its replies
BETWEEN = 0.2  # s between looks


def already_served(
    bus, role: str, ident: str, lease: float, stop: threading.Event | None = None
) -> bool:
    """Whether a live part holds ``alive/<role>/<ident>`` (still there ``lease`` + 1 s on)."""
    deadline = time.monotonic() + lease + 1.0
    while True:
        if ident not in bus.alive_ids(role, timeout=LOOK):
            return False
        if time.monotonic() >= deadline or (stop is not None and stop.is_set()):
            return True
        if stop is not None:
            stop.wait(BETWEEN)
        else:
            time.sleep(BETWEEN)  # between looks at the bus (each look is a real query)
