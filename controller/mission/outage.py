"""One fleet-wide silence is one outage, not N robot losses (pure).

When the hub restarts, the world stalls or the network is cut, every robot goes quiet at once:
their estimates turn stale, their liveliness tokens go. Counting each as lost would re-plan
the job around nobody and fail it with ``robots_lost``. Instead, when two or more of the robots
the mission relies on go missing together, the mission pauses (every robot commanded still; the
agents' watchdogs stop them anyway) for up to ``fleet.outage_grace`` s: robots that come back
within it carry on as if nothing happened; those still missing after it are lost, and only
they are re-planned around. A single robot going missing is a loss at once, as before.
"""

from __future__ import annotations

import numpy as np

from controller.events import OutageEndEvent, OutageEvent
from controller.mission.types import Event


class OutageWatch:
    """Decides, tick by tick, which missing robots count as lost and whether to pause."""

    def __init__(self, grace: float, together: int = 2) -> None:
        """``grace`` (s) an outage may last before its missing robots are lost; ``together``:
        robots missing at once that make an outage."""
        self.grace = grace
        self.together = together
        self.start: float | None = None
        self.robots: np.ndarray | None = None  # (N,) the robots the outage took
        self.outages = 0

    @property
    def active(self) -> bool:
        return self.start is not None

    def filter(
        self, t: float, gone: np.ndarray, relied: np.ndarray, ids: tuple[str, ...]
    ) -> tuple[np.ndarray, bool, list[Event]]:
        """``gone`` (N,) robots missing now, ``relied`` (N,) those the mission counts on.
        Returns (the gone robots to treat as lost now, whether the mission pauses, events)."""
        gone = np.asarray(gone, bool)
        missing = gone & np.asarray(relied, bool)
        events: list[Event] = []
        if self.start is None:
            if int(missing.sum()) < self.together or self.grace <= 0:
                return gone, False, events
            self.start, self.robots = t, missing.copy()
            self.outages += 1
            robots = [ids[i] for i in np.flatnonzero(missing)]
            events.append(OutageEvent(t=t, robots=robots, grace_s=self.grace))
            return np.zeros_like(gone), True, events
        if missing.any() and t - self.start < self.grace - 1e-9:
            self.robots |= missing
            return gone & ~relied, True, events  # nobody it relies on is lost yet
        lost = [ids[i] for i in np.flatnonzero(missing)]
        events.append(OutageEndEvent(t=t, duration_s=round(t - self.start, 3), lost=lost))
        self.start, self.robots = None, None
        return gone, False, events
