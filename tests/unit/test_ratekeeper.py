"""The drift-free rate keeper of the lab loop, on a fake clock (no sleeping)."""

from __future__ import annotations

import numpy as np
import pytest

from controller.io.ratekeeper import Ratekeeper


class FakeClock:
    """A clock that only moves when the keeper sleeps or the test says a tick cost time."""

    def __init__(self) -> None:
        self.t = 100.0
        self.slept: list[float] = []

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.slept.append(dt)
        self.t += dt


def test_ticks_are_due_on_a_fixed_schedule_whatever_each_costs():
    clk = FakeClock()
    rk = Ratekeeper(20.0, clock=clk, sleep=clk.sleep)
    dues = []
    for cost in (0.0, 0.01, 0.03, 0.0, 0.049, 0.02):
        dues.append(rk.keep_time())
        clk.t += cost  # the tick's own work
    # no drift: tick k is due at start + k * period, however long each tick took
    assert dues == pytest.approx([100.0 + 0.05 * k for k in range(6)])
    assert rk.lagged == 0 and rk.skipped == 0 and rk.frame == 6


def test_a_late_tick_counts_as_lag_and_a_long_stall_skips_instead_of_bursting():
    clk = FakeClock()
    rk = Ratekeeper(20.0, clock=clk, sleep=clk.sleep)
    rk.keep_time()
    clk.t += 0.12  # the tick overran by more than a period: the next one starts 70 ms late
    rk.keep_time()
    assert rk.lagged == 1 and rk.last_lag == pytest.approx(0.07)
    clk.t += 1.0  # a one-second stall (a hung disk): whole periods are skipped, not replayed
    before = len(clk.slept)
    dues = [rk.keep_time() for _ in range(4)]
    assert rk.skipped == 19
    # at most two ticks run back to back (the overdue one, the slot just behind now), then the
    # keeper sleeps again: no burst of 20 catch-up ticks
    assert len(clk.slept) - before == 2
    assert list(np.diff(dues[1:])) == pytest.approx([0.05, 0.05], abs=1e-9)
