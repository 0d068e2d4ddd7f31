"""A second process for the bus tests: a robot-side peer that answers every command with a pose.

Usage: python tests/peer_echo.py ENDPOINT FLEET ROBOT_ID COUNT
Connects to ENDPOINT, holds a liveliness token for the robot, and for each Twist2D received on
the robot's cmd key publishes a PoseMeasurement with x = vx, seq = the command's seq. Exits after
COUNT commands (or 30 s).
"""

from __future__ import annotations

import sys
import time

from controller import wire
from controller.config import ZenohSection
from controller.io.bus import Bus


def main() -> int:
    endpoint, fleet, rid, count = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
    with Bus(ZenohSection(), fleet, listen=[], connect=[endpoint]) as bus:
        inbox = bus.subscribe_topic("robot_cmd", id=rid)
        pose = bus.publisher("robot_pose", id=rid)
        bus.declare_alive("robot", rid)
        seen = 0
        deadline = time.monotonic() + 30.0
        while seen < count and time.monotonic() < deadline:
            item = inbox.get(timeout=0.1)
            if item is None:
                continue
            cmd = item.msg
            pose.put(wire.PoseMeasurement(t=cmd.t, seq=cmd.seq, x=cmd.vx, y=0.0, theta=0.0))
            seen += 1
    return 0 if seen >= count else 1


if __name__ == "__main__":
    sys.exit(main())
