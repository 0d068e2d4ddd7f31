"""``[ros2_graph]``: the lab daemon shows the fleet to a ROS 2 graph on rmw_zenoh's keys (issue
32 item 4). A zenoh peer of the test stands in for the graph's router (rmw_zenohd); what the
daemon puts there is read as a ROS 2 tool would: the data keys built from the type hashes rosidl
publishes (not from our code), the payloads decoded by rosbags (a CDR codec independent of the
daemon's), the attachments and liveliness tokens as rmw_zenoh lays them out."""

from __future__ import annotations

import math
import threading
from collections import defaultdict

import pytest
import zenoh

from controller.config import load_config
from drivers.ros2 import keys
from drivers.ros2.node import open_session
from drivers.ros2.standin import rosbags_decode
from tests.support.config import free_port
from tests.support.lab import lab_config, spawn, stop_all, tail
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e

# the REP-2011 hashes as rosidl computes them (the keys of every rmw_zenoh graph: rmw_zenoh's
# own README for String, rosidl's generated type descriptions for the others)
TF = "tf2_msgs::msg::dds_::TFMessage_/RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"  # noqa: E501
POSE = "geometry_msgs::msg::dds_::PoseStamped_/RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"  # noqa: E501
STRING = "std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"  # noqa: E501


def test_the_daemon_shows_the_fleet_to_a_ros2_graph(tmp_path, port):
    ros_ep = f"tcp/127.0.0.1:{free_port()}"
    graph = {"enabled": True, "connect": [ros_ep], "namespace": "/cell1", "rate_hz": 10.0}
    path = lab_config(tmp_path, port, robots=2, sections={"ros2_graph": graph})
    cfg = load_config(str(path))
    starts = {r.id: r.start for r in cfg.robots}
    lock = threading.Lock()
    got: dict[str, list[tuple[bytes, bytes | None]]] = defaultdict(list)
    tokens: set[str] = set()

    def keep(name: str):
        def cb(sample: zenoh.Sample) -> None:
            att = sample.attachment
            with lock:
                got[name].append((sample.payload.to_bytes(), att and att.to_bytes()))

        return cb

    with open_session(listen=[ros_ep], mode="peer") as ros:  # the graph's router
        handles = [
            ros.declare_subscriber(f"0/tf/{TF}", keep("tf")),
            ros.declare_subscriber(f"0/cell1/r1/pose/{POSE}", keep("r1")),
            ros.declare_subscriber(f"0/cell1/object/pose/{POSE}", keep("object")),
            ros.declare_subscriber(f"0/cell1/phase/{STRING}", keep("phase")),
            ros.liveliness().declare_subscriber(
                "@ros2_lv/0/**", lambda s: tokens.add(str(s.key_expr)), history=True
            ),
        ]
        c = str(path)
        procs = [spawn(tmp_path / "daemon.txt", "daemon", "--config", c, "--mission", "hold")]
        procs += [spawn(tmp_path / f"{r}.txt", "driver", r, "--config", c) for r in starts]
        try:
            wanted = ("tf", "r1", "phase")
            wait_for(lambda: all(got[k] for k in wanted), 40, "the fleet on the ROS graph")
            with_robots = lambda: any(  # noqa: E731 - the estimates come with the first poses
                len(rosbags_decode("tf2_msgs/msg/TFMessage", p).transforms) >= 2
                for p, _ in list(got["tf"])
            )
            wait_for(with_robots, 20, "both robots in /tf")
            tf = next(
                m
                for m in (rosbags_decode("tf2_msgs/msg/TFMessage", p) for p, _ in got["tf"][::-1])
                if len(m.transforms) >= 2
            )
            frames = {t.child_frame_id: t for t in tf.transforms}
            assert {"r1/base_link", "r2/base_link"} <= set(frames)
            for rid, (x, y, yaw) in starts.items():
                t = frames[f"{rid}/base_link"]
                assert t.header.frame_id == "map"
                assert (t.transform.translation.x, t.transform.translation.y) == pytest.approx(
                    (x, y), abs=0.05
                )
                q = t.transform.rotation
                assert 2 * math.atan2(q.z, q.w) == pytest.approx(yaw, abs=0.05)
            pose = rosbags_decode("geometry_msgs/msg/PoseStamped", got["r1"][-1][0])
            assert pose.header.frame_id == "map"
            assert pose.pose.position.x == pytest.approx(starts["r1"][0], abs=0.05)
            phase = rosbags_decode("std_msgs/msg/String", got["phase"][-1][0]).data
            assert phase == "hold"
            # rmw_zenoh's attachment: sequence numbers from 1 up, a 16-byte publisher GID
            seqs = [keys.parse_attachment(a)[0] for _, a in got["r1"]]
            assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
            assert len(keys.parse_attachment(got["r1"][0][1])[2]) == 16
            # the liveliness tokens a ROS 2 graph lists: the node and its publishers
            assert any("/NN/" in k and "/fleet_controller" in k for k in tokens), tokens
            assert any("/MP/" in k and k.count(TF.split("/")[0]) for k in tokens), tokens
            assert all(p.poll() is None for p in procs), [tail(p) for p in procs]
        finally:
            codes = stop_all(procs)
            for h in handles:
                h.undeclare()
    assert codes[0] == 0, tail(procs[0])
