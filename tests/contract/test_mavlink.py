"""MAVLink adapter and vehicle emulator: conversions, routing, failsafes and the driver contract.

Everything runs in lockstep on a fake clock shared by the driver, the emulator and the ideal
world: ``Lockstep.advance(dt)`` steps the world and pumps the emulators; the driver's ``idle``
hook is that same ``advance``, so handshakes take no wall time and nothing sleeps. Loopback UDP
delivers a datagram into the receiver's buffer during ``sendto``, so the order is deterministic.

The ``contract_*`` functions take a connected (or, for the timeout, an unconnected) driver and an
``advance(seconds)`` callable, so a suite parametrized over all adapters can reuse them.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.wire import Twist2D
from drivers.agent import AgentCore
from drivers.base import ConnectTimeout, LinkLost, RobotDriver
from drivers.mavlink import convert as mc
from drivers.mavlink.driver import MavlinkDriver
from drivers.mavlink.link import LinkPool
from sim_backend.ideal import IdealWorld
from sim_backend.mavlink_vehicle import VehicleEmulator, start_emulators, vehicle_url
from tests.support.mavlink_rig import H, Lockstep, free_udp_port, make_config, robot

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

# --------------------------------------------------------------------------- contract checks


def _run(driver: RobotDriver, advance: Callable[[float], None], seconds: float,
         cmd: Twist2D | None = None, dt: float = 0.05) -> list:  # fmt: skip
    """Advance ``seconds`` in ``dt`` steps, sending ``cmd`` each step like an agent; poses."""
    poses = []
    for _ in range(max(1, round(seconds / dt))):
        if cmd is not None:
            driver.send(cmd)
        advance(dt)
        poses.extend(driver.poll())
    return poses


def contract_connect_timeout(driver: RobotDriver, advance: Callable[[float], None]) -> None:
    """An unconnected driver whose robot never answers: connect raises ConnectTimeout."""
    with pytest.raises(ConnectTimeout):
        driver.connect(timeout=0.5)
    assert not driver.health().ok
    driver.close()


def contract_forward_motion(driver: RobotDriver, advance: Callable[[float], None]) -> None:
    """Forward command -> poses move along the robot's world heading (ENU), not sideways."""
    start = _run(driver, advance, 0.3)
    assert start, "no pose measurements after connect"
    p0 = start[-1]
    poses = _run(driver, advance, 1.0, Twist2D(t=0.0, vx=0.3, ttl=0.5))
    assert len(poses) >= 20, f"only {len(poses)} poses in 1 s"
    p1 = poses[-1]
    d = np.array([p1.x - p0.x, p1.y - p0.y])
    u = np.array([math.cos(p0.theta), math.sin(p0.theta)])
    forward = float(d @ u)
    lateral = float(abs(d[0] * u[1] - d[1] * u[0]))
    assert 0.2 < forward < 0.4, f"moved {forward:.3f} m forward in 1 s at 0.3 m/s"
    assert lateral < 0.02, f"moved {lateral:.3f} m sideways on a forward command"
    ts = [p.t for p in poses]
    assert all(b >= a for a, b in zip(ts, ts[1:], strict=False)), "pose times go backwards"


def _mean_pose(poses: list) -> np.ndarray:
    th = np.array([p.theta for p in poses])
    return np.array(
        [
            np.mean([p.x for p in poses]),
            np.mean([p.y for p in poses]),
            math.atan2(np.mean(np.sin(th)), np.mean(np.cos(th))),
        ]
    )


def contract_stop(driver: RobotDriver, advance: Callable[[float], None]) -> None:
    """stop() zeroes motion: after a short settle the pose stays put (window means compared,
    so noisy sensors pass)."""
    before = _run(driver, advance, 0.2)
    moving = _run(driver, advance, 0.5, Twist2D(t=0.0, vx=0.3, wz=0.4, ttl=0.5))
    assert before and moving
    assert math.hypot(moving[-1].x - before[-1].x, moving[-1].y - before[-1].y) > 0.05
    driver.stop()
    _run(driver, advance, 0.3)  # settle
    a = _run(driver, advance, 0.5)
    _run(driver, advance, 0.5)
    b = _run(driver, advance, 0.5)
    assert a and b
    pa, pb = _mean_pose(a), _mean_pose(b)
    assert math.hypot(*(pb[:2] - pa[:2])) < 5e-3, f"drifted {pb - pa} after stop()"
    assert abs(math.remainder(pb[2] - pa[2], 2 * math.pi)) < 1e-2


