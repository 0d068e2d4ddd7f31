"""TransportMission: carry the arrested object to ``object.goal`` (Sharma §4, Yamashita §3-4,
Vass §4), in the same closed loop as the capture. Its phases (moved by ``mission.sequence``):

- ``route``: the object's route (weighted A*, ``controller.planning.route``, along the ways
  the fleet can push) to the goal, in subgoals; none: ``no_route`` or ``too_heavy``, all stop.
- ``rearrange``: when the contacts cannot push along the segment (the contact-force LP), a new
  set (Sharma's Eq. 5) and the robots nearest to it move there (``mission.rearrange``).
- ``transport``: a local plan every interval (``transport.strategy``: simulated annealing,
  downhill or serpentine), its first interval executed every tick (``mission.push``); a
  subgoal reached moves to the next, an object off the route's corridor re-plans the route.
- ``done`` within ``transport.tolerance`` m and ``heading_tolerance_deg`` of the goal: the
  robots back off and stop; ``failed`` with ``stalled``, ``too_heavy``, ``robot_lost``.

Pure: the planners are pure; time comes from the view. Robots lost and outages: the job's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.events import DeliveredEvent, RouteEvent
from controller.mission.grip import Contact, Grip
from controller.mission.guard import SafetyStage
from controller.mission.planners import InlinePlanners, JobOwned, Planners, PlanSlot
from controller.mission.progress import RouteProgress, at, plan_route_job, route_planner_for
from controller.mission.push import Pusher
from controller.mission.rearrange import Rearranger
from controller.mission.sequence import Cue, Failure, Sequencer
from controller.mission.summary import TransportSummary
from controller.mission.transport_settings import SEQUENCE, TransportSettings
from controller.mission.types import Event, FleetView, Intent, MissionOutput, Phase, Reason
from controller.planning.arrangement import can_push, planning_model
from controller.planning.contact_lp import ContactForceLP
from controller.planning.transport_types import TransportParams

if TYPE_CHECKING:
    from controller.planning.route import RoutePlanner
__all__ = ["Contact", "TransportMission", "TransportSettings", "route_planner_for"]

MAX_HOPS = 6  # phases one tick may pass through (route → rearrange → transport → done: 4)


class TransportMission:
    """Carries the object from where the capture left it. ``robots`` (K,) indices of the robots
    that hold it, ``points``/``normals`` their contact points and outward normals (K, 2), object
    frame; the rest of the fleet starts free.

    The stages: the grip (who holds what, ``mission.grip``), the route progress
    (``mission.progress``), the re-arrangement (``mission.rearrange``) and the push
    (``mission.push``); this class reads their verdicts, reports cues to the sequence
    (``mission.sequence``) and hands each stage what it needs: no stage calls another."""

    def __init__(
        self,
        cfg: FleetConfig,
        rng: np.random.Generator,
        guard: SafetyStage,
        robots: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        route_planner: RoutePlanner | None = None,
        planners: Planners | None = None,
        sequencer: Sequencer | None = None,
    ) -> None:
        """``planners``: the port the route, the re-arrangement set and the local plans are
        asked of (off the tick; None: computed at once, ready the same tick). ``sequencer``:
        the job's phase, which this stage reads and reports into (None: one of its own, the
        object held: a transport alone)."""
        self.cfg = cfg
        self.rng = rng
        self.guard = guard
        self.s = TransportSettings.from_config(cfg)
        self.n = len(cfg.robots)
        o = cfg.object
        self.model = planning_model(cfg)  # the heaviest it may be, under transport.errors
        self.params = TransportParams.from_config(cfg.transport)
        self.planners = planners if planners is not None else InlinePlanners()
        # the route planner toward object.goal (its C-space and cost-to-go table take a second:
        # the job builds it before the loop starts; the first route job builds it otherwise)
        self._route_box = JobOwned(route_planner)
        self._route_job = PlanSlot(self.planners, "route")
        self.plan_waits = 0  # ticks a phase waited for a plan with the robots held
        # every robot of the fleet takes part: those holding the object keep their contacts,
        # the others are free (re-arrangement recruits them when the holders cannot push)
        self.lp = ContactForceLP(max(self.n, 1), friction=o.contact_friction > 0)
        self.grip = Grip(cfg, self.model, self.s.grip, robots, points, normals)
        self.way = RouteProgress(self.model, np.asarray(o.goal, float), self.s.progress)
        self.rearranger = Rearranger(
            cfg, self.model, self.params.speed, self.params.strategy, self.s.turn_margin,
            self.planners, rng,
        )  # fmt: skip
        self.pusher = Pusher(cfg, self.model, self.params, self.planners, rng, self.s.contact_gain)
        # the job's phase (its first carry cue moves it to ``route``; next_phase moves it)
        self._alone = sequencer is None
        self.seq = sequencer if sequencer is not None else Sequencer(Phase.ARRESTED, SEQUENCE)
        self.t0: float | None = None
        self.route_replans = 0
        self.done_t: float | None = None
        self._last_t: float | None = None  # the last tick's time (an outage's pause)

    @property
    def phase(self) -> Phase:
        return self.seq.phase

    # --- the plan stage -----------------------------------------------------------------------
    def plan(self, view: FleetView) -> Intent:
        """The stage of the job's phase; a handler whose cue moved the phase returns None and
        the stage of the new phase runs next, in the same tick (the table decides where a cue
        leads: no handler calls another)."""
        if view.object_pose is None or view.estop:
            return Intent.of(np.zeros((self.n, 2)), self.phase, stop=True)
        pose = np.asarray(view.object_pose, float)
        events: list[Event] = []
        if self.t0 is None:
            self.t0 = view.t
            self.way.hold_clock(view.t)
            if self._alone:  # a transport alone carries from its first tick (the job cues it)
                self._cue(Cue.CARRY, view.t, events)
        self._last_t = view.t
        handlers = {
            Phase.ROUTE: self._route,
            Phase.REARRANGE: self._rearrange,
            Phase.TRANSPORT: self._transport,
            Phase.DONE: self._done,
            Phase.FAILED: self._failed,
        }
        for _ in range(MAX_HOPS):
            out = handlers[self.phase](view, pose, events)
            if out is not None:
                return out
        raise RuntimeError(f"the transport moved phase {MAX_HOPS} times in one tick (a bug)")

    def lose(self, robots) -> None:
        """Robots the job's roster found gone leave the carry (no contact, path or part in the
        next arrangement); when the rest cannot push, the job fails ``robot_lost``."""
        for i in robots:
            self.grip.drop(int(i))

    def paused(self, view: FleetView, events: list[Event]) -> Intent:
        """An outage (the job's ``OutageWatch``): every robot still; the stall clock and the
        re-arrangement's timeout do not run while it lasts."""
        dt = 0.0 if self._last_t is None else view.t - self._last_t
        self._last_t = view.t
        self.wait(dt)
        return Intent.of(np.zeros((self.n, 2)), self.phase, events, stop=True)

    def wait(self, dt: float) -> None:
        """``dt`` s the carry was held: the stall clock and the re-arrangement's timeout wait."""
        self.way.pause(dt)
        self.rearranger.pause(dt)

    def _cue(self, cue: Cue | None, t: float, events: list[Event], failure: Failure | None = None):
        """Report what the transport saw: the sequence moves the phase (and writes events)."""
        events.extend(self.seq.report(t, cue, failure).events)

    def _fail(self, reason: str, detail: str, view: FleetView, events: list[Event]) -> Intent:
        if reason == Reason.STALLED and self.grip.lost:
            lost = ", ".join(view.ids[i] for i in sorted(self.grip.lost))
            reason, detail = Reason.ROBOT_LOST, f"{detail} (lost: {lost})"
        self._cue(None, view.t, events, Failure(Reason(reason), detail))
        return self._failed(view, None, events)

    def _failed(self, view: FleetView, pose: np.ndarray | None, events: list[Event]) -> Intent:
        failure = self.seq.state.failure
        why = failure.reason if failure is not None else ""
        return Intent.of(
            np.zeros((self.n, 2)), self.phase, events, stop=True, failed=True, reason=why
        )

    def _held(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """A plan is on its way: every robot holds where it is (those in contact keep it)."""
        self.plan_waits += 1
        zero = np.zeros((self.n, 2))
        return self._intent(zero, events, pose, self.grip.touching(), np.ones(self.n, bool))

    # --- route --------------------------------------------------------------------------------
    def _route(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent | None:
        """Ask for the route from the object's pose (off the tick), hold until it comes."""
        if not self._route_job.pending:
            self._route_job.request(view.t, plan_route_job, self._route_box, self.cfg, pose)
        got = self._route_job.take(view.t)
        if got is None:
            return self._held(view, pose, events)
        if not got.ok:
            why = f"the route planner failed: {got.error}"
            return self._fail(Reason.NO_ROUTE, why, view, events)
        res = got.value
        if not res.ok:
            why = Reason.TOO_HEAVY if res.too_heavy else Reason.NO_ROUTE
            return self._fail(why, res.reason, view, events)
        self.way.begin(res, view.t)
        event = RouteEvent(
            t=view.t,
            waypoints=np.round(res.waypoints, 4).tolist(),
            subgoals=np.round(res.subgoals, 4).tolist(),
            length_m=res.length_m,
            cost_s=res.cost,
            replans=self.route_replans,
        )
        events.append(event)
        return self._begin_segment(view, pose, events)

    def _begin_segment(
        self, view: FleetView, pose: np.ndarray, events: list[Event]
    ) -> Intent | None:
        """A new segment: re-arrange if the contacts cannot push along it, else transport (the
        cue moves the phase; its stage runs next)."""
        self.way.pass_reached(pose)
        self.pusher.forget()
        if self._can_push(pose):
            self._cue(Cue.CAN_PUSH, view.t, events)
        else:
            self._start_rearrangement(view, pose, events, Cue.CANNOT_PUSH)

    def _can_push(self, pose: np.ndarray) -> bool:
        """Whether the robots in contact can push the object along the segment (the LP)."""
        twist = self.way.direction(pose) * self.params.speed
        return can_push(
            self.lp, self.model, twist, *self.grip.contact_arrays(), self.params.com_error
        )

    # --- rearrange ----------------------------------------------------------------------------
    def _start_rearrangement(self, view: FleetView, pose: np.ndarray, events: list[Event], cue):
        """New contacts asked for (``cue``: why: cannot push, stuck, a set given up)."""
        self._cue(cue, view.t, events)
        self.grip.unplan()
        self.rearranger.ask(view.t, self.way.direction(pose), self.grip.active())

    def _take_arrangement(self, view: FleetView, pose: np.ndarray, events: list) -> Intent | None:
        """The new contacts, once come (None: go on with them; meanwhile the robots hold); a set
        no robots can push with fails ``too_heavy``, or re-plans a push-limited route."""
        got = self.rearranger.take(view.t)
        if got is None:
            return self._held(view, pose, events)
        if not got.ok:
            detail = f"the re-arrangement planner failed: {got.error}"
            return self._fail(Reason.STALLED, detail, view, events)
        replan = self.way.route.push_limited and self.route_replans < self.s.max_route_replans
        if replan and (not got.value.feasible or self.rearranger.doubted(got.value)):
            self.route_replans += 1
            self._cue(Cue.UNPUSHABLE, view.t, events)
            return self._held(view, pose, events)
        if not got.value.feasible:
            return self._fail(Reason.TOO_HEAVY, got.value.detail, view, events)
        direction = self.way.direction(pose)
        self.grip.regrip(view, pose, got.value.points, got.value.normals)
        self.rearranger.arranged(view, got.value, direction, self.grip, events)
        return None

    def _rearrange(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent | None:
        """Movers follow their path around the object; the others hold still. (The stall clock
        waits: re-arranging makes no progress by design; it has its own timeout.) An object
        nudged inside the goal tolerance meanwhile is delivered."""
        goal = np.asarray(self.cfg.object.goal, float)
        k = self.s.accept_margin
        if at(pose, goal, k * self.s.tolerance, k * self.s.heading_tolerance):
            return self._deliver(view, pose, events)
        self.way.hold_clock(view.t)
        if self.rearranger.pending:
            waiting = self._take_arrangement(view, pose, events)
            if waiting is not None:
                return waiting
        grip = self.grip
        vel = np.zeros((self.n, 2))
        hold = np.ones(self.n, bool)
        for i in grip.moves:
            hold[i] = False
        touch = grip.touching()
        grip.follow_paths(view, pose, vel, touch)
        grip.park(view, pose, vel, hold)
        futile = self.rearranger.futile
        if not grip.moves:
            grip.settle()
            if self._can_push(pose) or futile < self.s.max_rearrangements:
                self._cue(Cue.ARRANGED, view.t, events)
                return None
            detail = "the re-arranged contacts cannot push the object"
            return self._fail(Reason.STALLED, detail, view, events)
        if view.t - self.rearranger.since > self.s.rearrange_timeout:
            if futile >= self.s.max_rearrangements:
                return self._fail(Reason.STALLED, "re-arrangement timed out", view, events)
            # a robot that cannot get to its contact (blocked by the others, a wall): a new set
            self._start_rearrangement(view, pose, events, Cue.RESET)
        return self._intent(vel, events, pose, touch, hold)

    # --- transport ----------------------------------------------------------------------------
    def _transport(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent | None:
        goal = np.asarray(self.cfg.object.goal, float)
        s = self.s
        m = s.settle_margin  # stop well inside: the estimate is a centimetre and a degree off
        if at(pose, goal, m * s.tolerance, m * s.heading_tolerance):
            return self._deliver(view, pose, events)
        stall, progressed = self.way.stalled(view.t, pose)
        if progressed:
            self.rearranger.progressed()
        k = s.accept_margin  # the estimate is off by a centimetre: keep clear of the edge
        inside = at(pose, goal, k * s.tolerance, k * s.heading_tolerance)
        pusher = self.pusher
        if inside and (stall or pusher.stuck >= s.stuck_plans):
            # inside the tolerance and the last centimetres will not come: delivered as it is
            # (re-arranging there shuffles robots around a delivered object)
            return self._deliver(view, pose, events)
        if stall and self.rearranger.futile >= s.max_rearrangements:
            return self._fail(Reason.STALLED, stall, view, events)
        if stall or view.t - self.way.progress_t > s.stall_timeout / 2:
            # receding-horizon plans can keep re-positioning without ever pushing: re-arrange
            pusher.give_up(s.stuck_plans)
        if self.way.off_route(pose):
            if self.route_replans >= s.max_route_replans:
                return self._fail(Reason.STALLED, "left the route corridor too often", view, events)
            self.route_replans += 1
            self._cue(Cue.OFF_ROUTE, view.t, events)
            return None
        if self.way.subgoal_reached(pose):
            self.way.next_subgoal()
            return self._begin_segment(view, pose, events)
        if pusher.stuck >= s.stuck_plans:  # the contacts cannot push as the route asks
            pusher.unstick()
            pusher.forget()
            self._start_rearrangement(view, pose, events, Cue.STUCK)
            return None
        return self._plan_and_execute(view, pose, events)

    def _plan_and_execute(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """Ask for a local plan every interval; execute the latest one that has come, closed on
        the current estimate (hold while the segment's first plan is on its way)."""
        pusher = self.pusher
        if pusher.due(view.t):
            pusher.request(view, pose, self.grip, self.way.segment())
        got = pusher.take(view.t)
        if got is not None:
            if not got.ok:
                detail = f"the local planner failed: {got.error}"
                return self._fail(Reason.STALLED, detail, view, events)
            relocate_ok = not self._can_push(pose)
            self.grip.follow_plan(pusher.orders(got.value, self.grip, relocate_ok), view, pose)
            pusher.planned(view, self.grip, events)
        if pusher.last_plan is None:
            return self._held(view, pose, events)
        vel, touch, twist = pusher.execute(view, pose, self.grip)
        return self._intent(vel, events, pose, touch, None, twist)

    def _deliver(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent | None:
        self.done_t = view.t
        self._cue(Cue.DELIVERED, view.t, events)
        events.append(DeliveredEvent(t=view.t, pose=np.round(pose, 4).tolist()))
        return None

    # --- done ---------------------------------------------------------------------------------
    def _done(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """Back off from the delivered object, then stop."""
        vel = np.zeros((self.n, 2))
        c = geometry.transform(self.model.centroid[None], pose)[0]
        if view.t - self.done_t < self.s.back_off / 0.1:
            for i in self.grip.active():
                away = view.poses[i, :2] - c
                vel[i] = 0.1 * away / max(float(np.linalg.norm(away)), 1e-9)
        intent = self._intent(vel, events, pose, np.zeros(self.n, bool), None)
        return intent.ending(view.t - self.done_t >= self.s.back_off / 0.1)

    def _intent(self, vel, events, pose, touch, hold, twist=None) -> Intent:
        if self.way.route is not None:
            to_goal = self.way.remaining(pose)
        else:
            to_goal = float(np.linalg.norm(pose[:2] - np.asarray(self.cfg.object.goal)[:2]))
        progress = {"phase": str(self.phase), "to_goal_m": to_goal}
        progress.update(subgoal=float(self.way.subgoal), pushing=self.grip.pushing())
        return Intent.of(
            vel,
            self.phase,
            events,
            object_pose=pose,
            touch=touch,
            overlap=float(self.cfg.max_robot_radius) if np.any(touch) else 0.0,
            cage=True,
            hold=hold,
            progress=progress,
            object_push=None if twist is None else np.asarray(twist, float),
        )

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        return self.guard.apply(view, intent)

    def summary(self) -> TransportSummary:
        f, route, fail = np.asarray(self.pusher.forces), self.way.route, self.seq.state.failure
        return TransportSummary(
            transport_phase=str(self.phase),
            route_length_m=None if route is None else route.length_m,
            route_replans=self.route_replans,
            rearrangements=self.rearranger.count,
            relocations=self.grip.relocations,
            local_plans=self.pusher.plans,
            planned_force_mean_n=float(f.mean()) if len(f) else None,
            transport_failure=None if fail is None else fail.to_json(self.seq.state.since),
            **self.pusher.serpentine_summary(),
        )
