"""MAVLink stop must stop: stop() and close() read the link before deciding it is lost and
always send the zero; the link timeout follows the heartbeats the vehicle really sends; the
autopilot's own offboard timeout is read on connect (PX4 ``COM_OF_LOSS_T``).

Lockstep on a fake clock (tests/support/mavlink_rig.py): "the caller idle" is the world and the
vehicle advancing while nobody calls the driver.
"""

from __future__ import annotations

import logging

import pytest

from controller.wire import Twist2D
from drivers.base import DriverError
from drivers.mavlink import convert as mc
from drivers.mavlink.driver import MavlinkDriver
from drivers.mavlink.link import LinkPool
from tests.support.mavlink_rig import (
    Lockstep,
    emulated_vehicle_config,
    free_udp_port,
    make_config,
    robot,
    strict_driver_exit,
)


@pytest.fixture
def pool():
    return LinkPool()


def _connected(pool, profile: str, emu_kw: dict | None = None, **robot_kw):
    port = free_udp_port()
    cfg = make_config([robot("r", profile, port, 1, **robot_kw)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0], **(emu_kw or {}))
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    drv.connect(timeout=2.0)
    return ls, emu, drv


@pytest.mark.parametrize("profile", ["ardurover", "px4"])
@pytest.mark.parametrize("how", ["stop", "close"])
def test_stop_after_idle_reaches_the_vehicle(pool, profile, how):
    """vx = 0.3, the caller idle for longer than link_timeout while the vehicle stays alive,
    then stop()/close(): the vehicle's last setpoint is zero and it stands still."""
    ls, emu, drv = _connected(pool, profile, link_timeout=1.0)
    try:
        drv.send(Twist2D(t=0.0, vx=0.3, ttl=10.0))
        ls.advance(0.2)
        assert emu.command[0] == pytest.approx(0.3)
        ls.advance(1.1)  # nobody calls the driver; the vehicle keeps heart-beating
        n = emu.counters["setpoints"]
        t_stop = ls.t
        getattr(drv, how)()
        ls.advance(0.01)  # one lockstep step: the vehicle reads what was sent
        assert emu.counters["setpoints"] > n, f"{how}() sent nothing to a live vehicle"
        last = emu.setpoints[-1]
        assert (last.vx, last.vy, last.yaw_rate) == (0.0, 0.0, 0.0)
        assert last.t - t_stop <= 0.01 + 1e-9
        assert emu.command == (0.0, 0.0, 0.0)
        if how == "close":
            hold = mc.ROVER_HOLD if profile == "ardurover" else mc.PX4_HOLD
            assert emu.mode == hold  # hold_on_close (default true)
    finally:
        drv.close()
        ls.close()


def test_stop_sends_zero_even_when_the_link_looks_lost(pool):
    """A vehicle that went quiet may still hear us: the zero goes out anyway."""
    ls, emu, drv = _connected(pool, "ardurover", link_timeout=0.5)
    try:
        drv.send(Twist2D(t=0.0, vx=0.2, ttl=10.0))
        ls.advance(0.1)
        emu.set_silent(True)
        ls.advance(1.0)
        assert not drv.health().ok
        emu.set_silent(False)  # it hears again, but has said nothing yet
        drv.stop()
        ls.advance(0.01)
        assert emu.setpoints[-1].vx == 0.0 and emu.command == (0.0, 0.0, 0.0)
    finally:
        drv.close()
        ls.close()


def test_close_without_hold_leaves_the_mode(pool):
    ls, emu, drv = _connected(pool, "ardurover", hold_on_close=False)
    try:
        drv.send(Twist2D(t=0.0, vx=0.3, ttl=10.0))
        ls.advance(0.1)
        drv.close()
        ls.advance(0.01)
        assert emu.mode == mc.ROVER_GUIDED and emu.command == (0.0, 0.0, 0.0)
    finally:
        ls.close()


