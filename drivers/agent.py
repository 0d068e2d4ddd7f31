"""The driver agent: binds one robot's driver to the bus (``fleet driver ROBOT_ID``).

Command in (``robot/<id>/cmd``), pose out (``robot/<id>/pose``), a liveliness token for presence,
and the robot-side safety layer that does not trust the network:

- a command that is not finite never gets here (the codec refuses it, counted by the bus);
  commands beyond the robot's limits are clamped (counted); a differential robot given vy != 0
  gets vy dropped (counted);
- **watchdog**: no valid command for ``cmd_ttl`` (or the command's own shorter ``ttl``) → stop
  the robot; it resumes on the next command;
- **e-stop**: a latched stop on the ``estop`` key, released only by an explicit resume;
- **link**: a driver whose link is lost stops, its token is withdrawn and an event is published.

``AgentCore`` is the pure decision part (time passed in); ``Agent`` is the I/O shell the lab
daemon and the lockstep dry run both drive by calling ``step(now)``.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass, field

from controller import wire
from drivers.base import Capabilities, DriverError, RobotDriver

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AgentParams:
    """The agent's settings: ``cmd_ttl`` (s) is the watchdog timeout."""

    robot_id: str
    fleet: str
    cmd_ttl: float = 0.3


@dataclass
class AgentCounters:
    commands: int = 0
    clamped: int = 0
    vy_dropped: int = 0
    watchdog_stops: int = 0
    estop_rejected: int = 0
    poses: int = 0
    link_lost: int = 0


@dataclass
class AgentCore:
    """Pure command gate: clamp, watchdog and latched e-stop. Times in seconds on one clock."""

    caps: Capabilities
    cmd_ttl: float
    counters: AgentCounters = field(default_factory=AgentCounters)
    estop: bool = False
    last_cmd: wire.Twist2D | None = None
    last_cmd_time: float = -math.inf
    stopped_by_watchdog: bool = True

    def gate(self, cmd: wire.Twist2D) -> wire.Twist2D:
        """Clamp a command to the robot's limits (and drop vy on a differential robot)."""
        vx, vy, wz = cmd.vx, cmd.vy, cmd.wz
        if not self.caps.holonomic and vy != 0.0:
            vy = 0.0
            self.counters.vy_dropped += 1
        speed = math.hypot(vx, vy)
        clamped = False
        if speed > self.caps.max_speed:
            k = self.caps.max_speed / speed
            vx, vy = vx * k, vy * k
            clamped = True
        if abs(wz) > self.caps.max_yaw_rate:
            wz = math.copysign(self.caps.max_yaw_rate, wz)
            clamped = True
        if clamped:
            self.counters.clamped += 1
        return wire.Twist2D(t=cmd.t, seq=cmd.seq, vx=vx, vy=vy, wz=wz, ttl=cmd.ttl)

    def on_command(self, now: float, cmd: wire.Twist2D) -> wire.Twist2D | None:
        """A command arrived at ``now``: the command to forward, or None (e-stopped)."""
        if self.estop:
            self.counters.estop_rejected += 1
            return None
        self.counters.commands += 1
        self.last_cmd = self.gate(cmd)
        self.last_cmd_time = now
        self.stopped_by_watchdog = False
        return self.last_cmd

    def on_estop(self, msg: wire.EStop) -> None:
        self.estop = bool(msg.engaged)

    def expired(self, now: float) -> bool:
        """Whether the watchdog must stop the robot at ``now``."""
        ttl = self.cmd_ttl
        if self.last_cmd is not None and self.last_cmd.ttl > 0:
            ttl = min(ttl, self.last_cmd.ttl)
        return now - self.last_cmd_time > ttl + 1e-9

    def must_stop(self, now: float) -> bool:
        """Whether the robot must be held stopped now (e-stop or an expired command)."""
        return self.estop or self.expired(now)


class Agent:
    """One robot's agent on the bus. Call ``step(now)`` at the control rate (or each sim tick)."""

    def __init__(
        self,
        bus,
        driver: RobotDriver,
        params: AgentParams,
        commands_arrived: threading.Condition | None = None,
    ) -> None:
        """``commands_arrived`` is notified when a command arrives (the lockstep waits on it)."""
        self.bus = bus
        self.driver = driver
        self.params = params
        self.core = AgentCore(driver.capabilities, params.cmd_ttl)
        rid = params.robot_id
        self._cmds = bus.subscribe_topic("robot_cmd", waker=commands_arrived, id=rid)
        self._estops = bus.subscribe_topic("estop")
        self._pose_pub = bus.publisher("robot_pose", id=rid)
        self._event_pub = bus.publisher("robot_event", id=rid)
        self._token = bus.declare_alive("robot", rid)
        self.link_ok = True
        self._seq = 0
        self._stopped_sent = False

    @property
    def pose_publisher(self):
        return self._pose_pub

    @property
    def counters(self) -> AgentCounters:
        return self.core.counters

    def commands_seen(self) -> int:
        """Commands received so far, taken in or still queued (the lockstep handshake)."""
        c = self.core.counters
        return c.commands + c.estop_rejected + self._cmds.qsize()

    def _event(self, now: float, kind: str, **data) -> None:
        self._seq += 1
        self._event_pub.put(wire.PlanEvent(t=now, seq=self._seq, kind=kind, data=data))

    def handle_inputs(self, now: float) -> None:
        """Apply e-stops and commands received since the last call, in arrival order."""
        for item in self._estops.drain():
            before = self.core.estop
            self.core.on_estop(item.msg)
            if self.core.estop != before:
                state = "engaged" if self.core.estop else "released"
                log.warning(
                    "robot %s: e-stop %s by %s", self.params.robot_id, state, item.msg.source
                )
                if self.core.estop:
                    self.driver.stop()
        latest = None
        for item in self._cmds.drain():
            out = self.core.on_command(now, item.msg)
            if out is not None:
                latest = out
        if latest is not None and self.link_ok:
            try:
                self.driver.send(latest)
                self._stopped_sent = False
            except DriverError as exc:
                self._lose_link(now, str(exc))

    def enforce(self, now: float) -> None:
        """Watchdog, e-stop and link checks at ``now``."""
        if self.link_ok:
            health = self.driver.health()
            if not health.ok:
                self._lose_link(now, health.detail)
        if self.core.must_stop(now) and not self._stopped_sent:
            if self.core.expired(now) and not self.core.estop and self.core.last_cmd is not None:
                self.core.counters.watchdog_stops += 1
                log.info("robot %s: watchdog stop (no command)", self.params.robot_id)
            self.driver.stop()
            self._stopped_sent = True

    def publish_poses(self) -> int:
        """Forward every pose measurement the driver has received; returns how many."""
        n = 0
        for m in self.driver.poll():
            self._pose_pub.put(m)
            n += 1
        self.core.counters.poses += n
        return n

    def step(self, now: float) -> None:
        """One agent cycle: inputs, safety checks, poses out."""
        self.handle_inputs(now)
        self.enforce(now)
        self.publish_poses()

    def _lose_link(self, now: float, detail: str) -> None:
        if not self.link_ok:
            return
        self.link_ok = False
        self.core.counters.link_lost += 1
        log.error("robot %s: link lost (%s): robot stopped", self.params.robot_id, detail)
        self.driver.stop()
        self._stopped_sent = True
        self._event(now, "link_lost", detail=detail)
        try:
            self._token.undeclare()
        except Exception:  # noqa: BLE001 - already gone
            pass

    def close(self) -> None:
        self.driver.close()
