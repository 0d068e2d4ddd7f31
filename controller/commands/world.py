"""``fleet world [--config F] [--duration S]``: the shared stand-in world as its own process.

One world (``sim.backend``) with every ``sim`` robot and the object, in real time, for a lab
rehearsal on one machine (``controller.runtime.world``): it publishes ``object/pose`` the way a
motion-capture system would and serves the ``sim`` agents of ``fleet driver`` (with
``sim.world = "process"``). Stops on SIGINT/SIGTERM or after ``--duration`` seconds; exit 0, 2
on bad config, 1 when its session cannot open.
"""

from __future__ import annotations

from controller.commands import add_config_argument, serve_until_signalled


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")


def run(args) -> int:
    from controller.runtime.world import run_world

    return serve_until_signalled(args, run_world)