def contract_health_lost(driver: RobotDriver, advance: Callable[[float], None],
                         silence: Callable[[], None], link_timeout: float) -> None:  # fmt: skip
    """The vehicle goes silent: health turns not-ok within link_timeout (+ one step), then
    send raises LinkLost."""
    _run(driver, advance, 0.3)
    assert driver.health().ok, driver.health().detail
    silence()
    dt, waited = 0.05, 0.0
    while driver.health().ok:
        assert waited <= link_timeout + 2 * dt + 1e-6, f"still ok {waited:.2f} s after silence"
        advance(dt)
        driver.poll()
        waited += dt
    assert waited >= link_timeout - 0.3, f"declared lost after only {waited:.2f} s"
    with pytest.raises(LinkLost):
        driver.send(Twist2D(t=0.0, vx=0.1))
    driver.stop()  # never raises


def contract_close_idempotent(driver: RobotDriver, advance: Callable[[float], None]) -> None:
    """close() twice is fine; afterwards the link reports not ok and poll returns nothing."""
    driver.close()
    driver.close()
    advance(0.1)
    assert not driver.health().ok
    assert driver.poll() == []


# --------------------------------------------------------------------------- harness


@pytest.fixture
def pool():
    return LinkPool()


@pytest.fixture(params=["ardurover", "px4"])
def rig(request, pool):
    """A connected driver and its emulator for one profile."""
    port = free_udp_port()
    cfg = make_config([robot("r1", request.param, port, 1)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0])
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    drv.connect(timeout=2.0)
    yield ls, emu, drv
    drv.close()
    ls.close()


# --------------------------------------------------------------------------- contract suite


@pytest.mark.parametrize("profile", ["ardurover", "px4"])
def test_contract_connect_timeout(profile, pool):
    port = free_udp_port()
    cfg = make_config([robot("r1", profile, port, 7)])
    ls = Lockstep(cfg)  # no emulator: nothing answers
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    with pytest.raises(ConnectTimeout, match=rf"system 7 on udpin:127.0.0.1:{port}"):
        drv.connect(timeout=0.5)
    assert ls.t >= 0.5
    contract_connect_timeout(drv, ls.advance)


def test_contract_forward_motion(rig):
    ls, emu, drv = rig
    assert isinstance(drv, RobotDriver)
    contract_forward_motion(drv, ls.advance)


def test_contract_stop(rig):
    ls, emu, drv = rig
    contract_stop(drv, ls.advance)


def test_contract_health_lost(rig):
    ls, emu, drv = rig
    contract_health_lost(drv, ls.advance, lambda: emu.set_silent(True), drv.cfg.link_timeout)
    # commands stop: nothing more reaches the vehicle once the link is lost
    emu.set_silent(False)
    n = emu.counters["setpoints"]
    emu.set_silent(True)
    _run(drv, ls.advance, 0.5)
    assert emu.counters["setpoints"] == n


def test_contract_close_idempotent(rig):
    ls, emu, drv = rig
    contract_close_idempotent(drv, ls.advance)


# --------------------------------------------------------------------------- adapter specifics


def test_connect_sets_mode_arms_and_rates(rig):
    ls, emu, drv = rig
    want = mc.ROVER_GUIDED if drv.profile == "ardurover" else mc.PX4_OFFBOARD
    assert emu.mode == want and emu.armed
    assert emu.intervals[mc.MSG_LOCAL_POSITION_NED] <= 1 / 30
    assert emu.intervals[mc.MSG_ATTITUDE] <= 1 / 30
    assert drv.health().ok
    poses = _run(drv, ls.advance, 1.0)
    assert len(poses) >= 30
    truth = ls.world.robot_pose("r1")
    assert abs(poses[-1].x - truth[0]) < 1e-3 and abs(poses[-1].y - truth[1]) < 1e-3


