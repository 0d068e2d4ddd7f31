"""``fleet daemon``: the controller on the lab network, ticking on the wall clock.

Listens on the config's zenoh endpoints (robot agents and tools connect to it), ticks at
``fleet.rate_hz`` with a drift-free rate keeper, runs the mission, serves ``fleet status`` and
obeys ``fleet estop``/``resume``, and records the bus to MCAP. Returns when ``stop`` is set,
after ``duration`` seconds, or when the mission ends (robots then stop by their own watchdogs
after one last zero command for everyone).
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from pathlib import Path

from controller import wire
from controller.config import FleetConfig
from controller.io.bus import Bus
from controller.io.ratekeeper import Ratekeeper
from controller.mission.types import Mission
from controller.runtime.node import ControllerNode
from controller.runtime.recording import open_recorder
from controller.runtime.wiring import make_estimator

log = logging.getLogger(__name__)


def run_daemon(
    cfg: FleetConfig,
    mission: Mission,
    mission_kind: str,
    out: Path,
    stop: threading.Event,
    duration: float = 0.0,
    viz: bool = False,
) -> int:
    """The lab loop. Exit status: 0 stopped or done, 1 the mission failed. ``viz``: serve the
    recorded messages live to Foxglove on 127.0.0.1."""
    recorder = open_recorder(cfg, out, f"daemon/{mission_kind}", viz=viz, who="fleet daemon")
    status = 0
    try:
        with Bus(cfg.zenoh, cfg.fleet.name) as bus:
            bus.subscribe_raw(wire.fleet_prefix(cfg.fleet.name), recorder.on_sample)
            node = ControllerNode(
                cfg,
                bus,
                mission,
                make_estimator(cfg),
                extra_drops=recorder.drops,
                clock=time.monotonic,
            )
            rk = Ratekeeper(cfg.fleet.rate_hz)
            print(
                f"fleet daemon: fleet {cfg.fleet.name!r} on {list(cfg.zenoh.listen)}, "
                f"{cfg.fleet.rate_hz} Hz, log {recorder.location}",
                file=sys.stderr,
            )
            t0 = time.time()
            lag_reported = 0
            while not stop.is_set():
                rk.keep_time()
                now = time.time()  # wall clock: pose stamps come from other computers
                result = node.tick(now)
                if rk.lagged > lag_reported:
                    lag_reported = rk.lagged
                    log.warning(
                        "control loop lag %.1f ms (%d late ticks)", rk.last_lag * 1e3, rk.lagged
                    )
                if result.done or result.failed:
                    status = 1 if result.failed else 0
                    log.info(
                        "mission %s in phase %s",
                        "failed" if result.failed else "done",
                        result.phase,
                    )
                    break
                if duration and now - t0 >= duration:
                    break
            node.hold(time.time())
    finally:
        recorder.close()
    print(
        f"fleet daemon: stopped; {recorder.written} messages in {recorder.location}",
        file=sys.stderr,
    )
    return status
