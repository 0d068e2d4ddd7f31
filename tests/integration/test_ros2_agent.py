"""``fleet driver`` with a ROS 2 robot: the agent (watchdog, e-stop, liveliness, events) over
the ROS 2 driver, against the stand-in robot running on the wall clock on its own zenoh
endpoint (the robot's ROS graph), the fleet bus on another. The robot's odometry reaches the
fleet as world poses; when the robot goes silent the agent reports a lost link."""

from __future__ import annotations

import threading

import pytest

from controller.config import parse_config
from controller.io.bus import Bus
from controller.runtime.agent_runner import run_agent
from controller.runtime.wiring import ros2_settings
from drivers.ros2.node import open_session
from tests.support.config import base_config_dict, free_port
from tests.support.ros2_robot import StandInRobot
from tests.support.wait import wait_for


@pytest.mark.e2e
def test_fleet_driver_serves_a_ros2_robot_and_reports_its_silence():
    ros_endpoint = f"tcp/127.0.0.1:{free_port()}"
    data = base_config_dict()
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{free_port()}"], "connect": []}
    start = data["robots"][0]["start"]
    data["robots"][0].update(
        driver="ros2",
        ros2={"namespace": "/tb1", "connect": [ros_endpoint], "odom_to_world": start},
    )
    cfg = parse_config(data, "test")
    r = cfg.robots[0]
    robot_stop, agent_stop = threading.Event(), threading.Event()
    result: list = []
    with (
        Bus(cfg.zenoh, cfg.fleet.name) as bus,
        open_session(listen=[ros_endpoint], mode="peer") as ros,
    ):
        poses = bus.subscribe_topic("robot_pose", lossless=True, id=r.id)
        events = bus.subscribe_topic("robot_event", lossless=True, id=r.id)
        robot = StandInRobot(ros, ros2_settings(r), r.kind, r.start)
        robot_thread = threading.Thread(target=robot.run, args=(30.0, robot_stop), daemon=True)
        robot_thread.start()
        agent = threading.Thread(
            target=lambda: result.append(run_agent(cfg, r.id, agent_stop, connect_timeout=10)),
            daemon=True,
        )
        agent.start()
        try:
            first = poses.get(timeout=15)
            assert first is not None, "no pose from the agent"
            m = first.msg
            assert m.source == "ros2"
            assert (m.x, m.y, m.theta) == pytest.approx(tuple(r.start), abs=1e-6)
            # the agent commands the robot (its watchdog's zero, the e-stop's hold) on cmd_vel
            wait_for(lambda: robot.commands_seen() > 0, 10, "a command from the agent")
            robot_stop.set()  # the robot goes silent: a lost link after ros2.link_timeout
            robot_thread.join(5)

            def lost() -> bool:
                return any(e.msg.kind == "link_lost" for e in events.drain())

            wait_for(lost, 10, "link_lost on robot/<id>/event")
        finally:
            agent_stop.set()
            agent.join(15)
            robot.close()
    assert not agent.is_alive()
