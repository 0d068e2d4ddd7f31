"""``ControllerNode.tick``: the fixed pipeline sample → estimate → plan → safety → publish, on an
in-memory bus (tests/support/fakebus.py) and a mission that records what it saw."""

from __future__ import annotations

import itertools
import logging

import numpy as np
import pytest

from controller import wire
from controller.events import PhaseEvent
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
        return Intent.of(
            np.zeros((self.n, 2)), Phase.APPROACH, events=[PhaseEvent(phase=Phase.APPROACH, t=0.0)]
        )

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        cmds = np.tile([0.2, 0.0, 0.1], (self.n, 1))
        return MissionOutput(cmds, intent.report.phase, list(intent.report.events))


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
    assert {k: len(v) for k, v in node.times.stages.items()} == dict.fromkeys(node.times.stages, 1)
    assert node.timing_summary()["step_ms"]["calls"] == 1


def test_an_engaged_estop_zeroes_every_command_until_released(rig):
    cfg, bus, _, node = rig
    bus.deliver("estop", wire.EStop(t=0.0, engaged=True, source="op", epoch=1))
    node.tick(1.0)
    assert all(bus.last("robot_cmd", id=r.id).vx == 0.0 for r in cfg.robots)
    assert node.status().estop is True
    bus.deliver("estop", wire.EStop(t=0.0, engaged=False, source="op", epoch=2))
    node.tick(1.05)
    assert all(bus.last("robot_cmd", id=r.id).vx == 0.2 for r in cfg.robots)


def test_a_lost_link_or_a_missing_token_takes_the_robot_out_of_the_view(rig):
    cfg, bus, mission, node = rig
    r1, r2 = cfg.robot_ids[:2]
    bus.alive_cb["robot"](r1, False)  # r1's agent withdraws its token, then reports
    bus.deliver("robot_event", wire.PlanEvent(t=0.0, kind="link_lost"), id=r1)
    bus.alive_cb["robot"](r2, False)
    node.tick(1.0)
    present = dict(zip(cfg.robot_ids, mission.views[-1].present, strict=True))
    assert present[r1] is np.False_ and present[r2] is np.False_
    assert sum(present.values()) == len(cfg.robots) - 2
    st = node.status()
    assert [r["link_lost"] for r in st.robots if r["id"] == r1] == [True]


def test_a_link_event_its_robots_token_does_not_bear_out_is_ignored(rig):
    """Issue 22: a spoofed ``link_lost`` (anyone may put on a robot's event key on the open
    default) while the robot's agent is alive, and a spoofed ``link_restored`` while it is gone,
    change nothing; each is counted after ``EVENT_GRACE`` s of ticks."""
    from controller.runtime.node_inputs import EVENT_GRACE

    cfg, bus, mission, node = rig
    r1, r2 = cfg.robot_ids[:2]
    bus.deliver("robot_event", wire.PlanEvent(t=0.0, kind="link_lost"), id=r1)
    bus.alive_cb["robot"](r2, False)
    bus.deliver("robot_event", wire.PlanEvent(t=0.0, kind="link_restored"), id=r2)
    n = round(EVENT_GRACE * cfg.fleet.rate_hz) + 1
    for k in range(n):
        node.tick(1.0 + k / cfg.fleet.rate_hz)
        present = dict(zip(cfg.robot_ids, mission.views[-1].present, strict=True))
        assert present[r1] and not present[r2]
    assert node.counters.link_events == 0 and node.counters.link_restored == 0
    assert node.status().counters["spoofed_events"] == 2


def test_status_reports_every_drop_counter(rig):
    _, bus, _, node = rig
    bus.bad = 3
    node.extra_drops = lambda: {"recorder_dropped": 2}
    counters = node.status().counters
    assert counters["bad_payloads"] == 3 and counters["recorder_dropped"] == 2
    assert "inbox_overflow" in counters