def test_link_timeout_adapts_to_a_vehicle_that_refuses_faster_heartbeats(pool, caplog):
    """Heartbeats stay at 1 Hz when the vehicle refuses a faster rate: a 1 s link_timeout
    would flap; the driver widens it to 2.5 heartbeat periods (and says so)."""
    with caplog.at_level(logging.WARNING, logger="drivers.mavlink.driver"):
        ls, emu, drv = _connected(
            pool, "ardurover", {"heartbeat_rate_fixed": True}, link_timeout=1.0
        )
    try:
        assert emu.intervals[mc.MSG_HEARTBEAT] == 1.0
        assert drv.link_timeout == pytest.approx(2.5)
        assert "link_timeout" in caplog.text
        for _ in range(100):  # 5 s of a live, 1 Hz link polled at 20 Hz: never lost
            ls.advance(0.05)
            assert drv.health().ok, drv.health().detail
        emu.set_silent(True)
        waited = 0.0
        while drv.health().ok:
            ls.advance(0.05)
            waited += 0.05
            assert waited < 2.5 + 0.15
        assert waited > 2.5 - 1.0 - 0.1  # lost 2.5 s after the last heartbeat
    finally:
        drv.close()
        ls.close()


def test_default_link_timeout_is_at_least_2_5_heartbeats():
    cfg = make_config([robot("r", "ardurover", free_udp_port(), 1)])
    assert cfg.robots[0].link_timeout >= 2.5  # vehicles send 1 Hz heartbeats by default


def test_px4_offboard_loss_timeout_read_on_connect(pool, caplog):
    with caplog.at_level(logging.WARNING, logger="drivers.mavlink.driver"):
        ls, emu, drv = _connected(pool, "px4", {"offboard_loss_timeout": 0.5})
    try:
        assert drv.vehicle_timeout == pytest.approx(0.5)
        assert emu.counters["param_reads"] >= 1
        assert "COM_OF_LOSS_T" not in caplog.text
    finally:
        drv.close()
        ls.close()


def test_px4_offboard_loss_timeout_too_long_warns(pool, caplog):
    with caplog.at_level(logging.WARNING, logger="drivers.mavlink.driver"):
        ls, emu, drv = _connected(pool, "px4", {"offboard_loss_timeout": 5.0})
    try:
        assert drv.vehicle_timeout == pytest.approx(5.0)
        assert drv.health().ok
        assert "COM_OF_LOSS_T" in caplog.text and "5" in caplog.text
    finally:
        drv.close()
        ls.close()


def test_px4_offboard_loss_timeout_too_long_refused_when_strict(pool):
    port = free_udp_port()
    cfg = make_config([robot("r", "px4", port, 1)])
    ls = Lockstep(cfg)
    emu = ls.emulator(cfg.robots[0], offboard_loss_timeout=5.0)
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool, strict=True)
    try:
        with pytest.raises(DriverError, match=r"COM_OF_LOSS_T = 5.*max_vehicle_timeout"):
            drv.connect(timeout=2.0)
        assert emu.mode != mc.PX4_OFFBOARD and not emu.armed  # refused before OFFBOARD
    finally:
        drv.close()
        ls.close()


def test_fleet_driver_strict_refuses_a_long_offboard_timeout(tmp_path, capsys):
    """`fleet driver R --strict` against a PX4 whose COM_OF_LOSS_T is 5 s: exit 1 naming the
    parameter; without --strict the same check is a warning (tested above)."""
    from sim_backend.ideal import IdealWorld
    from sim_backend.mavlink_vehicle import VehicleEmulator

    path, cfg = emulated_vehicle_config(tmp_path, "px4")
    emu = VehicleEmulator(IdealWorld(cfg), cfg.robots[0], offboard_loss_timeout=5.0)
    code = strict_driver_exit(path, emu.start())
    err = capsys.readouterr().err
    assert code == 1
    assert "COM_OF_LOSS_T = 5 s" in err and "--strict" in err
    assert emu.mode != mc.PX4_OFFBOARD
