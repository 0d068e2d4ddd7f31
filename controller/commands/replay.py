"""``fleet replay LOG [--json] [--plots DIR] [--check] [--republish [--wait S]]``: a run's log.

Reads the MCAP log of a dry run, a daemon or ``fleet record`` (a file cut short by a crash is
read up to the cut; a folder of segments as one run) and prints metrics: per-robot pose and
command rates, path lengths, estimation error against ground truth (dry runs log it), minimum
robot-robot clearance, the deepest robot-object overlap, obstacle and wall contacts, the
arrested object's displacement and the object's clearance, and the run's own verdict on them;
phases, the arrest, e-stops and lost links. ``--plots DIR`` writes PNG figures. ``--check`` is
the regression replay: the logged inputs through today's controller, its commands compared with
the logged ones tick by tick (``--tolerance``); exit 1 at a divergence, naming the first
diverging tick and robot. ``--republish`` plays the messages back on the config's zenoh bus,
paced on the log's own time (``--speed``), after waiting up to ``--wait`` s for subscribers,
without the command and e-stop keys unless ``--with-commands`` (a replay must not drive real
robots).
"""

from __future__ import annotations

import sys
from pathlib import Path

from controller.commands import DEFAULT_CONFIG
from controller.config import MISSION_KINDS

EXAMPLES = """examples:
  fleet run --out runs/demo.mcap && fleet replay runs/demo.mcap   a dry run, then its metrics
  fleet replay runs/demo.mcap --plots runs/demo-plots --json
  fleet replay runs/demo.mcap --check          today's controller against the logged commands
  fleet replay runs/demo.mcap --republish --wait 5   play it back on the bus (for Foxglove)
"""


def add_arguments(parser, word: str) -> None:
    parser.add_argument("log", help="MCAP file of a run, or a folder of its segments")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plots", default=None, help="write PNG figures into this directory")
    parser.add_argument(
        "--check",
        action="store_true",
        help="regression replay: the logged inputs through today's controller, commands compared",
    )
    parser.add_argument(
        "--tolerance",
        type=float,
        default=1e-6,
        help="--check: largest command difference accepted (m/s, rad/s; default 1e-6)",
    )
    parser.add_argument(
        "--mission",
        choices=MISSION_KINDS,
        default=None,
        help="--check: the mission to run (default: the log's own)",
    )
    parser.add_argument(
        "--republish", action="store_true", help="publish the messages again on the bus"
    )
    parser.add_argument(
        "--wait",
        type=float,
        default=0.0,
        help="--republish: wait up to S seconds until every key has a subscriber",
    )
    parser.add_argument(
        "--speed", type=float, default=1.0, help="playback speed factor (0: no pacing)"
    )
    parser.add_argument(
        "--with-commands", action="store_true", help="also republish commands and e-stops"
    )
    parser.add_argument(
        "--config",
        default=None,
        help=f"zenoh settings for --republish (default: recorded config, else {DEFAULT_CONFIG})",
    )


def run(args) -> int:
    from controller.cli import emit_json
    from controller.config import InputError
    from controller.replay.log import load_run, metrics_of, print_summary
    from controller.viz import plot_run

    path = Path(args.log)
    if args.speed < 0:
        raise InputError("--speed: expected >= 0")
    if args.wait < 0 or args.tolerance < 0:
        raise InputError("--wait and --tolerance: expected >= 0")
    run_log = load_run(path)  # InputError for a missing, unreadable or empty file
    result = metrics_of(run_log)
    status = 0
    if args.plots:
        result["plots"] = [str(p) for p in plot_run(run_log, args.plots, result)]
    if args.check:
        from controller.replay.check import check_log

        result["check"] = check_log(path, args.tolerance, args.mission)
        print(f"fleet replay --check: {result['check']['message']}", file=sys.stderr)
        status = 0 if result["check"]["ok"] else 1
    if args.republish:
        from controller.replay.republish import republish_run

        timing: dict = {}
        result["republished"] = republish_run(
            path,
            run_log,
            args.config,
            args.speed,
            args.with_commands,
            DEFAULT_CONFIG,
            args.wait,
            timing,
        )
        result["republish_timing"] = timing
    if args.json:
        emit_json(result)
    else:
        print_summary(result)
    return status
