"""The cost of showing the fleet to a ROS 2 graph (``[ros2_graph]``): prints ONE JSON object.

Per publication (what the lab daemon does once per ``ros2_graph.rate_hz`` after a tick), in
milliseconds, median and p90 over ``--n`` rounds, at 6, 20 and 50 robots: building the messages
(``graph_messages``: /tf and a PoseStamped per robot and the object), encoding them (the
driver's CDR codec) and the puts on a zenoh session with a subscriber of every key on
loopback (rmw_zenoh's attachment included), against the tick's period at 20 Hz (50 ms).

Usage: ``python bench/ros2_graph.py [--n 200]``.
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

from controller.runtime.ros2_graph import POSE, TF, graph_messages  # noqa: E402
from drivers.ros2 import msgs  # noqa: E402
from drivers.ros2.node import RmwNode, open_session  # noqa: E402
from tests.support.config import free_port  # noqa: E402


def one_size(n_robots: int, rounds: int, session) -> dict:
    node = RmwNode(session, 0, "/fleet", f"bench_{n_robots}")
    ids = [f"r{i + 1}" for i in range(n_robots)]
    tf_pub = node.publisher("/tf", TF)
    pubs = {name: node.publisher(f"/fleet/{name}/pose", POSE) for name in [*ids, "object"]}
    rng = np.random.default_rng(7)
    build, total = [], []
    for k in range(rounds):
        poses = rng.uniform(0, 10, (n_robots, 3))
        t = 1_800_000_000.0 + 0.1 * k
        t0 = time.perf_counter()
        tf, pose_msgs = graph_messages(t, "map", ids, poses, np.ones(n_robots, bool), (5, 5, 0))
        t1 = time.perf_counter()
        tf_pub.put(msgs.encode(TF, tf), int(t * 1e9))
        for name, m in pose_msgs.items():
            pubs[name].put(msgs.encode(POSE, m), int(t * 1e9))
        t2 = time.perf_counter()
        build.append(t1 - t0)
        total.append(t2 - t0)
    node.close()
    return {
        "robots": n_robots,
        "build_ms_median": round(float(np.median(build)) * 1e3, 3),
        "publish_ms_median": round(float(np.median(total)) * 1e3, 3),
        "publish_ms_p90": round(float(np.percentile(total, 90)) * 1e3, 3),
        "share_of_a_20hz_tick_median": round(float(np.median(total)) / 0.05, 4),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    args = ap.parse_args()
    ep = f"tcp/127.0.0.1:{free_port()}"
    with open_session(listen=[ep], mode="peer") as router, open_session(connect=[ep]) as daemon:
        sub = router.declare_subscriber("0/**", lambda s: None)  # the puts go somewhere
        sizes = [one_size(n, args.n, daemon) for n in (6, 20, 50)]
        sub.undeclare()
    print(json.dumps({"sizes": sizes, "loadavg": [round(v, 2) for v in os.getloadavg()]}))


if __name__ == "__main__":
    main()