def test_a_pose_stamped_far_in_the_future_is_dropped_and_counted_not_freezing_the_estimate(
    rig, caplog
):
    cfg, bus, mission, node = rig
    r1 = cfg.robot_ids[0]
    x0, y0, th = cfg.robot(r1).start
    bus.deliver("robot_pose", wire.PoseMeasurement(t=1.0, x=x0, y=y0, theta=th), id=r1)
    node.tick(1.0)
    bad = wire.PoseMeasurement(t=100001.0, x=x0, y=y0, theta=th)
    bus.deliver("robot_pose", bad, id=r1)
    with caplog.at_level(logging.WARNING):
        node.tick(1.05)
    assert f"robot {r1}: its poses are stamped +99999.950 s" in caplog.text
    assert node.counters.skewed == 1
    assert node.status().counters["skewed"] == 1  # in fleet status
    # the robot whose clock is off is named: skewed in fleet status, until a good pose
    by_id = {r["id"]: r for r in node.status().robots}
    assert by_id[r1]["skewed"] is True
    assert not any(r["skewed"] for rid, r in by_id.items() if rid != r1)
    # later real poses still move the estimate (nothing is out of order)
    for k in range(1, 21):
        t = 1.05 + 0.05 * k
        m = wire.PoseMeasurement(t=t, x=x0 + 0.01 * k, y=y0, theta=th)
        bus.deliver("robot_pose", m, id=r1)
        node.tick(t)
    assert node.counters.out_of_order == 0
    assert {r["id"]: r["skewed"] for r in node.status().robots}[r1] is False
    i = cfg.robot_ids.index(r1)
    view = mission.views[-1]
    assert view.poses[i, 0] == pytest.approx(x0 + 0.2, abs=0.03)
    assert not view.stale[i]
    # and a pose from the far past is dropped too
    bus.deliver("robot_pose", wire.PoseMeasurement(t=0.0, x=x0, y=y0, theta=th), id=r1)
    node.tick(2.1)
    assert node.counters.skewed == 2


