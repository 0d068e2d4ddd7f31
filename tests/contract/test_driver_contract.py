"""One contract suite for every driver adapter (drivers.base.RobotDriver).

Each adapter (the sim driver on both backends, MAVLink, the remote sim driver of the shared
``fleet world`` process, and ROS 2 over rmw_zenoh against the stand-in robot) joins through a
factory in ``ADAPTERS`` that returns a ``Rig``: a connected driver for an omni or a differential
robot, an ``advance(seconds)`` that moves time on the robot's side, and a ``close``. Everything
here is what the agent relies on.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

from controller.wire import Twist2D
from drivers.base import Capabilities, ConnectTimeout, LinkHealth, RobotDriver
from drivers.sim import SimDriver
from sim_backend.hub import PerfectSensor, SimHub
from tests.support.config import make_config


@dataclass
class Rig:
    driver: RobotDriver
    advance: Callable[[float], None]
    close: Callable[[], None]
    unreachable: Callable[[], RobotDriver]  # a driver whose robot does not answer


def _sim_rig(backend: str, kind: str) -> Rig:
    cfg = make_config(
        {
            "object": {"motion": {"kind": "static"}, "start": [8.0, 8.0, 0.0]},
            "sim": {"backend": backend},
        }
    )
    from sim_backend.factory import make_world

    world = make_world(cfg)
    hub = SimHub(
        world, {r.id: PerfectSensor(50) for r in cfg.robots}, PerfectSensor(50), cfg.sim.timestep
    )
    rid = "r1" if kind == "omni" else "r3"
    r = cfg.robot(rid)
    caps = Capabilities(r.kind, r.kind == "omni", r.max_speed, r.max_yaw_rate, r.radius)
    drv = SimDriver(hub, rid, caps)
    drv.connect(timeout=1.0)

    def advance(dt: float) -> None:
        hub.advance_to(hub.t + dt)

    return Rig(drv, advance, world.close, lambda: SimDriver(hub, "nobody", caps))


def _remote_rig(backend: str, kind: str) -> Rig:
    """The shared world process's adapter: the world's side (``WorldServer``) on a listening
    zenoh session, the ``RemoteSimDriver`` on a client session, over loopback. ``advance`` is a
    lockstep: the world takes every command sent, steps, publishes, and the driver holds every
    sample before it returns (handshakes with deadlines, no sleeps)."""
    from controller.io.bus import Bus
    from controller.runtime.world import WorldServer
    from drivers.remote_sim import RemoteSimDriver
    from sim_backend.factory import make_world
    from tests.support.wait import wait_for

    cfg = make_config(
        {
            "object": {"motion": {"kind": "static"}, "start": [8.0, 8.0, 0.0]},
            "sim": {"backend": backend},
        }
    )
    world = make_world(cfg)
    hub = SimHub(
        world, {r.id: PerfectSensor(50) for r in cfg.robots}, PerfectSensor(50), cfg.sim.timestep
    )
    world_bus = Bus(cfg.zenoh, cfg.fleet.name)
    agent_bus = Bus(
        cfg.zenoh, cfg.fleet.name, mode="client", listen=[], connect=list(cfg.zenoh.listen)
    )
    server = WorldServer(world_bus, hub, 0.0, 0.0, 0.0)
    rid = "r1" if kind == "omni" else "r3"
    r = cfg.robot(rid)
    caps = Capabilities(r.kind, r.kind == "omni", r.max_speed, r.max_yaw_rate, r.radius)

    def driver(robot_id: str) -> RemoteSimDriver:
        return RemoteSimDriver(agent_bus, robot_id, caps, clock=lambda: hub.t)

    drv = driver(rid)
    wait_for(lambda: server.serving(rid), 10, "the driver's subscription at the world")
    server.publish_samples()  # the t = 0 samples: the driver's connect handshake
    drv.connect(timeout=5.0)

    def advance(dt: float) -> None:
        wait_for(lambda: server.commands_seen() >= drv.sent, 5, "the commands at the world")
        server.apply_commands(time.monotonic())
        hub.advance_to(hub.t + dt)
        server.publish_samples()
        wait_for(lambda: drv.samples_seen() >= server.published(rid), 5, "the samples")

    def close() -> None:
        drv.close()
        agent_bus.close()
        world_bus.close()
        world.close()

    return Rig(drv, advance, close, lambda: driver("nobody"))


def _mavlink_rig(kind: str) -> Rig:
    """An emulated MAVLink rover on loopback UDP: px4 (holonomic) for omni, ardurover for diff."""
    from drivers.mavlink.driver import MavlinkDriver
    from drivers.mavlink.link import LinkPool
    from tests.support.mavlink_rig import Lockstep, free_udp_port, robot
    from tests.support.mavlink_rig import make_config as mav_config

    profile = "px4" if kind == "omni" else "ardurover"
    cfg = mav_config([robot("r1", profile, free_udp_port(), 1, theta=0.3)])
    ls = Lockstep(cfg)
    ls.emulator(cfg.robots[0])
    pool = LinkPool()
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    drv.connect(timeout=2.0)

    def unreachable() -> RobotDriver:
        other = mav_config([robot("r9", profile, free_udp_port(), 9)]).robots[0]
        return MavlinkDriver(other, clock=ls.clock, idle=ls.advance, pool=pool)

    def close() -> None:
        drv.close()
        ls.close()

    return Rig(drv, ls.advance, close, unreachable)


def _ros2_rig(kind: str) -> Rig:
    """A ROS 2 robot over rmw_zenoh's keys: the stand-in (rosbags CDR) listening on a loopback
    port as the robot's zenoh peer, the driver joining it as a client. ``advance`` is a
    lockstep: the stand-in takes every command sent, moves, publishes its odometry (odom frame,
    placed in the world by ``odom_to_world``), and the driver holds the sample before it
    returns (handshakes with deadlines, no sleeps)."""
    from drivers.ros2.driver import Ros2Driver, Ros2Settings
    from drivers.ros2.node import open_session
    from tests.support.config import free_port
    from tests.support.ros2_robot import StandInRobot
    from tests.support.wait import wait_for

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    settings = Ros2Settings(
        namespace="/tb1", odom_to_world=(1.0, 2.0, 0.5), connect=(endpoint,), mode="client"
    )
    robot_session = open_session(listen=[endpoint], mode="peer")
    robot = StandInRobot(robot_session, settings, kind, start=(3.0, 4.0, 0.3))
    caps = Capabilities(kind, kind == "omni", 0.5, 2.0, 0.15)
    opened: list[Ros2Driver] = []

    def driver(s: Ros2Settings) -> Ros2Driver:
        d = Ros2Driver("r1", caps, s, stale_after=5.0, clock=lambda: robot.t)
        opened.append(d)
        return d

    drv = driver(settings)
    drv.open()
    wait_for(robot.pub.matching, 10, "the driver's odometry subscription at the robot")
    robot.publish()
    drv.connect(timeout=5.0)

    def advance(dt: float) -> None:
        wait_for(lambda: robot.commands_seen() >= drv.sent, 5, "the commands at the robot")
        robot.step(dt)
        robot.publish()
        wait_for(lambda: drv.samples_seen() >= robot.published, 5, "the odometry")

    def close() -> None:
        for d in opened:
            d.close()
        robot.close()
        robot_session.close()

    def unreachable() -> RobotDriver:
        return driver(dataclasses.replace(settings, namespace="/nobody"))

    return Rig(drv, advance, close, unreachable)


ADAPTERS: dict[str, Callable[[str], Rig]] = {
    "ideal": lambda kind: _sim_rig("ideal", kind),
    "pybullet": lambda kind: _sim_rig("pybullet", kind),
    "mavlink": _mavlink_rig,
    "remote-ideal": lambda kind: _remote_rig("ideal", kind),
    "ros2": _ros2_rig,
}


@pytest.fixture(
    params=[(a, k) for a in ADAPTERS for k in ("omni", "diff")], ids=lambda p: f"{p[0]}-{p[1]}"
)
def rig(request):
    adapter, kind = request.param
    r = ADAPTERS[adapter](kind)
    yield r
    r.close()


def latest(driver: RobotDriver, rig: Rig, dt: float = 0.1):
    rig.advance(dt)
    ms = driver.poll()
    assert ms, "no pose measurement arrived"
    return ms


def test_satisfies_protocol(rig):
    assert isinstance(rig.driver, RobotDriver)
    caps = rig.driver.capabilities
    assert isinstance(caps, Capabilities)
    assert caps.max_speed > 0 and caps.max_yaw_rate > 0 and caps.radius > 0
    assert caps.holonomic == (caps.kind == "omni")


def test_connect_to_missing_robot_times_out(rig):
    with pytest.raises(ConnectTimeout):
        rig.unreachable().connect(timeout=0.5)


def test_poll_never_blocks_and_stamps_increase(rig):
    d = rig.driver
    ms = latest(d, rig, 0.2)
    ts = [m.t for m in ms]
    assert ts == sorted(ts)
    assert d.poll() == [] or all(m.t >= ts[-1] for m in d.poll())


def test_forward_command_moves_along_heading(rig):
    d = rig.driver
    p0 = latest(d, rig)[-1]
    d.send(Twist2D(t=0.0, vx=0.2))
    p1 = latest(d, rig, 1.0)[-1]
    dx, dy = p1.x - p0.x, p1.y - p0.y
    heading = np.array([math.cos(p0.theta), math.sin(p0.theta)])
    along = dx * heading[0] + dy * heading[1]
    assert 0.12 < along < 0.25, f"moved {along:.3f} m along the heading in 1 s at 0.2 m/s"
    assert abs(-dx * heading[1] + dy * heading[0]) < 0.03


def test_turn_command_rotates_ccw(rig):
    d = rig.driver
    p0 = latest(d, rig)[-1]
    d.send(Twist2D(t=0.0, wz=0.5))
    p1 = latest(d, rig, 1.0)[-1]
    dth = math.remainder(p1.theta - p0.theta, 2 * math.pi)
    assert 0.3 < dth < 0.6


def test_lateral_command_only_moves_holonomic_robots(rig):
    d = rig.driver
    p0 = latest(d, rig)[-1]
    d.send(Twist2D(t=0.0, vy=0.2))
    p1 = latest(d, rig, 1.0)[-1]
    moved = math.hypot(p1.x - p0.x, p1.y - p0.y)
    if d.capabilities.holonomic:
        assert moved > 0.12
    else:
        assert moved < 0.02


def test_stop_halts_motion(rig):
    d = rig.driver
    d.send(Twist2D(t=0.0, vx=0.2))
    rig.advance(0.5)
    d.stop()
    p0 = latest(d, rig, 0.3)[-1]
    p1 = latest(d, rig, 1.0)[-1]
    assert math.hypot(p1.x - p0.x, p1.y - p0.y) < 0.01


def test_health_and_idempotent_close(rig):
    d = rig.driver
    h = d.health()
    assert isinstance(h, LinkHealth) and h.ok
    d.close()
    d.close()
