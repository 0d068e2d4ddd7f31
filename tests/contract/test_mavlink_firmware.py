"""The MAVLink driver against the emulator behaving like ArduPilot's own firmware (NOTES.md,
checked on its SITL; tests/contract/test_sitl.py runs the same against the firmware itself):
a telemetry rate it refuses, a position estimate that comes late, arming refused at first, and
what an e-stop or watchdog stop does to the vehicle's mode (``stop_hold``, ``disarm_on_stop``).

Lockstep on a fake clock (tests/support/mavlink_rig.py).
"""

from __future__ import annotations

import logging

import pytest

from controller.wire import Twist2D
from drivers.base import ConnectTimeout, DriverError
from drivers.mavlink import convert as mc
from drivers.mavlink.driver import MavlinkDriver
from drivers.mavlink.link import LinkPool
from tests.support.mavlink_rig import Lockstep, free_udp_port, make_config, robot

LOGGER = "drivers.mavlink.driver"


@pytest.fixture
def pool():
    return LinkPool()


def _rig(pool, profile: str, emu_kw: dict | None = None, **robot_kw):
    cfg = make_config([robot("r", profile, free_udp_port(), 1, **robot_kw)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0], **(emu_kw or {}))
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    return ls, emu, drv


def _until(ls, drv, pred, seconds: float) -> float:
    """Advance the lockstep, polling the driver each step as the agent does, until ``pred``;
    the sim time it took (fails after ``seconds``)."""
    t0 = ls.t
    while not pred():
        assert ls.t - t0 < seconds, f"not within {seconds} s"
        ls.advance(0.01)
        drv.poll()
    return ls.t - t0


def _run(ls, drv, seconds: float) -> None:
    """``seconds`` of the agent polling the driver."""
    end = ls.t + seconds
    while ls.t < end:
        ls.advance(0.01)
        drv.poll()


def test_telemetry_rate_steps_down_to_what_the_vehicle_grants(pool, caplog):
    ls, emu, drv = _rig(pool, "ardurover", {"max_rate_hz": 40.0})
    try:
        with caplog.at_level(logging.INFO, LOGGER):
            drv.connect(timeout=2.0)
        assert drv.cfg.telemetry_hz == 50.0 and drv.telemetry_hz == 40.0
        assert emu.intervals[mc.MSG_LOCAL_POSITION_NED] == pytest.approx(0.025)
        assert emu.intervals[mc.MSG_ATTITUDE] == pytest.approx(0.025)
        assert "refused SET_MESSAGE_INTERVAL LOCAL_POSITION_NED at 50 Hz: DENIED" in caplog.text
        assert "too fast" in caplog.text  # the vehicle's own reason
        assert "system 1 grants telemetry at 40 Hz (asked 50 Hz)" in caplog.text
    finally:
        drv.close()
        ls.close()


def test_a_vehicle_refusing_every_rate_down_to_the_floor_is_refused(pool):
    ls, emu, drv = _rig(pool, "ardurover", {"max_rate_hz": 3.0}, mavlink={"telemetry_min_hz": 5})
    try:
        with pytest.raises(DriverError, match="refused every telemetry rate from 50 Hz down to "
                           "telemetry_min_hz 5 Hz"):  # fmt: skip
            drv.connect(timeout=2.0)
    finally:
        drv.close()
        ls.close()


@pytest.mark.parametrize("profile", ["ardurover", "px4"])
def test_connect_waits_for_the_position_estimate_then_sets_the_mode_and_arms(pool, caplog, profile):
    ls, emu, drv = _rig(pool, profile, {"estimate_after": 12.0})
    try:
        with caplog.at_level(logging.INFO, LOGGER):
            drv.connect(timeout=20.0)
        assert ls.t >= 12.0
        assert "waiting for the vehicle's position estimate: 5 s" in caplog.text
        assert "waiting for the vehicle's position estimate: 10 s" in caplog.text
        want = mc.ROVER_GUIDED if profile == "ardurover" else mc.PX4_OFFBOARD
        assert emu.mode == want and emu.armed and drv.health().ok
    finally:
        drv.close()
        ls.close()


def test_no_position_estimate_within_the_timeout_is_a_connect_timeout(pool):
    ls, emu, drv = _rig(pool, "ardurover", {"estimate_after": 30.0})
    try:
        with pytest.raises(ConnectTimeout, match="no position estimate"):
            drv.connect(timeout=5.0)
        assert 5.0 <= ls.t < 12.0
        assert emu.mode == mc.ROVER_MANUAL and not emu.armed
    finally:
        drv.close()
        ls.close()


def test_arming_refused_is_asked_again_with_the_vehicles_reason_logged(pool, caplog):
    ls, emu, drv = _rig(pool, "ardurover", {"arm_refusals": 2})
    try:
        with caplog.at_level(logging.INFO, LOGGER):
            drv.connect(timeout=5.0)
        assert emu.armed and emu.arm_refusals == 0
        refusals = [r for r in caplog.records if "refused arming: FAILED" in r.getMessage()]
        assert len(refusals) == 2
        assert all("PreArm: Hardware safety switch" in r.getMessage() for r in refusals)
    finally:
        drv.close()
        ls.close()


