"""One fleet-wide silence is one outage, not N robot losses (pure).

When the hub restarts, the world stalls or the network is cut, every robot goes quiet at once:
their estimates turn stale, their liveliness tokens go. Counting each as lost would re-plan
the job around nobody and fail it with ``robots_lost``. Instead, when two or more of the robots
the mission relies on go missing together, the mission pauses (every robot commanded still; the
agents' watchdogs stop them anyway) for up to ``fleet.outage_grace`` s: robots that come back
within it carry on as if nothing happened; those still missing after it are lost, and only
they are re-planned around. A single robot whose liveliness goes is a loss at once; a single
robot gone *silent* (its estimate stale, its liveliness still up) may be the first of a
fleet-wide silence whose robots' last poses came a few tens of milliseconds apart, so it is
given ``window`` s for others to follow (then an outage, which it is part of) before it is lost.
"""

from __future__ import annotations

import numpy as np

from controller.events import OutageEndEvent, OutageEvent
from controller.mission.types import Event


class OutageWatch:
    """Decides, tick by tick, which missing robots count as lost and whether to pause."""

    def __init__(self, grace: float, together: int = 2, window: float = 0.5) -> None:
        """``grace`` (s) an outage may last before its missing robots are lost; ``together``:
        robots missing at once that make an outage; ``window`` (s) a lone silent robot waits
        for others."""
        self.grace = grace
        self.together = together
        self.window = window
        self.silent_since: dict[int, float] = {}  # a lone silent robot: since when
        self.start: float | None = None
        self.robots: np.ndarray | None = None  # (N,) the robots the outage took
        self.outages = 0

    @property
    def active(self) -> bool:
        return self.start is not None

    def filter(
        self,
        t: float,
        gone: np.ndarray,
        relied: np.ndarray,
        ids: tuple[str, ...],
        silent: np.ndarray | None = None,
    ) -> tuple[np.ndarray, bool, list[Event]]:
        """``gone`` (N,) robots missing now, ``relied`` (N,) those the mission counts on,
        ``silent`` (N,) the gone ones whose liveliness is still up (None: none told apart).
        Returns (the gone robots to treat as lost now, whether the mission pauses, events)."""
        gone = np.asarray(gone, bool)
        missing = gone & np.asarray(relied, bool)
        events: list[Event] = []
        if self.start is None:
            if int(missing.sum()) < self.together or self.grace <= 0:
                return gone & ~self._waiting(t, missing, silent), False, events
            self.silent_since.clear()
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

    def _waiting(self, t: float, missing: np.ndarray, silent: np.ndarray | None) -> np.ndarray:
        """(N,) the lone silent robots still within ``window`` of going silent (not lost yet)."""
        wait = np.zeros_like(missing)
        quiet = missing & (np.zeros_like(missing) if silent is None else np.asarray(silent, bool))
        if self.grace <= 0:
            return wait
        for i in list(self.silent_since):
            if not quiet[i]:
                del self.silent_since[i]
        for i in np.flatnonzero(quiet):
            wait[i] = t - self.silent_since.setdefault(int(i), t) < self.window - 1e-9
        return wait
