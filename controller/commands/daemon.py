"""``fleet daemon [--config F] [--out F.mcap] [--duration S]``: the controller on the lab network.

Listens on the config's zenoh endpoints (robot agents and tools connect to it), ticks on the
wall clock at ``fleet.rate_hz`` with a drift-free rate keeper, runs the mission, serves
``fleet status`` and obeys ``fleet estop``/``resume``, and records the bus to MCAP. Stops on
SIGINT/SIGTERM (robots then stop by their own watchdogs) or when the mission ends.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
import time
from pathlib import Path

from controller.commands import add_config_argument

log = logging.getLogger(__name__)


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--out", help="MCAP log (default: <log.dir>/<fleet>-daemon-<time>.mcap)")
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")
    parser.add_argument(
        "--mission",
        choices=("capture", "hold"),
        default="capture",
        help="capture: the whole job; hold: keep every robot stopped (bring-up checks)",
    )


def run(args) -> int:
    from controller import wire
    from controller.commands.record import default_log_path
    from controller.config import load_config
    from controller.io.bus import Bus
    from controller.io.ratekeeper import Ratekeeper
    from controller.io.recorder import McapRecorder, config_metadata
    from controller.mission.factory import MissionError, build_mission
    from controller.runtime.node import ControllerNode
    from controller.runtime.wiring import make_estimator

    cfg = load_config(args.config)
    out = Path(args.out) if args.out else default_log_path(cfg.log.dir, cfg.fleet.name, "daemon")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        mission = build_mission(cfg, args.mission)
    except MissionError as exc:
        print(f"fleet daemon: {exc}", file=sys.stderr)
        return 1
    recorder = McapRecorder(out, cfg.fleet.name, cfg.log.flush_interval)
    recorder.metadata("fleet.config", config_metadata(cfg, f"daemon/{args.mission}"))
    status = 0
    try:
        with Bus(cfg.zenoh, cfg.fleet.name) as bus:
            bus.subscribe_raw(wire.fleet_prefix(cfg.fleet.name), recorder.on_sample)
            node = ControllerNode(cfg, bus, mission, make_estimator(cfg))
            rk = Ratekeeper(cfg.fleet.rate_hz)
            print(
                f"fleet daemon: fleet {cfg.fleet.name!r} on {list(cfg.zenoh.listen)}, "
                f"{cfg.fleet.rate_hz} Hz, log {out}",
                file=sys.stderr,
            )
            t0 = time.time()
            lag_reported = 0
            while not stop.is_set():
                rk.keep_time()
                now = time.time()  # wall clock: pose stamps come from other computers
                out_ = node.tick(now)
                if rk.lagged > lag_reported:
                    lag_reported = rk.lagged
                    log.warning(
                        "control loop lag %.1f ms (%d late ticks)", rk.last_lag * 1e3, rk.lagged
                    )
                if out_.done or out_.failed:
                    status = 1 if out_.failed else 0
                    log.info(
                        "mission %s in phase %s", "failed" if out_.failed else "done", out_.phase
                    )
                    break
                if args.duration and now - t0 >= args.duration:
                    break
            # leave the robots stopped: one last zero command for everyone
            node.hold(time.time())
    finally:
        recorder.close()
    print(f"fleet daemon: stopped; {recorder.written} messages in {out}", file=sys.stderr)
    return status
