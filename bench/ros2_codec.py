"""ROS 2 codec benchmark: prints ONE JSON object on stdout (progress on stderr).

Per message, in microseconds (median and p90 over interleaved rounds), for the driver's codec
(mcap-ros2-support from our .msg text, drivers/ros2/msgs.py) against rosbags' CDR, the baseline
run in the same process on the same messages:

- encode ``geometry_msgs/msg/Twist`` and ``TwistStamped`` (what ``send`` puts on cmd_vel);
- decode ``nav_msgs/msg/Odometry`` and ``geometry_msgs/msg/PoseStamped`` (what ``poll`` takes);
- the driver's whole per-message path: a command (message dict, CDR, rmw_zenoh attachment) and
  a pose (CDR decode, planar pose, odom → world).

Ratios are ours / rosbags (below 1: ours faster). The machine is shared: trust the ratios more
than absolute figures. Usage: ``python bench/ros2_codec.py [--n N] [--rounds R]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from drivers.ros2 import keys, msgs  # noqa: E402
from tests.support.ros2_robot import TYPESTORE, rosbags_pose  # noqa: E402

TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
ODOM = "nav_msgs/msg/Odometry"
POSE = "geometry_msgs/msg/PoseStamped"


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def per_message_us(fn, n: int, rounds: int) -> list[float]:
    out = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        out.append((time.perf_counter() - t0) / n * 1e6)
    return out


def rosbags_twist(stamped: bool):
    T = TYPESTORE.types
    vec = T["geometry_msgs/msg/Vector3"]
    tw = T[TWIST](linear=vec(x=0.2, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.5))
    if not stamped:
        return tw
    stamp = T["builtin_interfaces/msg/Time"](sec=12, nanosec=5)
    return T[TWIST_STAMPED](header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="base"), twist=tw)


def cases():
    """name -> (ours, rosbags): callables doing the same work on the same message."""
    tw = msgs.twist_message("twist", 0.2, 0.0, 0.5, 12.0, "base")
    tws = msgs.twist_message("twist_stamped", 0.2, 0.0, 0.5, 12.0, "base")
    rb_tw, rb_tws = rosbags_twist(False), rosbags_twist(True)
    odom = rosbags_pose(ODOM, 12.0, 1.0, 2.0, 0.3)
    pose = rosbags_pose(POSE, 12.0, 1.0, 2.0, 0.3)
    gid = bytes(16)

    def our_command():
        m = msgs.twist_message("twist", 0.2, 0.0, 0.5, 12.0, "base")
        return msgs.encode(TWIST, m), keys.attachment(1, 12_000_000_000, gid)

    def rosbags_command():
        return TYPESTORE.serialize_cdr(rosbags_twist(False), TWIST), keys.attachment(1, 0, gid)

    def our_pose():
        p = msgs.read_pose("odometry", msgs.decode(ODOM, odom))
        return keys.odom_to_world(p.x, p.y, p.yaw, (1.0, 2.0, 0.5))

    def rosbags_pose_path():
        m = TYPESTORE.deserialize_cdr(odom, ODOM)
        q = m.pose.pose.orientation
        yaw = msgs.quaternion_yaw(q)
        return keys.odom_to_world(m.pose.pose.position.x, m.pose.pose.position.y, yaw, (1, 2, 0.5))

    return {
        "encode_twist": (
            lambda: msgs.encode(TWIST, tw),
            lambda: TYPESTORE.serialize_cdr(rb_tw, TWIST),
        ),
        "encode_twist_stamped": (
            lambda: msgs.encode(TWIST_STAMPED, tws),
            lambda: TYPESTORE.serialize_cdr(rb_tws, TWIST_STAMPED),
        ),
        "decode_odometry": (
            lambda: msgs.decode(ODOM, odom),
            lambda: TYPESTORE.deserialize_cdr(odom, ODOM),
        ),
        "decode_pose_stamped": (
            lambda: msgs.decode(POSE, pose),
            lambda: TYPESTORE.deserialize_cdr(pose, POSE),
        ),
        "driver_command_path": (our_command, rosbags_command),
        "driver_pose_path": (our_pose, rosbags_pose_path),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=2000, help="messages per round")
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    out: dict = {
        "benchmark": "ros2_codec",
        "unit": "us_per_message",
        "n": args.n,
        "rounds": args.rounds,
        "loadavg_1m": round(os.getloadavg()[0], 2),
        "baseline": "rosbags serialize_cdr/deserialize_cdr (same process)",
        "cases": {},
    }
    for name, (ours, theirs) in cases().items():
        log(f"ros2_codec: {name}")
        ours(), theirs()  # warm (codec generation, caches)
        a, b = [], []
        for _ in range(args.rounds):  # interleaved: load drift hits both alike
            a += per_message_us(ours, args.n, 1)
            b += per_message_us(theirs, args.n, 1)
        med_a, med_b = float(np.median(a)), float(np.median(b))
        out["cases"][name] = {
            "ours_median_us": round(med_a, 2),
            "ours_p90_us": round(float(np.percentile(a, 90)), 2),
            "rosbags_median_us": round(med_b, 2),
            "ratio_ours_to_rosbags": round(med_a / med_b, 3),
        }
    out["loadavg_1m_after"] = round(os.getloadavg()[0], 2)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
