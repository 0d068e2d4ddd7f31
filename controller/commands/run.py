"""``fleet run [--config F] [--out F.mcap] [--json] [--gui] [--viz]``: the dry run of the whole job.

A stand-in world (pybullet by default, ``sim.backend``), the same agents, bus and controller
loop as the lab, in lockstep with the sim clock. Prints the outcome on stdout (a verdict line,
the figures with their units and limits, the next steps; ``--json``: one object instead) and
exits 0 when the job is done with a clean verdict, 1 when it failed, 2 on bad config (and on
``--gui`` without a display or with a backend that has no window). ``--viz`` serves the run live
to Foxglove (``[viz]`` port, 127.0.0.1 only).
"""

from __future__ import annotations

import sys
from pathlib import Path

from controller.commands import add_config_argument, config_path, require_log_target
from controller.config import MISSION_KINDS, SIM_BACKENDS

EXAMPLES = """examples:
  fleet run                                 the dry run of ./fleet.toml (what make run does)
  fleet run --config lab/secure.toml --json one JSON object of figures on stdout
  fleet run --backend ideal --max-time 60   the fast ideal backend, 60 s of sim time
  fleet run --out runs/demo.mcap --viz      a named log; watch live in Foxglove meanwhile
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--out", help="MCAP log (default: <log.dir>/<fleet>-run-<time>.mcap)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--gui", action="store_true", help="show the pybullet GUI")
    parser.add_argument(
        "--viz",
        action="store_true",
        help="serve the run live to Foxglove on ws://127.0.0.1:<viz.port>",
    )
    parser.add_argument(
        "--max-time", type=float, default=None, help="sim seconds (default: sim.max_time)"
    )
    parser.add_argument("--backend", choices=SIM_BACKENDS, help="override sim.backend for this run")
    parser.add_argument(
        "--mission",
        choices=MISSION_KINDS,
        default="capture",
        help="capture: the whole job (default); transport: carry an object the robots already "
        "hold; stage, hold: bring-up missions",
    )


def run(args) -> int:
    import dataclasses

    from controller.cli import emit_json
    from controller.config import InputError, load_config
    from controller.io.recorder import default_log_path
    from controller.mission.factory import build_mission
    from controller.runtime.dry_run import DryRun
    from controller.runtime.planner import PlannerWorker

    cfg = load_config(config_path(args))  # InputError without a config: exit 2
    if cfg.sim.bus == "private" and cfg.sim.world == "solo":
        from controller.runtime.sweep import on_free_port

        cfg = on_free_port(cfg)  # a run beside another never finds its port taken
    if args.backend:
        cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, backend=args.backend))
    if args.gui:
        from controller.runtime.gui import gui_problem

        problem = gui_problem(cfg.sim.backend)
        if problem:
            raise InputError(f"--gui: {problem}")
    out = Path(args.out) if args.out else default_log_path(cfg.log.dir, cfg.fleet.name)
    require_log_target(cfg, out, bool(args.out))  # exit 2 before anything starts
    # the slow plans off the tick, applied after their modelled latency in sim time
    planners = PlannerWorker.for_config(cfg, lockstep=True)
    mission = build_mission(cfg, args.mission, planners=planners)  # MissionError: exit 1
    print(f"fleet run: {cfg.source}, backend {cfg.sim.backend}, log {out}", file=sys.stderr)
    dry = DryRun(
        cfg, mission, out, gui=args.gui, max_time=args.max_time, viz=args.viz, planners=planners
    )
    bar = None
    if sys.stderr.isatty():  # a progress bar on a terminal; the progress lines otherwise
        from controller.runtime.console import RunProgress

        bar = RunProgress(dry.max_time)
        dry.on_progress = bar.update
    try:
        summary = dry.run_summary()
    finally:
        if bar is not None:
            bar.close()
    figures = summary.to_json()
    if args.json:
        emit_json(figures)
    else:
        from controller.outcome import report

        print(report({**figures, "config": cfg.source}))
    return 0 if summary.ok else 1
