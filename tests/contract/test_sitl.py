"""The MAVLink driver against ArduPilot's own Rover firmware (SITL): the ``sitl`` tier.

Three fresh vehicles start at once (module fixture, one instance ``-I N`` each, ``--speedup 1``):
a skid-steer (differential) rover, a 3-wheel mecanum omni rover and the default ackermann car, so
their ~42 s wait for a position estimate is paid once. Each is driven the way ``fleet driver``
drives it: the driver built by ``driver_class(robot).local`` (keepalive thread, wall clock),
``connect(--connect-timeout)``, and the real ``Agent`` (its watchdog, latched e-stop, link checks)
fed through the in-memory bus. What the vehicle does is judged by the firmware's own
LOCAL_POSITION_NED, HEARTBEAT and ATTITUDE on a second link (SERIAL1), never by the driver.

Stop times are from the stop (the e-stop's arrival at the agent; the agent's watchdog stop) to
the first LOCAL_POSITION_NED under 0.05 m/s (``STOPPED``), bounded by ``STOP_BOUND``.
Skipped when ``../shared/sitl/ardurover`` is absent (a user's clone).
"""

from __future__ import annotations

import logging
import math
import signal
import threading
import time

import pytest

from controller.cli import main
from controller.runtime.wiring import driver_class
from drivers.agent import Agent, AgentParams
from tests.support.config import free_port, write_toml
from tests.support.mavlink_rig import make_config
from tests.support.sitl import (
    CMD_TTL,
    ROVER_GUIDED,
    ROVER_HOLD,
    SPEED,
    STOPPED,
    Monitor,
    Records,
    Sitl,
    Vehicle,
    free_instances,
    missing_reason,
    settle,
    stop_time,
    wait_until,
)

REASON = missing_reason()
pytestmark = [pytest.mark.sitl, pytest.mark.skipif(REASON is not None, reason=REASON or "")]

FRAMES = {"skid": "rover-skid", "omni": "rover-omni3mecanum", "car": "rover"}
CONNECT_TIMEOUT = 90.0  # s: a fresh vehicle's estimate takes ~42 s, more on a loaded machine
# s from the stop to STOPPED; measured (stop_hold "at_rest": the GUIDED speed controller brakes)
# skid 0.7, car 1.5-1.75, omni 4.3 (its own tuning: HOLD or zero, the same); HOLD at once: car 3.6
STOP_BOUND = {"skid": 1.2, "omni": 5.5, "car": 2.5}
HOLD_BOUND = 1.5  # s from STOPPED to the HEARTBEAT reporting HOLD
STOP_TIMES: dict[str, float] = {}


@pytest.fixture(scope="module")
def vehicles():
    """The three vehicles started at once and connected in parallel (the estimate waits
    overlap); torn down (SITL killed by pid) whatever happens."""
    logger = logging.getLogger("drivers.mavlink.driver")
    records = Records()
    level = logger.level
    logger.addHandler(records)
    logger.setLevel(logging.DEBUG)
    fleet: dict[str, Vehicle] = {}
    try:
        for (rid, frame), inst in zip(FRAMES.items(), free_instances(len(FRAMES)), strict=True):
            fleet[rid] = Vehicle(rid, Sitl(frame, inst).start())
        data = [
            {"id": v.rid, "kind": "diff", "start": [2.0 + i, 3.0, 0.0], "driver": "mavlink",
             "url": v.sitl.url, "system_id": 1, "profile": "ardurover"}
            for i, v in enumerate(fleet.values())
        ]  # fmt: skip
        cfg = make_config(data)

        def connect(v: Vehicle) -> None:
            t0 = time.monotonic()
            try:
                v.sitl.wait_listening()
                v.driver.connect(timeout=CONNECT_TIMEOUT)
                v.connect_s = time.monotonic() - t0
            except BaseException as exc:  # noqa: BLE001 - reported by the tests
                v.error = exc

        threads = []
        for v in fleet.values():
            v.robot = cfg.robot(v.rid)
            v.driver, _ = driver_class(v.robot).local(cfg, v.robot, time.time(), False)
            threads.append(threading.Thread(target=connect, args=(v,), daemon=True))
        for t in threads:
            t.start()
        for t in threads:
            t.join(CONNECT_TIMEOUT + 30)
        for v in fleet.values():
            if v.error is None and v.sitl.alive():
                v.monitor = Monitor(v.sitl)
                params = AgentParams(v.rid, "t", cmd_ttl=CMD_TTL, max_clock_skew=1.0)
                v.agent = Agent(v.bus, v.driver, params)
        yield fleet, records
    finally:
        for v in fleet.values():
            try:
                if v.driver is not None:
                    v.driver.close()
            finally:
                if v.monitor is not None:
                    v.monitor.close()
                v.sitl.stop()
        logger.removeHandler(records)
        logger.setLevel(level)
        if STOP_TIMES:
            print("\nSITL stop times (s):", {k: round(t, 2) for k, t in STOP_TIMES.items()})


