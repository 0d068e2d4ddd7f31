"""The driver agent on the bus: watchdog, latched e-stop, clamping, link loss, liveliness."""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
import pytest

from controller import wire
from controller.config import ZenohSection
from controller.io.bus import Bus
from drivers.agent import Agent, AgentCore, AgentParams
from drivers.base import Capabilities
from drivers.sim import SimDriver
from sim_backend.hub import PerfectSensor, SimHub
from sim_backend.ideal import IdealWorld
from tests.support.config import make_config
from tests.support.wait import wait_for

TICK = 0.05


@pytest.fixture
def rig(port):
    """An ideal world, one agent for robot r1 on a robot-side bus, a controller-side bus."""
    cfg = make_config({"object": {"motion": {"kind": "static"}}}, port=port)
    world = IdealWorld(cfg)
    hub = SimHub(world, {r.id: PerfectSensor(30) for r in cfg.robots}, PerfectSensor(30), 1 / 240)
    ep = cfg.zenoh.listen[0]
    with (
        Bus(ZenohSection(), "lab", listen=[ep], connect=[]) as ctl,
        Bus(ZenohSection(), "lab", listen=[], connect=[ep]) as rob,
    ):
        r1 = cfg.robot("r1")
        caps = Capabilities("omni", True, r1.max_speed, r1.max_yaw_rate, r1.radius)
        drv = SimDriver(hub, "r1", caps)
        drv.connect(1.0)
        agent = Agent(rob, drv, AgentParams("r1", "lab", cmd_ttl=0.3))
        r3 = cfg.robot("r3")
        caps3 = Capabilities("diff", False, r3.max_speed, r3.max_yaw_rate, r3.radius)
        drv3 = SimDriver(hub, "r3", caps3)
        drv3.connect(1.0)
        agent3 = Agent(rob, drv3, AgentParams("r3", "lab", cmd_ttl=0.3))
        cmd = ctl.publisher("robot_cmd", command=True, id="r1")
        cmd3 = ctl.publisher("robot_cmd", command=True, id="r3")
        estop = ctl.publisher("estop")
        wait_for(lambda: cmd._pub.matching_status.matching, 10, "agent r1 subscribed")
        wait_for(lambda: cmd3._pub.matching_status.matching, 10, "agent r3 subscribed")
        wait_for(lambda: estop._pub.matching_status.matching, 10, "e-stop subscribed")
        yield {
            "world": world,
            "hub": hub,
            "agent": agent,
            "agent3": agent3,
            "cmd": cmd,
            "cmd3": cmd3,
            "estop": estop,
            "ctl": ctl,
            "drv": drv,
        }


def deliver(pub, inbox_owner, msg, box="_cmds"):
    before = getattr(inbox_owner, box).qsize()
    pub.put(msg)
    wait_for(lambda: getattr(inbox_owner, box).qsize() > before, 5, "delivery")


def speed(world, rid="r1"):
    return float(np.linalg.norm(world.robot_velocity(rid)[:2]))


def test_watchdog_stops_within_ttl_plus_one_tick(rig):
    w, hub, agent = rig["world"], rig["hub"], rig["agent"]
    t = 0.0
    deliver(rig["cmd"], agent, wire.Twist2D(t=t, seq=1, vx=0.2, ttl=0.3))
    stopped_at = None
    for k in range(40):
        t = k * TICK
        agent.step(t)
        hub.advance_to(t + TICK)
        if speed(w) < 1e-9 and stopped_at is None:
            stopped_at = t
    assert stopped_at is not None, "the robot never stopped without commands"
    assert 0.3 <= stopped_at <= 0.3 + TICK + 1e-9
    assert agent.counters.watchdog_stops == 1
    # resumes on the next command
    deliver(rig["cmd"], agent, wire.Twist2D(t=t, seq=2, vx=0.2))
    agent.step(t + TICK)
    hub.advance_to(t + 2 * TICK)
    assert speed(w) == pytest.approx(0.2)


def test_estop_is_latched_until_resume(rig):
    w, hub, agent = rig["world"], rig["hub"], rig["agent"]
    deliver(rig["cmd"], agent, wire.Twist2D(t=0.0, seq=1, vx=0.2))
    agent.step(0.0)
    hub.advance_to(TICK)
    assert speed(w) > 0.1
    deliver(
        rig["estop"], agent, wire.EStop(t=0.05, engaged=True, source="test", epoch=1), "_estops"
    )
    for k in range(1, 6):  # commands keep coming but are refused
        deliver(rig["cmd"], agent, wire.Twist2D(t=k * TICK, seq=k + 1, vx=0.2))
        agent.step(k * TICK)
        hub.advance_to((k + 1) * TICK)
        assert speed(w) == 0.0
    assert agent.counters.estop_rejected == 5
    deliver(
        rig["estop"], agent, wire.EStop(t=0.4, engaged=False, source="test", epoch=2), "_estops"
    )
    agent.step(0.4)
    hub.advance_to(0.45)
    assert speed(w) == 0.0  # released, but nothing moves until a new command
    deliver(rig["cmd"], agent, wire.Twist2D(t=0.45, seq=99, vx=0.1))
    agent.step(0.45)
    hub.advance_to(0.5)
    assert speed(w) == pytest.approx(0.1)


