"""The driver agent: binds one robot's driver to the bus (``fleet driver ROBOT_ID``).

Command in (``robot/<id>/cmd``), pose out (``robot/<id>/pose``), a liveliness token for presence,
and the robot-side safety layer that does not trust the network:

- a command that is not finite never gets here (the codec refuses it, counted by the bus);
  commands beyond the robot's limits are clamped (counted); a differential robot given vy != 0
  gets vy dropped (counted);
- **watchdog**: no valid command for ``cmd_ttl`` (or the command's own shorter ``ttl``) → stop
  the robot; it resumes on the next command;
- **e-stop**: a latched stop on the ``estop`` key, released only by an operator's resume
  (``controller.latch``: the one latch of every holder; a release at or below the latch's epoch
  is refused). The agent holds the latch itself and answers queries for it
  (``estop/state/robot/<id>``): a late agent asks every holder (hub, controller, other agents);
  any engaged answer at its epoch stops it, a released one never releases it, and a fresh agent
  (the lab: ``latch_at_start`` None) stays stopped until it learns the latch from the hub or the
  controller, or an operator releases it. ``fleet estop`` reads each agent's answer as its
  confirmation;
- **stamps**: a command stamped further than ``max_clock_skew`` from the agent's clock (the same
  domain: wall time in the lab, sim time in the dry run) is dropped and counted (``skewed``);
- **link**: a driver whose link is lost stops, its token is withdrawn and an event is published
  (``link_lost``); when the link comes back (or a new agent starts) ``link_restored`` follows.

``AgentCore`` is the pure decision part (time passed in); ``Agent`` is the I/O shell the lab
daemon and the lockstep dry run both drive by calling ``step(now)``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field

from controller import wire
from controller.latch import FRESH_WORLD, Latch, note_latch, role_of
from drivers.base import Capabilities, DriverError, RobotDriver

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AgentParams:
    """The agent's settings: ``cmd_ttl`` (s) is the watchdog timeout."""

    robot_id: str
    fleet: str
    cmd_ttl: float = 0.3
    max_clock_skew: float = 1.0
    # s: an operator's release stamped further than this from the agent's clock is refused
    # (a replayed old resume); the lab's wall clock only (in the dry run, commands and the
    # agent's clock are sim time, an operator's e-stop is not)
    release_max_age: float = math.inf


@dataclass
class AgentCounters:
    commands: int = 0
    clamped: int = 0
    vy_dropped: int = 0
    watchdog_stops: int = 0
    estop_rejected: int = 0
    poses: int = 0
    link_lost: int = 0
    link_restored: int = 0
    skewed: int = 0


@dataclass
class AgentCore:
    """Pure command gate: clamp, watchdog and latched e-stop. Times in seconds on one clock."""

    caps: Capabilities
    cmd_ttl: float
    counters: AgentCounters = field(default_factory=AgentCounters)
    max_clock_skew: float = math.inf
    # the latched e-stop (a fresh world's release unless given; None in it: unknown, stopped)
    latch: Latch = field(default_factory=lambda: Latch("robot", FRESH_WORLD))
    last_cmd: wire.Twist2D | None = None
    last_cmd_time: float = -math.inf

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
        """A command arrived at ``now``: the command to forward, or None (e-stopped, or its
        stamp too far from ``now``)."""
        if abs(cmd.t - now) > self.max_clock_skew:
            self.counters.skewed += 1
            return None
        if self.estop:
            self.counters.estop_rejected += 1
            return None
        self.counters.commands += 1
        self.last_cmd = self.gate(cmd)
        self.last_cmd_time = now
        return self.last_cmd

    @property
    def estop(self) -> bool:
        """Whether the robot is held stopped by the latch (engaged, or unknown)."""
        return self.latch.stopped

    def expired(self, now: float) -> bool:
        """Whether the watchdog must stop the robot at ``now``."""
        ttl = self.cmd_ttl
        if self.last_cmd is not None and self.last_cmd.ttl > 0:
            ttl = min(ttl, self.last_cmd.ttl)
        return now - self.last_cmd_time > ttl + 1e-9

    def must_stop(self, now: float) -> bool:
        """Whether the robot must be held stopped now (e-stop or an expired command)."""
        return self.estop or self.expired(now)


