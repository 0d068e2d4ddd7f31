"""Issue #25 item 6: the MCAP log keeps a ROS 2 robot's own messages (``ros2msg`` schemas,
``cdr`` messages, ROS topic names), read back by mcap-ros2-support (what ROS tools use) and,
independently, by rosbags."""

from __future__ import annotations

import threading

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from controller.config import parse_config
from controller.io.bus import Bus
from controller.io.recorder import McapRecorder, read_log
from controller.replay.log import load_run, metrics_of
from controller.runtime.recording import record_ros2
from controller.runtime.wiring import ros2_settings
from controller.wire import Twist2D
from drivers.base import Capabilities
from drivers.ros2.driver import Ros2Driver
from drivers.ros2.node import open_session
from tests.support.config import base_config_dict, free_port
from tests.support.ros2_robot import StandInRobot, rosbags_decode
from tests.support.wait import wait_for

COMMANDS = [(0.2, 0.0, 0.1), (0.1, 0.05, -0.3), (0.0, 0.0, 0.0)]


def _publish_until(robot: StandInRobot, done: threading.Event) -> None:
    """The robot's odometry every 0.1 s until ``done``."""
    while not done.is_set():
        robot.publish()
        done.wait(0.1)


def test_ros2_topics_go_into_the_log_as_ros2_messages(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    data = base_config_dict()
    data["zenoh"] = {"mode": "peer", "listen": [endpoint], "connect": []}
    data["robots"][0].update(driver="ros2", ros2={"namespace": "/tb1", "connect": [endpoint]})
    cfg = parse_config(data, "test")
    r = cfg.robots[0]
    settings = ros2_settings(r)
    out = tmp_path / "run.mcap"
    with Bus(cfg.zenoh, cfg.fleet.name) as bus:
        rec = McapRecorder(out, cfg.fleet.name)
        assert set(record_ros2(bus, cfg, rec)) == {settings.cmd_key(), settings.pose_key()}
        robot_session = open_session(connect=[endpoint])
        robot = StandInRobot(robot_session, settings, r.kind, r.start)
        caps = Capabilities(r.kind, r.kind == "omni", 0.5, 2.0, 0.1)
        drv = Ros2Driver(r.id, caps, settings, stale_after=5.0, clock=lambda: robot.t)
        try:
            drv.open()
            # the robot's odometry at 10 Hz until the driver holds one: its publisher matches the
            # recorder's subscriber before the driver's, so a single first sample may miss it
            connected = threading.Event()
            odom = threading.Thread(target=_publish_until, args=(robot, connected), daemon=True)
            odom.start()
            try:
                drv.connect(timeout=30.0)
            finally:
                connected.set()
                odom.join()
            for vx, vy, wz in COMMANDS:
                drv.send(Twist2D(t=0.0, vx=vx, vy=vy, wz=wz))
                wait_for(lambda: robot.commands_seen() >= drv.sent, 5, "the command")
                robot.step(0.1)
                robot.publish()
            total = drv.sent + robot.published
            wait_for(lambda: rec.native_written >= total, 5, "the samples at the recorder")
        finally:
            drv.close()
            robot.close()
            robot_session.close()
            rec.close()

    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    channels = {c.topic: c for c in summary.channels.values()}
    schemas = {s.id: s for s in summary.schemas.values()}
    cmd = channels["/tb1/cmd_vel"]
    odom = channels["/tb1/odom"]
    assert cmd.message_encoding == odom.message_encoding == "cdr"
    assert (schemas[cmd.schema_id].name, schemas[cmd.schema_id].encoding) == (
        "geometry_msgs/msg/Twist", "ros2msg",
    )  # fmt: skip
    assert schemas[odom.schema_id].name == "nav_msgs/msg/Odometry"

    # what ROS tools read (mcap-ros2-support decodes from the schema text in the file)
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msgs = [(c.topic, m) for _, c, _, m in reader.iter_decoded_messages()]
    sent = [(t.linear.x, t.linear.y, t.angular.z) for topic, t in msgs if topic == "/tb1/cmd_vel"]
    assert sent[: len(COMMANDS)] == COMMANDS
    assert all(v == (0.0, 0.0, 0.0) for v in sent[len(COMMANDS) :])  # the stop of close()
    poses = [m for topic, m in msgs if topic == "/tb1/odom"]
    assert len(poses) == robot.published and poses[0].header.frame_id == "odom"
    assert len(poses) >= len(COMMANDS) + 1

    # and an independent decoder of the raw records agrees
    raw = [x for x in read_log(out) if x.topic == "/tb1/odom"]
    last = rosbags_decode("nav_msgs/msg/Odometry", raw[-1].data)
    assert last.pose.pose.position.x == poses[-1].pose.pose.position.x

    # fleet replay counts them apart from the Foxglove scene (--json "ros2")
    figures = metrics_of(load_run(out))
    assert figures["ros2"]["/tb1/odom"] == len(poses) and "/tb1/odom" not in figures["scene"]
