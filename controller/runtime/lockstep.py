"""The lockstep sim clock: the robot side of the dry run.

The sim is the clock. Each control tick k at sim time t_k:

1. every agent forwards its robot's pose measurements (stamped with their own sim times) and the
   object's measurements and ground truth go out on their keys;
2. the coordinator publishes ``SimTick(step=k, t=t_k, measurements=<published so far>)``; the
   controller waits (on a condition its inboxes notify, never polling) until it has taken in that
   many, then ticks;
3. it waits (at most ``tick_timeout`` s of wall time) for the controller's ``TickDone(step=k)``,
   which the controller sends after publishing every command for tick k, and then until the
   agents hold every command it announced (a condition their command inboxes notify);
4. every agent applies the commands it received (watchdog and e-stop at sim time t_k);
5. the world steps to t_{k+1}.

Every command and pose crosses the bus exactly as in the lab: only the adapter behind the agents
and the source of time differ. Same seed, same truth trajectory. Both halves of the protocol live
here: ``LockstepCoordinator`` (the sim side) and ``ControllerLockstep`` (the controller side).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from controller import wire
from controller.io.bus import Bus
from controller.runtime.node import ControllerNode
from drivers.agent import Agent
from sim_backend.hub import SimHub

log = logging.getLogger(__name__)


# ticks missed in a row after which the lockstep is lost: the run ends (``lockstep_lost``)
# instead of waiting ``sim.tick_timeout`` per tick for answers that do not come (one stalled
# bench run waited 10 s a tick for 30 minutes, another 19 minutes and was then counted a
# timeout); a controller that is only slow misses one tick, not three in a row
MAX_MISSED_IN_A_ROW = 3


@dataclass
class LockstepCounters:
    ticks: int = 0
    missed: int = 0  # ticks the controller did not answer in time
    missed_in_a_row: int = 0
    measurements: int = 0


class LockstepCoordinator:
    """Drives a SimHub and its agents tick by tick, in lockstep with the controller."""

    def __init__(
        self,
        bus,
        hub: SimHub,
        agents: list[Agent],
        control_dt: float,
        tick_timeout: float,
        commands_arrived: threading.Condition,
        planning: Callable[[], bool] | None = None,
    ) -> None:
        """``commands_arrived`` is the condition the agents' command inboxes notify;
        ``planning`` tells whether the controller is waiting for a plan due at this tick (its
        modelled latency is up): the tick's timeout does not run meanwhile."""
        self.planning = planning
        self.commands_arrived = commands_arrived
        self.bus = bus
        self.hub = hub
        self.agents = agents
        self.dt = control_dt
        self.tick_timeout = tick_timeout
        self.counters = LockstepCounters()
        self.step_index = 0
        # the sim time the first tick is at: connecting MAVLink drivers steps the world (their
        # handshakes run on sim time), and the ticks continue from there
        self.t0 = float(hub.t)
        self._clock = bus.publisher("sim_clock")
        self._done = bus.subscribe_topic("sim_done", lossless=True)
        self._object_pub = bus.publisher("object_pose")
        self._truth_obj = bus.publisher("truth_object")
        self._truth_robot = {
            a.params.robot_id: bus.publisher("truth_robot", id=a.params.robot_id) for a in agents
        }
        self._seq = 0
        self._answered = -1
        self._commands_due = 0  # the controller's count of the commands it has published
        self._written_off = 0  # of those, the ones that never arrived (given up on)

    def publishers_for_handshake(self) -> list:
        """Publishers the controller side must have matched before the first tick."""
        return [self._clock, self._object_pub]

    @property
    def t(self) -> float:
        return self.t0 + self.step_index * self.dt

    def publish_measurements(self) -> int:
        n = 0
        for agent in self.agents:
            n += agent.publish_poses()
        for t, x, y, th in self.hub.take_object():
            self._seq += 1
            self._object_pub.put(
                wire.PoseMeasurement(t=t, seq=self._seq, x=x, y=y, theta=th, source="sim")
            )
            n += 1
        self.counters.measurements += n
        return n

    def publish_truth(self, now: float) -> None:
        """Ground truth of every robot and the object (scoring and logs only)."""
        w = self.hub.world
        for rid, pub in self._truth_robot.items():
            pub.put(self._truth(now, w.robot_pose(rid)))
        self._truth_obj.put(self._truth(now, w.object_pose()))

    def _truth(self, now: float, pose) -> wire.PoseMeasurement:
        x, y, th = (float(v) for v in pose)
        return wire.PoseMeasurement(
            t=now,
            seq=self.step_index,
            x=x,
            y=y,
            theta=th,
            sigma_xy=0.0,
            sigma_theta=0.0,
            source="truth",
        )

    def wait_done(self, step: int) -> bool:
        """Wait for the controller's TickDone for ``step`` (wall-clock timeout)."""
        if self._answered >= step:
            return True
        # the only wall-clock use: the handshake timeout
        deadline = time.monotonic() + self.tick_timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0 and self.planning is not None and self.planning():
                deadline = time.monotonic() + self.tick_timeout  # a modelled plan latency
                continue
            if left <= 0:
                return False
            item = self._done.get(timeout=min(left, 0.1))
            if item is None:
                continue
            self._answered = max(self._answered, item.msg.step)
            self._commands_due = max(self._commands_due, item.msg.commands)
            if self._answered >= step:
                return self._wait_commands(deadline)

    def _seen(self) -> int:
        """Commands the agents received, plus those written off as lost: what the controller's
        cumulative count is compared with."""
        return sum(a.commands_seen() for a in self.agents) + self._written_off

    def _wait_commands(self, deadline: float) -> bool:
        """Wait until the agents hold every command the controller says it published."""
        with self.commands_arrived:
            ok = self.commands_arrived.wait_for(
                lambda: self._seen() >= self._commands_due,
                timeout=max(0.0, deadline - time.monotonic()),
            )
        if not ok:
            missing = self._commands_due - self._seen()
            per_robot = ", ".join(f"{a.params.robot_id} {a.commands_seen()}" for a in self.agents)
            log.warning(
                "%d commands never arrived (the controller says %d sent; received per robot: %s)",
                missing,
                self._commands_due,
                per_robot,
            )
            # written off: the next ticks wait only for their own commands (without this, one
            # lost command made every later tick wait tick_timeout for it again). One that
            # still comes after its tick_timeout is counted twice: a later tick may then go on
            # one command early (the run has missed a tick already: it is not the lockstep run)
            self._written_off += missing
        return ok

    @property
    def lost(self) -> bool:
        """Whether the controller missed ``MAX_MISSED_IN_A_ROW`` ticks in a row: its answers or
        its commands stopped arriving, and waiting on would only repeat the timeout."""
        return self.counters.missed_in_a_row >= MAX_MISSED_IN_A_ROW

    def tick(self) -> bool:
        """One lockstep tick; returns whether the controller answered in time."""
        now = self.t
        self.publish_measurements()
        self.publish_truth(now)
        self._clock.put(
            wire.SimTick(
                t=now,
                seq=self.step_index,
                step=self.step_index,
                dt=self.dt,
                measurements=self.counters.measurements,
            )
        )
        ok = self.wait_done(self.step_index)
        if not ok:
            self.counters.missed += 1
            self.counters.missed_in_a_row += 1
            log.warning("controller missed tick %d (t=%.2f s)", self.step_index, now)
        else:
            self.counters.missed_in_a_row = 0
        for agent in self.agents:
            agent.handle_inputs(now)
            agent.enforce(now)
        self.step_index += 1
        self.counters.ticks += 1
        self.hub.advance_to(self.t)
        return ok