class _Replies:
    """Latch answers put by zenoh's thread (items with ``key`` and ``msg``), drained by the
    agent loop (``deque`` appends and pops are atomic)."""

    def __init__(self) -> None:
        self._q: deque = deque()

    def put(self, item) -> None:
        self._q.append(item)

    def drain(self) -> list:
        out = []
        while self._q:
            out.append(self._q.popleft())
        return out


class Agent:
    """One robot's agent on the bus. Call ``step(now)`` at the control rate (or each sim tick)."""

    def __init__(
        self,
        bus,
        driver: RobotDriver,
        params: AgentParams,
        commands_arrived: threading.Condition | None = None,
        latch_at_start: wire.EStop | None = FRESH_WORLD,
        estop_bus=None,
    ) -> None:
        """``commands_arrived`` is notified when a command arrives (the lockstep waits on it).
        ``latch_at_start``: the e-stop latch the agent starts with - a fresh world's release (the
        dry run, tests: the default) or None: unknown, the robot stopped (``fleet driver``).
        ``estop_bus``: the e-stop's second path (a session to the daemon's own listener): the
        operators' e-stops are taken from it too and the latch answered there, so an e-stop
        reaches the robot with the hub hung or dead."""
        self.bus = bus
        self.driver = driver
        self.params = params
        self.core = AgentCore(
            driver.capabilities,
            params.cmd_ttl,
            max_clock_skew=params.max_clock_skew,
            latch=Latch(f"robot/{params.robot_id}", latch_at_start),
        )
        rid = params.robot_id
        # lossless: the lockstep handshake counts every command, and no e-stop may be lost
        self._cmds = bus.subscribe_topic("robot_cmd", waker=commands_arrived, lossless=True, id=rid)
        self._estop_arrived = threading.Condition()  # wakes the loop's wait (wait_for_estop)
        self._estops = bus.subscribe_topic("estop", waker=self._estop_arrived, lossless=True)
        self._second_estops = (
            None
            if estop_bus is None
            else estop_bus.subscribe_topic("estop", waker=self._estop_arrived, lossless=True)
        )
        self._latch_replies = _Replies()
        self._pose_pub = bus.publisher("robot_pose", id=rid)
        self._event_pub = bus.publisher("robot_event", id=rid)
        self._latch_key = bus.serve_estop("robot", rid, self.latch_state)
        if estop_bus is not None:
            estop_bus.serve_estop("robot", rid, self.latch_state)
        self._token = bus.declare_alive("robot", rid)
        self.link_ok = True
        self.latch_answered = False  # some other holder answered a latch query
        self._seq = 0
        self._stopped_sent = False
        self._skew_told = False  # the drop of skewed commands was logged (until one passes)

    def latch_state(self) -> wire.EStop | None:
        """This agent's latched e-stop (answered on ``estop/state/robot/<id>``; runs on zenoh's
        thread); None (no answer) while unknown."""
        return self.core.latch.state()

    def request_latch(self, timeout: float = 1.0) -> None:
        """Ask every holder for the latched e-stop without waiting; the answers are applied by
        ``handle_inputs``."""
        self.bus.query_async(
            self.bus.estop_wildcard(), wire.EStop, self._latch_replies, timeout=timeout
        )

    def sync_latch(self, timeout: float) -> bool:
        """Ask every holder for the latched e-stop until one (not this agent) answers or
        ``timeout`` s pass (a session just opened may not yet see the holders' queryables);
        applies the answers (``Latch.answers``). Returns whether anyone answered."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            got = [
                (role_of(k, self.params.fleet), msg)
                for k, msg in self.bus.query_replies(
                    self.bus.estop_wildcard(), wire.EStop, timeout=max(0.05, min(0.5, left))
                )
                if k != self._latch_key
            ]
            if got:
                self.latch_answered = True
                self._apply_answers(got)
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.05)  # polling: nobody answered yet (a retry, not a handshake stand-in)

    def _apply_answers(self, answers: list[tuple[str, wire.EStop]]) -> None:
        before = self.core.estop
        self._note_estop(before, self.core.latch.answers(answers))

    def _apply_operator(self, msg: wire.EStop, now: float) -> None:
        before = self.core.estop
        age = self.params.release_max_age
        change = self.core.latch.operator(msg, now if math.isfinite(age) else None, age)
        self._note_estop(before, change)

    @property
    def pose_publisher(self):
        return self._pose_pub

    @property
    def counters(self) -> AgentCounters:
        return self.core.counters

    def commands_seen(self) -> int:
        """Commands received so far, taken in or still queued (the lockstep handshake)."""
        c = self.core.counters
        return c.commands + c.estop_rejected + c.skewed + self._cmds.qsize()

    def _event(self, now: float, kind: str, **data) -> None:
        self._seq += 1
        self._event_pub.put(wire.PlanEvent(t=now, seq=self._seq, kind=kind, data=data))

    def handle_inputs(self, now: float) -> None:
        """Apply e-stops (live ones in arrival order, latch answers when newer) and commands
        received since the last call."""
        fleet = self.params.fleet
        replies = [
            (role_of(i.key, fleet), i.msg)
            for i in self._latch_replies.drain()
            if i.key != self._latch_key
        ]
        if replies:
            self.latch_answered = True
            self._apply_answers(replies)
        for inbox in (self._estops, self._second_estops):  # a repeat is harmless (its epoch)
            for item in [] if inbox is None else inbox.drain():
                self._apply_operator(item.msg, now)
        latest = None
        for item in self._cmds.drain():
            skewed = self.core.counters.skewed
            out = self.core.on_command(now, item.msg)
            if out is not None:
                latest = out
                self._skew_told = False
            elif self.core.counters.skewed > skewed and not self._skew_told:
                self._skew_told = True  # once per run of skewed commands: the reason, named
                log.warning(
                    "robot %s: commands are stamped %+.3f s from this computer's clock, beyond "
                    "max_clock_skew (%.3f s): dropped, the robot stands still until the clocks "
                    "agree (NTP or chrony here and on the controller's computer)",
                    self.params.robot_id,
                    item.msg.t - now,
                    self.core.max_clock_skew,
                )
        if latest is not None and self.link_ok:
            try:
                self.driver.send(latest)
                self._stopped_sent = False
            except DriverError as exc:
                self._lose_link(now, str(exc))

    def _note_estop(self, before: bool, change) -> None:
        note_latch(f"robot {self.params.robot_id}", change)
        if self.core.estop == before:
            return
        if self.core.estop:
            self.driver.stop()
            self._stopped_sent = True

    def enforce(self, now: float) -> None:
        """Watchdog, e-stop and link checks at ``now``."""
        health = self.driver.health()
        if self.link_ok and not health.ok:
            self._lose_link(now, health.detail)
        elif not self.link_ok and health.ok:
            self._restore_link(now, "link back")
        if self.core.must_stop(now) and not self._stopped_sent:
            if self.core.expired(now) and not self.core.estop and self.core.last_cmd is not None:
                self.core.counters.watchdog_stops += 1
                log.info(
                    "robot %s: watchdog stop (no command for %.3f s)",
                    self.params.robot_id,
                    now - self.core.last_cmd_time,
                )
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

    def wait_for_estop(self, timeout: float) -> None:
        """Sleep up to ``timeout`` s, woken at once by an operator's e-stop (the wall-clock
        loop's pause between cycles: an e-stop is acted on when it arrives, not a period
        later)."""
        inboxes = [i for i in (self._estops, self._second_estops) if i is not None]
        with self._estop_arrived:  # the inboxes notify under this lock: no arrival is missed
            if not any(i.qsize() for i in inboxes):
                self._estop_arrived.wait(timeout)

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

    def _restore_link(self, now: float, detail: str) -> None:
        self.link_ok = True
        self.core.counters.link_restored += 1
        log.warning("robot %s: link restored (%s)", self.params.robot_id, detail)
        self._token = self.bus.declare_alive("robot", self.params.robot_id)
        self._event(now, "link_restored", detail=detail)

    def announce(self, now: float) -> None:
        """A new agent for this robot is up with a working link: ``link_restored`` (clears a
        ``link_lost`` the controller may hold from this robot's previous agent)."""
        self._event(now, "link_restored", detail="agent started")

    def close(self) -> None:
        self.driver.close()
