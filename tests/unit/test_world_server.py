"""The world process's side of the bus (``controller.runtime.world.WorldServer``) on the
in-memory bus: applied commands in, samples stamped in the lab's clock domain and truth out, the
vehicles' setpoint timeout, and nothing the controller says reaching the world."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from controller import wire
from controller.runtime.world import WorldServer, world_config
from sim_backend.factory import make_world
from sim_backend.hub import PerfectSensor, SimHub
from tests.support.config import make_config
from tests.support.fakebus import FakeBus

OFFSET = 1.8e9  # s: the wall-clock instant of sim time 0


@pytest.fixture
def rig():
    cfg = make_config({"sim": {"backend": "ideal"}, "object": {"motion": {"kind": "static"}}})
    world = make_world(cfg)
    hub = SimHub(
        world, {r.id: PerfectSensor(30) for r in cfg.robots}, PerfectSensor(30), cfg.sim.timestep
    )
    bus = FakeBus(cfg.fleet.name)
    server = WorldServer(bus, hub, OFFSET, 0.005, 0.01)
    yield server, bus, hub
    world.close()


def _cmd(vx: float, ttl: float = 1.0) -> wire.Twist2D:
    return wire.Twist2D(t=OFFSET, vx=vx, ttl=ttl)


def test_listens_only_to_the_agents_applied_commands(rig):
    _, bus, _ = rig
    assert set(bus.inboxes) == {"world_cmd"}  # no plan, phase, estop or robot/<id>/cmd


def test_latest_command_drives_the_robot_and_samples_carry_lab_stamps(rig):
    server, bus, hub = rig
    p0 = hub.world.robot_pose("r1").copy()
    bus.deliver("world_cmd", _cmd(0.1), id="r1")
    bus.deliver("world_cmd", _cmd(0.2), id="r1")
    bus.deliver("world_cmd", _cmd(0.3), id="nobody")  # not a robot of this world: ignored
    server.apply_commands(mono=0.0)
    assert server.commands == 2
    hub.advance_to(1.0)
    server.publish_samples()
    heading = np.array([np.cos(p0[2]), np.sin(p0[2])])
    assert 0.15 < float(np.dot(hub.world.robot_pose("r1")[:2] - p0[:2], heading)) < 0.25
    poses = bus.sent[bus.key("world_pose", id="r1")]
    assert len(poses) >= 30 and all(OFFSET <= m.t <= OFFSET + 1.0 for m in poses)
    assert [m.seq for m in poses] == list(range(1, len(poses) + 1))
    assert poses[-1].sigma_xy == 0.005 and poses[-1].sigma_theta == 0.01
    assert len(bus.sent[bus.key("object_pose")]) >= 30  # the motion capture's samples


def test_a_silent_command_stream_stops_the_robot_after_its_ttl(rig):
    server, bus, hub = rig
    bus.deliver("world_cmd", _cmd(0.2, ttl=0.5), id="r1")
    bus.deliver("world_cmd", _cmd(0.0, ttl=0.5), id="r2")  # stopped: nothing to time out
    server.apply_commands(mono=10.0)
    server.apply_commands(mono=10.4)
    assert server.failsafe_stops == 0
    server.apply_commands(mono=10.6)
    assert server.failsafe_stops == 1
    p = hub.world.robot_pose("r1").copy()
    hub.advance_to(hub.t + 0.5)
    assert np.allclose(hub.world.robot_pose("r1"), p)
    server.apply_commands(mono=20.0)
    assert server.failsafe_stops == 1  # once


def test_truth_of_every_robot_and_the_object(rig):
    server, bus, hub = rig
    server.publish_truth()
    for rid in server.robot_ids:
        m = bus.last("truth_robot", id=rid)
        assert m.source == "truth" and m.t == OFFSET and m.sigma_xy == 0.0
        assert (m.x, m.y) == pytest.approx(tuple(hub.world.robot_pose(rid)[:2]))
    assert bus.last("truth_object").source == "truth"


def test_world_holds_only_sim_robots():
    cfg = make_config()
    real = dataclasses.replace(cfg.robots[1], driver="mavlink")
    cfg = dataclasses.replace(cfg, robots=(cfg.robots[0], real, *cfg.robots[2:]))
    ids = [r.id for r in world_config(cfg).robots]
    assert real.id not in ids and len(ids) == len(cfg.robots) - 1


def test_a_capped_catch_up_steps_no_more_than_asked_and_the_world_falls_behind(rig):
    """An agent with a world of its own steps at most two loop periods of physics per
    iteration (its watchdog and e-stop come first): two seconds behind, one call does not
    step them all; called again and again, the world gets there."""
    _, _, hub = rig
    assert hub.advance_to(2.0, max_steps=5) == 5
    assert hub.t == pytest.approx(5 * hub.dt)
    steps = 5
    while hub.t + 0.5 * hub.dt < 2.0:
        n = hub.advance_to(2.0, max_steps=5)
        assert 1 <= n <= 5
        steps += n
    assert hub.t == pytest.approx(2.0, abs=hub.dt) and steps == round(2.0 / hub.dt)
    assert hub.advance_to(2.0) == 0  # uncapped (the world process): already there
