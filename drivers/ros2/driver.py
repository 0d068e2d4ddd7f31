"""The ROS 2 driver: the driver contract (drivers/base.py) over a ROS 2 robot's own topics,
straight on zenoh with rmw_zenoh's keys, attachments and liveliness tokens (no bridge).

Our side is a ROS 2 node (``node_name`` in the robot's ``namespace`` on ``domain_id``):

- ``send``/``stop`` publish ``geometry_msgs/msg/Twist`` (or ``TwistStamped``, ``cmd_type``) on
  ``cmd_topic``: the body frame of REP 103 is our command's (x forward, y left, z up), so
  vx, vy, wz go to linear.x, linear.y, angular.z unchanged;
- ``poll`` returns the poses of ``pose_topic`` (``nav_msgs/msg/Odometry`` from the robot's
  odometry, or ``geometry_msgs/msg/PoseStamped`` from motion capture), mapped from the robot's
  odom frame (REP 105) to our world by ``odom_to_world``; each is stamped with its header
  stamp (``time_source = "header"``: the robot's clock, synchronised with ours) or with our
  clock on receipt (``"receipt"``); sigma from the covariance when the message has one;
- a pose whose stamp is older than ``stale_after`` (``fleet.stale_after``) on our clock is
  stale: counted and dropped, it does not keep the link alive; the link is lost when no fresh
  pose came for ``link_timeout`` seconds (``[robots.ros2] link_timeout``; until then the robot
  is only stale for the controller, which stops commanding it); the node, its subscription and
  the session stay, so the link is up again with the next fresh pose (``fleet driver`` holds
  the robot stopped meanwhile and reports ``link_restored`` then);
- ``connect`` waits for the first fresh pose and for the robot's ``cmd_vel`` subscription to
  match our publisher (``ConnectTimeout`` naming the key).

Settings come from the robot's ``[robots.ros2]`` table (controller/config/driver_sections.py),
read by the wiring into :class:`Ros2Settings`: drivers/ imports nothing of the config.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from controller.wire import PoseMeasurement, Twist2D
from drivers.base import Capabilities, ConnectTimeout, LinkHealth, LinkLost
from drivers.ros2 import keys, msgs
from drivers.ros2.node import RmwNode, open_session

log = logging.getLogger(__name__)

ROUTER = "tcp/127.0.0.1:7447"  # rmw_zenohd's default listen endpoint (on the robot's host)


@dataclass(frozen=True)
class Ros2Settings:
    """One ROS 2 robot's link (the ``[robots.ros2]`` keys; units SI, angles rad)."""

    domain_id: int = 0
    namespace: str = ""
    node_name: str = ""  # "" : fleet_driver_<robot id>
    cmd_topic: str = "cmd_vel"
    cmd_type: str = "twist"
    cmd_frame_id: str = "base_link"
    pose_topic: str = "odom"
    pose_type: str = "odometry"
    odom_to_world: tuple[float, float, float] = (0.0, 0.0, 0.0)
    time_source: str = "header"
    sigma_xy: float = 0.02
    sigma_theta: float = 0.02
    connect: tuple[str, ...] = (ROUTER,)
    mode: str = "client"
    link_timeout: float = 2.5  # s without a fresh pose: the link is lost
    rmw_zenoh: str = ""  # the robot's rmw_zenoh release as configured ("": not stated)

    def cmd_key(self) -> str:
        ros_type = msgs.CMD_TYPES[self.cmd_type]
        return keys.topic_key(self.domain_id, self.cmd_fq(), ros_type)

    def pose_key(self) -> str:
        ros_type = msgs.POSE_TYPES[self.pose_type]
        return keys.topic_key(self.domain_id, self.pose_fq(), ros_type)

    def cmd_fq(self) -> str:
        return keys.qualify(self.namespace, self.cmd_topic)

    def pose_fq(self) -> str:
        return keys.qualify(self.namespace, self.pose_topic)


