"""``fleet world [--config F] [--duration S] [--mavlink [IDS]] [--ros2 [IDS]]``: the shared
stand-in world as its own process.

One world (``sim.backend``) with every ``sim`` robot and the object, in real time, for a lab
rehearsal on one machine (``controller.runtime.world``): it publishes ``object/pose`` the way a
motion-capture system would and serves the ``sim`` agents of ``fleet driver`` (with
``sim.world = "process"``). ``--mavlink`` makes MAVLink robots bodies of the same world too,
each behind an emulated flight controller answering its ``url`` on loopback (every MAVLink robot,
or the ids given, comma-separated), so a mixed fleet rehearses together; their ``fleet driver``
talks MAVLink to it. ``--ros2`` does the same for ROS 2 robots: each a body of the world behind
its ROS graph (rmw_zenoh's keys, tokens and attachments) on a session answering its
``ros2.connect`` endpoints on loopback, so their ``fleet driver`` drives them as real robots.
Stops on SIGINT/SIGTERM or after ``--duration`` seconds; exit 0, 2 on bad config (or a
``--mavlink`` id that is not a MAVLink robot with a loopback-answerable url, a ``--ros2`` id
that is not a ROS 2 robot with loopback endpoints), 1 when its session cannot open.
"""

from __future__ import annotations

from controller.commands import add_config_argument, add_emulation_arguments, serve_until_signalled

EXAMPLES = """examples:
  fleet world --config fleet.toml        the shared world (with sim.world = "process"), then
  fleet driver r1 --config fleet.toml    a driver per robot, and fleet daemon
  fleet world --duration 600 --mavlink   and every MAVLink robot of the config emulated
"""


def add_arguments(parser, word: str) -> None:
    add_config_argument(parser)
    parser.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")
    add_emulation_arguments(parser)


def run(args) -> int:
    from controller.runtime.world import run_world

    def serve(cfg, stop, duration):
        return run_world(cfg, stop, duration, mavlink=args.mavlink, ros2=args.ros2)

    return serve_until_signalled(args, serve)