def _vehicle(vehicles, rid: str) -> Vehicle:
    fleet, _ = vehicles
    v = fleet[rid]
    if v.error is not None:
        pytest.fail(f"{rid} did not connect: {v.error}\n{v.sitl.tail()}")
    assert v.agent is not None and v.monitor is not None
    wait_until(lambda: v.monitor.last() is not None, 10, f"{rid}'s position on SERIAL1")
    return v


@pytest.mark.parametrize("rid", list(FRAMES))
def test_connects_after_the_estimate_in_guided_and_armed(vehicles, rid):
    """The default telemetry_hz (50) is refused by the firmware: the driver steps down to a
    rate it grants; it waits for the position estimate (logging the wait), then GUIDED, armed."""
    v = _vehicle(vehicles, rid)
    lines = v.log(vehicles[1].lines)
    assert v.robot.telemetry_hz == 50.0
    assert v.driver.telemetry_hz is not None and 5.0 <= v.driver.telemetry_hz < 50.0
    assert any("too fast" in ln for ln in lines), lines  # the vehicle's reason, logged
    assert any(f"grants telemetry at {v.driver.telemetry_hz:g} Hz" in ln for ln in lines)
    waits = [ln for ln in lines if "waiting for the vehicle's position estimate:" in ln]
    assert waits, lines
    assert v.connect_s > 15.0  # a fresh vehicle: the estimate really was waited for
    wait_until(
        lambda: v.monitor.mode == ROVER_GUIDED and v.monitor.armed, 5, f"{rid} GUIDED and armed"
    )
    assert v.driver.health().ok
    print(f"{rid}: connected in {v.connect_s:.1f} s at {v.driver.telemetry_hz:g} Hz")


@pytest.mark.parametrize("rid", list(FRAMES))
def test_commands_move_the_rover_as_commanded(vehicles, rid):
    """vx = 0.4 m/s: the firmware reports 0.4 m/s along the rover's heading; then vx with a CCW
    turn rate: its yaw (NED, clockwise) decreases."""
    v = _vehicle(vehicles, rid)
    v.steady(SPEED)
    v.drive(SPEED, 0.0, 1.0)
    recent = v.monitor.since(time.monotonic() - 1.0)
    speed = sum(s.speed for s in recent) / len(recent)
    course = math.atan2(recent[-1].vy, recent[-1].vx)
    off = math.degrees(abs(math.remainder(course - v.monitor.yaw, math.tau)))
    assert speed == pytest.approx(SPEED, abs=0.05)
    assert off < 10.0, f"moving {off:.1f} deg off its heading"
    yaw0 = v.monitor.yaw
    v.drive(0.3, 0.3, 3.0)  # FLU: CCW
    turned = math.remainder(v.monitor.yaw - yaw0, math.tau)
    assert turned < -0.15, f"yaw changed by {turned:.2f} rad for a CCW turn"
    print(f"{rid}: {speed:.3f} m/s, {off:.1f} deg off heading, turned {turned:.2f} rad in 3 s")
    settle(v)


@pytest.mark.parametrize("rid", list(FRAMES))
def test_estop_zeroes_the_setpoint_and_holds_until_released(vehicles, rid):
    v = _vehicle(vehicles, rid)
    v.steady(SPEED)
    t_stop = time.monotonic()
    v.estop(True)
    assert v.agent.core.estop
    assert v.monitor.mode == ROVER_GUIDED  # braking by the speed controller first
    stop_s = stop_time(v, t_stop)
    STOP_TIMES[f"{rid} estop"] = stop_s
    held = wait_until(lambda: v.monitor.mode == ROVER_HOLD, HOLD_BOUND, f"{rid} in HOLD",
                      step=v.step)  # fmt: skip
    STOP_TIMES[f"{rid} estop HOLD"] = held - t_stop
    # commands while e-stopped are refused: the rover stays put
    rejected = v.agent.counters.estop_rejected
    v.drive(SPEED, 0.0, 1.0)
    assert v.agent.counters.estop_rejected > rejected
    assert v.speed() < STOPPED and v.monitor.mode == ROVER_HOLD
    assert v.driver.health().ok and v.agent.link_ok  # HOLD is what it was asked for
    v.estop(False)
    wait_until(lambda: v.speed() > 0.3, 8, f"{rid} moving after the release",
               step=lambda: v.command(SPEED))  # fmt: skip
    assert v.monitor.mode == ROVER_GUIDED and v.monitor.armed
    print(f"{rid}: e-stop to under {STOPPED} m/s in {stop_s:.2f} s, HOLD at {held - t_stop:.2f} s")
    assert stop_s < STOP_BOUND[rid]
    settle(v)


