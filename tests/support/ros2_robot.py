"""A stand-in ROS 2 robot on zenoh, as rmw_zenoh shows one: for tests and lab rehearsals.

It is a node (``robot_base`` in the robot's namespace) with rmw_zenoh's liveliness tokens that
subscribes to ``cmd_vel`` (``Twist`` or ``TwistStamped``) and publishes its pose
(``nav_msgs/Odometry`` in its odom frame, REP 105, or ``PoseStamped``) from a kinematic model:
a differential base drops vy, an omni base takes it. Its CDR is rosbags' (pure Python, an
implementation independent of the driver's mcap-ros2-support), so every exchange with the
driver also checks one codec against the other. Time is the caller's: ``step(dt)`` and
``publish(t)`` (the contract suite's lockstep), or :meth:`run` on the wall clock.

Rehearsal, beside ``fleet driver r5`` of a config whose robot r5 has ``driver = "ros2"``:

    python -m tests.support.ros2_robot --config fleet.toml --robot r5 \
        --listen tcp/127.0.0.1:7447
"""

from __future__ import annotations

import argparse
import math
import threading
import time
from collections import deque
from typing import Any

from rosbags.typesys import Stores, get_typestore

from drivers.ros2 import keys
from drivers.ros2.driver import Ros2Settings
from drivers.ros2.msgs import CMD_TYPES, POSE_TYPES
from drivers.ros2.node import RmwNode

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def rosbags_decode(type_name: str, payload: bytes) -> Any:
    """A CDR payload decoded by rosbags (the independent codec)."""
    return TYPESTORE.deserialize_cdr(bytes(payload), type_name)


def _time(t: float) -> Any:
    ns = int(round(t * 1e9))
    return TYPESTORE.types["builtin_interfaces/msg/Time"](
        sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000
    )


def rosbags_pose(type_name: str, t: float, x: float, y: float, yaw: float, v=(0.0, 0.0, 0.0)):
    """A pose message built with rosbags' types, CDR-encoded by rosbags."""
    import numpy as np

    T = TYPESTORE.types
    header = T["std_msgs/msg/Header"](stamp=_time(t), frame_id="odom")
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                       orientation=q)  # fmt: skip
    if type_name == "geometry_msgs/msg/PoseStamped":
        msg = T[type_name](header=header, pose=pose)
    else:
        vec = T["geometry_msgs/msg/Vector3"]
        twist = T["geometry_msgs/msg/Twist"](linear=vec(x=v[0], y=v[1], z=0.0),
                                             angular=vec(x=0.0, y=0.0, z=v[2]))  # fmt: skip
        msg = T[type_name](
            header=header,
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
        )
    return bytes(TYPESTORE.serialize_cdr(msg, type_name))


class StandInRobot:
    """One ROS 2 robot base: ``start`` is its pose in our world; it reports poses in its odom
    frame, placed in the world by ``settings.odom_to_world`` (as the driver assumes)."""

    def __init__(
        self,
        session: Any,
        settings: Ros2Settings,
        kind: str,
        start: tuple[float, float, float],
        cmd_timeout: float | None = None,
        name: str = "robot_base",
    ) -> None:
        self.settings = settings
        self.holonomic = kind == "omni"
        self.cmd_timeout = cmd_timeout
        self.pose = [float(v) for v in start]
        self.t = 0.0
        self._cmd = (0.0, 0.0, 0.0)
        self._cmd_age = 0.0
        self._cmd_type = CMD_TYPES[settings.cmd_type]
        self._pose_type = POSE_TYPES[settings.pose_type]
        self.commands: deque[tuple[bytes, bytes | None]] = deque()
        self.received = 0  # cmd_vel samples taken
        self.published = 0
        self.node = RmwNode(session, settings.domain_id, settings.namespace or "/", name)
        self.cmd_key = self.node.subscribe(settings.cmd_fq(), self._cmd_type, self._on_cmd)
        self.pub = self.node.publisher(settings.pose_fq(), self._pose_type)
        self.raw_commands: list[tuple[bytes, bytes | None]] = []  # every sample, for the tests

    def _on_cmd(self, payload: bytes, attachment: bytes | None) -> None:
        self.commands.append((payload, attachment))  # zenoh's thread: enqueue only

    def commands_seen(self) -> int:
        return self.received + len(self.commands)

    def _apply_commands(self) -> None:
        while self.commands:
            payload, att = self.commands.popleft()
            self.received += 1
            self.raw_commands.append((payload, att))
            msg = rosbags_decode(self._cmd_type, payload)
            tw = msg if self.settings.cmd_type == "twist" else msg.twist
            self._cmd = (tw.linear.x, tw.linear.y if self.holonomic else 0.0, tw.angular.z)
            self._cmd_age = 0.0

    def step(self, dt: float) -> None:
        """Take the commands that arrived, then move ``dt`` seconds (exact for constant
        body velocities over small substeps)."""
        self._apply_commands()
        n = max(1, math.ceil(dt / 0.005))
        h = dt / n
        for _ in range(n):
            vx, vy, wz = self._cmd
            if self.cmd_timeout is not None and self._cmd_age > self.cmd_timeout:
                vx = vy = wz = 0.0
            x, y, th = self.pose
            mid = th + 0.5 * wz * h
            x += (vx * math.cos(mid) - vy * math.sin(mid)) * h
            y += (vx * math.sin(mid) + vy * math.cos(mid)) * h
            self.pose = [x, y, math.remainder(th + wz * h, 2 * math.pi)]
            self._cmd_age += h
        self.t += dt

    def publish(self, t: float | None = None) -> None:
        """Publish the current pose (odom frame) stamped ``t`` (default: its own time)."""
        t = self.t if t is None else t
        ox, oy, oyaw = keys.world_to_odom(*self.pose, self.settings.odom_to_world)
        payload = rosbags_pose(self._pose_type, t, ox, oy, oyaw, self._cmd)
        self.pub.put(payload, int(t * 1e9))
        self.published += 1

    def run(self, rate_hz: float, stop: threading.Event, clock=time.time) -> None:
        """Real time: step and publish at ``rate_hz`` until ``stop`` is set."""
        period = 1.0 / rate_hz
        next_t = time.monotonic()
        while not stop.is_set():
            self.step(period)
            self.publish(clock())
            next_t += period
            stop.wait(max(0.0, next_t - time.monotonic()))

    def close(self) -> None:
        self.node.close()


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