class Ros2Driver:
    """One ROS 2 robot behind the driver contract."""

    def __init__(
        self,
        robot_id: str,
        capabilities: Capabilities,
        settings: Ros2Settings,
        *,
        stale_after: float,
        clock: Callable[[], float] = time.time,
        monotonic: Callable[[], float] = time.monotonic,
        session: Any = None,
    ) -> None:
        """``clock`` stamps commands and judges a pose's age (the lab's clock domain);
        ``monotonic`` measures silences; ``session``: an open zenoh session to use (not
        closed here), else one is opened on ``settings.connect`` at ``connect``."""
        self.robot_id = robot_id
        self.capabilities = capabilities
        self.settings = settings
        self.stale_after = stale_after
        self._clock = clock
        self._mono = monotonic
        self._session = session
        self._own_session = session is None
        self._node: RmwNode | None = None
        self._pub: Any = None
        self._inbox: deque[tuple[bytes, float]] = deque(maxlen=1000)
        self._arrived = threading.Event()
        self._pending: list[PoseMeasurement] = []
        self._last_heard: float | None = None
        self._connected = False
        self._closed = False
        self.pose_type = msgs.POSE_TYPES[settings.pose_type]
        self.cmd_type = msgs.CMD_TYPES[settings.cmd_type]
        self.cmd_key = settings.cmd_key()
        self.pose_key = settings.pose_key()
        self.sent = 0  # commands published
        self.received = 0  # pose samples taken off the bus
        self.bad = 0  # pose payloads that did not decode
        self.stale = 0  # poses older than stale_after on arrival
        self.foreign_attachments = 0  # pose samples whose attachment is not rmw_zenoh's 33 bytes
        self._seq = 0

    # -- link
    def open(self) -> None:
        """Join the robot's ROS graph (node, command publisher, pose subscription) without
        waiting for the robot; ``connect`` does it when not done yet."""
        if self._node is not None:
            return
        s = self.settings
        if self._session is None:
            try:
                self._session = open_session(s.connect, mode=s.mode)
            except Exception as exc:  # zenoh.ZError: nothing listens at the endpoints yet
                raise ConnectTimeout(
                    f"robot {self.robot_id!r}: no zenoh router of its ROS graph at "
                    f"{', '.join(s.connect)} ({exc})"
                ) from exc
        name = s.node_name or f"fleet_driver_{self.robot_id.replace('-', '_')}"
        self._node = RmwNode(self._session, s.domain_id, s.namespace or "/", name)
        self._pub = self._node.publisher(s.cmd_fq(), self.cmd_type, express=True)
        self._node.subscribe(s.pose_fq(), self.pose_type, self._on_pose)

    def _on_pose(self, payload: bytes, attachment: bytes | None) -> None:
        # zenoh's thread: enqueue only (the stamp of receipt on our clock)
        self._inbox.append((payload, self._clock()))
        if attachment is None or len(attachment) != keys.ATTACHMENT_SIZE:
            self.foreign_attachments += 1
            if self.foreign_attachments == 1:
                log.error(
                    "robot %s: its %s carries a %s attachment, not rmw_zenoh's %d bytes: an "
                    "rmw_zenoh older than %s, which drops our commands (upgrade the robot's "
                    "rmw_zenoh)", self.robot_id, self.pose_key,
                    "missing" if attachment is None else f"{len(attachment)}-byte",
                    keys.ATTACHMENT_SIZE, keys.SUPPORTED_RMW_ZENOH,
                )  # fmt: skip
        self._arrived.set()

    def connect(self, timeout: float) -> None:
        """The handshake: a fresh pose arrived and the robot subscribes to our commands. On
        ConnectTimeout the link is released (the session too, when ours): the agent does not
        close a driver that never connected. A router not up yet is retried until then."""
        deadline = self._mono() + max(0.0, timeout)
        retry = threading.Event()
        while True:
            try:
                self.open()
                break
            except ConnectTimeout:
                if self._mono() + 0.2 >= deadline:
                    raise
                retry.wait(0.2)  # the router's own start (rmw_zenohd, the stand-in)
        try:
            self._handshake(deadline, timeout)
        except ConnectTimeout:
            self.close()
            raise
        self._connected = True
        self._closed = False

    def _handshake(self, deadline: float, timeout: float) -> None:
        while not self._take():
            left = deadline - self._mono()
            if left <= 0:
                raise ConnectTimeout(
                    f"robot {self.robot_id!r}: no fresh {self.pose_type} on {self.pose_key} "
                    f"within {timeout:g} s (is the robot up on ROS domain "
                    f"{self.settings.domain_id}, its router reachable at "
                    f"{', '.join(self.settings.connect)}?)"
                )
            self._arrived.clear()
            self._arrived.wait(min(left, 0.05))
        wait = threading.Event()
        while not self._pub.matching():
            if self._mono() >= deadline:
                raise ConnectTimeout(
                    f"robot {self.robot_id!r}: nothing subscribes to {self.cmd_key} "
                    f"(within {timeout:g} s): check cmd_topic and cmd_type"
                )
            wait.wait(0.01)  # polling the match (a handshake with a deadline)

    def samples_seen(self) -> int:
        """Pose samples received so far, taken or still queued (a lockstep handshake)."""
        return self.received + len(self._inbox)

    def _take(self) -> int:
        """Decode what arrived into pending measurements; the number of fresh poses."""
        fresh = 0
        while self._inbox:
            payload, t_recv = self._inbox.popleft()
            self.received += 1
            m = self._measurement(payload, t_recv)
            if m is not None:
                self._pending.append(m)
                self._last_heard = self._mono()
                fresh += 1
        return fresh

    def _measurement(self, payload: bytes, t_recv: float) -> PoseMeasurement | None:
        s = self.settings
        try:
            p = msgs.read_pose(s.pose_type, msgs.decode(self.pose_type, payload))
        except ValueError as exc:
            self.bad += 1
            if self.bad == 1:
                log.warning("robot %s: a bad %s payload (more are counted): %s",
                            self.robot_id, self.pose_type, exc)  # fmt: skip
            return None
        t = p.t if s.time_source == "header" else t_recv
        if self._clock() - t > self.stale_after or not all(map(math.isfinite, (p.x, p.y, p.yaw))):
            self.stale += 1
            return None
        x, y, theta = keys.odom_to_world(p.x, p.y, p.yaw, s.odom_to_world)
        self._seq += 1
        return PoseMeasurement(
            t=t,
            seq=self._seq,
            x=x,
            y=y,
            theta=theta,
            sigma_xy=math.sqrt(p.var_xy) if p.var_xy > 0 else s.sigma_xy,
            sigma_theta=math.sqrt(p.var_yaw) if p.var_yaw > 0 else s.sigma_theta,
            source="ros2",
        )

    def _silence(self) -> float:
        if self._last_heard is None:
            return float("inf")
        return self._mono() - self._last_heard

    def health(self) -> LinkHealth:
        if not self._connected:
            return LinkHealth(False, "not connected")
        self._take()
        silent = self._silence()
        if silent > self.settings.link_timeout:
            return LinkHealth(
                False, f"no fresh {self.pose_type} on {self.pose_key} for {silent:.2f} s"
            )
        return LinkHealth(True, "", self._last_heard)

    # -- commands
    def _put(self, vx: float, vy: float, wz: float) -> None:
        s = self.settings
        t = self._clock()
        msg = msgs.twist_message(s.cmd_type, vx, vy, wz, t, s.cmd_frame_id)
        self._pub.put(msgs.encode(self.cmd_type, msg), int(t * 1e9))
        self.sent += 1

    def send(self, cmd: Twist2D) -> None:
        if not self._connected:
            raise LinkLost(f"robot {self.robot_id}: not connected")
        self._take()
        if self._silence() > self.settings.link_timeout:
            raise LinkLost(f"robot {self.robot_id}: no fresh pose on {self.pose_key}")
        self._put(cmd.vx, cmd.vy, cmd.wz)

    def stop(self) -> None:
        if self._pub is None:
            return
        try:
            self._put(0.0, 0.0, 0.0)
        except Exception:  # noqa: BLE001 - stop never raises
            pass

    # -- poses
    def poll(self) -> list[PoseMeasurement]:
        if not self._connected:
            return []
        self._take()
        out, self._pending = self._pending, []
        return out

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.stop()
        self._connected = False
        if self._node is not None:
            self._node.close()
            self._node = None
        self._pub = None
        if self._own_session and self._session is not None:
            self._session.close()
            self._session = None