class ControllerLockstep:
    """The controller side of the lockstep: answers each SimTick with one node tick."""

    def __init__(self, node: ControllerNode, bus: Bus, wait_inputs: float) -> None:
        self.node = node
        self.ticks = bus.subscribe_topic("sim_clock", lossless=True)
        self.wait_inputs = wait_inputs
        self.stop = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="controller", daemon=True)
        self.lag_waits = 0
        self._deficit = 0  # measurements announced but never received (lost before matching)

    def _run(self) -> None:
        try:
            while not self.stop.is_set():
                item = self.ticks.get(timeout=0.1)
                if item is None:
                    continue
                tick: wire.SimTick = item.msg
                self._wait_inputs(tick)
                self.node.tick(tick.t, step=tick.step)
        except BaseException as exc:  # noqa: BLE001 - surfaced by the runner
            self.error = exc
            log.exception("controller loop failed")

    def _have(self) -> int:
        return self.node.received + self.node.pending_measurements() + self._deficit

    def _wait_inputs(self, tick: wire.SimTick) -> None:
        """Handshake: every measurement published before the tick has arrived (taken in or
        queued); measurements lost on the way are written off after ``wait_inputs`` seconds."""
        cond = self.node.inputs.arrived
        with cond:
            ok = cond.wait_for(lambda: self._have() >= tick.measurements, timeout=self.wait_inputs)
        if not ok:
            self.lag_waits += 1
            missing = tick.measurements - self._have()
            self._deficit += missing
            log.warning("tick %d: %d measurements never arrived", tick.step, missing)
