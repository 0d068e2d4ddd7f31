"""TransportMission: carry the arrested object to ``object.goal`` (Sharma §4, Yamashita §3-4,
Vass §4), in the same closed loop as the capture.

Phases (each transition a ``phase`` event):

- ``route``: the object route (weighted A*, ``controller.planning.route``) from the object's
  estimated pose to the goal, cut into subgoals where the travel direction or the heading
  changes (event ``route``). No route: ``failed`` with reason ``no_route``, every robot stops
  where it is and the object is not pushed.
- ``rearrange``: for each segment's travel direction D, the robots' contacts must be able to
  push the object along it (the contact-force LP with their force limits,
  ``controller.planning.contact_lp``). If they cannot, Sharma's Eq. 5 (``plan_push_arrangement``)
  picks the contacts that push hardest along D, robots are matched to them (least travel
  around the object), the robots whose contact changes move there along the lane around the
  object while the others hold still, and the LP confirms the new set.
- ``transport``: every interval the local planner (``transport.strategy``: Vass's simulated
  annealing, its downhill ablation, or Sharma's serpentine; ``controller.planning.transport``)
  plans from the filtered object pose and the robots execute its first interval (event
  ``transport`` with the actions, energy and LP status). A subgoal reached moves to the next;
  an object that leaves the route's corridor re-plans the route.
- ``done`` when the object is within ``transport.tolerance`` m and
  ``transport.heading_tolerance_deg`` of the goal: the robots back off and stop. ``failed``
  with reason ``no_route`` or ``stalled`` (no progress for ``transport.stall_timeout`` s).

Pure: the planners are pure; time comes from the view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from controller import geometry
from controller.config import FleetConfig
from controller.mission.guard import SafetyStage
from controller.mission.outage import OutageWatch
from controller.mission.planners import (
    InlinePlanners,
    JobOwned,
    Planners,
    PlanSlot,
    spawn_rng,
)
from controller.mission.sequence import (
    Cue,
    Failure,
    JobState,
    Measures,
    SequenceSettings,
    next_phase,
)
from controller.mission.types import Event, FleetView, Intent, MissionOutput, Phase, Reason
from controller.planning.arrangement import Arrangement, can_push, plan_arrangement
from controller.planning.contact_lp import ContactForceLP
from controller.planning.serpentine import passive_velocity
from controller.planning.transport import TransportPlanner
from controller.planning.transport_model import ObjectModel, relocation_path
from controller.planning.transport_types import (
    ATTACHED,
    FOLLOW,
    PUSH,
    RELOCATE,
    SLIDE_LEFT,
    SLIDE_RIGHT,
    LocalPlan,
    RobotState,
    RouteSegment,
    TransportParams,
    TransportState,
    action_code,
)

SEQUENCE = SequenceSettings(carry=True)  # the transport is the job carrying the object on


@dataclass(frozen=True)
class TransportSettings:
    """The transport mission's constants (SI). From ``[transport]``: ``tolerance`` (m) and
    ``heading_tolerance`` (rad) at the goal, ``stall_timeout`` (s). Internal: ``subgoal_tolerance``
    (m, rad: a subgoal counts as reached), ``corridor`` (m: farther from the route re-plans it),
    ``progress_step`` (m of progress that resets the stall clock), ``contact_tolerance`` (m: a
    robot this close to its contact point is in contact), ``back_off`` (m the robots withdraw
    from the delivered object), ``rearrange_timeout`` (s), ``waypoint_reached`` (m)."""

    tolerance: float = 0.2
    heading_tolerance: float = math.radians(10.0)
    stall_timeout: float = 10.0
    subgoal_tolerance: float = 0.1
    subgoal_heading: float = math.radians(8.0)
    corridor: float = 0.4
    progress_step: float = 0.02
    contact_tolerance: float = 0.15
    back_off: float = 0.25
    rearrange_timeout: float = 25.0  # s: then a new arrangement (and failed when futile)
    waypoint_reached: float = 0.08
    contact_gain: float = 1.5  # 1/s, pull back onto the contact point
    arrival_tolerance: float = 0.03  # m: a relocating robot this close to its contact arrived
    max_route_replans: int = 5
    progress_window: float = 0.6  # m of route ahead that the progress measure looks at
    settle_margin: float = 0.6  # the estimate must be this share of the tolerances from the goal
    accept_margin: float = 0.85  # ... or this share when the object stalls there
    stuck_plans: int = 3
    park_margin: float = 0.05  # m beyond the lane's band where idle robots wait
    turn_margin: float = 1.2  # a set chosen to turn the object produces this times the wrench
    max_rearrangements: int = 8  # re-arrangements in a row without progress, then stalled

    @classmethod
    def from_config(cls, cfg: FleetConfig) -> TransportSettings:
        t = cfg.transport
        return cls(
            tolerance=t.tolerance,
            heading_tolerance=math.radians(t.heading_tolerance_deg),
            stall_timeout=t.stall_timeout,
        )


@dataclass
class Contact:
    """A robot's contact on the object (object frame): a point and the inward push direction."""

    point: np.ndarray
    inward: np.ndarray


