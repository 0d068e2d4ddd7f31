"""The dry run's lockstep, when the controller's commands stop arriving: one missed tick is
ridden out (a slow controller), three in a row end the run as ``lockstep_lost`` instead of
waiting ``sim.tick_timeout`` per tick until sim time runs out (two transport bench runs did:
one for 30 minutes of wall time, one for 19 and was then counted a ``timeout``)."""

from __future__ import annotations

import numpy as np
import pytest

from controller import wire
from controller.io import bus as bus_module
from controller.mission.basic import GotoMission
from controller.mission.tracking import RobotLimits
from controller.runtime.dry_run import DryRun
from controller.runtime.lockstep import MAX_MISSED_IN_A_ROW
from tests.support.config import make_config

TICK_TIMEOUT = 1.0  # s of wall time per missed tick (a loaded machine answers well within it)


def lose_commands(monkeypatch, when) -> list[float]:
    """Commands whose stamp ``when(t)`` selects are counted as sent but never reach the bus
    (the controller still answers each tick); returns the stamps dropped."""
    dropped: list[float] = []
    put = bus_module.Publisher.put

    def lossy(self, msg):
        if isinstance(msg, wire.Twist2D) and when(msg.t):
            dropped.append(msg.t)
            self.sent += 1
            return
        put(self, msg)

    monkeypatch.setattr(bus_module.Publisher, "put", lossy)
    return dropped


def run(tmp_path, max_time: float):
    cfg = make_config({"sim": {"backend": "ideal", "tick_timeout": TICK_TIMEOUT}})
    targets = np.array(cfg.robots[0].start[:2]) + np.array(
        [[1.0 + 0.5 * i, 1.0] for i in range(len(cfg.robots))]
    )
    mission = GotoMission(targets, RobotLimits.from_config(cfg.robots))
    return DryRun(cfg, mission, tmp_path / "run.mcap", max_time=max_time).run()


def test_commands_that_stop_arriving_end_the_run_as_lockstep_lost(tmp_path, monkeypatch):
    dropped = lose_commands(monkeypatch, lambda t: t >= 1.0)
    res = run(tmp_path, max_time=30.0)
    assert res["status"] != "ok"
    assert res["failure"]["reason"] == "lockstep_lost"
    assert "ticks in a row" in res["failure"]["detail"]
    assert res["missed_ticks"] >= MAX_MISSED_IN_A_ROW
    # cut short a few ticks after the loss, not run on to max_time at tick_timeout per tick
    assert 1.0 <= res["sim_time_s"] <= 1.0 + 0.05 * (MAX_MISSED_IN_A_ROW + 1)
    assert res["failure"]["t"] == pytest.approx(res["sim_time_s"])
    assert len(dropped) >= MAX_MISSED_IN_A_ROW


def test_one_tick_whose_commands_are_lost_is_ridden_out(tmp_path, monkeypatch):
    lose_commands(monkeypatch, lambda t: abs(t - 1.0) < 1e-6)
    res = run(tmp_path, max_time=2.0)
    assert res["missed_ticks"] >= 1  # the tick whose commands were lost
    assert res["failure"] is None or res["failure"]["reason"] != "lockstep_lost"
    assert res["sim_time_s"] >= 2.0
