"""MAVLink vehicles as bodies of the shared world (``fleet world --mavlink``): an emulated flight
controller per MAVLink robot answers its url on loopback and drives a body of the same world as
the ``sim`` robots, so a mixed fleet rehearses together.

In process first (the world's hub stepping the emulator, the real MavlinkDriver on the world's
clock), then the lab as processes: ``fleet world --mavlink`` + ``fleet daemon --mission capture``
+ one ``fleet driver`` per robot, two of them MAVLink (a PX4 and an ArduRover), arresting the
crate the world publishes."""

from __future__ import annotations

import dataclasses
import math
import sys
import time
import tomllib

import pytest

from controller.config import ConfigError
from controller.runtime.wiring import make_hub
from controller.runtime.world import (
    _start_vehicles,
    emulated_vehicles,
    pump_vehicles,
    world_config,
)
from controller.wire import Twist2D
from drivers.mavlink.driver import MavlinkDriver
from drivers.mavlink.link import LinkPool
from tests.integration.test_world_lab import (
    Truth,
    _all_present,
    _arrested,
    _status,
    rehearsal_config,
)
from tests.support.config import write_toml
from tests.support.lab import connect_client, fleet, release, spawn, stop_all, tail
from tests.support.mavlink_rig import free_udp_port, make_config, robot
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e

SIM = {"id": "s", "kind": "omni", "start": [6.0, 3.0, 0.0]}


def _mixed(px4_port: int, rover_port: int):
    return make_config(
        [
            robot("p", "px4", px4_port, 1, theta=0.0),
            robot("a", "ardurover", rover_port, 2, theta=math.pi / 2),
            SIM,
        ]
    )


def test_which_mavlink_robots_the_world_emulates():
    cfg = _mixed(free_udp_port(), free_udp_port())
    assert emulated_vehicles(cfg, None) == ()
    assert emulated_vehicles(cfg, "all") == ("p", "a")
    assert emulated_vehicles(cfg, " a ") == ("a",)
    assert [r.id for r in world_config(cfg, ("a",)).robots] == ["a", "s"]
    assert [r.id for r in world_config(cfg).robots] == ["s"]  # MAVLink robots: real vehicles
    with pytest.raises(ConfigError, match=r"--mavlink 's': not a MAVLink robot"):
        emulated_vehicles(cfg, "a,s")


def test_a_vehicle_url_off_loopback_is_refused_naming_the_key():
    cfg = make_config([robot("p", "px4", 14550, 1), SIM])
    m = dataclasses.replace(cfg.robots[0].mavlink, url="udpout:10.1.2.3:14550")  # never opened
    cfg = dataclasses.replace(
        cfg, robots=(dataclasses.replace(cfg.robots[0], mavlink=m), cfg.robots[1])
    )
    with pytest.raises(ConfigError, match=r"robots\[0\]\.url.*loopback"):
        emulated_vehicles(cfg, "all")


def test_mavlink_bodies_move_in_the_shared_world_and_report_its_pose():
    """The world's loop steps a PX4 and an ArduRover body next to a sim robot: the real
    driver's setpoints move the bodies (NED setpoints, ENU world), its poses are the world's
    truth."""
    cfg = _mixed(free_udp_port(), free_udp_port())
    vehicles = emulated_vehicles(cfg, "all")
    hub = make_hub(world_config(cfg, vehicles))
    assert set(hub.robot_sensors) == {"s"}  # the vehicles report their own pose
    emus = _start_vehicles(cfg, hub, vehicles)
    pool = LinkPool()

    connected: list[MavlinkDriver] = []

    def idle(dt: float) -> None:  # one loop of the world; the connected drivers keep streaming
        target = hub.t + max(dt, hub.dt)
        pump_vehicles(emus, target)
        hub.advance_to(target)
        pump_vehicles(emus, hub.t)
        for d in connected:
            d.health()

    drivers = {
        r.id: MavlinkDriver(r, clock=lambda: hub.t, idle=idle, pool=pool)
        for r in cfg.robots
        if r.id in vehicles
    }
    try:
        for d in drivers.values():
            d.connect(timeout=3.0)
            connected.append(d)
        start = {rid: hub.world.robot_pose(rid).copy() for rid in drivers}
        s0 = hub.world.robot_pose("s").copy()
        drivers["p"].send(Twist2D(t=hub.t, vx=0.0, vy=0.2, ttl=5.0))  # p: left = north
        drivers["a"].send(Twist2D(t=hub.t, vx=0.2, ttl=5.0))  # a faces north: forward
        for _ in range(100):  # 1 s
            idle(0.01)
        moved = {rid: hub.world.robot_pose(rid) - start[rid] for rid in drivers}
        for rid in drivers:  # both went about 0.2 m north (+y), not east
            assert 0.12 < moved[rid][1] < 0.22 and abs(moved[rid][0]) < 0.02, (rid, moved)
        assert (hub.world.robot_pose("s") == s0).all()  # the sim robot was not commanded
        for rid, d in drivers.items():
            poses = d.poll()
            assert len(poses) > 20
            truth = hub.world.robot_pose(rid)
            last = poses[-1]
            assert math.dist((last.x, last.y), truth[:2]) < 0.01
            assert abs(math.remainder(last.theta - truth[2], math.tau)) < 0.01
        assert all(e.counters["setpoints"] > 10 for e in emus)
    finally:
        for d in drivers.values():
            d.close()
        for e in emus:
            e.stop()
        hub.world.close()