def test_arming_refused_until_the_timeout_fails_naming_the_reason(pool):
    ls, emu, drv = _rig(pool, "ardurover", {"arm_refusals": 1000})
    try:
        with pytest.raises(DriverError, match="refused arming: FAILED .*Hardware safety switch"):
            drv.connect(timeout=3.0)
    finally:
        drv.close()
        ls.close()


def _driving(pool, profile: str, **mavlink):
    ls, emu, drv = _rig(pool, profile, mavlink=mavlink) if mavlink else _rig(pool, profile)
    drv.connect(timeout=3.0)
    drv.send(Twist2D(t=0.0, vx=0.3, ttl=10.0))
    ls.advance(0.2)
    assert emu.command[0] == pytest.approx(0.3)
    return ls, emu, drv


@pytest.mark.parametrize("profile", ["ardurover", "px4"])
def test_stop_brakes_in_guided_then_holds_at_rest_and_resumes_on_a_command(pool, profile):
    """stop_hold "at_rest" (the default): the zero at once, the mode left as it is (the speed
    controller brakes), HOLD once the vehicle reports it stopped; a command: GUIDED/OFFBOARD."""
    ls, emu, drv = _driving(pool, profile)
    drive = mc.ROVER_GUIDED if profile == "ardurover" else mc.PX4_OFFBOARD
    hold = mc.ROVER_HOLD if profile == "ardurover" else mc.PX4_HOLD
    try:
        drv.stop()
        ls.advance(0.01)
        assert emu.command == (0.0, 0.0, 0.0) and emu.mode == drive
        took = _until(ls, drv, lambda: emu.mode == hold, 1.0)  # the ideal world stops at once
        assert took < 0.5 and drv.health().ok and drv.braking
        _run(ls, drv, 2.0)
        assert emu.mode == hold and drv.health().ok  # no flapping back
        drv.send(Twist2D(t=ls.t, vx=0.2, ttl=10.0))
        _until(ls, drv, lambda: emu.mode == drive and emu.command[0] == pytest.approx(0.2), 1.0)
        assert drv.health().ok and not drv.braking
    finally:
        drv.close()
        ls.close()


def test_stop_hold_now_holds_at_once_and_off_never(pool):
    ls, emu, drv = _driving(pool, "ardurover", stop_hold="now")
    try:
        drv.stop()
        ls.advance(0.01)
        assert emu.mode == mc.ROVER_HOLD and emu.command == (0.0, 0.0, 0.0)
    finally:
        drv.close()
        ls.close()
    ls, emu, drv = _driving(pool, "ardurover", stop_hold="off")
    try:
        drv.stop()
        _run(ls, drv, 4.0)
        assert emu.mode == mc.ROVER_GUIDED and emu.command == (0.0, 0.0, 0.0)
        assert drv.health().ok
    finally:
        drv.close()
        ls.close()


def test_disarm_on_stop_disarms_and_a_command_rearms(pool):
    ls, emu, drv = _driving(pool, "ardurover", disarm_on_stop=True)
    try:
        drv.stop()
        _until(ls, drv, lambda: not emu.armed and emu.mode == mc.ROVER_HOLD, 1.0)
        assert drv.health().ok
        drv.send(Twist2D(t=ls.t, vx=0.2, ttl=10.0))
        _until(ls, drv, lambda: emu.armed and emu.mode == mc.ROVER_GUIDED, 1.5)
        _until(ls, drv, lambda: emu.command[0] == pytest.approx(0.2), 0.5)
        assert drv.health().ok
    finally:
        drv.close()
        ls.close()


def test_a_failsafe_hold_is_not_overridden_by_the_driver(pool):
    """The vehicle's own HOLD (not asked by us) is reported, never switched back."""
    ls, emu, drv = _driving(pool, "ardurover")
    try:
        emu.mode = mc.ROVER_HOLD  # e.g. its GCS failsafe
        _run(ls, drv, 2.0)
        drv.send(Twist2D(t=ls.t, vx=0.2, ttl=10.0))  # not braking: no resume asked
        _run(ls, drv, 2.0)
        assert emu.mode == mc.ROVER_HOLD
        assert not drv.health().ok and "vehicle in HOLD, expected GUIDED" in drv.health().detail
    finally:
        drv.close()
        ls.close()


def test_a_failsafe_while_braking_is_taken_to_hold_never_back_to_guided(pool):
    modes: list[int] = []

    def listen(m) -> None:
        if m.get_type() == "COMMAND_LONG" and m.command == mc.CMD_DO_SET_MODE:
            modes.append(int(m.param2))

    ls, emu, drv = _rig(pool, "ardurover", {"listener": listen})
    try:
        drv.connect(timeout=3.0)
        drv.send(Twist2D(t=0.0, vx=0.3, ttl=10.0))
        ls.advance(0.2)
        emu.mode = mc.ROVER_RTL  # the vehicle's own failsafe, before the stop
        _run(ls, drv, 1.2)  # its next HEARTBEAT says so
        modes.clear()
        drv.stop()
        _run(ls, drv, 1.0)
        assert emu.mode == mc.ROVER_HOLD and drv.health().ok
        assert mc.ROVER_GUIDED not in modes and mc.ROVER_HOLD in modes
    finally:
        drv.close()
        ls.close()
