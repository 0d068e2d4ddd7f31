"""``fleet replay F.mcap [--json] [--plots DIR] [--republish]``: a run's log, analysed.

Reads the MCAP log of a dry run, a daemon or ``fleet record`` (a file cut short by a crash is
read up to the cut) and prints metrics: per-robot pose and command rates, path lengths,
estimation error against ground truth (dry runs log it), minimum robot-robot clearance, the
deepest robot-object overlap, phases, the arrest, e-stops and lost links. ``--plots DIR`` writes
PNG figures; ``--republish`` plays the messages back on the config's zenoh bus with their
original spacing (``--speed``), without the command and e-stop keys unless
``--with-commands`` (a replay must not drive real robots).
"""

from __future__ import annotations

from pathlib import Path

from controller.commands import DEFAULT_CONFIG


def add_arguments(parser, word: str) -> None:
    parser.add_argument("log", help="MCAP file of a run")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plots", default=None, help="write PNG figures into this directory")
    parser.add_argument(
        "--republish", action="store_true", help="publish the messages again on the bus"
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
    run_log = load_run(path)  # InputError for a missing, unreadable or empty file
    result = metrics_of(run_log)
    if args.plots:
        result["plots"] = [str(p) for p in plot_run(run_log, args.plots)]
    if args.republish:
        from controller.replay.republish import republish_run

        result["republished"] = republish_run(
            args.log, run_log, args.config, args.speed, args.with_commands, DEFAULT_CONFIG
        )
    if args.json:
        emit_json(result)
    else:
        print_summary(result)
    return 0