def test_px4_connect_streams_before_offboard(pool):
    port = free_udp_port()
    cfg = make_config([robot("r1", "px4", port, 3)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0])
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    drv.connect(timeout=2.0)
    sps = [s.t for s in emu.setpoints]
    assert sps and max(np.diff(sps)) < 0.5  # above 2 Hz
    offboard_at = ls.t
    assert offboard_at - sps[0] >= 1.0
    drv.close()
    ls.close()


def test_differential_robot_never_receives_vy(pool):
    port = free_udp_port()
    cfg = make_config([robot("d", "ardurover", port, 4)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0])
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    assert not drv.capabilities.holonomic
    drv.connect(timeout=2.0)
    start = ls.world.robot_pose("d")
    gate = AgentCore(drv.capabilities, cmd_ttl=1.0)  # what the agent does before the driver
    for vy in (0.3, -0.2, 0.0, 0.5):
        _run(drv, ls.advance, 0.2, gate.gate(Twist2D(t=0.0, vx=0.0, vy=vy, wz=0.0)))
    assert emu.setpoints
    assert all(s.vy == 0.0 and s.vz == 0.0 for s in emu.setpoints)
    assert all(s.type_mask == mc.MASK_VELOCITY_YAW_RATE for s in emu.setpoints)
    assert all(s.frame == mc.FRAME_BODY_NED for s in emu.setpoints)
    assert gate.counters.vy_dropped == 3
    assert np.allclose(ls.world.robot_pose("d"), start, atol=1e-9)
    drv.close()
    ls.close()


def test_heartbeat_loss_detected_within_link_timeout(pool):
    port = free_udp_port()
    cfg = make_config([robot("r", "ardurover", port, 5, link_timeout=0.4)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0])
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    drv.connect(timeout=2.0)
    # heartbeats come often enough that a live link never flaps at this timeout
    for _ in range(60):
        ls.advance(H)
        assert drv.health().ok, drv.health().detail
    contract_health_lost(drv, ls.advance, lambda: emu.set_silent(True), 0.4)
    assert "no HEARTBEAT from system 5" in drv.health().detail
    emu.set_silent(False)  # the link comes back; the vehicle is still in GUIDED
    _run(drv, ls.advance, 0.3)
    assert drv.health().ok
    drv.close()
    ls.close()


@pytest.mark.parametrize("profiles", [("ardurover", "ardurover"), ("ardurover", "px4")])
def test_two_robots_on_one_port_do_not_get_each_others_commands(pool, profiles):
    port = free_udp_port()
    cfg = make_config([robot("a", profiles[0], port, 1), robot("b", profiles[1], port, 2)])
    ls = Lockstep(cfg)
    ea, eb = ls.emulator(cfg.robots[0]), ls.emulator(cfg.robots[1])
    da = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    db = MavlinkDriver(cfg.robots[1], clock=ls.clock, idle=ls.advance, pool=pool)
    da.connect(timeout=2.0)
    db.connect(timeout=2.0)
    pa0, pb0 = ls.world.robot_pose("a"), ls.world.robot_pose("b")
    for _ in range(20):
        da.send(Twist2D(t=0.0, vx=0.11))
        db.send(Twist2D(t=0.0, vx=-0.22))
        ls.advance(0.05)
        assert all(p.source == "mavlink:1" for p in da.poll())
        assert all(p.source == "mavlink:2" for p in db.poll())
    assert ea.counters["foreign"] == 0 and eb.counters["foreign"] == 0
    assert {s.target_system for s in ea.setpoints} == {1}
    assert {s.target_system for s in eb.setpoints} == {2}
    moving_a = [s.vx for s in ea.setpoints if s.vx != 0.0]
    moving_b = [s.vx for s in eb.setpoints if s.vx != 0.0]
    assert moving_a and set(np.round(moving_a, 4)) == {0.11}
    assert moving_b and set(np.round(moving_b, 4)) == {-0.22}
    da_d = ls.world.robot_pose("a")[:2] - pa0[:2]
    db_d = ls.world.robot_pose("b")[:2] - pb0[:2]
    ua = np.array([math.cos(pa0[2]), math.sin(pa0[2])])
    assert float(da_d @ ua) > 0.08 and float(db_d @ ua) < -0.16
    da.close()
    db.close()
    ls.close()


