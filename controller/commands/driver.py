"""``fleet driver ROBOT_ID [--config F] [--duration S]``: one robot's agent.

Binds the robot's driver (``robots[].driver``) to the bus: commands in, poses out, liveliness,
watchdog, e-stop. Runs on the robot's computer or beside the daemon, on the wall clock at
``fleet.rate_hz`` (at least 20 Hz). A ``mavlink`` robot is the real vehicle at its url; a ``sim``
robot runs alone in a real-time stand-in world of its own (bench-top bring-up without hardware).
Exit 1 when the robot does not answer at start or (MAVLink) its link is lost, 2 on bad config; a
ROS 2 robot (or a sim robot of ``fleet world``) whose link is lost is held stopped, its agent
staying up (``link_lost``, then ``link_restored`` when it answers again). ``--strict``: also
refuse (exit 1) a MAVLink vehicle whose own setpoint timeout (PX4 ``COM_OF_LOSS_T``; ArduRover
its GUIDED timeout and GCS failsafe) is longer than the robot's ``max_vehicle_timeout``, cannot
be read, or is unsafe (drivers/mavlink/failsafe.py; otherwise a warning).
"""

from __future__ import annotations

import sys

from controller.commands import add_config_argument, stop_on_signals

EXAMPLES = """examples:
  fleet driver r1                            robot r1 of ./fleet.toml (sim: a world of its own)
  fleet driver r1 --config fleet.toml --duration 30
  fleet driver r1 --connect-timeout 120      wait longer for a slow fleet world to serve r1
  fleet driver r1,r2,r3 --config lab.toml    three agents in one process (a thread each)
  fleet driver r1 --strict                   (MAVLink robots) refuse an unsafe vehicle timeout
"""

#: s ``fleet driver`` waits for its robot's first answer by default: a ``fleet world`` under
#: heavy load once took 71-83 s to start (2-3 s measured at a load average of 5 on 2 cores)
CONNECT_TIMEOUT = 60.0


def add_arguments(parser, word: str) -> None:
    parser.add_argument(
        "robot_id",
        help="the robot's id in the config; several, comma-separated, run one agent each in "
        "this one process (fleet up --agents-per-process)",
    )
    add_config_argument(parser)
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")
    parser.add_argument(
        "--connect-timeout",
        type=float,
        default=CONNECT_TIMEOUT,
        metavar="S",
        help=f"seconds to wait for the robot's first answer: its vehicle (a MAVLink vehicle's "
        "handshake, each step, including its position estimate: about 42 s after a fresh "
        "ArduPilot's first connection), or with sim.world = "
        f'"process" the fleet world serving it (default: {CONNECT_TIMEOUT:g}; a world on a '
        "loaded machine has taken over a minute to start)",
    )
    parser.add_argument(
        "--strict",
        action="store_true",
        help="refuse a MAVLink vehicle whose own setpoint timeout (PX4 COM_OF_LOSS_T; ArduRover "
        "GUID_TIMEOUT and GCS failsafe) is longer than the robot's max_vehicle_timeout, "
        "unreadable or unsafe (default: warn)",
    )


def run(args) -> int:
    from controller.config import ConfigError, load_config
    from controller.runtime.agent_runner import run_agent, run_agents

    cfg = load_config(args.config)
    ids = [w.strip() for w in args.robot_id.split(",") if w.strip()]
    for rid in ids or [args.robot_id]:
        if rid not in cfg.robot_ids:
            raise ConfigError(cfg.source, "robots", f"no robot {rid!r}; ids: {cfg.robot_ids}")
    stop = stop_on_signals()
    if len(ids) == 1:
        code, message = run_agent(
            cfg, ids[0], stop, args.duration, args.connect_timeout, strict=args.strict
        )
        if message:
            print(f"fleet driver {ids[0]}: {message}", file=sys.stderr)
        return code
    return run_agents(cfg, ids, stop, args.duration, args.connect_timeout, strict=args.strict)
