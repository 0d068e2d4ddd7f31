"""ArduRover's own failsafe read on connect, like PX4's ``COM_OF_LOSS_T``: ``FS_GCS_ENABLE``,
``FS_TIMEOUT``, ``FS_ACTION`` and, where the firmware has them, ``FS_GCS_TIMEOUT`` and
``GUID_TIMEOUT`` (drivers/mavlink/failsafe.py). Unsafe is a warning, refused under ``--strict``
(``fleet driver --strict``). The emulated ArduRover answers them as it behaves.

Lockstep on a fake clock (tests/support/mavlink_rig.py), except the real-time keepalive test.
"""

from __future__ import annotations

import logging
import threading

import pytest

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

pytestmark = pytest.mark.e2e

LOGGER = "drivers.mavlink.driver"
SAFE = {"target_timeout": 0.5}  # GUID_TIMEOUT 0.5 s: under the 1 s max_vehicle_timeout


@pytest.fixture
def pool():
    return LinkPool()


def _rig(profile: str = "ardurover", **emu_kw):
    cfg = make_config([robot("r", profile, free_udp_port(), 1)])
    ls = Lockstep(cfg)
    return cfg, ls, ls.emulator(cfg.robots[0], **emu_kw)


def test_safe_ardurover_connects_quietly_and_reports_its_failsafe(pool, caplog):
    cfg, ls, emu = _rig(**SAFE)
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool, strict=True)
    try:
        with caplog.at_level(logging.WARNING, logger=LOGGER):
            drv.connect(timeout=2.0)
        assert caplog.text == ""
        assert drv.vehicle_timeout == pytest.approx(0.5)
        assert drv.vehicle_params == {
            "FS_GCS_ENABLE": 1.0, "FS_TIMEOUT": 5.0, "FS_ACTION": 2.0, "GUID_TIMEOUT": 0.5,
        }  # fmt: skip
        assert emu.counters["param_reads"] >= 5  # FS_GCS_TIMEOUT asked too: not in this one
        assert emu.mode == mc.ROVER_GUIDED and emu.armed
    finally:
        drv.close()
        ls.close()


def test_default_ardurover_guided_timeout_warns(pool, caplog):
    """The emulator's defaults are ArduRover's: GUID_TIMEOUT 3 s, over the 1 s limit: a
    warning, the rover connected all the same (without --strict)."""
    cfg, ls, emu = _rig()
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    try:
        with caplog.at_level(logging.WARNING, logger=LOGGER):
            drv.connect(timeout=2.0)
        assert "keeps its last target for 3 s" in caplog.text
        assert "max_vehicle_timeout = 1 s" in caplog.text
        assert drv.vehicle_timeout == pytest.approx(3.0) and drv.health().ok
    finally:
        drv.close()
        ls.close()


UNSAFE = {
    "no GCS failsafe": ({"fs_gcs_enable": False}, r"FS_GCS_ENABLE = 0"),
    "failsafe drives home": ({"fs_action": 1}, r"FS_ACTION = 1 \(RTL\)"),
    "FS_TIMEOUT unanswered": ({"unanswered": {"FS_TIMEOUT"}}, r"did not answer.*FS_TIMEOUT"),
    # firmware without GUID_TIMEOUT: the fixed 3 s GUIDED timeout is over the limit
    "old firmware": ({"unanswered": {"GUID_TIMEOUT"}, "target_timeout": 3.0}, r"3 s.*GUID"),
}


@pytest.mark.parametrize("case", list(UNSAFE))
def test_unsafe_ardurover_warns_and_is_refused_when_strict(pool, caplog, case):
    kw, pattern = UNSAFE[case]
    cfg, ls, emu = _rig(**{**SAFE, **kw})
    strict = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool, strict=True)
    try:
        with pytest.raises(DriverError, match=pattern + r".*--strict"):
            strict.connect(timeout=2.0)
        assert emu.mode != mc.ROVER_GUIDED and not emu.armed  # refused before GUIDED
    finally:
        strict.close()
    lax = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    try:
        with caplog.at_level(logging.WARNING, logger=LOGGER):
            lax.connect(timeout=2.0)
        assert lax.health().ok
        assert caplog.records and all(r.levelno == logging.WARNING for r in caplog.records)
    finally:
        lax.close()
        ls.close()


@pytest.mark.parametrize(
    ("kw", "mode"),
    [({}, mc.ROVER_HOLD), ({"fs_action": 1}, mc.ROVER_RTL), ({"fs_gcs_enable": False}, None)],
)
def test_the_emulated_gcs_failsafe_follows_its_parameters(pool, kw, mode):
    """Its driver gone silent (no heartbeat, no setpoint), the emulated rover takes its
    FS_ACTION after FS_TIMEOUT s, or stays in GUIDED with FS_GCS_ENABLE = 0."""
    cfg, ls, emu = _rig(gcs_timeout=1.0, **kw)
    drv = MavlinkDriver(cfg.robots[0], clock=ls.clock, idle=ls.advance, pool=pool)
    try:
        drv.connect(timeout=2.0)
        assert emu.mode == mc.ROVER_GUIDED
        ls.advance(1.5)  # nobody calls the driver: its heartbeats stop
        assert emu.mode == (mode if mode is not None else mc.ROVER_GUIDED)
        assert emu.params()["FS_ACTION"] == kw.get("fs_action", 2)
    finally:
        drv.close()
        ls.close()


def test_fleet_driver_strict_refuses_an_ardurover_without_gcs_failsafe(tmp_path, capsys):
    """`fleet driver R --strict` against an ArduRover with FS_GCS_ENABLE = 0: exit 1 naming the
    parameter, the rover never put in GUIDED."""
    from sim_backend.ideal import IdealWorld
    from sim_backend.mavlink_vehicle import VehicleEmulator

    path, cfg = emulated_vehicle_config(tmp_path, "ardurover")
    emu = VehicleEmulator(IdealWorld(cfg), cfg.robots[0], fs_gcs_enable=False, target_timeout=0.5)
    code = strict_driver_exit(path, emu.start())
    err = capsys.readouterr().err
    assert code == 1
    assert "FS_GCS_ENABLE = 0" in err and "--strict" in err
    assert emu.mode != mc.ROVER_GUIDED and not emu.armed


@pytest.mark.parametrize(("thread", "mode"), [(True, mc.PX4_OFFBOARD), (False, mc.PX4_HOLD)])
def test_keepalive_thread_holds_offboard_while_the_caller_is_busy(tmp_path, thread, mode):
    """Real time: a PX4 (COM_OF_LOSS_T 1 s) connected, then its caller busy for 1.5 s (as an
    agent querying the e-stop latch): the driver's keepalive thread keeps the setpoints going
    and the vehicle in OFFBOARD; without it the vehicle falls to HOLD."""
    from sim_backend.ideal import IdealWorld
    from sim_backend.mavlink_vehicle import VehicleEmulator

    _, cfg = emulated_vehicle_config(tmp_path, "px4")
    emu = VehicleEmulator(IdealWorld(cfg), cfg.robots[0], offboard_loss_timeout=1.0).start()
    drv = MavlinkDriver(cfg.robots[0], pool=LinkPool(), keepalive_thread=thread)
    try:
        drv.connect(timeout=3.0)
        assert emu.mode == mc.PX4_OFFBOARD
        threading.Event().wait(1.5)  # the caller busy elsewhere: what is under test
        assert emu.mode == mode
    finally:
        drv.close()
        emu.stop()
