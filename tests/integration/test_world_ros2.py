"""ROS 2 robots as bodies of the shared world (``fleet world --ros2``): the robot side of each
one's ROS graph (rmw_zenoh keys, tokens, attachments; rosbags' CDR) answers its ``ros2.connect``
endpoint on loopback and drives a body of the same world as the ``sim`` robots, so the real
ROS 2 driver drives it as it would a real robot. In process: the world's hub stepped by hand
(its loop's order: ``cmd_vel`` in at the wall clock's sim time, physics, odometry out), the
driver on the world's clock (the lab's clock domain). The whole lab as processes, with a mixed
fleet, is test_world_vehicles.py's."""

from __future__ import annotations

import dataclasses
import math

import pytest

from controller.config import ConfigError
from controller.runtime.wiring import make_hub, ros2_settings
from controller.runtime.world import (
    ROS2_CMD_TIMEOUT,
    Ros2Bodies,
    ros2_bodies,
    world_config,
)
from controller.wire import Twist2D
from drivers.base import capabilities_of
from drivers.ros2.driver import Ros2Driver
from drivers.ros2.node import open_session
from tests.support.config import free_port
from tests.support.lab import fleet
from tests.support.mavlink_rig import make_config
from tests.support.wait import wait_for
from tests.support.world_lab import rehearsal_config

SIM = {"id": "s", "kind": "omni", "start": [6.0, 3.0, 0.0]}
OFFSET = 1.7e9  # s: the wall-clock instant of sim time 0 (the world's time_offset)


def _ros2(rid: str, kind: str, start, endpoint: str, **ros2) -> dict:
    return {"id": rid, "kind": kind, "start": list(start), "driver": "ros2",
            "ros2": {"namespace": f"/{rid}", "connect": [endpoint],
                     "odom_to_world": list(start), **ros2}}  # fmt: skip


def _fleet(endpoint: str):
    """An omni robot on Odometry/Twist and a differential one on PoseStamped/TwistStamped, the
    latter's odom frame turned (yaw 2.0) and both on one router endpoint."""
    return make_config(
        [
            _ros2("o", "omni", (3.0, 3.0, 0.0), endpoint),
            _ros2(
                "d",
                "diff",
                (4.0, 5.0, 2.0),
                endpoint,
                pose_type="pose_stamped",
                cmd_type="twist_stamped",
            ),  # fmt: skip
            SIM,
        ]
    )


def test_which_ros2_robots_the_world_makes_bodies():
    cfg = _fleet("tcp/127.0.0.1:7447")
    assert ros2_bodies(cfg, None) == ()
    assert ros2_bodies(cfg, "all") == ("o", "d")
    assert ros2_bodies(cfg, " d ") == ("d",)
    assert [r.id for r in world_config(cfg, ("d",)).robots] == ["d", "s"]
    with pytest.raises(ConfigError, match=r"--ros2 's': not a ROS 2 robot"):
        ros2_bodies(cfg, "o,s")


def test_a_router_endpoint_off_loopback_is_refused_naming_the_key():
    cfg = _fleet("tcp/10.1.2.3:7447")  # never opened: refused before any session
    with pytest.raises(ConfigError, match=r"robots\[0\]\.ros2\.connect.*loopback"):
        ros2_bodies(cfg, "o")


class WorldRig:
    """The world's hub with its ROS 2 bodies and one real driver per body, in lockstep: the
    driver's clock is the world's (sim time + OFFSET, as ``fleet world`` stamps), every
    exchange waited for by handshake (samples seen), never by sleeping."""

    def __init__(self, router: bool = False) -> None:
        """``router``: something already listens at the robots' endpoint (rmw_zenohd's place,
        a peer session here): the world joins it instead of listening there."""
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.router = open_session(listen=[self.endpoint], mode="peer") if router else None
        self.cfg = _fleet(self.endpoint)
        ids = ros2_bodies(self.cfg, "all")
        self.hub = make_hub(world_config(self.cfg, ids))
        assert set(self.hub.robot_sensors) == {"s"}  # the bodies report over ROS 2
        self.wall = self.hub.t  # the wall clock's sim time (a stalled world lags it)
        self.bodies = Ros2Bodies(self.cfg, self.hub, ids, OFFSET)
        self.drivers: dict[str, Ros2Driver] = {}
        for rid in ids:
            r = self.cfg.robot(rid)
            s = dataclasses.replace(ros2_settings(r), mode="client")
            d = Ros2Driver(rid, capabilities_of(r), s, stale_after=0.5,
                           clock=lambda: self.wall + OFFSET)  # fmt: skip
            self.drivers[rid] = d
            d.open()
            base = self.bodies.robots[rid]
            wait_for(base.pub.matching, 10, f"{rid}'s driver subscribed to its odometry")
        self.bodies.publish()
        for d in self.drivers.values():
            d.connect(timeout=5.0)

    def loop(self, dt: float = 0.02, stall: float = 0.0) -> None:
        """One iteration of the world's loop ``dt`` s of wall time on (plus ``stall`` s the
        world was held up while the drivers' commands kept arriving)."""
        for d in self.drivers.values():
            base = self.bodies.robots[d.robot_id]
            wait_for(lambda b=base, d=d: b.commands_seen() >= d.sent, 5, "the cmd_vel")
        self.wall += dt + stall
        self.bodies.apply(self.wall)
        self.hub.advance_to(self.wall)
        published = {rid: b.published for rid, b in self.bodies.robots.items()}
        self.bodies.publish()
        for rid, d in self.drivers.items():
            n = published[rid] + 1 if self.bodies.robots[rid].published > published[rid] else 0
            wait_for(lambda d=d, n=n: d.samples_seen() >= n, 5, "the odometry")

    def close(self) -> None:
        for d in self.drivers.values():
            d.close()
        self.bodies.close()
        self.hub.world.close()
        if self.router is not None:
            self.router.close()


