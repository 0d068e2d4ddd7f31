"""Stop times on ArduPilot's own Rover firmware (SITL); prints one JSON object.

One fresh vehicle, ``rover-skid`` or ``--frame`` (``../shared/sitl/ardurover``, ``--speedup 1``,
on 127.0.0.1, killed at the end), driven the way ``fleet driver`` drives it: the MAVLink driver and
the real ``Agent`` (in-memory bus). For each stop, the rover is first held at 0.4 m/s until the
firmware reports it for 0.5 s, then stopped by

- ``estop``: an engaged e-stop arriving at the agent (timed from its arrival);
- ``watchdog``: no more commands; the agent's watchdog (``cmd_ttl`` 0.5 s) stops it (timed from
  the watchdog's stop);

with each of the driver's ``stop_hold`` settings: ``now`` (zero setpoint and HOLD at once),
``off`` (zero setpoint only: the GUIDED speed controller brakes), ``at_rest`` (the default: zero
setpoint, HOLD once the vehicle reports it stopped). A stop time is from the stop to the first
LOCAL_POSITION_NED under 0.05 m/s that the firmware sends on its second link (SERIAL1, 25 Hz).
Median, min and max of ``--tries`` each.

Usage: python bench/sitl.py [--tries N] [--frame rover-skid|rover-omni3mecanum|rover]
(about 45 s of boot + ~6 s per try; 3 tries: about 2.5 min)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controller.runtime.wiring import driver_class  # noqa: E402
from drivers.agent import Agent, AgentParams  # noqa: E402
from tests.support.mavlink_rig import make_config  # noqa: E402
from tests.support.sitl import (  # noqa: E402
    CMD_TTL,
    SPEED,
    STOPPED,
    Monitor,
    Sitl,
    Vehicle,
    free_instances,
    missing_reason,
    settle,
    stop_time,
    wait_until,
)


def _set_hold(v: Vehicle, how: str) -> None:
    """Switch the driver's ``stop_hold`` between tries (it reads its config live)."""
    r = v.driver.cfg
    v.driver.cfg = dataclasses.replace(r, mavlink=dataclasses.replace(r.mavlink, stop_hold=how))


def _one(v: Vehicle, how: str) -> float:
    v.steady(SPEED)
    if how == "estop":
        t_stop = time.monotonic()
        v.estop(True)
    else:
        stops = v.agent.counters.watchdog_stops
        t_stop = wait_until(lambda: v.agent.counters.watchdog_stops > stops, 2, "the watchdog",
                            step=v.step, every=0.01)  # fmt: skip
    s = stop_time(v, t_stop)
    settle(v)
    if how == "estop":
        v.estop(False)
    return s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tries", type=int, default=3)
    ap.add_argument(
        "--frame", default="rover-skid", choices=("rover-skid", "rover-omni3mecanum", "rover")
    )
    args = ap.parse_args(argv)
    reason = missing_reason()
    if reason:
        print(json.dumps({"skipped": reason}))
        return 2
    sitl = Sitl(args.frame, free_instances(1)[0]).start()
    v = Vehicle("skid", sitl)
    out: dict = {"frame": args.frame, "speed_mps": SPEED, "stopped_below_mps": STOPPED,
                 "cmd_ttl_s": CMD_TTL, "tries": args.tries}  # fmt: skip
    try:
        cfg = make_config(
            [
                {
                    "id": "skid",
                    "kind": "diff",
                    "start": [2.0, 3.0, 0.0],
                    "driver": "mavlink",
                    "url": sitl.url,
                    "system_id": 1,
                    "profile": "ardurover",
                }
            ]  # fmt: skip
        )
        v.robot = cfg.robot("skid")
        v.driver, _ = driver_class(v.robot).local(cfg, v.robot, time.time(), False)
        sitl.wait_listening()
        t0 = time.monotonic()
        v.driver.connect(timeout=90.0)
        out["connect_s"] = round(time.monotonic() - t0, 1)
        out["telemetry_hz"] = v.driver.telemetry_hz
        v.monitor = Monitor(sitl)
        v.agent = Agent(v.bus, v.driver, AgentParams("skid", "t", cmd_ttl=CMD_TTL))
        wait_until(lambda: v.monitor.last() is not None, 10, "the monitor's first position")
        for hold, name in (("now", "zero_and_hold"), ("off", "zero_only"),
                           ("at_rest", "zero_then_hold_at_rest")):  # fmt: skip
            _set_hold(v, hold)
            for how in ("estop", "watchdog"):
                times = [_one(v, how) for _ in range(args.tries)]
                key = f"{how}_{name}_s"
                out[key] = {
                    "median": round(statistics.median(times), 3),
                    "min": round(min(times), 3),
                    "max": round(max(times), 3),
                    "all": [round(t, 3) for t in times],
                }
    finally:
        try:
            if v.driver is not None:
                v.driver.close()
        finally:
            if v.monitor is not None:
                v.monitor.close()
            sitl.stop()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
