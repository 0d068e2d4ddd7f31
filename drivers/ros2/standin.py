"""The robot's side of a ROS 2 robot on zenoh, as rmw_zenoh shows one: for tests and rehearsals.

:class:`RobotBase` is what a ROS 2 base exposes on its graph: a node (``robot_base`` in the
robot's namespace) with rmw_zenoh's liveliness tokens that subscribes to ``cmd_vel``
(``Twist`` or ``TwistStamped``) and publishes its pose (``nav_msgs/Odometry`` in its odom
frame, REP 105, or ``PoseStamped``), each sample with rmw_zenoh's attachment. What moves the
robot is the owner's: :class:`StandInRobot` runs its own kinematic model (a differential base
drops vy, an omni base takes it); ``fleet world --ros2`` makes a body of the shared world
(controller/runtime/world.py).

Its CDR is rosbags' (pure Python, an implementation independent of the driver's
mcap-ros2-support, drivers/ros2/msgs.py), so every exchange with the driver also checks one
codec against the other. Time is the caller's: ``step(dt)`` and ``publish(t)`` (the contract
suite's lockstep), or :meth:`StandInRobot.run` on the wall clock.
"""

from __future__ import annotations

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


class RobotBase:
    """One ROS 2 robot base's graph: ``cmd_vel`` in, its pose out, in its odom frame placed in
    our world by ``settings.odom_to_world`` (as the driver assumes). ``session``: an open zenoh
    session (not owned). ``keep_raw``: keep every command sample (payload, attachment) in
    ``raw_commands`` (the tests read them)."""

    def __init__(
        self,
        session: Any,
        settings: Ros2Settings,
        holonomic: bool,
        name: str = "robot_base",
        keep_raw: bool = False,
    ) -> None:
        self.settings = settings
        self.holonomic = holonomic
        self._cmd_type = CMD_TYPES[settings.cmd_type]
        self._pose_type = POSE_TYPES[settings.pose_type]
        self.commands: deque[tuple[bytes, bytes | None]] = deque()
        self.received = 0  # cmd_vel samples taken
        self.bad = 0  # cmd_vel samples that did not decode
        self.published = 0
        self.raw_commands: list[tuple[bytes, bytes | None]] = []
        self._keep_raw = keep_raw
        self.node = RmwNode(session, settings.domain_id, settings.namespace or "/", name)
        self.cmd_key = self.node.subscribe(settings.cmd_fq(), self._cmd_type, self._on_cmd)
        self.pub = self.node.publisher(settings.pose_fq(), self._pose_type)

    def _on_cmd(self, payload: bytes, attachment: bytes | None) -> None:
        self.commands.append((payload, attachment))  # zenoh's thread: enqueue only

    def commands_seen(self) -> int:
        """``cmd_vel`` samples received so far, taken or still queued (a lockstep handshake)."""
        return self.received + len(self.commands)

    def take_command(self) -> tuple[float, float, float] | None:
        """The latest body velocity (vx, vy, wz; m/s, rad/s; vy 0 on a differential base) of
        the ``cmd_vel`` samples that arrived since the last call, or None when none did (or
        none decoded: those are counted in ``bad``)."""
        latest = None
        while self.commands:
            payload, att = self.commands.popleft()
            self.received += 1
            if self._keep_raw:
                self.raw_commands.append((payload, att))
            try:
                msg = rosbags_decode(self._cmd_type, payload)
            except Exception:  # noqa: BLE001 - a robot drops what it cannot read
                self.bad += 1
                continue
            tw = msg if self.settings.cmd_type == "twist" else msg.twist
            latest = (tw.linear.x, tw.linear.y if self.holonomic else 0.0, tw.angular.z)
        return latest

    def publish_pose(
        self, t: float, x: float, y: float, yaw: float, velocity=(0.0, 0.0, 0.0)
    ) -> None:
        """Publish the world pose (x, y in m, yaw in rad) in the odom frame, stamped ``t`` (s
        since the epoch, also the attachment's source time); ``velocity``: the body twist an
        Odometry carries."""
        ox, oy, oyaw = keys.world_to_odom(x, y, yaw, self.settings.odom_to_world)
        payload = rosbags_pose(self._pose_type, t, ox, oy, oyaw, velocity)
        self.pub.put(payload, int(t * 1e9))
        self.published += 1

    def close(self) -> None:
        self.node.close()


class StandInRobot(RobotBase):
    """A ROS 2 robot base with its own kinematic model: ``start`` is its pose in our world.
    ``cmd_timeout`` (s): stop when ``cmd_vel`` has been silent that long (None: never)."""

    def __init__(
        self,
        session: Any,
        settings: Ros2Settings,
        kind: str,
        start: tuple[float, float, float],
        cmd_timeout: float | None = None,
        name: str = "robot_base",
    ) -> None:
        super().__init__(session, settings, kind == "omni", name, keep_raw=True)
        self.cmd_timeout = cmd_timeout
        self.pose = [float(v) for v in start]
        self.t = 0.0
        self._cmd = (0.0, 0.0, 0.0)
        self._cmd_age = 0.0

    def step(self, dt: float) -> None:
        """Take the commands that arrived, then move ``dt`` seconds (exact for constant
        body velocities over small substeps)."""
        cmd = self.take_command()
        if cmd is not None:
            self._cmd, self._cmd_age = cmd, 0.0
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
        self.publish_pose(self.t if t is None else t, *self.pose, self._cmd)

    def run(
        self,
        rate_hz: float,
        stop: threading.Event,
        clock=time.time,
        mute: threading.Event | None = None,
    ) -> None:
        """Real time: step and publish at ``rate_hz`` until ``stop`` is set; while ``mute`` is
        set it still moves and takes commands but publishes no pose (its odometry withheld)."""
        period = 1.0 / rate_hz
        next_t = time.monotonic()
        while not stop.is_set():
            self.step(period)
            if mute is None or not mute.is_set():
                self.publish(clock())
            next_t += period
            stop.wait(max(0.0, next_t - time.monotonic()))