@pytest.mark.parametrize("rid", list(FRAMES))
def test_watchdog_stop_zeroes_the_setpoint_and_holds(vehicles, rid):
    v = _vehicle(vehicles, rid)
    v.steady(SPEED)
    stops = v.agent.counters.watchdog_stops
    t_last = time.monotonic()  # the last command
    t_wd = wait_until(lambda: v.agent.counters.watchdog_stops > stops, 2, "the watchdog",
                      step=v.step, every=0.01)  # fmt: skip
    assert t_wd - t_last >= CMD_TTL - 0.05
    stop_s = stop_time(v, t_wd)
    STOP_TIMES[f"{rid} watchdog"] = stop_s
    held = wait_until(lambda: v.monitor.mode == ROVER_HOLD, HOLD_BOUND, f"{rid} in HOLD",
                      step=v.step)  # fmt: skip
    wait_until(lambda: v.speed() > 0.3, 8, f"{rid} moving after new commands",
               step=lambda: v.command(SPEED))  # fmt: skip
    assert v.monitor.mode == ROVER_GUIDED
    print(f"{rid}: watchdog stop to under {STOPPED} m/s in {stop_s:.2f} s, HOLD at "
          f"{held - t_wd:.2f} s")  # fmt: skip
    assert stop_s < STOP_BOUND[rid]
    settle(v)


def test_fleet_driver_strict_refuses_the_stock_firmware_naming_its_failsafe(
    vehicles, tmp_path, capsys
):
    """`fleet driver --strict` on the skid's SERIAL2 (the CLI path, same firmware): the stock
    parameters have no GCS failsafe (FS_GCS_ENABLE = 0) and a fixed 3 s GUIDED timeout, so a
    rover whose driver dies drives on: refused (exit 1) naming them."""
    v = _vehicle(vehicles, "skid")
    data = {
        "fleet": {"name": "t"},
        "zenoh": {"listen": [f"tcp/127.0.0.1:{free_port()}"]},
        "object": {"polygon": [[0, 0], [0.5, 0], [0.5, 0.5], [0, 0.5]], "start": [8.0, 8.0, 0.0],
                   "motion": {"kind": "static"}},
        "sim": {"backend": "ideal", "timestep": 0.01},
        "robots": [{"id": "skid", "kind": "diff", "start": [2.0, 3.0, 0.0], "driver": "mavlink",
                    "url": f"tcp:127.0.0.1:{v.sitl.port + 3}", "system_id": 1,
                    "profile": "ardurover"}],
    }  # fmt: skip
    path = write_toml(tmp_path / "sitl.toml", data)
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        code = main(["driver", "skid", "--config", str(path), "--strict",
                     "--connect-timeout", "10"])  # fmt: skip
    finally:
        for sig, h in handlers.items():
            signal.signal(sig, h)
    err = capsys.readouterr().err
    assert code == 1, err
    assert "FS_GCS_ENABLE = 0" in err and "refused: --strict" in err


def test_a_vehicle_gone_is_reported_as_link_lost(vehicles):
    """The car's firmware killed (SIGKILL: no goodbye): the agent reports link_lost within the
    link timeout (and a margin) and stops commanding it."""
    v = _vehicle(vehicles, "car")
    v.drive(0.2, 0.0, 0.5)
    assert v.agent.link_ok
    t_kill = time.monotonic()
    v.sitl.kill()
    at = wait_until(lambda: not v.agent.link_ok, v.driver.link_timeout + 2.0, "link_lost",
                    step=v.step)  # fmt: skip
    events = v.bus.sent[v.bus.key("robot_event", id=v.rid)]
    lost = [e for e in events if e.kind == "link_lost"]
    assert lost and "link lost" in lost[-1].data["detail"]
    assert v.agent.counters.link_lost == 1
    print(f"car: link_lost {at - t_kill:.2f} s after the kill: {lost[-1].data['detail']}")
