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

The node times the stages with an injected clock (``timings``). The tick source is injected too:
the wall-clock rate keeper of the lab daemon or the sim's lockstep clock. Nothing here reads a
clock for control decisions; ``now`` is passed in.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from controller import wire
from controller.config import FleetConfig
from controller.events import LinkLostEvent, LinkRestoredEvent, link_event
from controller.io.bus import Inbox
from controller.latch import FRESH_WORLD, Latch, note_latch, role_of
from controller.mission.types import FleetView, Mission, MissionOutput

log = logging.getLogger(__name__)

# s: a pose stamped at most this after the tick is taken as stamped (float rounding of sim time,
# sub-tick sensor timing); later stamps are taken at the tick
AHEAD_TOLERANCE = 1e-3
# s (in ticks): how long a robot's link event may wait for its liveliness token to agree
EVENT_GRACE = 1.0
STAGES = ("sample", "plan", "safety", "publish")  # timed: sample+estimate, plan, safety, publish
TIMINGS = 200_000  # ticks of stage timings kept (the run summary's; about 3 h at 20 Hz)


class Estimator(Protocol):
    def command(self, robot_id: str, t: float, vx: float, vy: float, wz: float) -> None: ...
    def measure_robot(self, robot_id: str, t: float, x: float, y: float, theta: float) -> str: ...
    def measure_object(self, t: float, x: float, y: float, theta: float) -> str: ...
    def robot_arrays(self, now: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
    def robot_estimate(self, robot_id: str, now: float) -> Any: ...
    def object_estimate(self, now: float) -> Any: ...
    def predict_object(self, now: float, horizon: float) -> Any: ...
    def set_object_arrested(self, arrested: bool) -> None: ...
    def push_object(self, t: float, vx: float, vy: float, wz: float) -> None: ...


@dataclass
class NodeCounters:
    ticks: int = 0
    poses: int = 0
    object_poses: int = 0
    rejected: int = 0
    out_of_order: int = 0
    commands: int = 0
    link_events: int = 0
    link_restored: int = 0
    skewed: int = 0  # poses stamped further than fleet.max_clock_skew from the tick time
    over_budget: int = 0  # lab ticks that took longer than fleet.tick_budget
    ahead: int = 0  # poses stamped > 1 ms after the tick time (within the skew): taken at the tick
    spoofed_events: int = 0  # link events the robot's liveliness token did not bear out


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
    ) -> None:
        """``clock`` (s, monotonic) only times the stages; ``extra_drops`` adds drop counters
        of other parts (the recorder) to ``fleet status``; ``planners`` (the planner worker)
        adds its plan latencies (``plan_latency_s``); ``ident`` is the controller's liveliness
        id (``alive/controller/<ident>``, named in ``fleet status``). ``latch_at_start``: the
        e-stop latch this node starts with - a fresh world's release (the dry run, replay,
        tests: the default), the latch's file, or None: unknown, commanding zero until it
        learns the latch or an operator releases it (the lab daemon)."""
        self.ident = ident
        self.clock = clock
        self.planners = planners
        self.last_tick_s: float | None = None  # the last tick's duration (with a clock)
        # the last TIMINGS ticks' stage durations (s), and the whole ticks' for fleet status
        self.timings: dict[str, deque[float]] = {k: deque(maxlen=TIMINGS) for k in STAGES}
        self.tick_totals: deque[float] = deque(maxlen=1000)
        self.cfg = cfg
        self.bus = bus
        self.extra_drops = extra_drops
        self.mission = mission
        self.est = estimator
        self.ids = cfg.robot_ids
        self.index = {rid: i for i, rid in enumerate(self.ids)}
        self.counters = NodeCounters()
        self.phase = "init"
        self.latch = Latch("controller/main", latch_at_start)
        # True from ``expect_latch`` until a holder answers: every command is zero meanwhile
        self.latch_pending = False
        self.present = np.zeros(len(self.ids), dtype=bool)
        # the robot's last pose was dropped for its stamp (its clock is off): ``fleet status``
        # says ``skewed``; the first such drop of a robot (and the next after a good pose) logged
        self.skewed = np.zeros(len(self.ids), dtype=bool)
        self.link_lost = np.zeros(len(self.ids), dtype=bool)
        self._events_pending: dict[str, tuple[LinkLostEvent | LinkRestoredEvent, int]] = {}
        self.arrested = False
        # set by the runner when the process is stopping: robots leaving then are no news
        self.winding_down = False
        # s: an operator's release stamped further than this from the tick's time is refused
        # (a replayed old resume); the daemon sets fleet.max_clock_skew, the dry run none
        self.release_max_age = math.inf
        self.last_output: MissionOutput | None = None
        self._seq = 0
        self.inputs_arrived = threading.Condition()  # notified on every pose (lockstep waits)
        # bounded per robot (a flood drops the oldest), lossless in the lockstep dry run
        lossless = lossless_commands
        self._poses = bus.subscribe_topic(
            "robot_pose", waker=self.inputs_arrived, lossless=lossless
        )
        self._object = bus.subscribe_topic(
            "object_pose", waker=self.inputs_arrived, lossless=lossless
        )
        self._estops = bus.subscribe_topic("estop", lossless=True)  # never drop an e-stop
        self._robot_events = bus.subscribe_topic("robot_event")
        self._latch_replies = Inbox()
        self._latch_key = bus.serve_estop("controller", "main", self.latch_state)
        self._cmd_pub = {
            r: bus.publisher("robot_cmd", command=True, lossless=lossless, id=r) for r in self.ids
        }
        self._state_pub = {r: bus.publisher("robot_state", id=r) for r in self.ids}
        self._object_pub = bus.publisher("object_state")
        self._done_pub = bus.publisher("sim_done", command=True, lossless=True)
        bus.watch_alive("robot", self._on_alive)
        bus.serve("status", self.status)
        bus.declare_alive("controller", ident)

    # -- inputs
    def _on_alive(self, rid: str, alive: bool) -> None:
        i = self.index.get(rid)
        if i is None:
            return
        if self.present[i] != alive:
            # a robot leaving during the job is news (WARNING); after it, or while the process
            # stops (its agents close), it is the expected end (INFO)
            quiet = alive or self.job_over
            log.log(logging.INFO if quiet else logging.WARNING, "robot %s %s", rid,
                    "present" if alive else "gone")  # fmt: skip
        self.present[i] = alive

    @property
    def job_over(self) -> bool:
        """The mission ended (done or failed), or the runner is stopping (``winding_down``)."""
        out = self.last_output
        return self.winding_down or (out is not None and bool(out.done or out.failed))

    # -- the latched e-stop
    @property
    def estop(self) -> bool:
        """Whether the robots are held stopped: an e-stop latched, or the latch unknown."""
        return self.latch.stopped

    def latch_state(self) -> wire.EStop | None:
        """The controller's latched e-stop, answered on ``estop/state/controller/main`` (zenoh's
        thread); None (no answer) while unknown."""
        return self.latch.answer()

    def expect_latch(self, timeout: float = 1.0) -> None:
        """Ask every holder of the latched e-stop (hub, agents) and command zero until one
        answers (a start, or a resume after the loop was hung): the controller must not command
        robots on a state it may have missed. ``release_latch`` ends the wait unanswered."""
        self.latch_pending = True
        self.ask_latch(timeout)

    def ask_latch(self, timeout: float = 1.0) -> None:
        """Ask every holder of the latched e-stop without holding the commands (an unknown
        latch holds them anyway); the answers are applied in the next tick's sample stage."""
        self.bus.query_async(
            self.bus.estop_wildcard(), wire.EStop, self._latch_replies, timeout=timeout
        )

    def release_latch(self) -> None:
        """Nobody answered the latch query (no hub, no agent): go on with what this node holds
        (an unknown latch stays stopped until an operator's release)."""
        if self.latch_pending:  # a fresh lab: nobody knows the latch yet (fail closed)
            state = (
                "unknown: stopped until an operator's resume"
                if not self.latch.known
                else ("engaged" if self.estop else "released")
            )
            log.info("no holder answered the e-stop latch query; the e-stop is %s", state)
        self.latch_pending = False

    def _sample_estop(self, now: float) -> None:
        fleet = self.cfg.fleet.name
        replies = [
            (role_of(i.key, fleet), i.msg)
            for i in self._latch_replies.drain()
            if i.key != self._latch_key
        ]
        if replies:
            self.latch_pending = False
            note_latch("controller", self.latch.answers(replies))
        age = self.release_max_age  # the lab's wall clock only (see drivers.agent.AgentParams)
        for item in self._estops.drain():
            stamp = now if math.isfinite(age) else None
            note_latch("controller", self.latch.operator(item.msg, stamp, age))

    def _sample_events(self) -> None:
        """Robot events, believed only when the robot's liveliness token agrees: its agent
        withdraws the token before it reports ``link_lost`` and declares it before
        ``link_restored``. An event the token does not bear out within ``EVENT_GRACE`` s of
        ticks is ignored and counted (``spoofed_events``): on the open default anyone may put
        on a robot's event key (under the lab ACL only that robot's agent may)."""
        for item in self._robot_events.drain():
            rid = self._robot_id(item.key)
            ev = link_event(item.msg.kind, item.msg.data)
            if rid in self.index and ev is not None:
                until = self.counters.ticks + max(1, round(EVENT_GRACE * self.cfg.fleet.rate_hz))
                self._events_pending[rid] = (ev, until)
        for rid, (ev, until) in list(self._events_pending.items()):
            i = self.index[rid]
            if bool(self.present[i]) == isinstance(ev, LinkRestoredEvent):
                del self._events_pending[rid]
                self._apply_event(rid, ev)
            elif self.counters.ticks >= until:
                del self._events_pending[rid]
                self.counters.spoofed_events += 1
                log.warning(
                    "robot %s: %s ignored: its liveliness token says otherwise (not its agent)",
                    rid,
                    ev.kind,
                )

    def _apply_event(self, rid: str, ev: LinkLostEvent | LinkRestoredEvent) -> None:
        i = self.index[rid]
        if isinstance(ev, LinkLostEvent):
            self.link_lost[i] = True
            self.counters.link_events += 1
            log.error("robot %s reports a lost link: %s", rid, ev.detail)
        else:
            if self.link_lost[i]:
                log.warning("robot %s: link restored (%s)", rid, ev.detail)
            self.link_lost[i] = False
            self.counters.link_restored += 1

    def _skewed(self, t: float, now: float | None, robot: int | None = None) -> bool:
        """Whether a pose stamped ``t`` is too far from the tick ``now`` (dropped, counted; a
        robot's first in a row logged with the offset, so a robot whose clock is off is named)."""
        if now is None or abs(t - now) <= self.cfg.fleet.max_clock_skew:
            if robot is not None:
                self.skewed[robot] = False
            return False
        self.counters.skewed += 1
        if robot is not None and not self.skewed[robot]:
            self.skewed[robot] = True
            log.warning(
                "robot %s: its poses are stamped %+.3f s from the controller's clock, beyond "
                "fleet.max_clock_skew (%.3f s): dropped until its clock agrees (NTP or chrony "
                "on the robot's computer)",
                self.ids[robot],
                t - now,
                self.cfg.fleet.max_clock_skew,
            )
        elif self.counters.skewed == 1 or self.counters.skewed % 100 == 0:
            log.warning(
                "dropped a pose stamped %.3f s at tick %.3f s (%d so far)",
                t,
                now,
                self.counters.skewed,
            )
        return True

    def _stamp(self, t: float, now: float | None) -> float:
        """A pose's stamp, but never after the tick: a measurement from the future (a fast
        clock, or a spoofer inside the skew) is taken as made at the tick, so it cannot
        extrapolate a filter past the tick nor push its timeline ahead (counted: ``ahead``).
        Up to ``AHEAD_TOLERANCE`` after the tick a stamp is kept (rounding, not a clock)."""
        if now is None or t <= now + AHEAD_TOLERANCE:
            return t
        self.counters.ahead += 1
        return now

    def sample(self, now: float | None = None) -> None:
        """Drain the inboxes into the filters and the latched e-stop. With ``now`` (the tick
        time: the same clock domain as the stamps) a pose stamped further than
        ``fleet.max_clock_skew`` from it is dropped and counted (``skewed``), and one stamped
        after it is taken at ``now`` (``ahead``)."""
        self._sample_estop(now)
        self._sample_events()
        for item in self._poses.drain():
            rid = self._robot_id(item.key)
            if rid not in self.index:
                continue
            m = item.msg
            if self._skewed(m.t, now, self.index[rid]):
                continue
            res = self.est.measure_robot(rid, self._stamp(m.t, now), m.x, m.y, m.theta)
            self.counters.poses += 1
            self.counters.rejected += res == "rejected"
            self.counters.out_of_order += res == "out_of_order"
        for item in self._object.drain():
            m = item.msg
            if self._skewed(m.t, now):
                continue
            self.est.measure_object(self._stamp(m.t, now), m.x, m.y, m.theta)
            self.counters.object_poses += 1

    def _robot_id(self, key: str) -> str:
        parsed = wire.parse_key(key, self.cfg.fleet.name)
        return "" if parsed is None else parsed.id

    def publishers_for_handshake(self) -> list:
        """Publishers whose subscribers must be matched before the first tick."""
        return [*self._cmd_pub.values(), self._done_pub]

    def pending_measurements(self) -> int:
        """Pose measurements received but not yet taken in."""
        return self._poses.qsize() + self._object.qsize()

    @property
    def received(self) -> int:
        """Pose measurements (robots and object) taken in so far, those dropped for their
        stamp included (they arrived: the lockstep handshake counts arrivals)."""
        return self.counters.poses + self.counters.object_poses + self.counters.skewed

    # -- the tick
    def view(self, now: float) -> FleetView:
        poses, vels, stale = self.est.robot_arrays(now)
        obj = _known(self.est.object_estimate(now))
        pred = _known(self.est.predict_object(now, self.cfg.approach.prediction_horizon))
        return FleetView(
            t=now,
            ids=self.ids,
            poses=poses,
            velocities=vels,
            stale=stale,
            present=self.present & ~self.link_lost,
            object_pose=None if obj is None else np.array([obj.x, obj.y, obj.theta]),
            object_velocity=None if obj is None else np.array([obj.vx, obj.vy, obj.wz]),
            object_prediction=None if pred is None else np.array([pred.x, pred.y, pred.theta]),
            estop=self.estop,
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
            for name, a, b in zip(STAGES, marks[:-1], marks[1:], strict=True):
                self.timings[name].append(b - a)
            self.last_tick_s = marks[-1] - marks[0]
            self.tick_totals.append(self.last_tick_s)
        return out

    def _now(self) -> float:
        return self.clock() if self.clock is not None else 0.0

    def timing_summary(self) -> dict[str, dict[str, float]]:
        """Per stage (and the mission's plan + safety as ``step_ms``): median, p90, max in ms."""
        if self.clock is None or not self.timings["plan"]:
            return {}
        series = {f"{k}_ms": np.asarray(v) * 1e3 for k, v in self.timings.items()}
        series["filter_ms"] = series.pop("safety_ms")
        series["step_ms"] = series["plan_ms"] + series["filter_ms"]
        return {
            k: {
                "median": float(np.median(a)),
                "p90": float(np.percentile(a, 90)),
                "max": float(a.max()),
                "calls": len(a),
            }
            for k, a in series.items()
        }

    def _publish(self, now: float, view: FleetView, out: MissionOutput, step: int | None) -> None:
        stopped = self.estop or self.latch_pending
        cmds = np.zeros_like(out.commands) if stopped else out.commands
        if out.arrest and not self.arrested:
            self.arrested = True
            self.est.set_object_arrested(True)
        if out.object_push is not None:
            self.est.push_object(now, *(float(v) for v in out.object_push))
        self.phase = out.phase
        self.counters.ticks += 1
        ttl = self.cfg.fleet.cmd_ttl
        for i, rid in enumerate(self.ids):
            vx, vy, wz = (float(v) for v in cmds[i])
            self._seq += 1
            self._cmd_pub[rid].put(wire.Twist2D(t=now, seq=self._seq, vx=vx, vy=vy, wz=wz, ttl=ttl))
            self.est.command(rid, now, vx, vy, wz)
            self.counters.commands += 1
        for ev in out.events:
            self._seq += 1
            data = ev.to_dict()
            self.bus.put(
                "plan",
                wire.PlanEvent(t=now, seq=self._seq, kind=ev.kind, phase=out.phase, data=data),
                what=ev.kind,
            )
        self._publish_states(now, view)
        self.last_output = out  # before TickDone: the sim reads it once the tick is answered
        if step is not None:
            self._done_pub.put(
                wire.TickDone(
                    t=now,
                    seq=step,
                    step=step,
                    commands=self.counters.commands,
                )
            )

    def hold(self, now: float) -> None:
        """Command every robot to stop now (shutdown, mission end)."""
        for rid in self.ids:
            self._seq += 1
            self._cmd_pub[rid].put(wire.Twist2D(t=now, seq=self._seq, ttl=self.cfg.fleet.cmd_ttl))

    def _publish_states(self, now: float, view: FleetView) -> None:
        for i, rid in enumerate(self.ids):
            e = _known(self.est.robot_estimate(rid, now))
            if e is None:
                continue
            self._state_pub[rid].put(
                wire.RobotState(
                    t=now,
                    seq=self.counters.ticks,
                    id=rid,
                    x=e.x,
                    y=e.y,
                    theta=e.theta,
                    vx=e.vx,
                    vy=e.vy,
                    wz=e.wz,
                    sigma_xy=e.sigma_xy,
                    sigma_theta=e.sigma_theta,
                    stale=bool(view.stale[i]),
                    rejected=int(e.rejected),
                )
            )
        o = _known(self.est.object_estimate(now))
        if o is not None:
            self._object_pub.put(
                wire.ObjectState(
                    t=now,
                    seq=self.counters.ticks,
                    x=o.x,
                    y=o.y,
                    theta=o.theta,
                    vx=o.vx,
                    vy=o.vy,
                    wz=o.wz,
                    sigma_xy=o.sigma_xy,
                    stale=bool(o.stale),
                    arrested=self.arrested,
                )
            )

    # -- status
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
                "link_lost": bool(self.link_lost[i]),
                "skewed": bool(self.skewed[i]),
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
            counters={**vars(self.counters), **self.drops(), **self._latch_counters()},
            plan_latency_s={} if self.planners is None else self.planners.summary(),
            tick_ms=self._tick_percentiles(),
            controller=self.ident,
        )

    def _tick_percentiles(self) -> dict[str, float]:
        """The whole tick's p50/p99/max over the last 1 000 ticks, ms (with a clock)."""
        if not self.tick_totals:
            return {}
        total = np.asarray(self.tick_totals)
        return {
            "p50": float(np.median(total) * 1e3),
            "p99": float(np.percentile(total, 99) * 1e3),
            "max": float(total.max() * 1e3),
        }

    def _latch_counters(self) -> dict[str, int]:
        """The latch in ``fleet status``: its epoch, 1 while unknown, refusals so far."""
        c = self.latch.counters
        return {
            "estop_epoch": self.latch.epoch,
            "estop_unknown": int(not self.latch.known),
            "estop_replays_refused": c.replays_refused,
            "estop_answers_refused": c.answers_refused,
            # 0 while the daemon's latch is not in its file (a failed write: full disk...)
            "estop_durable": int(self.latch.durable),
            "estop_implausible_epochs": c.implausible_epochs,
            "estop_releases_refused_not_durable": c.releases_refused_not_durable,
            "estop_stale_releases": c.stale_releases,
        }


def _known(estimate: Any) -> Any:
    """The estimate, or None before its first measurement."""
    if estimate is None or not getattr(estimate, "initialized", True):
        return None
    return estimate
