"""A stand-in ROS 2 robot on zenoh for tests and lab rehearsals: the robot side lives in
``drivers/ros2/standin.py`` (``fleet world --ros2`` uses it too); this module keeps the names
the tests import and the command line of a lone stand-in.

Rehearsal, beside ``fleet driver r5`` of a config whose robot r5 has ``driver = "ros2"``
(``fleet world --ros2 r5`` does the same with r5 a body of the shared world):

    python -m tests.support.ros2_robot --config fleet.toml --robot r5 \
        --listen tcp/127.0.0.1:7447
"""

from __future__ import annotations

import argparse
import threading

from drivers.ros2.standin import (  # noqa: F401 - re-exported for the tests
    TYPESTORE,
    RobotBase,
    StandInRobot,
    rosbags_decode,
    rosbags_pose,
)


def main(argv: list[str] | None = None) -> int:
    from controller.config import load_config
    from controller.runtime.wiring import ros2_settings
    from drivers.ros2.node import open_session

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default="fleet.toml")
    ap.add_argument("--robot", required=True)
    ap.add_argument("--listen", default="tcp/127.0.0.1:7447")
    ap.add_argument("--rate", type=float, default=30.0)
    args = ap.parse_args(argv)
    cfg = load_config(args.config)
    r = cfg.robot(args.robot)
    settings = ros2_settings(r)
    stop = threading.Event()
    with open_session(listen=[args.listen], mode="peer") as session:
        robot = StandInRobot(session, settings, r.kind, r.start, cmd_timeout=0.5)
        try:
            robot.run(args.rate, stop)
        except KeyboardInterrupt:
            pass
        finally:
            robot.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