def test_an_estop_ends_the_agents_pause_between_cycles_at_once(rig):
    """The wall-clock loop sleeps between cycles in ``wait_for_estop``: an e-stop arriving
    wakes it (acted on when it comes, not a period later); nothing else shortens the pause."""
    agent = rig["agent"]
    t0 = time.monotonic()
    agent.wait_for_estop(0.3)  # nothing arrives: the whole pause
    assert time.monotonic() - t0 >= 0.29
    timer = threading.Timer(
        0.1, rig["estop"].put, [wire.EStop(t=0.0, engaged=True, source="test", epoch=1)]
    )
    timer.start()
    t0 = time.monotonic()
    agent.wait_for_estop(5.0)
    woke = time.monotonic() - t0
    timer.join()
    assert woke < 2.0, woke  # woken by the arrival (~0.1 s), not at the 5 s timeout
    assert agent._estops.qsize() == 1
    t0 = time.monotonic()
    agent.wait_for_estop(5.0)  # one waiting already: no pause at all
    assert time.monotonic() - t0 < 1.0
    agent.step(0.0)
    assert agent.core.estop


def test_limits_are_clamped_and_diff_vy_dropped(rig):
    w, hub, agent, agent3 = rig["world"], rig["hub"], rig["agent"], rig["agent3"]
    deliver(rig["cmd"], agent, wire.Twist2D(t=0.0, seq=1, vx=3.0, vy=4.0, wz=50.0))
    deliver(rig["cmd3"], agent3, wire.Twist2D(t=0.0, seq=1, vx=0.1, vy=0.3))
    agent.step(0.0)
    agent3.step(0.0)
    hub.advance_to(TICK)
    v = w.robot_velocity("r1")
    assert np.hypot(v[0], v[1]) == pytest.approx(0.4)  # max_speed, direction kept
    assert v[2] == pytest.approx(2.0)
    assert agent.counters.clamped == 1
    th3 = w.robot_pose("r3")[2]
    v3 = w.robot_velocity("r3")
    lateral = -np.sin(th3) * v3[0] + np.cos(th3) * v3[1]
    assert abs(lateral) < 1e-12 and agent3.counters.vy_dropped == 1


def test_lost_link_stops_robot_and_is_reported(rig):
    w, hub, agent, ctl = rig["world"], rig["hub"], rig["agent"], rig["ctl"]
    present = {}
    ctl.watch_alive("robot", lambda rid, alive: present.__setitem__(rid, alive))
    events = ctl.subscribe_topic("robot_event", id="r1")
    wait_for(lambda: present.get("r1") is True, 10, "r1 present")
    deliver(rig["cmd"], agent, wire.Twist2D(t=0.0, seq=1, vx=0.2))
    agent.step(0.0)
    hub.advance_to(TICK)
    rig["drv"].fail_link("radio out of range")
    agent.step(TICK)
    hub.advance_to(2 * TICK)
    assert speed(w) == 0.0
    ev = events.get(timeout=5)
    assert ev is not None and ev.msg.kind == "link_lost"
    assert "radio" in ev.msg.data["detail"]
    wait_for(lambda: present.get("r1") is False, 10, "r1 token withdrawn")
    assert agent.counters.link_lost == 1


def test_core_expiry_honours_shorter_command_ttl():
    core = AgentCore(Capabilities("omni", True, 1.0, 1.0, 0.1), cmd_ttl=0.3)
    core.on_command(1.0, wire.Twist2D(t=1.0, vx=0.1, ttl=0.1))
    assert not core.expired(1.09)
    assert core.expired(1.11)


def test_a_command_stamped_far_from_the_agents_clock_is_dropped_and_counted(rig, caplog):
    w, hub, agent = rig["world"], rig["hub"], rig["agent"]
    deliver(rig["cmd"], agent, wire.Twist2D(t=100000.0, seq=1, vx=0.2))
    with caplog.at_level(logging.WARNING):
        agent.step(0.0)
        deliver(rig["cmd"], agent, wire.Twist2D(t=100000.0, seq=2, vx=0.2))
        agent.step(0.0)
    hub.advance_to(TICK)
    assert speed(w) == 0.0 and agent.counters.skewed == 2 and agent.commands_seen() == 2
    # the agent says why its robot stands still, once for the run of skewed commands
    told = [r for r in caplog.records if "beyond max_clock_skew" in r.getMessage()]
    assert len(told) == 1 and "+100000.000 s" in told[0].getMessage(), caplog.text
    deliver(rig["cmd"], agent, wire.Twist2D(t=TICK, seq=2, vx=0.2))
    agent.step(TICK)
    hub.advance_to(2 * TICK)
    assert speed(w) == pytest.approx(0.2)


def test_a_late_agent_reads_the_latch_from_another_holder_and_comes_up_stopped(rig):
    agent, hub = rig["agent"], rig["hub"]
    deliver(rig["estop"], agent, wire.EStop(t=5.0, engaged=True, source="op", epoch=1), "_estops")
    agent.step(0.0)
    assert agent.latch_state().engaged
    r2 = Capabilities("omni", True, 0.5, 2.0, 0.15)
    drv = SimDriver(hub, "r2", r2)
    drv.connect(1.0)
    late = Agent(rig["ctl"], drv, AgentParams("r2", "lab"))
    assert late.sync_latch(5.0) and late.core.estop and late.latch_answered
    deliver(rig["ctl"].publisher("robot_cmd", id="r2"), late, wire.Twist2D(t=0.0, vx=0.2))
    late.step(0.0)
    assert late.counters.estop_rejected == 1 and late.counters.commands == 0


def test_link_restored_follows_link_lost_when_the_driver_link_comes_back(rig):
    agent, drv, ctl = rig["agent"], rig["drv"], rig["ctl"]
    events = ctl.subscribe_topic("robot_event", id="r1")
    wait_for(agent._event_pub.matching, 5, "the event subscription")
    drv.fail_link()
    agent.step(0.0)
    assert not agent.link_ok
    drv.restore_link()
    agent.step(TICK)
    assert agent.link_ok and agent.counters.link_restored == 1
    got: list[str] = []
    wait_for(lambda: got.extend(i.msg.kind for i in events.drain()) or len(got) >= 2, 5, "events")
    assert got == ["link_lost", "link_restored"]