class Still:
    """A mission that commands every robot to stand still and records its views."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.views: list[FleetView] = []

    def plan(self, view: FleetView) -> Intent:
        self.views.append(view)
        return Intent.of(np.zeros((self.n, 2)), Phase.APPROACH)

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        return MissionOutput(np.zeros((self.n, 3)), intent.report.phase, [])


def test_poses_stamped_ahead_inside_the_skew_cannot_move_the_estimate():
    """A spoofer's poses stamped 0.9 s ahead (inside fleet.max_clock_skew) and 0.5 m off are
    taken at the tick, not as "now + 0.9 s": the filter is not extrapolated 0.9 s, the gate
    rejects them, and the real poses that follow are not out of order (issue 22, 6a)."""
    cfg = make_config({"sim": {"backend": "ideal"}})
    assert cfg.fleet.max_clock_skew > 0.9
    bus = FakeBus(cfg.fleet.name)
    mission = Still(len(cfg.robots))
    node = ControllerNode(cfg, bus, mission, make_estimator(cfg))
    r1 = cfg.robot_ids[0]
    x0, y0, th = cfg.robot(r1).start
    errors, stale = [], []
    for k in range(60):
        t = 100.0 + 0.05 * k
        bus.deliver("robot_pose", wire.PoseMeasurement(t=t - 0.01, x=x0, y=y0, theta=th), id=r1)
        if k == 20:
            for j in range(3):
                spoof = wire.PoseMeasurement(t=t + 0.9 + 0.01 * j, x=x0 + 0.5, y=y0, theta=th)
                bus.deliver("robot_pose", spoof, id=r1)
        node.tick(t)
        if k >= 20:
            errors.append(abs(mission.views[-1].poses[0, 0] - x0))
            stale.append(bool(mission.views[-1].stale[0]))
    assert max(errors) < 0.02, max(errors)  # today's code: 0.5 m off for over a second
    assert not any(stale)
    assert node.counters.ahead == 3 and node.status().counters["ahead"] == 3
    assert node.counters.skewed == 0
    assert node.counters.out_of_order <= 2  # only the spoofs that share the tick's stamp
    # a pose a few ms ahead (a fast clock) is still taken in, at the tick
    t = 103.0
    bus.deliver("robot_pose", wire.PoseMeasurement(t=t + 0.004, x=x0, y=y0, theta=th), id=r1)
    before = node.counters.poses
    node.tick(t)
    assert node.counters.poses == before + 1 and node.counters.rejected <= 1


def test_link_restored_clears_link_lost(rig):
    cfg, bus, mission, node = rig
    r1 = cfg.robot_ids[0]
    bus.alive_cb["robot"](r1, False)  # the agent withdraws its token, then reports
    bus.deliver("robot_event", wire.PlanEvent(t=0.0, kind="link_lost"), id=r1)
    node.tick(1.0)
    assert not mission.views[-1].present[0]
    bus.alive_cb["robot"](r1, True)  # ... declares it again, then reports
    bus.deliver("robot_event", wire.PlanEvent(t=1.0, kind="link_restored"), id=r1)
    node.tick(1.05)
    assert mission.views[-1].present[0]
    assert [r["link_lost"] for r in node.status().robots if r["id"] == r1] == [False]
    assert node.counters.link_restored == 1


def test_commands_are_zero_while_the_latch_is_unread_and_a_newer_latch_engages(rig):
    from controller.io.bus import Received

    cfg, bus, mission, node = rig
    node.estop_latch.expect()
    ((key, replies),) = bus.queries
    assert key == "fleet/lab/estop/state/*/*"
    node.tick(1.0)
    assert all(bus.last("robot_cmd", id=r.id).vx == 0.0 for r in cfg.robots)
    # the mission is held too: a kept release read at start must not start the job before the
    # hub's newer engaged arrives (a lab run's job started, then failed pinned under the e-stop)
    assert mission.views[-1].estop
    # the controller's own (stale) answer does not count; an agent's newer engaged one does
    own = node.estop_latch.answer()
    replies.put(Received(0.0, "fleet/lab/estop/state/controller/main", own))
    node.tick(1.05)
    assert node.estop_latch.pending
    # (at most one above the operator's epoch the node knows: issue 31, a robot's engage at a
    # greater epoch is refused)
    engaged = wire.EStop(t=5.0, engaged=True, source="op", epoch=1)
    replies.put(Received(0.0, "fleet/lab/estop/state/robot/r1", engaged))
    node.tick(1.1)
    assert not node.estop_latch.pending and node.estop and node.status().estop
    assert all(bus.last("robot_cmd", id=r.id).vx == 0.0 for r in cfg.robots)
    assert node.estop_latch.answer() == engaged
    # a released answer does not lift it, even at a newer epoch; only an operator's resume does
    node.estop_latch.expect()
    newer = wire.EStop(t=1.0, engaged=False, source="op", epoch=4)
    bus.queries[-1][1].put(Received(0.0, "fleet/lab/estop/state/hub/main", newer))
    node.tick(1.15)
    assert node.estop
    bus.deliver("estop", wire.EStop(t=6.0, engaged=False, source="op", epoch=4))
    node.tick(1.2)
    assert not node.estop
    assert all(bus.last("robot_cmd", id=r.id).vx == 0.2 for r in cfg.robots)


def test_a_robot_gone_is_a_warning_during_the_job_and_info_once_it_is_over(rig, caplog):
    import logging

    cfg, bus, mission, node = rig
    caplog.set_level(logging.INFO, logger="controller.runtime.node")
    a, b, c = cfg.robot_ids[:3]
    bus.alive_cb["robot"](a, False)  # mid-job: news
    node.last_output = MissionOutput(np.zeros((len(cfg.robots), 3)), Phase.DONE, [], done=True)
    bus.alive_cb["robot"](b, False)  # the job is done
    node.last_output = None
    node.winding_down = True
    bus.alive_cb["robot"](c, False)  # the process is stopping
    gone = {r.getMessage(): r.levelno for r in caplog.records if "gone" in r.getMessage()}
    assert gone == {
        f"robot {a} gone": logging.WARNING,
        f"robot {b} gone": logging.INFO,
        f"robot {c} gone": logging.INFO,
    }