def test_plain_udpin_would_broadcast(pool):
    """Why routing matters: pymavlink's own udpin write reaches every peer it has heard."""
    port = free_udp_port()
    cfg = make_config([robot("a", "ardurover", port, 1), robot("b", "ardurover", port, 2)])
    ls = Lockstep(cfg)
    ea, eb = ls.emulator(cfg.robots[0]), ls.emulator(cfg.robots[1])
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
    try:
        ls.advance(H)
        while gcs.recv_msg() is not None:
            pass
        gcs.mav.command_long_send(1, 1, mc.CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        ls.advance(H)
        assert eb.counters["foreign"] == 1 and ea.armed and not eb.armed
    finally:
        gcs.close()
        ls.close()


def test_connect_refuses_wrong_autopilot(pool):
    port = free_udp_port()
    cfg = make_config([robot("r", "px4", port, 6)])
    ls = Lockstep(cfg)
    ls.emulator(cfg.robots[0])
    wrong = make_config([robot("r", "ardurover", port, 6)]).robots[0]
    drv = MavlinkDriver(wrong, clock=ls.clock, idle=ls.advance, pool=pool)
    with pytest.raises(RuntimeError, match="autopilot 12"):
        drv.connect(timeout=1.0)
    ls.close()


# --------------------------------------------------------------------------- emulator semantics


class RawGcs:
    """A bare pymavlink GCS on the robot's udpin port, for emulator tests."""

    def __init__(self, port: int, ls: Lockstep):
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
        self.ls = ls
        ls.advance(H)  # the vehicle's first heartbeat teaches us its address
        while self.conn.recv_msg() is not None:
            pass

    def command(self, sysid: int, cmd: int, *params: float) -> int:
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(sysid, 1, cmd, 0, *p)
        self.ls.advance(H)
        result = None
        while (m := self.conn.recv_msg()) is not None:
            if m.get_type() == "COMMAND_ACK" and m.command == cmd:
                result = m.result
        assert result is not None, f"no ACK for command {cmd}"
        return result

    def heartbeat(self) -> None:
        self.conn.mav.heartbeat_send(mc.TYPE_GCS, mc.AUTOPILOT_INVALID, 0, 0, 4)

    def velocity(self, sysid: int, vx: float, vy: float, yaw_rate: float = 0.0,
                 mask: int = mc.MASK_VELOCITY_YAW_RATE) -> None:  # fmt: skip
        self.conn.mav.set_position_target_local_ned_send(
            0, sysid, 1, mc.FRAME_BODY_NED, mask, 0, 0, 0, vx, vy, 0, 0, 0, 0, 0, yaw_rate
        )

    def close(self) -> None:
        self.conn.close()


def _body_displacement(start: np.ndarray, end: np.ndarray) -> tuple[float, float]:
    d = end[:2] - start[:2]
    c, s = math.cos(start[2]), math.sin(start[2])
    return float(c * d[0] + s * d[1]), float(-s * d[0] + c * d[1])


@pytest.mark.parametrize("profile", ["ardurover", "px4"])
def test_emulator_lateral_command(profile):
    """ArduRover GUIDED ignores a lateral command; PX4 OFFBOARD (holonomic) follows it."""
    port = free_udp_port()
    cfg = make_config([robot("r", profile, port, 1)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0])
    gcs = RawGcs(port, ls)
    try:
        if profile == "ardurover":
            assert gcs.command(1, mc.CMD_DO_SET_MODE, 1, mc.ROVER_GUIDED) == mc.RESULT_ACCEPTED
        else:
            for _ in range(30):
                gcs.velocity(1, 0.0, 0.0)
                ls.advance(0.05)
            assert gcs.command(1, mc.CMD_DO_SET_MODE, 1, mc.PX4_MAIN_OFFBOARD) == 0
        assert gcs.command(1, mc.CMD_COMPONENT_ARM_DISARM, 1) == mc.RESULT_ACCEPTED
        start = ls.world.robot_pose("r")
        for _ in range(20):  # 1 s of "0.3 m/s to the right" (FRD vy > 0)
            gcs.velocity(1, 0.0, 0.3)
            ls.advance(0.05)
        fwd, left = _body_displacement(start, ls.world.robot_pose("r"))
        assert emu.counters["setpoints"] >= 20
        if profile == "ardurover":
            assert abs(fwd) < 1e-9 and abs(left) < 1e-9
        else:
            assert abs(fwd) < 1e-6 and -0.33 < left < -0.27
    finally:
        gcs.close()
        ls.close()


def test_emulator_ardurover_target_timeout_and_gcs_failsafe():
    port = free_udp_port()
    cfg = make_config([robot("r", "ardurover", port, 1)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0], gcs_timeout=2.0)
    gcs = RawGcs(port, ls)
    try:
        gcs.heartbeat()
        gcs.command(1, mc.CMD_DO_SET_MODE, 1, mc.ROVER_GUIDED)
        gcs.command(1, mc.CMD_COMPONENT_ARM_DISARM, 1)
        for k in range(16):  # keep the GCS alive, one target only
            gcs.heartbeat()
            if k == 0:
                gcs.velocity(1, 0.2, 0.0)
            ls.advance(0.2)
            if (k + 1) * 0.2 < 2.9:
                assert emu.command[0] == pytest.approx(0.2), f"stopped early at step {k}"
        assert emu.command == (0.0, 0.0, 0.0)  # 3 s target timeout
        assert emu.mode == mc.ROVER_GUIDED
        gcs.heartbeat()
        gcs.velocity(1, 0.2, 0.0)
        ls.advance(1.9)  # no GCS heartbeat for < 2 s: still GUIDED
        assert emu.mode == mc.ROVER_GUIDED and emu.command[0] == pytest.approx(0.2)
        ls.advance(0.3)
        assert emu.mode == mc.ROVER_HOLD and emu.command == (0.0, 0.0, 0.0)
        gcs.velocity(1, 0.2, 0.0)  # HOLD ignores targets
        ls.advance(0.1)
        assert emu.command == (0.0, 0.0, 0.0)
    finally:
        gcs.close()
        ls.close()


def test_emulator_px4_offboard_needs_stream_and_leaves_when_it_stops():
    port = free_udp_port()
    cfg = make_config([robot("r", "px4", port, 1)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0])
    gcs = RawGcs(port, ls)
    try:
        off = (1, mc.PX4_MAIN_OFFBOARD)
        assert gcs.command(1, mc.CMD_DO_SET_MODE, *off) == mc.RESULT_TEMPORARILY_REJECTED
        for _ in range(10):  # 0.5 s of stream is not enough
            gcs.velocity(1, 0.0, 0.0)
            ls.advance(0.05)
        assert gcs.command(1, mc.CMD_DO_SET_MODE, *off) == mc.RESULT_TEMPORARILY_REJECTED
        for _ in range(3):  # 1 Hz is not a stream
            gcs.velocity(1, 0.0, 0.0)
            ls.advance(1.0)
        assert gcs.command(1, mc.CMD_DO_SET_MODE, *off) == mc.RESULT_TEMPORARILY_REJECTED
        for _ in range(25):
            gcs.velocity(1, 0.1, 0.0)
            ls.advance(0.05)
        assert gcs.command(1, mc.CMD_DO_SET_MODE, *off) == mc.RESULT_ACCEPTED
        gcs.command(1, mc.CMD_COMPONENT_ARM_DISARM, 1)
        assert emu.mode == mc.PX4_OFFBOARD and emu.command[0] == pytest.approx(0.1)
        ls.advance(0.9)
        assert emu.mode == mc.PX4_OFFBOARD
        ls.advance(0.3)  # setpoints stopped > 1 s ago
        assert emu.mode == mc.PX4_HOLD and emu.command == (0.0, 0.0, 0.0)
    finally:
        gcs.close()
        ls.close()


def test_emulator_threaded_real_time(pool):
    """The background-thread mode against the driver on the real monotonic clock."""
    port = free_udp_port()
    cfg = make_config([robot("r", "ardurover", port, 9)])
    world = IdealWorld(cfg)
    emu = VehicleEmulator(world, cfg.robots[0]).start()
    drv = MavlinkDriver(cfg.robots[0], pool=pool)
    try:
        drv.connect(timeout=3.0)
        assert drv.health().ok
        assert emu.mode == mc.ROVER_GUIDED and emu.armed
        drv.send(Twist2D(t=0.0, vx=0.2))
        emu_cmd_seen = False
        for _ in range(200):
            drv.poll()
            if emu.command[0] == pytest.approx(0.2):
                emu_cmd_seen = True
                break
            emu._stop_evt.wait(0.005)
        assert emu_cmd_seen
    finally:
        drv.close()
        emu.stop()


def test_vehicle_url():
    assert vehicle_url("udpin:0.0.0.0:14551") == "udpout:127.0.0.1:14551"
    assert vehicle_url("udpout:127.0.0.1:14552") == "udpin:127.0.0.1:14552"
    assert vehicle_url("tcp:127.0.0.1:5760") == "tcpin:127.0.0.1:5760"
    with pytest.raises(ValueError):
        vehicle_url("udpout:10.0.0.5:14552")


# --------------------------------------------------------------------------- conversions

finite = st.floats(-1e3, 1e3, allow_nan=False)
angle = st.floats(-20.0, 20.0, allow_nan=False)


def _same_angle(a: float, b: float) -> bool:
    return abs(math.remainder(a - b, 2 * math.pi)) < 1e-9


@settings(max_examples=200, deadline=None)
@given(finite, finite, angle)
def test_pose_round_trips(x, y, th):
    n, e, yaw = mc.enu_to_ned_pose(x, y, th)
    assert -math.pi <= yaw <= math.pi
    x2, y2, th2 = mc.ned_to_enu_pose(n, e, yaw)
    assert (x2, y2) == (x, y) and _same_angle(th2, th)
    n2, e2, yaw2 = mc.enu_to_ned_pose(*mc.ned_to_enu_pose(x, y, th))
    assert (n2, e2) == (x, y) and _same_angle(yaw2, th)


@settings(max_examples=200, deadline=None)
@given(finite, finite, finite)
def test_twist_and_velocity_round_trips(a, b, c):
    assert mc.frd_to_flu(*mc.flu_to_frd(a, b, c)) == (a, b, c)
    assert mc.ned_to_enu_velocity(*mc.enu_to_ned_velocity(a, b, c)) == (a, b, c)


@settings(max_examples=100, deadline=None)
@given(angle, st.floats(0.01, 2.0), st.floats(-2.0, 2.0))
def test_conversions_agree_with_motion(theta, v, w):
    """A body FLU twist moved through NED gives the same world motion as in ENU."""
    vx_b, vy_b, wz = v, 0.5 * v, w
    # ENU world velocity of the body twist
    c, s = math.cos(theta), math.sin(theta)
    ve, vn = c * vx_b - s * vy_b, s * vx_b + c * vy_b
    # the same through NED: rotate the FRD twist by yaw (clockwise from north)
    _, _, yaw = mc.enu_to_ned_pose(0.0, 0.0, theta)
    fx, fy, yaw_rate = mc.flu_to_frd(vx_b, vy_b, wz)
    vn2 = math.cos(yaw) * fx - math.sin(yaw) * fy
    ve2 = math.sin(yaw) * fx + math.cos(yaw) * fy
    assert math.isclose(vn, vn2, abs_tol=1e-9) and math.isclose(ve, ve2, abs_tol=1e-9)
    assert mc.ned_to_enu_velocity(vn2, ve2, yaw_rate) == pytest.approx((ve, vn, wz))


def test_conversion_fixed_points():
    assert mc.enu_to_ned_pose(1.0, 2.0, math.pi / 2) == (2.0, 1.0, 0.0)  # facing north
    assert mc.enu_to_ned_pose(0.0, 0.0, 0.0)[2] == pytest.approx(math.pi / 2)  # east
    assert mc.enu_to_ned_pose(0.0, 0.0, math.pi)[2] == pytest.approx(-math.pi / 2)  # west
    assert mc.flu_to_frd(1.0, 0.5, 0.2) == (1.0, -0.5, -0.2)


def test_shared_link_keeps_every_robots_heartbeat(pool):
    """While only one driver on a port is being called (e.g. the others wait for a slow
    handshake), the others still send their GCS heartbeats: no GCS failsafe."""
    port = free_udp_port()
    cfg = make_config([robot("a", "ardurover", port, 1), robot("b", "ardurover", port, 2)])
    ls = Lockstep(cfg)
    ea = ls.emulator(cfg.robots[0], gcs_timeout=2.0)
    ls.emulator(cfg.robots[1], gcs_timeout=2.0)
    da = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    db = MavlinkDriver(cfg.robots[1], clock=ls.clock, idle=ls.advance, pool=pool)
    da.connect(timeout=2.0)
    db.connect(timeout=2.0)
    for _ in range(120):  # 6 s, only b is polled
        ls.advance(0.05)
        db.poll()
    assert ea.mode == mc.ROVER_GUIDED and not ea.failsafe
    assert da.health().ok, da.health().detail
    da.close()
    db.close()
    ls.close()


@pytest.mark.parametrize(("heartbeat_hz", "tripped"), [(1.0, True), (3.0, False)])
def test_gcs_heartbeat_rate_against_fs_timeout(pool, heartbeat_hz, tripped):
    """An ArduRover whose FS_TIMEOUT is 1 s (the README's old advice) trips its GCS failsafe
    against our default 1 Hz heartbeat (one period plus a poll's lateness); three heartbeats per
    FS_TIMEOUT (``[robots.mavlink] heartbeat_hz = 3``) keep it in GUIDED."""
    port = free_udp_port()
    r = robot("a", "ardurover", port, 1, mavlink={"heartbeat_hz": heartbeat_hz})
    cfg = make_config([r])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0], gcs_timeout=1.0)
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    assert drv.heartbeat_period == pytest.approx(1.0 / heartbeat_hz)
    drv.connect(timeout=2.0)
    for _ in range(100):  # 5 s, polled every 50 ms as the agent does
        ls.advance(0.05)
        drv.poll()
    assert emu.counters["gcs_heartbeats"] >= 4 * heartbeat_hz
    assert (emu.failsafe == "gcs" or emu.mode == mc.ROVER_HOLD) is tripped
    drv.close()
    ls.close()


def test_start_emulators_only_for_mavlink_robots():
    port = free_udp_port()
    sim_robot = {"id": "s", "kind": "omni", "start": [6.0, 6.0, 0.0]}
    cfg = make_config([robot("m", "px4", port, 1), sim_robot])
    ls = Lockstep(cfg)
    emus = start_emulators(ls.world, cfg.robots, clock=ls.clock)
    try:
        assert [e.robot_id for e in emus] == ["m"]
        assert emus[0].url == f"udpout:127.0.0.1:{port}"
    finally:
        for e in emus:
            e.stop()


def test_udpout_url_driver_sends_first(pool):
    """The driver dials out (``udpout``): its first heartbeat tells the vehicle where we are."""
    port = free_udp_port()
    r = robot("r", "ardurover", port, 1)
    r["url"] = f"udpout:127.0.0.1:{port}"
    cfg = make_config([r])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0])
    assert emu.url == f"udpin:127.0.0.1:{port}"
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    drv.connect(timeout=2.0)
    contract_forward_motion(drv, ls.advance)
    drv.close()
    ls.close()