def test_fleet_world_mavlink_with_an_unknown_id_exits_2(tmp_path, port):
    cfg, _ = rehearsal_config(tmp_path, port)
    proc = fleet("world", "--config", str(cfg), "--mavlink", "r1", "--duration", "1")
    assert proc.returncode == 2, proc.stderr
    assert "not a MAVLink robot" in proc.stderr and "r1" in proc.stderr


MAVLINK = {"r1": ("px4", 1), "r3": ("ardurover", 3)}  # r3 is differential: an ArduRover


def mixed_rehearsal(tmp_path, port: int):
    """test_world_lab's rehearsal (four robots around a creeping crate) with r1 a PX4 and r3 an
    ArduRover, each on its own loopback UDP port."""
    path, fleet_keys = rehearsal_config(tmp_path, port)
    data = tomllib.loads(path.read_text())
    for r in data["robots"]:
        if r["id"] in MAVLINK:
            profile, sysid = MAVLINK[r["id"]]
            r.update(driver="mavlink", profile=profile, system_id=sysid,
                     url=f"udpin:127.0.0.1:{free_udp_port()}")  # fmt: skip
    return write_toml(tmp_path / "mixed.toml", data), [r["id"] for r in data["robots"]]


@pytest.mark.e2e
def test_world_daemon_and_drivers_with_mavlink_vehicles_arrest_the_object(tmp_path, port):
    t0 = time.monotonic()
    cfg, ids = mixed_rehearsal(tmp_path, port)
    c = str(cfg)
    world = spawn(tmp_path / "world.txt", "world", "--config", c, "--mavlink")
    procs = [world]
    try:
        with connect_client(port, "the world") as bus:
            truth = Truth(bus)
            phases = bus.subscribe_topic("plan", lossless=True, what="phase")
            wait_for(lambda: truth.take() > 0, 20, "the world's truth")
            start = {r: truth.tracks[r][-1] for r in ids}  # the MAVLink bodies' truth too
            procs.append(spawn(tmp_path / "daemon.txt", "daemon", "--config", c, "--mission",
                               "capture", "--out", str(tmp_path / "d.mcap")))  # fmt: skip
            procs += [spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ids]
            # a fresh lab is stopped until an operator's first resume (the daemon up to hear it)
            wait_for(lambda: _all_present(_status(cfg), set(ids)), 60, "the daemon and its robots")
            release(cfg, timeout=90)
            seen: list[str] = []
            wait_for(lambda: _arrested(phases, seen), 60, "the daemon's arrest")
            assert seen[0] == "approach" and "hold" in seen, seen
            truth.take()
            went = {r: math.dist(start[r][1:3], truth.tracks[r][-1][1:3]) for r in MAVLINK}
            assert all(d > 0.1 for d in went.values()), went  # the vehicles drove in the world
    finally:
        codes = stop_all(procs)
    assert codes == [0] * len(procs), (codes, [tail(p) for p in procs])
    for r, (_, sysid) in MAVLINK.items():
        text = (tmp_path / f"{r}.txt").read_text()
        assert f"connected to system {sysid}" in text, text[-2000:]
    out = tail(world, 600)
    assert "2 MAVLink vehicles" in out and "real-time factor" in out, out
    print(f"\n{out}\nmixed rehearsal: {time.monotonic() - t0:.1f} s", file=sys.stderr)


def test_a_world_held_up_by_the_machine_does_not_trip_the_vehicles_own_timeout():
    """The world's loop held up 1.5 s (starved of CPU) while the PX4's driver kept streaming:
    the setpoints that waited in the socket count from when they arrived, so the next loop's
    physics catch-up does not read as 1.5 s without setpoints (COM_OF_LOSS_T 1 s: HOLD)."""
    from drivers.mavlink import convert as mc

    cfg = make_config([robot("p", "px4", free_udp_port(), 1), SIM])
    vehicles = emulated_vehicles(cfg, "all")
    hub = make_hub(world_config(cfg, vehicles))
    emus = _start_vehicles(cfg, hub, vehicles)
    wall = [hub.t]  # the driver's clock: the wall clock's sim time
    served = [False]

    def loop() -> None:  # one iteration of the world's loop at the wall clock's sim time
        pump_vehicles(emus, wall[0])
        hub.advance_to(wall[0])
        pump_vehicles(emus, hub.t)

    def idle(dt: float) -> None:
        wall[0] += max(dt, hub.dt)
        if served[0]:
            drv.health()  # the driver streams on its own clock
        loop()

    drv = MavlinkDriver(cfg.robots[0], clock=lambda: wall[0], idle=idle, pool=LinkPool())
    try:
        drv.connect(timeout=3.0)
        served[0] = True
        assert emus[0].mode == mc.PX4_OFFBOARD
        for _ in range(30):  # the world held up 1.5 s; the driver streams every 50 ms
            wall[0] += 0.05
            drv.health()
        loop()
        assert emus[0].mode == mc.PX4_OFFBOARD, "the world's stall tripped the vehicle"
        assert hub.t == pytest.approx(wall[0], abs=hub.dt)
    finally:
        drv.close()
        for e in emus:
            e.stop()
        hub.world.close()
