"""``ControllerNode.tick``: the fixed pipeline sample → estimate → plan → safety → publish, on an
in-memory bus (tests/support/fakebus.py) and a mission that records what it saw."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from controller import wire
from controller.mission.types import FleetView, Intent, MissionOutput, Phase
from controller.runtime.node import ControllerNode
from controller.runtime.wiring import make_estimator
from tests.support.config import make_config
from tests.support.fakebus import FakeBus


class Recorder:
    """A mission that drives every robot forward at 0.2 m/s and records its views."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.views: list[FleetView] = []

    def plan(self, view: FleetView) -> Intent:
        self.views.append(view)
        return Intent(np.zeros((self.n, 2)), Phase.APPROACH, events=[("phase", {"x": 1})])

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        cmds = np.tile([0.2, 0.0, 0.1], (self.n, 1))
        return MissionOutput(cmds, intent.phase, list(intent.events))


@pytest.fixture
def rig():
    cfg = make_config({"sim": {"backend": "ideal"}})
    bus = FakeBus(cfg.fleet.name)
    mission = Recorder(len(cfg.robots))
    ticks = itertools.count()
    node = ControllerNode(cfg, bus, mission, make_estimator(cfg), clock=lambda: float(next(ticks)))
    for r in cfg.robots:
        bus.alive_cb["robot"](r.id, True)
    return cfg, bus, mission, node


def pose_of(cfg, rid: str, t: float) -> wire.PoseMeasurement:
    x, y, th = cfg.robot(rid).start
    return wire.PoseMeasurement(t=t, x=x, y=y, theta=th)


def test_a_tick_takes_in_poses_and_publishes_one_command_per_robot(rig):
    cfg, bus, mission, node = rig
    for r in cfg.robots:
        bus.deliver("robot_pose", pose_of(cfg, r.id, 1.0), id=r.id)
    out = node.tick(1.05, step=7)
    view = mission.views[-1]
    assert view.t == 1.05 and np.all(view.present) and not view.estop
    assert np.allclose(view.poses[:, :2], [r.start[:2] for r in cfg.robots], atol=1e-6)
    for r in cfg.robots:
        cmd = bus.last("robot_cmd", id=r.id)
        assert (cmd.vx, cmd.vy, cmd.wz, cmd.t) == (0.2, 0.0, 0.1, 1.05)
        assert cmd.ttl == cfg.fleet.cmd_ttl
        assert bus.last("robot_state", id=r.id).id == r.id
    assert bus.last("plan", what="phase").phase == "approach"
    done = bus.last("sim_done")
    assert done.step == 7 and done.commands == len(cfg.robots)
    assert out.phase == node.phase == "approach"
    # the stages were timed with the injected clock, one sample each
    assert {k: len(v) for k, v in node.timings.items()} == dict.fromkeys(node.timings, 1)
    assert node.timing_summary()["step_ms"]["calls"] == 1


def test_an_engaged_estop_zeroes_every_command_until_released(rig):
    cfg, bus, _, node = rig
    bus.deliver("estop", wire.EStop(t=0.0, engaged=True, source="op"))
    node.tick(1.0)
    assert all(bus.last("robot_cmd", id=r.id).vx == 0.0 for r in cfg.robots)
    assert node.status().estop is True
    bus.deliver("estop", wire.EStop(t=0.0, engaged=False, source="op"))
    node.tick(1.05)
    assert all(bus.last("robot_cmd", id=r.id).vx == 0.2 for r in cfg.robots)


def test_a_lost_link_or_a_missing_token_takes_the_robot_out_of_the_view(rig):
    cfg, bus, mission, node = rig
    r1, r2 = cfg.robot_ids[:2]
    bus.deliver("robot_event", wire.PlanEvent(t=0.0, kind="link_lost"), id=r1)
    bus.alive_cb["robot"](r2, False)
    node.tick(1.0)
    present = dict(zip(cfg.robot_ids, mission.views[-1].present, strict=True))
    assert present[r1] is np.False_ and present[r2] is np.False_
    assert sum(present.values()) == len(cfg.robots) - 2
    st = node.status()
    assert [r["link_lost"] for r in st.robots if r["id"] == r1] == [True]


def test_status_reports_every_drop_counter(rig):
    _, bus, _, node = rig
    bus.bad = 3
    node.extra_drops = lambda: {"recorder_dropped": 2}
    counters = node.status().counters
    assert counters["bad_payloads"] == 3 and counters["recorder_dropped"] == 2
    assert "inbox_overflow" in counters
