"""``fleet up [--config F] [--mission M] [--mavlink [IDS]] [--ros2 [IDS]] [--detach]``: the
whole lab from one config, in one command.

Brings up the hub, the stand-in world when rehearsing (any ``sim`` robot, or MAVLink/ROS 2
robots emulated with ``--mavlink``/``--ros2``; none when every robot is real), one agent per
robot and the controller, in that order, each once the one before is seen ready on the bus, each
with its own log file in the run's folder (``<log.dir>/<fleet>-lab-<time>/``, beside the
daemon's MCAP). A crashed agent or hub is restarted with back-off; a restart never lifts an
e-stop. A fresh lab is stopped until an operator's resume (``fleet resume``, or r in the
console); in a rehearsal the object holds its start until then (``sim.object_start``). The
console shows every robot, the job's phase and what to do next; keys r resume, e e-stop, q stop.
The lab ends with the job (a verdict line, the figures, the next step), or on Ctrl-C: the e-stop
first (every robot stopped), then every process, the MCAP whole. ``--detach`` returns once the
lab is up; ``fleet down`` stops it (``--wait``: after the job's end). Exit 0 when the job did
what the config asks, 1 when it failed or was stopped, 2 on a bad config.
"""

from __future__ import annotations

import argparse

from controller.commands import (
    add_config_argument,
    add_emulation_arguments,
)
from controller.config import MISSION_KINDS
from controller.runtime.lab_launch import GROUP, ISOLATE_UP_TO

EXAMPLES = """examples:
  fleet init rehearsal --out lab.toml          # a rehearsal config: six sim robots, one world
  fleet up --config lab.toml                    # bring the lab up; r resumes, Ctrl-C stops
  fleet up --config lab.toml --detach           # in the background; then:
  fleet resume --config lab.toml                #   the operator's go: the job starts
  fleet down --config lab.toml --wait           #   the job's verdict, then everything stops
  fleet up --config mixed.toml --mavlink r3 --ros2 r5   # emulate r3 (MAVLink) and r5 (ROS 2)
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument(
        "--mission",
        choices=MISSION_KINDS,
        default="capture",
        help="the daemon's mission (capture: the whole job; hold: every robot still)",
    )
    add_emulation_arguments(parser)
    parser.add_argument(
        "--remote",
        default="",
        metavar="IDS",
        help="robots whose agents run on their own computers (fleet driver ID there): not "
        "started here, waited for on the bus all the same (comma-separated ids)",
    )
    parser.add_argument(
        "--agents-per-process",
        type=int,
        default=None,
        metavar="N",
        help="robot agents run N to a process, a thread each (default: a process per robot up "
        f"to {ISOLATE_UP_TO} robots, beyond that {GROUP} to a process; bench/lab.py measures "
        "both)",
    )
    parser.add_argument(
        "--viz",
        action="store_true",
        help="the daemon serves the fleet live to Foxglove on ws://127.0.0.1:<viz.port>",
    )
    parser.add_argument(
        "--detach",
        action="store_true",
        help="return once the lab is up (it runs on; fleet down stops it)",
    )
    parser.add_argument(
        "--ready-timeout",
        type=float,
        default=180.0,
        help="seconds each part may take to be ready (a loaded machine is slow; default 180)",
    )
    parser.add_argument(
        "--plain", action="store_true", help="plain lines even on a terminal (no live panel)"
    )
    parser.add_argument("--json", action="store_true", help="end with one JSON object on stdout")
    parser.add_argument("--run-dir", help=argparse.SUPPRESS, default=None)  # --detach's child


def run(args) -> int:
    from controller.runtime.lab_launch import up

    return up(args)
