"""The controller node: the central side's I/O shell around the pure mission.

Fixed, named pipeline per tick (``tick``):

1. **sample** - drain the inboxes: e-stops (live, and the latch's answers), robot events
   (``link_lost`` / ``link_restored``), pose measurements into the filters (a stamp further than
   ``fleet.max_clock_skew`` from the tick time, the same clock domain, is dropped and counted);
2. **estimate** - every filter predicted to the tick time (``FleetView``);
3. **plan** - the mission's plan stage (pure): nominal velocities, phase, events (``Intent``);
4. **safety** - the mission's safety stage (pure): CBF filter and tracking law, body-frame
   commands (``MissionOutput``); an engaged e-stop zeroes them;
5. **publish** - one command per robot (with a time-to-live), plan events, filter states, and in
   the lockstep dry run the ``TickDone`` answer.

The node is the tick pipeline and its status; its bus plumbing is in three parts, each its own
module: the latched e-stop (``node_latch``), what it hears of the robots (``node_inputs``) and
what it publishes (``node_outputs``). The node times the stages with an injected clock
(``timings``). The tick source is injected too: the wall-clock rate keeper of the lab daemon or
the sim's lockstep clock. Nothing here reads a clock for control decisions; ``now`` is passed in.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from controller import wire
from controller.config import FleetConfig
from controller.latch import FRESH_WORLD
from controller.mission.types import FleetView, Mission, MissionOutput
from controller.runtime.node_inputs import (  # noqa: F401 - the node's names, as before
    AHEAD_TOLERANCE,
    EVENT_GRACE,
    Estimator,
    NodeCounters,
    NodeInputs,
    known,
)
from controller.runtime.node_latch import NodeLatch
from controller.runtime.node_outputs import NodeOutputs
from controller.runtime.node_times import StageTimes

log = logging.getLogger(__name__)


class ControllerNode:
    """Subscribes to poses and e-stops, runs the mission per tick, publishes commands."""

    def __init__(
        self,
        cfg: FleetConfig,
        bus,
        mission: Mission,
        estimator: Estimator,
        lossless_commands: bool = False,
        extra_drops: Callable[[], dict[str, int]] | None = None,
        clock: Callable[[], float] | None = None,
        planners: Any = None,
        ident: str = "main",
        latch_at_start: wire.EStop | None = FRESH_WORLD,
        estop_bus=None,
        rings: bool = False,
        pose_tap: Callable[[str, bytes, float], None] | None = None,
    ) -> None:
        """``clock`` (s, monotonic) only times the stages; ``extra_drops`` adds drop counters
        of other parts (the recorder) to ``fleet status``; ``planners`` (the planner worker)
        adds its plan latencies (``plan_latency_s``); ``ident`` is the controller's liveliness
        id (``alive/controller/<ident>``, named in ``fleet status``). ``latch_at_start``: the
        e-stop latch this node starts with - a fresh world's release (the dry run, replay,
        tests: the default), the latch's file, or None: unknown, commanding zero until it
        learns the latch or an operator releases it (the lab daemon).
        ``lossless_commands``: the lockstep dry run (no inbox or command ever dropped).
        ``estop_bus``: the e-stop's second path (the daemon's, ``zenoh.estop_listen``).
        ``rings``, ``pose_tap``: poses read from zenoh rings at each tick (``NodeInputs``)."""
        self.ident = ident
        self.clock = clock
        self.planners = planners
        self.times = StageTimes()  # with a clock: the stages' durations (``node_times``)
        self.cfg = cfg
        self.bus = bus
        self.extra_drops = extra_drops
        self.mission = mission
        self.est = estimator
        self.ids = cfg.robot_ids
        self.counters = NodeCounters()
        self.phase = "init"
        self.arrested = False
        # set by the runner when the process is stopping: robots leaving then are no news
        self.winding_down = False
        self.last_output: MissionOutput | None = None
        over = lambda: self.job_over  # noqa: E731
        self.inputs = NodeInputs(cfg, bus, self.counters, lossless_commands, over, rings, pose_tap)
        self.estop_latch = NodeLatch(bus, cfg.fleet.name, latch_at_start, estop_bus)
        self.outputs = NodeOutputs(cfg, bus, self.counters, lossless_commands)
        self.estop_latch.serve_status(self.status)
        bus.declare_alive("controller", ident)

    # -- what the runners and tests read of the parts
    @property
    def present(self) -> np.ndarray:
        """Per robot (config order): its liveliness token is up."""
        return self.inputs.present

    @property
    def job_over(self) -> bool:
        """The mission ended (done or failed), or the runner is stopping (``winding_down``)."""
        out = self.last_output
        return self.winding_down or (out is not None and bool(out.done or out.failed))

    @property
    def estop(self) -> bool:
        """Whether the robots are held stopped: an e-stop latched, or the latch unknown
        (``estop_latch``: the latch, its queries and the operators' e-stops)."""
        return self.estop_latch.stopped

    # -- the tick
    def sample(self, now: float | None = None) -> None:
        """Drain the inboxes into the latched e-stop and the filters (``NodeInputs.sample``)."""
        self.estop_latch.sample(now)
        self.inputs.sample(self.est, now)

    def publishers_for_handshake(self) -> list:
        """Publishers whose subscribers must be matched before the first tick."""
        return self.outputs.for_handshake()

    def pending_measurements(self) -> int:
        """Pose measurements received but not yet taken in."""
        return self.inputs.pending()

    @property
    def received(self) -> int:
        """Pose measurements (robots and object) taken in so far, those dropped for their
        stamp included (they arrived: the lockstep handshake counts arrivals)."""
        return self.counters.poses + self.counters.object_poses + self.counters.skewed

    def view(self, now: float) -> FleetView:
        poses, vels, stale = self.est.robot_arrays(now)
        obj = known(self.est.object_estimate(now))
        pred = known(self.est.predict_object(now, self.cfg.approach.prediction_horizon))
        return FleetView(
            t=now,
            ids=self.ids,
            poses=poses,
            velocities=vels,
            stale=stale,
            present=self.present & ~self.inputs.link_lost,
            object_pose=None if obj is None else np.array([obj.x, obj.y, obj.theta]),
            object_velocity=None if obj is None else np.array([obj.vx, obj.vy, obj.wz]),
            object_prediction=None if pred is None else np.array([pred.x, pred.y, pred.theta]),
            estop=self.estop or self.estop_latch.pending,  # held while an answer is due too
        )

    def tick(self, now: float, step: int | None = None) -> MissionOutput:
        """sample → estimate → plan → safety → publish, at time ``now``."""
        marks = [self._now()]
        self.sample(now)
        view = self.view(now)
        marks.append(self._now())
        intent = self.mission.plan(view)
        marks.append(self._now())
        out = self.mission.safety(view, intent)
        marks.append(self._now())
        self._publish(now, view, out, step)
        marks.append(self._now())
        if self.clock is not None:
            self.times.record(marks)
        return out

    def _now(self) -> float:
        return self.clock() if self.clock is not None else 0.0

    def _publish(self, now: float, view: FleetView, out: MissionOutput, step: int | None) -> None:
        stopped = self.estop or self.estop_latch.pending
        if out.arrest and not self.arrested:
            self.arrested = True
            self.est.set_object_arrested(True)
        if out.object_push is not None:
            self.est.push_object(now, *(float(v) for v in out.object_push))
        self.phase = out.phase
        self.counters.ticks += 1
        cmds = np.zeros_like(out.commands) if stopped else out.commands
        self.outputs.commands(now, cmds, self.est)
        self.outputs.events(now, out)
        self.outputs.states(now, view, self.est, self.arrested)
        self.last_output = out  # before TickDone: the sim reads it once the tick is answered
        if step is not None:
            self.outputs.done(now, step)

    def hold(self, now: float) -> None:
        """Command every robot to stop now (shutdown, mission end)."""
        self.outputs.hold(now)

    # -- status
    def timing_summary(self) -> dict[str, dict[str, float]]:
        """Per stage (and plan + safety as ``step_ms``): median, p90, max in ms (with a clock)."""
        return self.times.summary()

    def drops(self) -> dict[str, int]:
        """Everything dropped so far: bad payloads and inbox overflow on the controller's bus,
        plus what ``extra_drops`` reports (e.g. the recorder's)."""
        out = dict(self.bus.drops())
        if self.extra_drops is not None:
            out.update(self.extra_drops())
        return out

    def status(self) -> wire.FleetStatus:
        robots = [
            {
                "id": rid,
                "present": bool(self.present[i]),
                "link_lost": bool(self.inputs.link_lost[i]),
                "skewed": bool(self.inputs.skewed[i]),
            }
            for i, rid in enumerate(self.ids)
        ]
        return wire.FleetStatus(
            t=0.0,
            seq=self.counters.ticks,
            fleet=self.cfg.fleet.name,
            phase=self.phase,
            estop=self.estop,
            robots=robots,
            counters={**vars(self.counters), **self.drops(), **self.estop_latch.counters()},
            plan_latency_s={} if self.planners is None else self.planners.summary(),
            tick_ms=self.times.percentiles(),
            controller=self.ident,
        )
