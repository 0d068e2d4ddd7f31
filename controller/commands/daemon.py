"""``fleet daemon [--config F] [--out F.mcap] [--duration S] [--mission capture|hold] [--viz]
[--take-over]``.

The controller on the lab network (``controller.runtime.daemon``). Stops on SIGINT/SIGTERM
(robots then stop by their own watchdogs) or when the mission ends; exit 1 when it failed.
"""

from __future__ import annotations

from pathlib import Path

from controller.commands import add_config_argument, require_log_target, stop_on_signals
from controller.config import MISSION_KINDS

EXAMPLES = """examples:
  fleet hub --config fleet.toml &                 the hub first (else the daemon starts one)
  fleet daemon --config fleet.toml --mission hold bring-up: every robot held stopped
  fleet daemon --config fleet.toml --out runs/lab.mcap --viz
                                                  the whole job, logged, live in Foxglove
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--out", help="MCAP log (default: <log.dir>/<fleet>-daemon-<time>.mcap)")
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")
    parser.add_argument(
        "--viz",
        action="store_true",
        help="serve the fleet live to Foxglove on ws://127.0.0.1:<viz.port>",
    )
    parser.add_argument(
        "--take-over",
        action="store_true",
        help="start although another controller of the fleet runs: it stops commanding and "
        "exits 1 once it sees this one, which commands nothing until it is gone",
    )
    parser.add_argument(
        "--mission",
        choices=MISSION_KINDS,
        default="capture",
        help="capture: the whole job; stage: drive to staging points around the object; "
        "hold: keep every robot stopped (bring-up checks)",
    )


def run(args) -> int:
    from controller.config import load_config
    from controller.io.recorder import default_log_path
    from controller.mission.factory import build_mission
    from controller.runtime.daemon import run_daemon
    from controller.runtime.planner import PlannerWorker

    cfg = load_config(args.config)
    out = Path(args.out) if args.out else default_log_path(cfg.log.dir, cfg.fleet.name, "daemon")
    require_log_target(cfg, out, bool(args.out))  # exit 2 before anything starts
    stop = stop_on_signals()
    planners = PlannerWorker.for_config(cfg, lockstep=False)  # the slow plans off the loop
    mission = build_mission(cfg, args.mission, planners=planners)  # MissionError: exit 1
    return run_daemon(
        cfg,
        mission,
        args.mission,
        out,
        stop,
        args.duration,
        viz=args.viz,
        planners=planners,
        take_over=args.take_over,
    )
