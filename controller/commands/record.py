"""``fleet record [--config F] [--out F.mcap] [--duration S]``: record the fleet's bus to MCAP.

Attaches to a running fleet (connects to the config's zenoh endpoints), writes every sample
under ``fleet/<name>/**`` until SIGINT/SIGTERM (or ``--duration``), then finishes the file.
The config goes in as metadata (``fleet replay`` needs the robots' sizes and the room), and the
Foxglove scene channels beside the bus's.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from controller.commands import add_config_argument, stop_on_signals

EXAMPLES = """examples:
  fleet record                                       the fleet of ./fleet.toml, until Ctrl-C
  fleet record --config fleet.toml --out runs/rehearsal.mcap --duration 60
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--out", help="MCAP file (default: <log.dir>/<fleet>-<time>.mcap)")
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")
    parser.add_argument(
        "--connect", action="append", help="zenoh endpoint to connect to (default: config listen)"
    )


def run(args) -> int:
    from controller import wire
    from controller.config import load_config
    from controller.io.bus import Bus
    from controller.io.recorder import default_log_path
    from controller.runtime.recording import open_recorder, record_ros2

    cfg = load_config(args.config)
    out = Path(args.out) if args.out else default_log_path(cfg.log.dir, cfg.fleet.name, "record")
    stop = stop_on_signals()
    connect = args.connect or list(cfg.zenoh.listen)
    # the config goes in too: replay needs the robots' sizes and the room (clearance, verdict)
    recorder = open_recorder(cfg, out, "record", who="fleet record")
    try:
        with Bus(cfg.zenoh, cfg.fleet.name, mode="peer", listen=[], connect=connect) as bus:
            bus.subscribe_raw(wire.fleet_prefix(cfg.fleet.name), recorder.on_sample, limit=True)
            record_ros2(bus, cfg, recorder)  # ROS 2 robots' own topics too
            print(
                f"fleet record: recording fleet {cfg.fleet.name!r} to {recorder.location}",
                file=sys.stderr,
            )
            deadline = time.monotonic() + args.duration if args.duration > 0 else None
            while not stop.is_set():
                if deadline is not None and time.monotonic() >= deadline:
                    break
                stop.wait(0.1)
    finally:
        recorder.close()
    print(f"fleet record: {recorder.written} messages in {recorder.location}", file=sys.stderr)
    return 0
