"""``fleet hub [--config F] [--duration S]``: the fleet's meeting point and e-stop keeper.

A zenoh router on the config's ``zenoh.listen`` endpoints that agents, the daemon and the tools
connect to, holding the latched e-stop (``controller.runtime.hub``). Start it before the daemon
(which then joins it instead of listening). Stops on SIGINT/SIGTERM; exit 1 when the endpoints
are taken.
"""

from __future__ import annotations

import signal
import threading

from controller.commands import add_config_argument


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")


def run(args) -> int:
    from controller.config import load_config
    from controller.runtime.hub import run_hub

    cfg = load_config(args.config)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return run_hub(cfg, stop, args.duration)  # BusError: exit 1 (cli.exit_code)