@pytest.fixture
def rig():
    r = WorldRig()
    try:
        yield r
    finally:
        r.close()


def test_ros2_bodies_move_in_the_shared_world_and_report_its_pose(rig):
    """The real driver's cmd_vel moves the bodies (REP 103 body frame; a differential base
    never slides), its poses are the world's truth through each robot's odom frame, stamped
    with the world's time in the lab's clock domain."""
    w = rig.hub.world
    start = {rid: w.robot_pose(rid).copy() for rid in rig.drivers}
    s0 = w.robot_pose("s").copy()
    for _ in range(50):  # 1 s, a command every loop (as an agent streams them)
        rig.drivers["o"].send(Twist2D(t=0.0, vx=0.0, vy=0.2, ttl=5.0))  # east-facing: left = N
        rig.drivers["d"].send(Twist2D(t=0.0, vx=0.2, vy=0.3, ttl=5.0))  # vy dropped
        rig.loop()
    moved = {rid: w.robot_pose(rid) - start[rid] for rid in rig.drivers}
    assert 0.17 < moved["o"][1] < 0.21 and abs(moved["o"][0]) < 1e-6, moved
    forward = (math.cos(2.0), math.sin(2.0))  # d went 0.2 m along its heading, nothing sideways
    assert moved["d"][:2] == pytest.approx([0.19 * f for f in forward], abs=0.02), moved
    assert abs(moved["d"][0] * forward[1] - moved["d"][1] * forward[0]) < 1e-6, moved
    assert (w.robot_pose("s") == s0).all()  # the sim robot was not commanded
    for rid, d in rig.drivers.items():
        poses = d.poll()
        assert len(poses) >= 30, (rid, len(poses))  # 1 s at sim.pose_rate_hz (30 Hz)
        last, truth = poses[-1], w.robot_pose(rid)
        assert math.dist((last.x, last.y), truth[:2]) < 1e-6
        assert abs(math.remainder(last.theta - truth[2], math.tau)) < 1e-6
        assert last.t == pytest.approx(rig.hub.t + OFFSET, abs=1e-6)  # the world's time
        assert d.stale == 0 and d.bad == 0
    assert rig.bodies.timeout_stops == 0


def test_the_world_joins_the_router_already_at_the_robots_endpoint():
    """rmw_zenohd (here a listening peer) already holds the endpoint: the world's ROS 2 side
    joins it as a client, and the driver reaches the bodies through it."""
    rig = WorldRig(router=True)
    try:
        assert rig.bodies.how == {rig.endpoint: "joined"}
        before = rig.hub.world.robot_pose("o").copy()
        for _ in range(10):
            rig.drivers["o"].send(Twist2D(t=0.0, vx=0.2, ttl=5.0))
            rig.loop()
        assert rig.hub.world.robot_pose("o")[0] - before[0] == pytest.approx(0.04, abs=0.005)
        assert len(rig.drivers["o"].poll()) >= 5
    finally:
        rig.close()


def test_a_silent_cmd_vel_stops_the_body_but_a_held_up_world_does_not(rig):
    """A ROS 2 base stops when its cmd_vel falls silent for ROS2_CMD_TIMEOUT; commands that
    waited in the queue while the world's loop was held up (1.5 s, starved of CPU) count from
    when the loop takes them, so the catch-up does not read as a silence."""
    w, drv = rig.hub.world, rig.drivers["o"]
    drv.send(Twist2D(t=0.0, vx=0.2, ttl=5.0))
    rig.loop()
    drv.send(Twist2D(t=0.0, vx=0.2, ttl=5.0))  # arrives while the world is held up
    rig.loop(stall=1.5)
    assert rig.bodies.timeout_stops == 0, "the world's stall read as a silent cmd_vel"
    x0 = w.robot_pose("o")[0]
    rig.loop()
    assert w.robot_pose("o")[0] > x0, "the body stopped"
    steps = math.ceil(ROS2_CMD_TIMEOUT / 0.02) + 1  # no more cmd_vel: silent past the timeout
    for _ in range(steps):
        rig.loop()
    assert rig.bodies.timeout_stops == 1
    x1 = w.robot_pose("o")[0]
    rig.loop()
    assert w.robot_pose("o")[0] == x1  # stopped
    assert rig.drivers["d"].stale == 0


def test_fleet_world_ros2_with_an_unknown_id_exits_2(tmp_path, port):
    cfg, _ = rehearsal_config(tmp_path, port)
    proc = fleet("world", "--config", str(cfg), "--ros2", "r9", "--duration", "1")
    assert proc.returncode == 2, proc.stderr
    assert "not a ROS 2 robot" in proc.stderr and "r9" in proc.stderr
