"""MAVLink vehicles as bodies of the shared world (``fleet world --mavlink``): an emulated flight
controller per MAVLink robot answers its url on loopback and drives a body of the same world as
the ``sim`` robots, so a mixed fleet rehearses together.

In process first (the world's hub stepping the emulator, the real MavlinkDriver on the world's
clock), then the lab as processes with a mixed fleet: ``fleet world --mavlink r1,r3 --ros2
r2,r4`` + ``fleet daemon --mission capture`` + six ``fleet driver`` processes (two sim, a PX4,
an ArduRover, two ROS 2 robots: test_world_ros2.py has the ROS 2 bodies in process), capturing
the crate the world publishes and delivering it."""

from __future__ import annotations

import dataclasses
import math
import sys
import time

import pytest

from controller.config import ConfigError
from controller.replay.log import events_of, load_run, metrics_of
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
from tests.support.config import free_port, write_toml
from tests.support.lab import fleet, release, spawn, stop_all, tail
from tests.support.mavlink_rig import free_udp_port, make_config, robot
from tests.support.wait import wait_for
from tests.support.world_lab import all_present, daemon_status, rehearsal_config, six_around

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
ROS2 = {  # r2 omni on Odometry + Twist; r4 differential on PoseStamped + TwistStamped
    "r2": {"namespace": "/r2"},
    "r4": {"namespace": "/r4", "domain_id": 3, "pose_type": "pose_stamped",
           "cmd_type": "twist_stamped"},
}  # fmt: skip
JOB_S = 240.0  # s of wall time the job may take (the lockstep dry run: about 38 s of sim time)


def mixed_fleet(tmp_path, port: int):
    """test_world_lab's rehearsal world (a small crate creeping east) with six robots around
    it: r1 a PX4 and r3 an ArduRover on their own loopback UDP ports, r2 and r4 ROS 2 robots
    on one rmw_zenoh router endpoint (their own domains and namespaces, each odom frame at
    its start), r5 and r6 sim robots; the crate's goal a short way east (capture, route,
    re-arrangement and transport all in it)."""
    data = six_around(tmp_path, port)
    router = f"tcp/127.0.0.1:{free_port()}"
    for r in data["robots"]:
        start = r["start"]
        if r["id"] in MAVLINK:
            profile, sysid = MAVLINK[r["id"]]
            r.update(driver="mavlink", profile=profile, system_id=sysid,
                     url=f"udpin:127.0.0.1:{free_udp_port()}")  # fmt: skip
        elif r["id"] in ROS2:
            r.update(driver="ros2", ros2={**ROS2[r["id"]], "connect": [router],
                                          "odom_to_world": list(start)})  # fmt: skip
    return write_toml(tmp_path / "mixed.toml", data), [r["id"] for r in data["robots"]]


def _text(path) -> str:
    return path.read_text(errors="replace") if path.exists() else ""


@pytest.mark.e2e
def test_a_mixed_fleet_in_the_world_captures_and_delivers_the_object(tmp_path, port):
    """``fleet world --mavlink r1,r3 --ros2 r2,r4`` + ``fleet daemon --mission capture`` + six
    ``fleet driver`` processes (two sim, a PX4, an ArduRover, two ROS 2 robots) on 127.0.0.1:
    the fleet arrests the crate and carries it to its goal. The daemon's MCAP decides, from
    the world's truth (sim/truth) it recorded: the arrest, the delivery within tolerance, and
    every vehicle of its own driving in the world."""
    t0 = time.monotonic()
    cfg, ids = mixed_fleet(tmp_path, port)
    c = str(cfg)
    world = spawn(tmp_path / "world.txt", "world", "--config", c, "--mavlink", "r1,r3",
                  "--ros2", "r2,r4")  # fmt: skip
    procs = [world]
    out = tmp_path / "d.mcap"
    try:
        wait_for(lambda: "fleet world: fleet" in _text(tmp_path / "world.txt"), 30, "the world")
        daemon = spawn(tmp_path / "daemon.txt", "daemon", "--config", c, "--mission", "capture",
                       "--out", str(out))  # fmt: skip
        procs.append(daemon)
        procs += [spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in ids]
        # a fresh lab is stopped until an operator's first resume (the daemon up to hear it)
        wait_for(lambda: all_present(daemon_status(cfg), set(ids)), 60, "the daemon and its robots")
        release(cfg, timeout=90)
        wait_for(lambda: daemon.poll() is not None, JOB_S, "the daemon's end of the job")
        wall = time.monotonic() - t0
    finally:
        codes = stop_all(procs)
    assert codes == [0] * len(procs), (codes, [tail(p) for p in procs])
    for r, (_, sysid) in MAVLINK.items():
        text = _text(tmp_path / f"{r}.txt")
        assert f"connected to system {sysid}" in text, text[-2000:]
    rep = metrics_of(load_run(out))
    seen = [p["phase"] for p in rep["phases"]]
    assert seen[0] == "approach" and "hold" in seen and "arrested" in seen, seen
    assert rep["arrested"] and rep["ground_truth"], rep["phases"]
    assert rep["transported"] is True, {k: rep.get(k) for k in ("goal_error_m", "phases")}
    # every vehicle of its own drove in the world through its driver (the capture takes four
    # of the six: the others make room), as the world's truth of it says
    went = {r: round(rep["robots"][r]["path_length_m"], 2) for r in (*MAVLINK, *ROS2)}
    assert all(d > 0.1 for d in went.values()), went
    assert all(rep["robots"][r]["poses"] > 100 for r in ids), rep["robots"]
    text = tail(world, 600)
    assert "2 MAVLink vehicles" in text and "2 ROS 2 robots" in text, text
    figures = {k: rep[k] for k in ("goal_error_m", "transport_time_s", "rearrangements")}
    figures["capture"] = [e["data"].get("robots") for e in events_of(load_run(out), "capture")]
    print(f"\n{text}\nmixed fleet: {wall:.1f} s wall to the job's end, "
          f"{time.monotonic() - t0:.1f} s in all; {figures}; went {went}",
          file=sys.stderr)  # fmt: skip


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