class TransportMission:
    """Carries the object from where the capture left it. ``robots`` (K,) indices of the robots
    that hold it, ``points``/``normals`` their contact points and outward normals (K, 2), object
    frame; the rest of the fleet starts free."""

    def __init__(
        self,
        cfg: FleetConfig,
        rng: np.random.Generator,
        guard: SafetyStage,
        robots: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        route_planner: Any = None,
        planners: Planners | None = None,
    ) -> None:
        """``planners``: the port the route, the re-arrangement set and the local plans are
        asked of (off the tick; None: computed at once, ready the same tick)."""
        self.cfg = cfg
        self.rng = rng
        self.guard = guard
        self.s = TransportSettings.from_config(cfg)
        self.n = len(cfg.robots)
        # every robot of the fleet takes part: those holding the object keep their contacts,
        # the others are free (re-arrangement recruits them when the holders cannot push)
        self.robots = np.arange(self.n)
        o = cfg.object
        self.model = ObjectModel.build(
            cfg.object_polygon(), o.mass, o.floor_friction, o.contact_friction, cfg.max_robot_radius
        )
        self.params = TransportParams.from_config(cfg.transport)
        self.planner = JobOwned(TransportPlanner(self.params))  # touched only by its jobs
        # the route planner toward object.goal (its C-space and cost-to-go table take a second:
        # the job builds it before the loop starts; the first route job builds it otherwise)
        self._route_box = JobOwned(route_planner)
        self.planners = planners if planners is not None else InlinePlanners()
        self._route_job = PlanSlot(self.planners, "route")
        self._set_job = PlanSlot(self.planners, "rearrange")
        self._plan_job = PlanSlot(self.planners, "transport")
        self._reset_planner = False  # the next local plan starts afresh (a new segment)
        self.plan_waits = 0  # ticks a phase waited for a plan with the robots held
        self.lp = ContactForceLP(max(len(self.robots), 1), friction=o.contact_friction > 0)
        self.contacts: dict[int, Contact | None] = {int(i): None for i in self.robots}
        for i, p, nv in zip(np.asarray(robots, int), points, normals, strict=True):
            self.contacts[int(i)] = Contact(np.asarray(p, float), -np.asarray(nv, float))
        self.actions: dict[int, str | None] = {int(i): None for i in self.robots}
        # the object held: the job goes on at ``route`` (sequence.next_phase moves the phase)
        self.job = JobState(Phase.ARRESTED)
        self.t0: float | None = None
        self.route: Any = None
        self.subgoal = 0
        self.plan_t: float | None = None
        self.last_plan: LocalPlan | None = None
        self.best_remaining = math.inf
        self.route_j = 0  # the route segment the object was last matched to
        self.progress_t = 0.0
        self.route_replans = 0
        self.rearrangements = 0
        self.futile = 0  # re-arrangements since the object last made progress
        self.relocations = 0
        self.moves: dict[int, list[np.ndarray]] = {}  # robot -> object-frame path (rearranging)
        self.targets: dict[int, Contact] = {}
        self.rearrange_t = 0.0
        self.done_t: float | None = None
        self.failure: dict[str, Any] | None = None
        self.plans = 0
        self.stuck = 0
        self.plan_energy: list[float] = []
        self.forces: list[float] = []
        self.lost: set[int] = set()  # robots gone during the job
        self.outage = OutageWatch(cfg.fleet.outage_grace)
        self._last_t: float | None = None  # the last tick's time (an outage's pause)

    # --- the plan stage -----------------------------------------------------------------------
    def plan(self, view: FleetView) -> Intent:
        zero = np.zeros((self.n, 2))
        if view.object_pose is None or view.estop:
            return Intent(zero, self.phase, stop=True)
        pose = np.asarray(view.object_pose, float)
        events: list[Event] = []
        if self.t0 is None:
            self.t0 = self.progress_t = view.t
            # the carrying starts here (the route comes a few ticks later, planned off the tick)
            self._cue(Cue.CARRY, view.t, events)
        dt = 0.0 if self._last_t is None else view.t - self._last_t
        self._last_t = view.t
        if self.phase not in (Phase.DONE, Phase.FAILED) and self._drop_lost(view, events):
            return self._paused(view, dt, events)
        handler = {
            Phase.ROUTE: self._route,
            Phase.REARRANGE: self._rearrange,
            Phase.TRANSPORT: self._transport,
            Phase.DONE: self._done,
            Phase.FAILED: self._failed,
        }[self.phase]
        return handler(view, pose, events)

    def _drop_lost(self, view: FleetView, events: list[Event]) -> bool:
        """A robot that is gone (its liveliness or its link lost) leaves the job: no contact, no
        path, no part in the next arrangement. The rest carry on; when they cannot push, the
        job fails with ``robot_lost`` instead of ``stalled``. Two or more gone at once are one
        outage (``OutageWatch``): True while the mission pauses for it."""
        relied = np.array([int(i) not in self.lost for i in self.robots])
        gone, pause, ev = self.outage.filter(view.t, ~view.present, relied, view.ids)
        events += ev
        if pause:
            return True  # one fleet-wide silence: paused until it ends or its grace runs out
        for i in self.robots:
            i = int(i)
            if not gone[i] or i in self.lost:
                continue
            self.lost.add(i)
            self.contacts[i] = None
            self.moves.pop(i, None)
            self.targets.pop(i, None)
            self.actions[i] = None
            events.append(("robot_lost", {"t": view.t, "robot": view.ids[i], "phase": self.phase}))
        return False

    def _active(self) -> list[int]:
        return [int(i) for i in self.robots if int(i) not in self.lost]

    @property
    def phase(self) -> Phase:
        return self.job.phase

    def _cue(self, cue: Cue | None, t: float, events: list[Event], failure: Failure | None = None):
        """Report what the transport saw: the sequence moves the phase (and writes its
        events)."""
        step = next_phase(self.job, Measures(t, cue, failure), SEQUENCE)
        self.job = step.state
        events.extend(step.events)

    def _fail(self, reason: str, detail: str, view: FleetView, events: list[Event]) -> Intent:
        if reason == Reason.STALLED and self.lost:
            lost = ", ".join(view.ids[i] for i in sorted(self.lost))
            reason, detail = Reason.ROBOT_LOST, f"{detail} (lost: {lost})"
        self._cue(None, view.t, events, Failure(Reason(reason), detail))
        self.failure = {"reason": str(reason), "t": view.t, "detail": detail}
        return Intent(
            np.zeros((self.n, 2)), self.phase, events, stop=True, failed=True, reason=reason
        )

    def _failed(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        reason = self.failure["reason"] if self.failure else ""
        zero = np.zeros((self.n, 2))
        return Intent(zero, self.phase, events, stop=True, failed=True, reason=reason)

    def _paused(self, view: FleetView, dt: float, events: list[Event]) -> Intent:
        """An outage: every robot still; the stall clock and the re-arrangement's timeout do
        not run while it lasts (``dt`` s since the last tick)."""
        self.progress_t += dt
        self.rearrange_t += dt
        zero = np.zeros((self.n, 2))
        return Intent(zero, self.phase, events, stop=True)

    def _held(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """A plan is on its way: every robot holds where it is (those in contact keep it)."""
        self.plan_waits += 1
        touch = np.array([self.contacts[int(i)] is not None for i in self.robots])
        zero = np.zeros((self.n, 2))
        return self._intent(zero, events, pose, touch, np.ones(self.n, bool))

    # --- route --------------------------------------------------------------------------------
    def _route(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """Ask for the route from the object's pose (off the tick), hold until it comes."""
        if not self._route_job.pending:
            self._route_job.request(view.t, _plan_route, self._route_box, self.cfg, pose)
        got = self._route_job.take(view.t)
        if got is None:
            return self._held(view, pose, events)
        if not got.ok:
            return self._fail(
                Reason.NO_ROUTE, f"the route planner failed: {got.error}", view, events
            )
        res = got.value
        if not res.ok:
            return self._fail(Reason.NO_ROUTE, res.reason, view, events)
        self.route = res
        self.subgoal = 0
        self.best_remaining = math.inf
        self.route_j = 0  # the route segment the object was last matched to
        self.progress_t = view.t
        events.append(
            (
                "route",
                {
                    "t": view.t,
                    "waypoints": np.round(res.waypoints, 4).tolist(),
                    "subgoals": np.round(res.subgoals, 4).tolist(),
                    "length_m": res.length_m,
                    "cost_s": res.cost,
                    "replans": self.route_replans,
                },
            )
        )
        return self._begin_segment(view, pose, events)

    def _begin_segment(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """A new segment: re-arrange if the contacts cannot push along it, else transport.
        Subgoals already within tolerance are passed (the route's exact joins can put one a
        hair's turn from the start)."""
        while self._subgoal_reached(pose):
            self.subgoal += 1
        self._forget_plan()
        if self._can_push(pose):
            self._cue(Cue.CAN_PUSH, view.t, events)
            return self._transport(view, pose, events)
        self._start_rearrangement(view, pose, events, Cue.CANNOT_PUSH)
        return self._rearrange(view, pose, events)

    def _segment(self) -> RouteSegment:
        wp = self.route.waypoints
        return RouteSegment.toward(wp, self.route.subgoals[self.subgoal])

    def _direction(self, pose: np.ndarray) -> np.ndarray:
        """The twist (object frame, centroid) the current segment asks for, unit speed."""
        goal = self.route.subgoals[self.subgoal]
        c = geometry.transform(self.model.centroid[None], pose)[0]
        cg = geometry.transform(self.model.centroid[None], goal)[0]
        d = np.r_[cg - c, self.model.mean_radius * geometry.wrap_angle(goal[2] - pose[2])]
        norm = float(np.linalg.norm(d))
        if norm < 1e-9:
            return np.zeros(3)
        d /= norm
        local = geometry.rot(float(pose[2])).T @ d[:2]
        return np.r_[local, d[2] / self.model.mean_radius]

    def _forget_plan(self) -> None:
        """A new segment or arrangement: the local plan starts afresh (the planner's warm
        start is reset by the next plan's job: only jobs touch the planner)."""
        self._plan_job.cancel()
        self._reset_planner = True
        self.last_plan = None
        self.plan_t = None

    def _can_push(self, pose: np.ndarray) -> bool:
        """Whether the robots in contact can push the object along the segment (the LP)."""
        twist = self._direction(pose) * self.params.speed
        return can_push(self.lp, self.model, twist, *self._contact_arrays())

    def _contact_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pts, nrm, fmax = [], [], []
        for i, c in self.contacts.items():
            if c is not None:
                pts.append(c.point)
                nrm.append(c.inward)
                fmax.append(self.cfg.robots[i].max_force)
        return np.reshape(pts, (-1, 2)), np.reshape(nrm, (-1, 2)), np.asarray(fmax, float)

    # --- rearrange ----------------------------------------------------------------------------
    def _start_rearrangement(self, view: FleetView, pose: np.ndarray, events: list[Event], cue):
        """Ask for new contacts for the segment (``planning.arrangement``, off the tick); the
        robots hold until they come (:meth:`_arrange`). ``cue``: why (cannot push, stuck, a
        set given up)."""
        self._cue(cue, view.t, events)
        self.rearrangements += 1
        self.futile += 1
        self.rearrange_t = view.t
        self.targets.clear()
        self.moves.clear()
        active = self._active()
        weakest = min(self.cfg.robots[i].max_force for i in active)
        self._set_job.request(
            view.t,
            plan_arrangement,
            self.cfg,
            self.model,
            self._direction(pose),
            self.params.speed,
            weakest,
            len(active),
            self.s.turn_margin,
            spawn_rng(self.rng),
            self.params.strategy,
        )

    def _arrange(self, view: FleetView, pose: np.ndarray, new: Arrangement, events: list[Event]):
        """The new contacts have come: the robots nearest to them move there, the others keep
        their contacts (one too close to a new contact lets go)."""
        self.rearrange_t = view.t  # its timeout counts from the set's arrival
        cfg = self.cfg
        r = cfg.max_robot_radius
        new_pts, new_nrm = new.points, new.normals
        ids = self._active()
        here = geometry.inverse_transform(view.poses[ids, :2], pose)
        cost = np.linalg.norm(here[:, None] - (new_pts + r * new_nrm)[None], axis=-1)
        rows, cols = linear_sum_assignment(cost)
        chosen = set()
        for row, col in zip(rows, cols, strict=True):
            i = ids[row]
            chosen.add(i)
            self.targets[i] = Contact(new_pts[col], -new_nrm[col])
            if cost[row, col] > self.s.arrival_tolerance:
                end = new_pts[col] + cfg.robots[i].radius * new_nrm[col]
                self.moves[i] = list(relocation_path(self.model, here[row], end))
                self.contacts[i] = None
                self.relocations += 1
        centres = new_pts + r * new_nrm
        for i in ids:
            c = self.contacts[i]
            if i in chosen or c is None:
                continue
            mine = c.point - r * c.inward
            if np.any(np.linalg.norm(centres - mine, axis=1) < 2 * r + cfg.capture.clearance):
                self.contacts[i] = None  # in the way of a new contact: it lets go
        d = self._direction(pose)[:2]
        events.append(
            (
                "rearrange",
                {
                    "t": view.t,
                    "direction": np.round(d if np.any(d) else np.array([1.0, 0.0]), 4).tolist(),
                    "pushers": new.pushers,
                    "basis": new.basis,
                    "eq5_value": float(new.value),
                    "moving": [view.ids[i] for i in self.moves],
                    "contacts": {
                        view.ids[i]: np.round(c.point, 4).tolist() for i, c in self.targets.items()
                    },
                },
            )
        )

    def _take_arrangement(
        self, view: FleetView, pose: np.ndarray, events: list[Event]
    ) -> Intent | None:
        """The new contacts, once they have come (None: go on with them); meanwhile the robots
        hold; a set no robots can push with fails ``too_heavy`` before anyone pushes."""
        got = self._set_job.take(view.t)
        if got is None:
            return self._held(view, pose, events)
        if not got.ok:
            detail = f"the re-arrangement planner failed: {got.error}"
            return self._fail(Reason.STALLED, detail, view, events)
        if not got.value.feasible:
            return self._fail(Reason.TOO_HEAVY, got.value.detail, view, events)
        self._arrange(view, pose, got.value, events)
        return None

    def _rearrange(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """Movers follow their path around the object; the others hold still. (The stall clock
        waits: re-arranging makes no progress by design; it has its own timeout.) An object
        nudged inside the goal tolerance meanwhile is delivered."""
        goal = np.asarray(self.cfg.object.goal, float)
        k = self.s.accept_margin
        if self._at(pose, goal, k * self.s.tolerance, k * self.s.heading_tolerance):
            return self._deliver(view, pose, events)
        self.progress_t = view.t
        if self._set_job.pending:
            waiting = self._take_arrangement(view, pose, events)
            if waiting is not None:
                return waiting
        vel = np.zeros((self.n, 2))
        hold = np.ones(self.n, bool)
        for i in self.moves:
            hold[i] = False
        touch = np.zeros(self.n, bool)
        for i, c in self.contacts.items():
            touch[i] = c is not None
        self._follow_paths(view, pose, vel, touch)
        self._park(view, pose, vel, hold)
        if not self.moves:
            for i, c in self.targets.items():
                self.contacts[i] = c
            self.targets.clear()
            if self._can_push(pose) or self.futile < self.s.max_rearrangements:
                self._cue(Cue.ARRANGED, view.t, events)
                return self._transport(view, pose, events)
            return self._fail(
                Reason.STALLED, "the re-arranged contacts cannot push the object", view, events
            )
        if view.t - self.rearrange_t > self.s.rearrange_timeout:
            if self.futile >= self.s.max_rearrangements:
                return self._fail(Reason.STALLED, "re-arrangement timed out", view, events)
            # a robot that cannot get to its contact (blocked by the others, a wall): a new set
            self._start_rearrangement(view, pose, events, Cue.RESET)
        return self._intent(vel, events, pose, touch, hold)

    def _park(self, view: FleetView, pose: np.ndarray, vel: np.ndarray, hold: np.ndarray) -> None:
        """Robots without a contact or a path leave the relocation lane: each one whose disc
        reaches into the lane's band backs straight away from the object until it is clear
        (a robot left on the lane where its last path ended blocks every path that passes)."""
        if not self.moves:
            return
        m, r = self.model, self.cfg.max_robot_radius
        clear = 5.0 * r + self.s.park_margin  # the lane at 3r: its robots reach out to 4r
        hull = geometry.convex_hull(m.polygon)
        for i in self.robots:
            i = int(i)
            if i in self.moves or self.contacts[i] is not None or i in self.lost:
                continue
            local = geometry.inverse_transform(view.poses[i, None, :2], pose)
            d, closest = geometry.point_segment_distance(local, hull, np.roll(hull, -1, axis=0))
            k = int(np.argmin(d[0]))
            if d[0, k] >= clear or geometry.points_in_polygon(local, hull)[0]:
                continue
            out = (local[0] - closest[0, k]) / max(float(d[0, k]), 1e-9)
            speed = min(1.5 * (clear - float(d[0, k])) + 0.05, self.cfg.robots[i].max_speed)
            vel[i] = geometry.rot(float(pose[2])) @ out * speed
            hold[i] = False

    # --- transport ----------------------------------------------------------------------------
    def _transport(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        goal = np.asarray(self.cfg.object.goal, float)
        m = self.s.settle_margin  # stop well inside: the estimate is a centimetre and a degree off
        if self._at(pose, goal, m * self.s.tolerance, m * self.s.heading_tolerance):
            return self._deliver(view, pose, events)
        stall = self._stalled(view, pose)
        k = self.s.accept_margin  # the estimate is off by a centimetre: keep clear of the edge
        inside = self._at(pose, goal, k * self.s.tolerance, k * self.s.heading_tolerance)
        if inside and (stall or self.stuck >= self.s.stuck_plans):
            # inside the tolerance and the last centimetres will not come: delivered as it is
            # (re-arranging there shuffles robots around a delivered object)
            return self._deliver(view, pose, events)
        if stall and self.futile >= self.s.max_rearrangements:
            return self._fail(Reason.STALLED, stall, view, events)
        if stall or view.t - self.progress_t > self.s.stall_timeout / 2:
            # receding-horizon plans can keep re-positioning without ever pushing: re-arrange
            self.stuck = self.s.stuck_plans
        if self._off_route(pose):
            if self.route_replans >= self.s.max_route_replans:
                return self._fail(Reason.STALLED, "left the route corridor too often", view, events)
            self.route_replans += 1
            self._cue(Cue.OFF_ROUTE, view.t, events)
            return self._route(view, pose, events)
        if self._subgoal_reached(pose):
            self.subgoal += 1
            return self._begin_segment(view, pose, events)
        if self.stuck >= self.s.stuck_plans:  # the contacts cannot push as the route asks
            self.stuck = 0
            self._forget_plan()
            self._start_rearrangement(view, pose, events, Cue.STUCK)
            return self._rearrange(view, pose, events)
        return self._plan_and_execute(view, pose, events)

    def _plan_and_execute(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """Ask for a local plan every interval; execute the latest one that has come, closed on
        the current estimate (hold while the segment's first plan is on its way)."""
        due = self.plan_t is None or (
            self.last_plan is not None and view.t - self.plan_t >= self.last_plan.interval - 1e-9
        )
        if due and not self._plan_job.pending:
            self._request_plan(view, pose)
        got = self._plan_job.take(view.t)
        if got is not None:
            if not got.ok:
                detail = f"the local planner failed: {got.error}"
                return self._fail(Reason.STALLED, detail, view, events)
            self._apply_plan(view, pose, got.value, events)
        if self.last_plan is None:
            return self._held(view, pose, events)
        return self._execute(view, pose, events)

    def _deliver(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        self.done_t = view.t
        self._cue(Cue.DELIVERED, view.t, events)
        events.append(("delivered", {"t": view.t, "pose": np.round(pose, 4).tolist()}))
        return self._done(view, pose, events)

    def _at(self, pose: np.ndarray, goal: np.ndarray, tol: float, tol_th: float) -> bool:
        return bool(
            np.linalg.norm(pose[:2] - goal[:2]) <= tol
            and abs(geometry.wrap_angle(pose[2] - goal[2])) <= tol_th
        )

    def _subgoal_reached(self, pose: np.ndarray) -> bool:
        if self.subgoal >= len(self.route.subgoals) - 1:
            return False
        g = self.route.subgoals[self.subgoal]
        return self._at(pose, g, self.s.subgoal_tolerance, self.s.subgoal_heading)

    def _remaining(self, pose: np.ndarray, commit: bool = False) -> float:
        """What is left of the route (m): the way to a route segment, the rest of that segment
        and every later one, turns counted as arc at the mean radius, at the best segment of a
        window from the last one matched (``commit`` moves the window on). (A straight line to
        the goal would call a detour around an obstacle no progress; a window over the whole
        route would cut through the obstacle to its far side.)"""
        wp = self.route.waypoints
        r = self.model.mean_radius
        goal = np.asarray(self.cfg.object.goal, float)
        if len(wp) < 2:
            return float(np.linalg.norm(pose[:2] - goal[:2])) + r * abs(
                geometry.wrap_angle(pose[2] - goal[2])
            )
        step = np.linalg.norm(np.diff(wp[:, :2], axis=0), axis=1)
        step = step + r * np.abs(geometry.wrap_angle(np.diff(wp[:, 2])))
        tail = np.concatenate([np.cumsum(step[::-1])[::-1][1:], [0.0]])  # after segment j
        dist, closest = geometry.point_segment_distance(pose[None, :2], wp[:-1, :2], wp[1:, :2])
        rest = np.linalg.norm(wp[1:, :2] - closest[0], axis=1)
        turn = r * np.abs(geometry.wrap_angle(pose[2] - wp[1:, 2]))
        # the best way on from a segment of the window (turns in place share one spot: the
        # heading decides among them)
        lo = min(self.route_j, len(step) - 1)
        arc = np.concatenate([[0.0], np.cumsum(step)])
        hi = int(np.searchsorted(arc, arc[lo] + self.s.progress_window, side="right"))
        hi = min(len(step), max(hi, lo + 1))
        left = (dist[0] + rest + turn + tail)[lo:hi]
        k = int(np.argmin(left))
        if commit:
            self.route_j = lo + k
        return float(left[k])

    def _stalled(self, view: FleetView, pose: np.ndarray) -> str:
        rem = self._remaining(pose, commit=True)
        if rem < self.best_remaining - self.s.progress_step:
            self.best_remaining = rem
            self.progress_t = view.t
            self.futile = 0
        if view.t - self.progress_t > self.s.stall_timeout:
            return f"no progress for {self.s.stall_timeout:g} s, {rem:.2f} m from the goal"
        return ""

    def _off_route(self, pose: np.ndarray) -> bool:
        wp = self.route.waypoints
        if len(wp) < 2:
            return False
        seg_a, seg_b = wp[:-1, :2], wp[1:, :2]
        dist, _ = geometry.point_segment_distance(pose[None, :2], seg_a, seg_b)
        return bool(dist.min() > self.s.corridor)

    def _robot_states(self, view: FleetView) -> tuple[RobotState, ...]:
        out = []
        pose = np.asarray(view.object_pose, float)
        for i in self.robots:
            r = self.cfg.robots[i]
            c = self.contacts[int(i)]
            if c is not None:
                centre = geometry.transform((c.point - r.radius * c.inward)[None], pose)[0]
                if np.linalg.norm(centre - view.poses[i, :2]) > self.s.contact_tolerance:
                    c = None  # it lost its contact: the planner knows it as free
            out.append(
                RobotState(
                    position=view.poses[i, :2].copy(),
                    radius=r.radius,
                    max_force=r.max_force,
                    max_speed=r.max_speed,
                    contact=None if c is None else (c.point, c.inward),
                    action="relocate"
                    if int(i) in self.moves
                    else ("idle" if int(i) in self.lost else self.actions[int(i)]),
                    id=r.id,
                    target=self._target_of(int(i)),
                )
            )
        return tuple(out)

    def _target_of(self, i: int) -> tuple[np.ndarray, np.ndarray] | None:
        t = self.targets.get(i) if i in self.moves else None
        return None if t is None else (t.point, t.inward)

    def _request_plan(self, view: FleetView, pose: np.ndarray) -> None:
        """Ask for a local plan from the current estimate (off the tick); the robots execute
        the previous one meanwhile. ``plan_t`` is the state's time: the next plan is due one
        interval after it, however long this one takes to come."""
        cfg = self.cfg
        state = TransportState(
            self.model,
            pose,
            self._robot_states(view),
            self._segment(),
            tuple(cfg.obstacle_polygons()),
            cfg.bounds_array(),
        )
        elapsed = 0.0 if self.plan_t is None else view.t - self.plan_t
        reset, self._reset_planner = self._reset_planner, False
        self._plan_job.request(
            view.t, _plan_local, self.planner, state, spawn_rng(self.rng), elapsed, reset
        )
        self.plan_t = view.t

    def _apply_plan(
        self, view: FleetView, pose: np.ndarray, plan: LocalPlan, events: list[Event]
    ) -> None:
        """A local plan has come: its first interval's contacts, relocations and actions."""
        self.last_plan = plan
        self.plans += 1
        first_ok = plan.lp_status[0] == "optimal" if plan.lp_status else True
        self.stuck = 0 if first_ok or self.moves else self.stuck + 1
        self.plan_energy.append(plan.energy.total)
        # a relocation costs seconds of travel the kinematic model does not pay in full: the
        # robots leave their contacts only when the contacts they have cannot push as asked
        relocate_ok = not self._can_push(pose)
        for k, i in enumerate(self.robots):
            i = int(i)
            if i in self.lost:
                continue
            action = plan.first_actions[k]
            self.actions[i] = action
            p, nv = plan.contact_points[k], plan.contact_normals[k]
            if i in self.moves:
                continue  # committed to a relocation: it finishes it first
            if np.all(np.isfinite(p)) and action_code(action) in ATTACHED:
                self.contacts[i] = Contact(p.copy(), nv.copy())
            elif action_code(action) == RELOCATE and np.all(np.isfinite(p)) and relocate_ok:
                self._commit_relocation(i, Contact(p.copy(), nv.copy()), view, pose)
            elif action_code(action) == RELOCATE:
                self.actions[i] = "follow"
        f = plan.forces[0]
        self.forces.extend(float(x) for x in f if x > 0)
        moving = {
            view.ids[i]: float(np.sum(np.linalg.norm(np.diff(np.asarray(p), axis=0), axis=1)))
            for i, p in self.moves.items()
        }
        ids = [view.ids[int(i)] for i in self.robots]  # the plan's rows (the scene's pushers)
        lag = view.t - self.plan_t  # the state it was planned from is this old
        events.append(
            (
                "transport",
                {
                    "t": view.t,
                    "robots": ids,
                    **plan.to_dict(),
                    "relocating": moving,
                    "plan_age_s": round(lag, 6),
                },
            )
        )

    def _commit_relocation(self, i: int, target: Contact, view: FleetView, pose: np.ndarray):
        """A robot the plan relocates goes to that contact along the lane around the object,
        and keeps to it until it arrives (a plan made every interval would otherwise move the
        target before it gets there)."""
        r = self.cfg.robots[i].radius
        start = geometry.inverse_transform(view.poses[i, None, :2], pose)[0]
        end = target.point - r * target.inward
        cur = self.contacts[i]
        if cur is not None and np.linalg.norm(cur.point - target.point) < 2 * r:
            self.contacts[i] = target  # a short move along the boundary: stay attached
            return
        self.moves[i] = list(relocation_path(self.model, start, end))
        self.targets[i] = target
        self.contacts[i] = None
        self.relocations += 1

    def _follow_paths(
        self, view: FleetView, pose: np.ndarray, vel: np.ndarray, touch: np.ndarray
    ) -> None:
        """Robots on a committed path: pure pursuit of its next point; arrival attaches them;
        on the last leg a robot may touch the object (it is coming to its contact)."""
        for i, path in list(self.moves.items()):
            here = view.poses[i, :2]
            world = geometry.transform(np.asarray(path), pose)
            while len(world) > 1 and np.linalg.norm(world[0] - here) < self.s.waypoint_reached:
                path.pop(0)
                world = world[1:]
            err = world[0] - here
            dist = float(np.linalg.norm(err))
            if len(world) == 1 and dist < self.s.arrival_tolerance:
                del self.moves[i]
                self.contacts[i] = self.targets.pop(i)
                continue
            speed = min(1.5 * dist + 0.05, self.cfg.robots[i].max_speed)
            vel[i] = err / max(dist, 1e-9) * speed
            touch[i] = len(world) <= 2

    def _execute(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """The plan's first interval, closed every tick: a robot holding a contact moves with
        the object's planned twist at its contact point plus a pull back onto the point (and,
        pushing, ``push_bias`` into the object); a relocating or idle one takes the plan's
        velocity."""
        plan = self.last_plan
        vel = np.zeros((self.n, 2))
        touch = np.zeros(self.n, bool)
        twist = plan.object_twists[0] if len(plan.object_twists) else np.zeros(3)
        centroid = geometry.transform(self.model.centroid[None], pose)[0]
        rot = geometry.rot(float(pose[2]))
        for k, i in enumerate(self.robots):
            code = action_code(plan.first_actions[k])
            c = self.contacts[int(i)]
            if int(i) in self.moves or int(i) in self.lost:
                continue  # on its committed path (below); a lost robot is told nothing
            if code not in ATTACHED or c is None or code in (SLIDE_LEFT, SLIDE_RIGHT):
                vel[i] = plan.velocities[k]
                touch[i] = code in ATTACHED
                continue
            r = self.cfg.robots[i].radius
            centre = geometry.transform((c.point - r * c.inward)[None], pose)[0]
            if code == FOLLOW and plan.strategy == "serpentine":  # §4.3: passive, zero force
                vel[i] = passive_velocity(
                    centre, view.poses[i, :2], rot @ c.inward, pose, view.object_velocity,
                    self.s.contact_gain, self.cfg.robots[i].max_speed,
                )  # fmt: skip
                touch[i] = True
                continue
            rel = centre - centroid
            v = twist[:2] + twist[2] * np.array([-rel[1], rel[0]])
            v = v + self.s.contact_gain * (centre - view.poses[i, :2])
            if code == PUSH:
                v = v + self.params.push_bias * (rot @ c.inward)
            speed = float(np.linalg.norm(v))
            vmax = self.cfg.robots[i].max_speed
            vel[i] = v if speed <= vmax else v * vmax / speed
            touch[i] = True
        self._follow_paths(view, pose, vel, touch)
        return self._intent(vel, events, pose, touch, None, twist)

    # --- done ---------------------------------------------------------------------------------
    def _done(self, view: FleetView, pose: np.ndarray, events: list[Event]) -> Intent:
        """Back off from the delivered object, then stop."""
        vel = np.zeros((self.n, 2))
        c = geometry.transform(self.model.centroid[None], pose)[0]
        if view.t - self.done_t < self.s.back_off / 0.1:
            for i in self._active():
                away = view.poses[i, :2] - c
                vel[i] = 0.1 * away / max(float(np.linalg.norm(away)), 1e-9)
        intent = self._intent(vel, events, pose, np.zeros(self.n, bool), None)
        intent.done = view.t - self.done_t >= self.s.back_off / 0.1
        return intent

    def _intent(self, vel, events, pose, touch, hold, twist=None) -> Intent:
        return Intent(
            vel,
            self.phase,
            events,
            object_pose=pose,
            touch=touch,
            overlap=float(self.cfg.max_robot_radius) if np.any(touch) else 0.0,
            cage=True,
            hold=hold,
            progress={
                "phase": str(self.phase),
                "to_goal_m": self._remaining(pose)
                if self.route is not None
                else float(np.linalg.norm(pose[:2] - np.asarray(self.cfg.object.goal)[:2])),
                "subgoal": float(self.subgoal),
            },
            object_push=None if twist is None else np.asarray(twist, float),
        )

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        return self.guard.apply(view, intent)

    def summary(self) -> dict[str, Any]:
        f = np.asarray(self.forces) if self.forces else np.zeros(0)
        return {
            "transport_phase": str(self.phase),
            "route_length_m": None if self.route is None else self.route.length_m,
            "route_replans": self.route_replans,
            "rearrangements": self.rearrangements,
            "relocations": self.relocations,
            "local_plans": self.plans,
            "planned_force_mean_n": float(f.mean()) if len(f) else None,
            "transport_failure": self.failure,
        }


def _plan_route(box: JobOwned, cfg: FleetConfig, pose: np.ndarray) -> Any:
    """Job ``route``: the route from ``pose`` (the planner, kept in ``box``, built first when
    there is none)."""
    if box.value is None:
        box.value = route_planner_for(cfg)
    return box.value.plan(pose)


def _plan_local(
    box: JobOwned,
    state: TransportState,
    rng: np.random.Generator,
    elapsed: float,
    reset: bool,
) -> LocalPlan:
    """Job ``transport``: one local plan by the ``TransportPlanner`` in ``box`` (its warm
    start reset first on a new segment). Only these jobs touch it, one at a time."""
    if reset:
        box.value.reset()
    return box.value.plan(state, rng, elapsed)


def route_planner_for(cfg: FleetConfig) -> Any:
    """The object's route planner toward ``object.goal`` (C-space and cost-to-go table built)."""
    from controller.planning.route import RoutePlanner

    return RoutePlanner.from_config(cfg)
