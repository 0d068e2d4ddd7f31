"""A ROS 2 robot's lost link, as processes on 127.0.0.1 (issue 32, item 2): ``fleet daemon
--mission hold`` and ``fleet driver r1`` (a ROS 2 robot) with the stand-in robot base on its own
zenoh endpoint (the robot's ROS graph, in this process). The base withholds its odometry for
5 s, then resumes it: the agent reports ``link_lost``, holds the robot stopped and stays up;
``link_restored`` follows when the odometry returns, the controller sees the robot present again
and its commands reach ``cmd_vel`` again, without restarting anything."""

from __future__ import annotations

import threading
import time

import pytest

from controller.config import load_config
from controller.runtime.wiring import ros2_settings
from drivers.ros2.node import open_session
from tests.support.config import base_config_dict, free_port, write_toml
from tests.support.lab import connect_client, release, spawn, status, stop_all, tail
from tests.support.ros2_robot import StandInRobot
from tests.support.wait import wait_for

pytestmark = pytest.mark.e2e

SILENCE_S = 5.0  # s the base withholds its odometry (ros2.link_timeout is 2.5 s)


def _config(tmp_path, port: int, ros_endpoint: str):
    data = base_config_dict()
    r = data["robots"][0]
    data["robots"] = [r]
    r.update(driver="ros2", ros2={"namespace": "/tb1", "connect": [ros_endpoint],
                                  "odom_to_world": list(r["start"])})  # fmt: skip
    data["zenoh"] = {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []}
    data["sim"]["backend"] = "ideal"
    data["log"] = {"dir": str(tmp_path / "runs")}
    return write_toml(tmp_path / "ros2.toml", data)


def _robot(st: dict, rid: str) -> dict:
    return next((r for r in st.get("robots", []) if r["id"] == rid), {})


def _commands_flow(robot: StandInRobot, n: int, timeout: float, what: str) -> None:
    """``n`` more cmd_vel samples reach the base (the daemon's stream through the agent)."""
    before = robot.commands_seen()
    wait_for(lambda: robot.commands_seen() >= before + n, timeout, what)


def test_a_silent_ros2_robot_is_held_and_rejoins_without_a_restart(tmp_path, port):
    ros_endpoint = f"tcp/127.0.0.1:{free_port()}"
    cfg_path = _config(tmp_path, port, ros_endpoint)
    cfg = load_config(cfg_path)
    r = cfg.robots[0]
    c = str(cfg_path)
    stop, mute = threading.Event(), threading.Event()
    procs = []
    events: list[tuple[float, str]] = []
    with open_session(listen=[ros_endpoint], mode="peer") as ros:
        robot = StandInRobot(ros, ros2_settings(r), r.kind, r.start, cmd_timeout=0.5)
        base = threading.Thread(target=robot.run, args=(30.0, stop), kwargs={"mute": mute})
        base.start()
        bus = None
        try:
            daemon = spawn(tmp_path / "daemon.txt", "daemon", "--config", c, "--mission", "hold",
                           "--out", str(tmp_path / "d.mcap"))  # fmt: skip
            procs.append(daemon)
            bus = connect_client(port, "the daemon's hub")
            inbox = bus.subscribe_topic("robot_event", lossless=True, id=r.id)

            def seen(kind: str, after: str | None = None) -> bool:
                """An event ``kind`` arrived (after the first ``after`` one)."""
                events.extend((time.monotonic(), i.msg.kind) for i in inbox.drain())
                kinds = [k for _, k in events]
                start = kinds.index(after) + 1 if after in kinds else 0
                return (after is None or after in kinds) and kind in kinds[start:]

            agent = spawn(tmp_path / "r1.txt", "driver", r.id, "--config", c)
            procs.append(agent)
            wait_for(lambda: _robot(status(cfg_path), r.id).get("present"), 60, "r1 present")
            release(cfg_path)  # a fresh lab is stopped until the operator's first resume
            _commands_flow(robot, 20, 20, "the daemon's commands on cmd_vel")

            mute.set()  # the base stops publishing its odometry
            t_mute = time.monotonic()
            wait_for(lambda: seen("link_lost"), 10, "link_lost on robot/r1/event")
            t_lost = next(t for t, k in events if k == "link_lost")
            assert 2.0 < t_lost - t_mute < 4.5, t_lost - t_mute  # ros2.link_timeout: 2.5 s
            wait_for(lambda: _robot(status(cfg_path), r.id).get("link_lost"), 10,
                     "the daemon seeing r1's link lost")  # fmt: skip
            during = robot.commands_seen()
            # the withheld odometry's 5 s (the scenario's length, not a handshake)
            wait_for(lambda: time.monotonic() - t_mute >= SILENCE_S, SILENCE_S + 1, "5 s")
            assert agent.poll() is None, f"the agent exited: {tail(agent)}"
            held = robot.commands_seen() - during
            assert held <= 1, f"{held} commands reached a robot whose link is lost"

            mute.clear()  # the odometry returns
            wait_for(lambda: seen("link_restored", after="link_lost"), 10,
                     "link_restored after link_lost on robot/r1/event")  # fmt: skip
            kinds = [k for _, k in events]  # the loss and the return, once each
            assert kinds[kinds.index("link_lost") :] == ["link_lost", "link_restored"], kinds

            def back() -> bool:
                me = _robot(status(cfg_path), r.id)
                return bool(me.get("present")) and not me.get("link_lost")

            wait_for(back, 20, "fleet status: r1 present again, its link up")
            _commands_flow(robot, 20, 20, "commands on cmd_vel again")
            assert agent.poll() is None and daemon.poll() is None
            assert "link restored" in tail(agent, 20000)
        finally:
            codes = stop_all(procs)
            if bus is not None:
                bus.close()
            stop.set()
            base.join(5)
            robot.close()
    assert codes == [0, 0], (codes, [tail(p) for p in procs])
