"""A flooding process for the bus tests and bench: puts pose samples on robots' pose keys at a
set rate for a set time, then prints one JSON line (what it sent).

Usage: python tests/support/flooder.py ENDPOINT FLEET IDS RATE_HZ SECONDS KIND [X,Y,THETA;...]
IDS is comma-separated; every ``1/RATE_HZ`` s one sample goes to each robot's key. KIND
``poses``: valid ``PoseMeasurement`` stamped now at the given positions (one ``x,y,theta`` per
robot, the robots' own, so the flood is believable); ``big``: 4 MiB payloads.
"""

from __future__ import annotations

import json
import sys
import time

import zenoh

from controller import wire
from controller.config import ZenohSection
from controller.io.bus import Bus
from controller.io.ratekeeper import Ratekeeper

BIG = 4 * 1024 * 1024


def main() -> int:
    endpoint, fleet, ids_arg, rate, seconds, kind = sys.argv[1:7]
    ids = ids_arg.split(",")
    where = (
        [tuple(float(v) for v in p.split(",")) for p in sys.argv[7].split(";")]
        if (len(sys.argv) > 7)
        else [(0.0, 0.0, 0.0)] * len(ids)
    )
    big = b'{"t": 0.0, "seq": 0, "x": 0, "y": 0, "theta": 0, "pad": "' + b"x" * BIG + b'"}'
    sent = 0
    with Bus(ZenohSection(), fleet, listen=[], connect=[endpoint]) as bus:
        pubs = [
            bus.session.declare_publisher(
                bus.key("robot_pose", id=r), congestion_control=zenoh.CongestionControl.BLOCK
            )
            for r in ids
        ]
        rk = Ratekeeper(float(rate))
        end = time.monotonic() + float(seconds)
        seq = 0
        while time.monotonic() < end:
            rk.keep_time()
            now = time.time()
            seq += 1
            for pub, (x, y, th) in zip(pubs, where, strict=True):
                if kind == "big":
                    pub.put(big)
                else:
                    m = wire.PoseMeasurement(t=now, seq=seq, x=x, y=y, theta=th)
                    pub.put(wire.encode(m))
                sent += 1
    print(json.dumps({"sent": sent, "late": rk.lagged, "skipped": rk.skipped}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
