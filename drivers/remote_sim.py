"""The remote sim driver: the driver contract over the shared stand-in world process.

``fleet world`` runs one world for the whole fleet on the wall clock. A ``sim`` robot's agent
(``fleet driver`` with ``sim.world = "process"``) reaches its robot in that world through this
adapter, over the bus like a radio link to a real vehicle:

- ``send``/``stop`` put the command the agent applies (already gated: clamped, e-stop, watchdog)
  on ``fleet/<fleet>/sim/world/<id>/cmd`` (``Twist2D``; its ``ttl`` is the vehicle's own setpoint
  timeout: the world stops a robot whose command stream goes silent that long, as a PX4 rover
  does). The last command is repeated every ``keepalive`` seconds (from ``health``, which the
  agent calls every cycle), so one lost sample never leaves a robot on a stale setpoint;
- ``poll`` returns the robot's sensor samples the world put on ``.../sim/world/<id>/pose``
  (``PoseMeasurement``, stamped by the world in the lab's clock domain, wall time);
- ``connect`` waits for the first sample (``ConnectTimeout`` naming the key when the world does
  not serve this robot); the link is lost when no sample came for ``link_timeout`` seconds.

``bus`` is any object with the bus's ``key``, ``subscribe_topic(topic, **parts)`` (an inbox
with ``drain``/``get``) and ``publisher(topic, command=..., **parts)`` (``put``): drivers/
imports nothing of the controller but the wire contract.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from controller.wire import PoseMeasurement, Twist2D
from drivers.base import Capabilities, ConnectTimeout, LinkHealth, LinkLost

VEHICLE_TIMEOUT = 1.0  # s the world keeps a robot's last command once the stream stops
KEEPALIVE = 0.1  # s between repeats of the last command


class RemoteSimDriver:
    """One robot of the shared world process behind the driver contract."""

    def __init__(
        self,
        bus,
        robot_id: str,
        capabilities: Capabilities,
        *,
        clock: Callable[[], float] = time.time,
        link_timeout: float = 2.5,
        keepalive: float = KEEPALIVE,
        vehicle_timeout: float = VEHICLE_TIMEOUT,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        """``clock`` stamps the commands (the lab's clock domain); ``monotonic`` measures the
        link's silences and the keepalive."""
        self.robot_id = robot_id
        self.capabilities = capabilities
        self._clock = clock
        self._mono = monotonic
        self.link_timeout = link_timeout
        self.keepalive = keepalive
        self.vehicle_timeout = vehicle_timeout
        # lossless: the robot's own samples, counted for the handshake (samples_seen); only the
        # world puts there (lab ACL), and the agent drains them every step
        self._poses = bus.subscribe_topic("world_pose", lossless=True, id=robot_id)
        self._pub = bus.publisher("world_cmd", command=True, id=robot_id)
        self.pose_key = bus.key("world_pose", id=robot_id)
        self._pending: list[PoseMeasurement] = []
        self._connected = False
        self._closed = False
        self._last_heard: float | None = None
        self._last_cmd = (0.0, 0.0, 0.0)
        self._last_sent = -float("inf")
        self.sent = 0  # commands put on the bus (keepalives included)
        self.received = 0  # pose samples taken from the bus

    # -- link
    def connect(self, timeout: float) -> None:
        """The handshake: the world serves this robot (its first pose sample arrived) and hears
        its commands (the command publisher matches the world's subscriber)."""
        deadline = self._mono() + max(0.0, timeout)
        item = self._poses.get(timeout=max(0.0, timeout))
        if item is None:
            raise ConnectTimeout(
                f"no pose from the world process for robot {self.robot_id} after {timeout:g} s "
                f"on {self.pose_key} (is fleet world running with this robot? a slow machine "
                "may need a longer --connect-timeout)"
            )
        self._take([item])
        wait = threading.Event()
        while not self._pub.matching():
            if self._mono() >= deadline:
                raise ConnectTimeout(
                    f"the world process took no command for robot {self.robot_id} on "
                    f"{self._pub.key} after {timeout:g} s (a slow machine may need a longer "
                    "--connect-timeout)"
                )
            wait.wait(0.01)  # polling the match (a handshake with a deadline)
        self._connected = True
        self._closed = False

    def samples_seen(self) -> int:
        """Pose samples received so far, taken or still queued (a lockstep handshake)."""
        return self.received + self._poses.qsize()

    def _take(self, items) -> None:
        for item in items:
            self._pending.append(item.msg)
        if items:
            self.received += len(items)
            self._last_heard = self._mono()

    def _silence(self) -> float:
        if self._last_heard is None:
            return float("inf")
        return self._mono() - self._last_heard

    def health(self) -> LinkHealth:
        if not self._connected:
            return LinkHealth(False, "not connected")
        self._take(self._poses.drain())
        silent = self._silence()
        if silent > self.link_timeout:
            return LinkHealth(False, f"no pose from the world process for {silent:.1f} s")
        if self._mono() - self._last_sent >= self.keepalive:
            self._put(*self._last_cmd)
        return LinkHealth(True, "", self._last_heard)

    # -- commands
    def _put(self, vx: float, vy: float, wz: float) -> None:
        self.sent += 1
        self._last_cmd = (vx, vy, wz)
        self._last_sent = self._mono()
        self._pub.put(
            Twist2D(t=self._clock(), seq=self.sent, vx=vx, vy=vy, wz=wz, ttl=self.vehicle_timeout)
        )

    def send(self, cmd: Twist2D) -> None:
        if not self._connected:
            raise LinkLost(f"robot {self.robot_id}: not connected to the world process")
        if self._silence() > self.link_timeout:
            raise LinkLost(f"robot {self.robot_id}: the world process went silent")
        self._put(cmd.vx, cmd.vy, cmd.wz)

    def stop(self) -> None:
        if not self._connected:
            return
        try:
            self._put(0.0, 0.0, 0.0)
        except Exception:  # noqa: BLE001 - stop never raises
            pass

    # -- poses
    def poll(self) -> list[PoseMeasurement]:
        if not self._connected:
            return []
        self._take(self._poses.drain())
        out, self._pending = self._pending, []
        return out

    def close(self) -> None:
        if self._closed:
            return
        self.stop()
        self._connected = False
        self._closed = True
