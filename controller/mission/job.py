"""The whole job (pure, per tick): the capture plan (Sharma Eq. 3, reinforced to hold the
object's push: ``controller.planning.capture_set``), the roster, the assignment, the approach
and arrest, then the transport; re-plans (robot loss, walls, a start without robots never seen)
run off the tick. Its stages: ``roster``, ``assign``, ``reach``, ``capture``, ``transport``."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from controller.config import FleetConfig
from controller.mission.assign import Reassigner, assign, interception_costs
from controller.mission.brace import BraceWatch
from controller.mission.capture import CaptureMission
from controller.mission.capture_phase import CaptureSettings
from controller.mission.grip import CONTACT_REACH, touching
from controller.mission.guard import SafetyStage
from controller.mission.outage import OutageWatch
from controller.mission.planners import InlinePlanners, Planners, PlanSlot, spawn_rng
from controller.mission.reach import Reach
from controller.mission.roster import Roster, parked
from controller.mission.sequence import FINAL, Cue, Failure, Sequencer, SequenceSettings
from controller.mission.summary import CapturePlanSummary, JobSummary, capture_event
from controller.mission.transport import TransportMission, route_planner_for
from controller.mission.types import FleetView, Intent, MissionError, MissionOutput, Phase, Reason
from controller.planning.capture_set import (  # noqa: F401 - re-exported: the job's planning
    TOKEN_LOAD,
    WALL_TOLERANCE,
    CapturePlanError,
    CaptureSet,
    plan_capture_set,
    replan_for_robots,
    replan_pinned,
)

PIN_RETRIES = 6  # re-plans that find no set before an object at rest is declared pinned
PIN_STILL_SPEED = 0.03  # m/s: an object slower than this has come to rest against the wall
LOST_REPLAN_RETRIES = 2  # re-plans after a loss with no answer (a timeout) asked again
WATCHED = (Phase.APPROACH, Phase.CLOSE_IN, Phase.HOLD)  # phases a lost robot re-plans


class CaptureJob:
    """The job: the capture plan, the assignment at the first estimates, the capture, the carry.

    Until every robot is present with a fresh estimate and the object has been seen, every robot
    holds still (phase ``plan``); ``fleet.start_wait`` s after the first estimates, robots never
    seen no longer block: the capture starts with those seen (re-planned for them when the set
    needs more). The assignment minimises the total time for the robots to meet their points'
    stations where the moving object will be (interception at full speed), over the robots
    *available*; robots left over stay where they are.

    Robot loss and join (``mission.roster``): a robot lost during the approach, close-in or
    hold that held a capture point has the capture re-planned with the robots left
    (``replan_for_robots``) and re-assigned; when none closes the object, the job fails with
    ``robots_lost``. A robot back is available again, never given its old point by itself.
    While the e-stop holds, nothing starts and no clock counts.
    """

    def __init__(
        self,
        cfg: FleetConfig,
        rng: np.random.Generator | None = None,
        planners: Planners | None = None,
        entry: Phase = Phase.PLAN,
    ) -> None:
        """``planners``: the port slow plans are asked of, off the tick (None: at once).
        ``entry``: ``plan`` (the whole job) or ``route`` (``--mission transport``: the object
        already held by the robots touching it at the first estimates; no capture plan)."""
        if entry not in (Phase.PLAN, Phase.ROUTE):
            raise MissionError(f"a job is entered at plan or route, not {entry}")
        self.cfg = cfg
        self.planners = planners
        self.rng = rng if rng is not None else np.random.default_rng(cfg.capture.seed)
        self.n = len(cfg.robots)
        self.entry = entry
        # the job's one phase: the capture and the transport read it and report into it
        carry = SequenceSettings(cfg.object.goal is not None, cfg.transport.start_after)
        self.seq = Sequencer(Phase.PLAN, carry)
        self.capture: CaptureSet | None = None
        if entry == Phase.PLAN:
            try:
                self.capture = plan_capture_set(cfg, self.rng)
            except CapturePlanError as exc:
                raise MissionError(str(exc)) from None
        self._replan_job = PlanSlot(planners or InlinePlanners(), "capture")
        self._replan_why = ""  # what the pending capture re-plan is for: lost, pinned, start
        self._lost_retries = 0  # re-plans after a loss asked again for want of an answer
        self.outage = OutageWatch(cfg.fleet.outage_grace)
        self.assignment: np.ndarray | None = None
        self.braces = 0  # robots that braced
        self.brace_watch = BraceWatch(planners or InlinePlanners())  # braces (brace.py)
        self.inner: CaptureMission | None = None  # the capture stage, once started
        self.roster = Roster(self.n)
        self.reach = Reach(cfg)
        self.reassigner = Reassigner()
        self.pin_fails = 0
        self.failed = False
        self.failure_reason: str = Reason.PINNED
        self.start_tried = -1  # robots a start without the missing ones was last planned for
        self.loss_replans = 0
        self.transport: TransportMission | None = None  # the carry, once started
        self._held_since: float | None = None  # s: the e-stop holds the job since
        # the object's route planner, built before the loop (it takes a second)
        self.route_planner = route_planner_for(cfg) if cfg.object.goal is not None else None

    @property
    def phase(self) -> Phase:
        """The job's phase (the sequence moves it, on the stages' reports)."""
        return self.seq.phase

    def plan(self, view: FleetView) -> Intent:
        """One tick: the roster and the outage watch, then the stage of the job's phase (the
        transport from the tick the sequence's carry timer moves the job to ``route``)."""
        if self.failed:
            zero = np.zeros((self.n, 2))
            return Intent.of(zero, Phase.FAILED, stop=True, failed=True, reason=self.failure_reason)
        view = parked(view)  # (a robot never seen: no estimate)
        if view.estop:  # held: nothing starts, nothing times out; every clock waits
            self._held_since = view.t if self._held_since is None else self._held_since
            return Intent.of(np.zeros((self.n, 2)), self.phase, stop=True)
        if self._held_since is not None:
            self._clocks_wait(view.t - self._held_since)
        carrying = self.transport is not None
        gone = self.roster.gone(view, carrying)
        if self.inner is None and not carrying:
            return self._wait(view)
        if carrying and self.phase in FINAL:
            return self.transport.plan(view)
        gone, pause, events = self.outage.filter(
            view.t, gone, self.roster.available, view.ids, self.roster.silent
        )
        if pause:  # one fleet-wide silence: every robot still until it ends or its grace runs out
            if carrying:
                return self.transport.paused(view, events)
            return Intent.of(np.zeros((self.n, 2)), self.phase, events, stop=True)
        if carrying:
            lost, said, _ = self.roster.losses(view, gone, None, str(self.phase))
            self.transport.lose(lost)
            return self.transport.plan(view).after(list(events) + said)
        return self._capture(view, gone, events)

    def _clocks_wait(self, dt: float) -> None:
        """The e-stop lifted after ``dt`` s: no timer, timeout or stall clock counts them (an
        operator's e-stop is a pause, not a failure waiting to happen)."""
        self._held_since = None
        self.seq.wait(dt)
        self.reach.wait(dt)
        for stage in (self.inner, self.transport):
            if stage is not None:
                stage.wait(dt)

    def _capture(self, view: FleetView, gone: np.ndarray, events: list) -> Intent:
        """The capture's tick: joins and losses, re-assignment, the stage, a re-plan for a
        robot stuck on its way (the pin); the carry when the sequence has moved to ``route``."""
        events += self.roster.joins(view, gone)
        if self.phase in WATCHED:
            _, lost, replan = self.roster.losses(view, gone, self.assignment, str(self.phase))
            events += lost
            if replan:
                self._ask_replan_lost(view)
        if self._replan_job.pending and self._replan_why == "lost":
            return self._await_lost(view, events)
        events += self._reassign(view)
        intent = self.inner.plan(view).after(events)
        if self.phase == Phase.ROUTE:  # the sequence's carry timer ran out: carry it
            self._carry(
                self.inner.guard, self.assignment, self.capture.points, self.capture.normals
            )
            return self.transport.plan(view).after(intent.report.events)
        reach = self.reach
        bracing = self.inner.phase == Phase.APPROACH and self.inner.braces.any()
        if not self._replan_job.pending and reach.blocked(
            view, self.inner.phase, self.capture, self.inner.last_distance, self.inner
        ):
            reach.restart()
            k, a = self.roster.available, self.assignment
            if bracing:  # a robot stuck while others brace: re-planned around the braces
                self.brace_watch.rebrace(
                    self.cfg, self.capture, view, self.inner.braces.on, a, k, reach.unreachable
                )
            else:
                pose = np.asarray(view.object_pose, float)
                args = (pose, frozenset(reach.unreachable), int(k.sum()))
                self._ask_replan("pinned", view, replan_pinned, *args)
        if self._replan_job.pending:
            return self._await_pinned(view, intent)
        return intent

    def _carry(self, guard, robots: np.ndarray, points: np.ndarray, normals: np.ndarray) -> None:
        """The transport, from the contacts the ``robots`` hold (object frame); robots no
        longer available (lost during the capture, never seen) take no part."""
        self.transport = TransportMission(
            self.cfg,
            self.rng,
            guard,
            robots,
            points,
            normals,
            route_planner=self.route_planner,
            planners=self.planners,
            sequencer=self.seq,
        )
        self.transport.lose(np.flatnonzero(~self.roster.available).tolist())

    def _carry_from_contact(self, view: FleetView) -> Intent:
        """Entered at ``route``: the robots touching the object hold their nearest boundary
        point (``grip.touching``); the others are free."""
        held, points, normals = touching(self.cfg, view.object_pose, view.poses, CONTACT_REACH)
        self._carry(SafetyStage(self.cfg), held, points, normals)
        step = self.seq.report(view.t, Cue.CARRY)  # plan → route: the object held already
        return self.transport.plan(view).after(step.events)

    def _wait(self, view: FleetView) -> Intent:
        """Phase ``plan``: start when the object and every robot are seen, or, ``start_wait``
        s after the first estimates, with the robots seen when they can close the object."""
        still = Intent.of(np.zeros((self.n, 2)), Phase.PLAN, stop=True)
        ready = self.roster.seen(view)
        if view.object_pose is None:
            return still
        if self.entry == Phase.ROUTE:  # every robot seen: who holds the object is measured
            return self._carry_from_contact(view) if ready.all() else still
        if not ready.all():
            if view.t - self.roster.first_t < self.cfg.fleet.start_wait:
                return still
            k = int(ready.sum())
            if k < len(self.capture.points):
                return self._start_with(view, ready, k, still)
        self.roster.start_with(ready)
        return self._start(view, pinned=False)

    def _start_with(self, view: FleetView, ready: np.ndarray, k: int, still: Intent) -> Intent:
        """Start with the ``k`` robots seen: the capture re-planned for them (off the tick;
        every robot still meanwhile), or wait for another robot when none closes it."""
        if not self._replan_job.pending:
            if k == self.start_tried:
                return still  # planned for this many already: wait for another robot
            self.start_tried = k
            keep = np.zeros(len(self.capture.points), bool)
            self._ask_replan("start", view, replan_for_robots, keep, k, spawn_rng(self.rng))
        got = self._replan_job.take(view.t)
        if got is None or not got.ok or got.value is None or self.start_tried != k:
            return still
        self.capture = got.value
        self.roster.start_with(ready)
        return self._start(view, pinned=False)

    def _ask_replan(self, why: str, view: FleetView, fn, *args) -> None:
        """A capture re-plan off the tick (``why``: start, lost or pinned), with its own
        generator drawn from the job's."""
        self._replan_why = why
        self._replan_job.request(view.t, fn, self.cfg, self.capture, *args)

    def _ask_replan_lost(self, view: FleetView) -> None:
        """An assigned robot is lost: the capture re-planned for the robots left (off the
        tick; a pending re-plan is asked again with the robots left now)."""
        keep = self.roster.available[self.assignment]
        k = int(self.roster.available.sum())
        pose = np.asarray(view.object_pose, float)
        rng = spawn_rng(self.rng)
        self._ask_replan(
            "lost", view, replan_for_robots, keep, k, rng, pose, frozenset(self.reach.unreachable)
        )

    def _await_lost(self, view: FleetView, events: list) -> Intent:
        """Every robot holds until the re-plan comes; then it is re-assigned (the approach
        starts over), or the job fails with ``robots_lost``."""
        got = self._replan_job.take(view.t)
        hold = Intent.of(np.zeros((self.n, 2)), self.inner.phase, events, stop=True)
        if got is None:
            return hold
        if not got.ok and self._lost_retries < LOST_REPLAN_RETRIES:
            # no answer is not "no capture": asked again, every robot still held
            self._lost_retries += 1
            self._ask_replan_lost(view)
            return hold
        self._lost_retries = 0
        new = got.value if got.ok else None
        if new is None:
            k = int(self.roster.available.sum())
            lost = ", ".join(view.ids[i] for i in self.roster.lost)
            detail = (
                f"robots lost ({lost}): the {k} robots left cannot close the object "
                f"(the capture needs {len(self.capture.points)})"
            )
            if not got.ok:
                detail += f"; the re-plan failed: {got.error}"
            return self._fail(view, Reason.ROBOTS_LOST, detail, events)
        self.loss_replans += 1
        self.capture = new
        self.reach.restart()
        return self._start(view, pinned=bool(new.walls)).after(events)

    def _fail(self, view: FleetView, reason: Reason, detail: str, events: list) -> Intent:
        """Fail safe: every robot stopped, the failure event with its detail."""
        step = self.seq.report(view.t, None, Failure(reason, detail))
        events = events + list(step.events)
        self.failed = True
        self.failure_reason = reason
        return Intent.of(
            np.zeros((self.n, 2)), Phase.FAILED, events, stop=True, failed=True, reason=reason
        )

    def _reassign(self, view: FleetView) -> list:
        """A better assignment during the approach (``mission.assign``): a new approach, with
        the same timeout."""
        bracing = self.inner.braces.any()
        if self.inner.phase != Phase.APPROACH:
            return []
        got = self.brace_watch.look(self.cfg, self.capture, view, self.roster.available, bracing)
        if got is None and bracing:  # braces stay
            return []
        braces, events = None, []
        if got is not None:  # braces for a fast object, or a re-plan around them (brace.py)
            self.capture, braces, new = got
        else:
            new, events = self.reassigner.look(
                self.cfg, self.capture, view, self.assignment, self.roster.available
            )
        if new is not None:
            t0 = self.inner.state.t0
            self.assignment = new
            self.inner = self._mission(view, braces)
            self.inner.keep_clock(t0)
            self.braces = self.braces if braces is None else int(braces.sum())
        return events

    def _start(self, view: FleetView, pinned: bool) -> Intent:
        """Assign robots to the capture set and start the approach (the capture event first;
        the capture reports its start at its first tick: ``ready`` from ``plan``, ``replanned``
        after a re-plan, each moving the job to ``approach``)."""
        costs = interception_costs(self.cfg, self.capture, view)
        self.assignment = assign(costs, self.roster.available)
        self.reassigner.assigned(view.t)
        self.inner = self._mission(view)
        robots = [view.ids[i] for i in self.assignment]
        away = [view.ids[i] for i in np.flatnonzero(~self.roster.available)]
        event = capture_event(self.capture, robots, away, pinned)
        return self.inner.plan(view).after([event])

    def _mission(self, view: FleetView, braces: np.ndarray | None = None):
        settings = CaptureSettings.from_config(self.cfg)
        if self.cfg.object.goal is not None:  # the arrested object is carried, not let go
            settings = dataclasses.replace(settings, settle_s=math.inf)
        return CaptureMission(
            self.capture.points,
            self.capture.normals,
            self.assignment,
            self.cfg,
            self.rng,
            settings=settings,
            planners=self.planners,
            sequencer=self.seq,
            bracing=braces,
        )

    def _await_pinned(self, view: FleetView, intent: Intent) -> Intent:
        """The object is against a wall and its capture is being re-planned there (the wall a
        fixed contact; robots keep their stations meanwhile): the new set, or a standoff, or
        ``pinned`` when no set of reachable points holds the object at rest."""
        got = self._replan_job.take(view.t)
        if got is None:
            return intent
        new = got.value if got.ok else None
        if new is None:
            # a standoff first: an object still sliding along a wall or into a corner may
            # come to rest where the walls help (robots keep their stations meanwhile)
            self.pin_fails += 1
            ovel = view.object_velocity
            moving = ovel is not None and float(np.hypot(ovel[0], ovel[1])) > PIN_STILL_SPEED
            if moving or self.pin_fails < PIN_RETRIES:
                return intent
            x, y, th = (float(v) for v in np.asarray(view.object_pose, float))
            detail = (
                "the object is against a wall or an obstacle and no set of capture points a "
                f"robot can reach there holds it with {self.n} robots (object at "
                f"({x:.2f}, {y:.2f}, {math.degrees(th):.0f}°), at rest, {self.pin_fails} tries)"
            )
            return self._fail(view, Reason.PINNED, detail, [])
        self.reach.replanned()
        self.capture = new
        return self._start(view, pinned=True)

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        view = parked(view)
        if self.transport is not None:
            return self.transport.safety(view, intent)
        if self.inner is None or self.failed:
            return MissionOutput.of(np.zeros((self.n, 3)), intent)
        return self.inner.safety(view, intent)

    def summary(self) -> JobSummary:
        carry = None if self.transport is None else self.transport.summary()
        if self.capture is None:  # entered at route
            return JobSummary(transport=carry)
        plan = CapturePlanSummary.of(self)
        inner = None if self.inner is None else self.inner.summary()
        return JobSummary(plan, inner, carry)
