"""Wall-clock pacing for the lab daemon and agents (the I/O edge; the core never reads clocks).

``Ratekeeper`` keeps a drift-free schedule: tick k is due at start + k·period, whatever each
tick cost; a tick that starts more than ``lag_limit`` late counts as lag (a safety event the
caller reports), and a schedule that fell behind by whole periods skips ahead instead of
bursting.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class Ratekeeper:
    def __init__(
        self,
        rate_hz: float,
        lag_limit: float | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.period = 1.0 / rate_hz
        self.lag_limit = self.period if lag_limit is None else lag_limit
        self._clock = clock
        self._sleep = sleep
        self._next = clock()
        self.frame = 0
        self.lagged = 0
        self.skipped = 0
        self.last_lag = 0.0

    def keep_time(self) -> float:
        """Sleep until the next tick is due; returns that tick's scheduled time."""
        now = self._clock()
        wait = self._next - now
        if wait > 0:
            self._sleep(wait)
        lag = max(0.0, now - self._next)
        self.last_lag = lag
        if lag > self.lag_limit:
            self.lagged += 1
        due = self._next
        self._next += self.period
        behind = self._clock() - self._next
        if behind > self.period:  # fell behind by whole periods: skip, don't burst
            n = int(behind // self.period)
            self._next += n * self.period
            self.skipped += n
        self.frame += 1
        return due
