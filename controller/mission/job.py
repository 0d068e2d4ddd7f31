"""The whole job: the capture plan at construction, robot assignment once the first estimates
are in, then the approach-and-arrest mission (pure, per tick).

The plan is the GA's (Sharma Eq. 3, ``controller.planning.capture``), reinforced until the
contacts can hold the object's push (``capture.hold_force``) with the robots' force limits
(``controller.planning.capture_set``): form closure alone can need several times the push at a
contact. Re-plans (robot loss, walls, a start without robots never seen) run off the tick.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from controller import geometry
from controller.config import FleetConfig
from controller.mission.capture import CaptureMission
from controller.mission.capture_phase import CaptureSettings
from controller.mission.guard import SafetyStage
from controller.mission.outage import OutageWatch
from controller.mission.planners import InlinePlanners, Planners, PlanSlot, spawn_rng
from controller.mission.sequence import Cue, Failure, JobState, Measures, next_phase
from controller.mission.transport import TransportMission, route_planner_for
from controller.mission.types import FleetView, Intent, MissionOutput, Phase, Reason
from controller.planning.approach import envelope, interception_times
from controller.planning.capture_set import (  # noqa: F401 - re-exported: the job's planning
    TOKEN_LOAD,
    WALL_TOLERANCE,
    CapturePlanError,
    CaptureSet,
    plan_capture_set,
    replan_for_robots,
    replan_pinned,
)


class MissionError(RuntimeError):
    """The mission cannot be built for this fleet (e.g. no feasible capture plan: the message
    gives the planner's reason)."""


REASSIGN_PERIOD = 2.0  # s between looks at a better assignment during the approach
REASSIGN_GAIN = 0.25  # the share of the total interception time a new assignment must save
REASSIGN_MIN_S = 5.0  # s of total interception time it must save at least
REASSIGN_MIN_SPEED = 0.1  # m/s: slower objects keep their first assignment
PIN_TICKS = 10  # ticks a capture point must stay blocked by a wall before the capture re-plans
MAX_REPLANS = 8  # capture re-plans at walls before the set stands as it is
PIN_RETRIES = 6  # re-plans that find no set before an object at rest is declared pinned
PIN_STILL_SPEED = 0.03  # m/s: an object slower than this has come to rest against the wall
STUCK_S = 8.0  # s a robot may come no closer to its station (object at rest) before its point
STUCK_PROGRESS = 0.05  # m  ... is taken for out of reach and the capture re-planned without it
STUCK_POCKET = 0.3  # m around a stuck point whose nodes are excluded with it
STUCK_OBJECT_MOVE = 0.1  # m the object may move (estimate) and still count as at rest


# s a robot's estimate may stay stale (no pose for fleet.stale_after) before the capture takes
# the robot for lost (a robot whose liveliness token or link is gone is lost at once)
LOST_STALE_S = 0.5
WATCHED = (Phase.APPROACH, Phase.CLOSE_IN, Phase.HOLD)  # phases a lost robot re-plans
PARK = 1.0e3  # m: a robot never seen is parked this far away in the views the capture reads


class CaptureJob:
    """The capture: the plan at construction, robot assignment once the first estimates are in
    (robots and object), then the approach-and-arrest mission.

    Until every robot is present with a fresh estimate and the object has been seen, every robot
    holds still (phase ``plan``); ``fleet.start_wait`` s after the first estimates, robots never
    seen no longer block: the capture starts with those seen (re-planned for them when the set
    needs more). The assignment minimises the total time for the robots to meet their points'
    stations where the moving object will be (interception at full speed), over the robots
    *available*; robots left over stay where they are.

    Robot loss and join: a robot whose liveliness or link is gone, or whose estimate has been
    stale for ``LOST_STALE_S`` s, during the approach, close-in or hold is lost (event
    ``robot_lost``) and no longer available. When it held a capture point, the capture is
    re-planned with the robots left (``replan_for_robots``) and re-assigned; when none closes
    the object, the job fails with ``robots_lost``, every robot stopped. A robot present and
    fresh again (or seen for the first time) is available again (event ``robot_joined``): a
    later re-plan or re-assignment may pick it; it never gets its old point back by itself.
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
        self.job = JobState(Phase.PLAN)  # until the capture (or the transport) starts
        self.capture: CaptureSet | None = None
        if entry == Phase.PLAN:
            try:
                self.capture = plan_capture_set(cfg, self.rng)
            except CapturePlanError as exc:
                raise MissionError(str(exc)) from None
        self._replan_job = PlanSlot(planners or InlinePlanners(), "capture")
        self._replan_why = ""  # what the pending capture re-plan is for: lost, pinned, start
        self.outage = OutageWatch(cfg.fleet.outage_grace)
        self.assignment: np.ndarray | None = None
        self.inner: Any = None
        self.blocked_ticks = 0
        self.replans = 0
        self.reassignments = 0
        self.pin_fails = 0
        self.unreachable: set[int] = set()  # candidate nodes robots could not get to
        self.progress: tuple[np.ndarray, np.ndarray, np.ndarray, Any] | None = None
        self.assigned_t = -math.inf
        self.failed = False
        self.failure_reason: str = Reason.PINNED
        self.available = np.ones(self.n, bool)  # robots an assignment may use
        self.lost: list[int] = []  # robots lost during the capture, in order
        self.stale_since = np.full(self.n, np.nan)  # s: when each estimate turned stale
        self.first_t: float | None = None  # s: the first estimates (robot or object)
        self.start_tried = -1  # robots a start without the missing ones was last planned for
        self.loss_replans = 0
        self.lost_t: float | None = None  # s: the last loss that re-planned
        self.transport: Any = None
        self.arrest_t: float | None = None
        self.route_planner: Any = None
        if cfg.object.goal is not None:  # built before the loop: it takes a second
            self.route_planner = route_planner_for(cfg)

    def _assign(self, view: FleetView) -> np.ndarray:
        """Each capture point's robot (M,), among the available ones only."""
        cols = np.flatnonzero(self.available)
        rows, picked = linear_sum_assignment(self._costs(view)[:, cols])
        out = np.empty(len(rows), dtype=int)
        out[rows] = cols[picked]
        return out

    def _costs(self, view: FleetView) -> np.ndarray:
        """(M, N) s for each robot to meet each capture point's station where the moving
        object will be (interception at full speed, scaled by the detour around the object)."""
        radius = self.cfg.max_robot_radius
        margin = self.cfg.approach.envelope_margin
        stations = geometry.transform(
            self.capture.points + (radius + margin) * self.capture.normals, view.object_pose
        )
        ovel = np.zeros(3) if view.object_velocity is None else np.asarray(view.object_velocity)
        rel = stations - np.asarray(view.object_pose)[:2]
        vel = ovel[:2] + ovel[2] * np.stack([-rel[:, 1], rel[:, 0]], 1)
        speed = np.array([r.max_speed for r in self.cfg.robots])
        horizon = max(self.cfg.approach.intercept_horizon, 1.0) * 10.0
        cost = interception_times(view.poses[:, :2], stations, vel, speed, horizon)
        # a robot behind the object goes around it: scale by the detour around its envelope
        hull = envelope(
            geometry.transform(geometry.ensure_ccw(self.cfg.object_polygon()), view.object_pose),
            radius,
        )
        around = geometry.distance_around_convex(stations, view.poses[:, :2], hull)
        straight = np.linalg.norm(stations[:, None] - view.poses[None, :, :2], axis=-1)
        return cost * around / np.maximum(straight, 1e-9)

    def _reassign(self, view: FleetView) -> list:
        """During the approach, every ``REASSIGN_PERIOD`` s: hand the capture points to other
        robots when that meets the object sooner by ``REASSIGN_GAIN`` (the first assignment
        is made before the object's velocity estimate has settled: a fast object runs away from
        the robots that were nearest at first sight, toward others). Returns its events."""
        if view.t - self.assigned_t < REASSIGN_PERIOD or self.inner.phase != Phase.APPROACH:
            return []
        ovel = view.object_velocity
        if ovel is None or float(np.hypot(ovel[0], ovel[1])) < REASSIGN_MIN_SPEED:
            return []  # a slow object: the first assignment stands (no thrashing)
        self.assigned_t = view.t
        cost = self._costs(view)
        new = self._assign(view)
        m = np.arange(len(new))
        now, better = cost[m, self.assignment].sum(), cost[m, new].sum()
        gain = now - better
        if not (np.isfinite(better) and gain > REASSIGN_GAIN * now and gain > REASSIGN_MIN_S):
            return []
        t0 = self.inner.state.t0
        self.assignment = new
        self.inner = self._mission(view)
        self.inner.state = dataclasses.replace(self.inner.state, t0=t0)  # the same timeout
        self.reassignments += 1
        robots = [view.ids[i] for i in new]
        return [("reassign", {"robots": robots, "t": view.t, "eta_s": [now, better]})]

    @property
    def phase(self) -> Phase:
        """The job's phase: the stage in charge holds it (the sequence moves it)."""
        if self.transport is not None:
            return self.transport.phase
        return self.inner.phase if self.inner is not None and not self.failed else self.job.phase

    def plan(self, view: FleetView) -> Intent:
        if self.failed:
            zero = np.zeros((self.n, 2))
            return Intent(zero, Phase.FAILED, stop=True, failed=True, reason=self.failure_reason)
        view = self._parked(view)  # (a robot never seen: no estimate)
        if self.transport is not None:
            return self.transport.plan(view)
        gone = self._gone(view)
        if self.inner is None:
            return self._wait(view)
        gone, pause, events = self.outage.filter(view.t, gone, self.available, view.ids)
        if pause:  # one fleet-wide silence: every robot still until it ends or its grace runs out
            return Intent(np.zeros((self.n, 2)), self.inner.phase, events, stop=True)
        events += self._joins(view, gone)
        if self.inner.phase in WATCHED:
            lost, replan = self._losses(view, gone)
            events += lost
            if replan:
                self._ask_replan_lost(view)
        if self._replan_job.pending and self._replan_why == "lost":
            return self._await_lost(view, events)
        events += self._reassign(view)
        intent = self.inner.plan(view)
        intent.events[:0] = events
        if not self._replan_job.pending and self._blocked(view):
            self.blocked_ticks = 0
            pose = np.asarray(view.object_pose, float)
            k = int(self.available.sum())
            self._ask_replan("pinned", view, replan_pinned, pose, frozenset(self.unreachable), k)
        if self._replan_job.pending:
            return self._await_pinned(view, intent)
        if intent.arrest:
            self.arrest_t = view.t
        wait = self.cfg.transport.start_after
        waited = self.arrest_t is not None and view.t - self.arrest_t >= wait
        if waited and self.cfg.object.goal is not None:
            self._start_transport()
        return intent

    def _start_transport(self) -> None:
        """The object is arrested: from the next tick on, carry it to its goal."""
        self._carry(self.inner.guard, self.assignment, self.capture.points, self.capture.normals)

    def _carry(self, guard, robots: np.ndarray, points: np.ndarray, normals: np.ndarray) -> None:
        """The transport, from the contacts the ``robots`` hold (object frame)."""
        self.transport = TransportMission(
            self.cfg,
            self.rng,
            guard,
            robots,
            points,
            normals,
            route_planner=self.route_planner,
            planners=self.planners,
        )

    def _carry_from_contact(self, view: FleetView, reach: float = 0.03) -> Intent:
        """Entered at ``route``: the robots whose discs are within ``reach`` m of the object's
        surface hold their nearest boundary point; the others are free."""
        pose = np.asarray(view.object_pose, float)
        poly = geometry.ensure_ccw(self.cfg.object_polygon())
        local = geometry.inverse_transform(view.poses[:, :2], pose)
        d, closest = geometry.point_segment_distance(local, poly, np.roll(poly, -1, axis=0))
        j = np.argmin(d, axis=1)
        rows = np.arange(len(local))
        radii = np.array([r.radius for r in self.cfg.robots])
        held = np.flatnonzero(d[rows, j] - radii < reach)
        normals = geometry.outward_normals(poly)[j]
        self._carry(SafetyStage(self.cfg), held, closest[rows, j][held], normals[held])
        return self.transport.plan(view)

    # --- robot loss and join ---------------------------------------------------------------
    def _gone(self, view: FleetView) -> np.ndarray:
        """(N,) robots gone this tick: liveliness or link lost, or stale for ``LOST_STALE_S``."""
        stale = np.asarray(view.stale, bool)
        self.stale_since[~stale] = np.nan
        self.stale_since[stale & np.isnan(self.stale_since)] = view.t
        held = stale & (view.t - np.nan_to_num(self.stale_since, nan=view.t) >= LOST_STALE_S)
        return ~np.asarray(view.present, bool) | held

    def _parked(self, view: FleetView) -> FleetView:
        """The view with robots never seen (no estimate: NaN) parked far away, standing still:
        the planners and the safety filter read every robot's pose."""
        unknown = ~np.all(np.isfinite(view.poses), axis=1)
        if not unknown.any():
            return view
        poses, vels = view.poses.copy(), view.velocities.copy()
        k = np.flatnonzero(unknown)
        poses[k] = np.stack([PARK + 10.0 * k, np.full(len(k), PARK), np.zeros(len(k))], 1)
        vels[k] = 0.0
        return dataclasses.replace(view, poses=poses, velocities=vels)

    def _wait(self, view: FleetView) -> Intent:
        """Phase ``plan``: start when the object and every robot are seen, or, ``start_wait``
        s after the first estimates, with the robots seen when they can close the object."""
        still = Intent(np.zeros((self.n, 2)), Phase.PLAN, stop=True)
        ready = np.asarray(view.present & ~view.stale, bool)
        if self.first_t is None and (view.object_pose is not None or ready.any()):
            self.first_t = view.t
        if view.object_pose is None:
            return still
        if self.entry == Phase.ROUTE:  # every robot seen: who holds the object is measured
            return self._carry_from_contact(view) if ready.all() else still
        if not ready.all():
            if view.t - self.first_t < self.cfg.fleet.start_wait:
                return still
            k = int(ready.sum())
            if k < len(self.capture.points):
                return self._start_with(view, ready, k, still)
        self.available = ready
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
        self.available = ready
        return self._start(view, pinned=False)

    def _ask_replan(self, why: str, view: FleetView, fn, *args) -> None:
        """A capture re-plan off the tick (``why``: start, lost or pinned), with its own
        generator drawn from the job's."""
        self._replan_why = why
        self._replan_job.request(view.t, fn, self.cfg, self.capture, *args)

    def _joins(self, view: FleetView, gone: np.ndarray) -> list:
        """Robots present with a fresh estimate again (or seen at last) are available again."""
        back = ~self.available & ~gone & view.present & ~view.stale
        self.available |= back
        return [("robot_joined", {"t": view.t, "robot": view.ids[i]}) for i in np.flatnonzero(back)]

    def _losses(self, view: FleetView, gone: np.ndarray) -> tuple[list, bool]:
        """Robots lost this tick (events), and whether one of them held a capture point."""
        new = np.flatnonzero(gone & self.available)
        self.available[new] = False
        self.lost += [int(i) for i in new]
        assigned = {int(i) for i in self.assignment}
        phase = str(self.inner.phase)
        events = [
            ("robot_lost", {"t": view.t, "robot": view.ids[i], "phase": phase, "assigned": a})
            for i, a in ((int(i), int(i) in assigned) for i in new)
        ]
        return events, any(int(i) in assigned for i in new)

    def _ask_replan_lost(self, view: FleetView) -> None:
        """An assigned robot is lost: the capture re-planned for the robots left (off the
        tick; a pending re-plan is asked again with the robots left now)."""
        keep = self.available[self.assignment]
        k = int(self.available.sum())
        pose = np.asarray(view.object_pose, float)
        rng = spawn_rng(self.rng)
        self._ask_replan(
            "lost", view, replan_for_robots, keep, k, rng, pose, frozenset(self.unreachable)
        )

    def _await_lost(self, view: FleetView, events: list) -> Intent:
        """Every robot holds until the re-plan comes; then it is re-assigned (the approach
        starts over), or the job fails with ``robots_lost``."""
        got = self._replan_job.take(view.t)
        if got is None:
            return Intent(np.zeros((self.n, 2)), self.inner.phase, events, stop=True)
        new = got.value if got.ok else None
        if new is None:
            k = int(self.available.sum())
            lost = ", ".join(view.ids[i] for i in self.lost)
            detail = (
                f"robots lost ({lost}): the {k} robots left cannot close the object "
                f"(the capture needs {len(self.capture.points)})"
            )
            if not got.ok:
                detail += f"; the re-plan failed: {got.error}"
            return self._fail(view, Reason.ROBOTS_LOST, detail, events)
        self.loss_replans += 1
        self.lost_t = view.t
        self.capture = new
        self.blocked_ticks = 0
        intent = self._start(view, pinned=bool(new.walls))
        intent.events[:0] = events
        return intent

    def _fail(self, view: FleetView, reason: Reason, detail: str, events: list) -> Intent:
        """Fail safe: every robot stopped, the failure event with its detail."""
        step = next_phase(JobState(self.phase), Measures(view.t, None, Failure(reason, detail)))
        self.job = step.state
        events = events + list(step.events)
        self.failed = True
        self.failure_reason = reason
        return Intent(
            np.zeros((self.n, 2)), Phase.FAILED, events, stop=True, failed=True, reason=reason
        )

    def _start(self, view: FleetView, pinned: bool) -> Intent:
        """Assign robots to the capture set and start the approach (the capture event first;
        the approach announces itself at its first tick, as after every re-plan)."""
        self.job = next_phase(self.job, Measures(view.t, Cue.READY)).state
        self.assignment = self._assign(view)
        self.assigned_t = view.t
        self.inner = self._mission(view)
        data = {
            "points": self.capture.points.round(4).tolist(),
            "normals": self.capture.normals.round(4).tolist(),
            "robots": [view.ids[i] for i in self.assignment],
            "objective": self.capture.objective,
            "form_closure": self.capture.form_closure,
            "robots_needed": len(self.capture.points),
            "hold_capacity": self.capture.hold_capacity,
            "reinforced": self.capture.reinforced,
            "pinned": pinned,
            "wall_contacts": self.capture.walls,
            "unavailable": [view.ids[i] for i in np.flatnonzero(~self.available)],
        }
        intent = self.inner.plan(view)
        intent.events.insert(0, ("capture", data))
        return intent

    def _mission(self, view: FleetView):
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
        )

    def _stuck(self, view: FleetView) -> bool:
        """Whether, with the object at rest, some robot of the approach has come no closer to
        its station by ``STUCK_PROGRESS`` m for ``STUCK_S`` s: its point is out of reach in a
        way a disc test cannot see (a notch a wall closes, a gap too narrow to pass). The point
        is then excluded and the capture re-planned."""
        dist = getattr(self.inner, "last_distance", None)
        if self.inner.phase != Phase.APPROACH or dist is None:
            return False
        xy = np.asarray(view.object_pose[:2], float)
        fresh = self.progress is None or self.progress[3] is not self.inner  # a new approach
        if fresh or np.linalg.norm(xy - self.progress[2]) > STUCK_OBJECT_MOVE:
            # (re)start: a moving object is chased, not stuck on (its pose, not its noisy speed)
            self.progress = (dist.copy(), np.full(len(dist), view.t), xy, self.inner)
        best, since, _, _ = self.progress
        better = dist < best - STUCK_PROGRESS
        best[better], since[better] = dist[better], view.t
        stuck = (view.t - since > STUCK_S) & (dist > self.cfg.approach.envelope_tolerance)
        if not stuck.any():
            return False
        # the nodes around a stuck point are in the same pocket: exclude them together
        cand = self.capture.candidates
        for m in np.flatnonzero(stuck):
            near = np.linalg.norm(cand - self.capture.points[m], axis=1) < STUCK_POCKET
            self.unreachable |= {int(i) for i in np.flatnonzero(near)}
        return True

    def _blocked(self, view: FleetView) -> bool:
        """Whether some capture point has been out of a robot's reach (a wall or an obstacle
        where its disc must go) for ``PIN_TICKS`` ticks, before the fleet closes in, or a robot
        is stuck on the way to it (``_stuck``)."""
        if self.inner.phase not in (Phase.APPROACH, Phase.CLOSE_IN) or self.replans >= MAX_REPLANS:
            return False
        if self._stuck(view):
            return True
        r = self.cfg.max_robot_radius
        centres = geometry.transform(
            self.capture.points + (r + self.cfg.capture.clearance) * self.capture.normals,
            view.object_pose,
        )
        bounds = self.cfg.bounds_array() if self.cfg.world.walls else None
        hit = geometry.discs_touch_static(
            centres,
            r + self.cfg.approach.safety_margin,
            self.cfg.obstacle_polygons(),
            bounds,
            slack=0.0,
        )
        self.blocked_ticks = self.blocked_ticks + 1 if hit.any() else 0
        return self.blocked_ticks >= PIN_TICKS

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
        self.replans += 1
        self.capture = new
        return self._start(view, pinned=True)

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        view = self._parked(view)
        if self.transport is not None:
            return self.transport.safety(view, intent)
        if self.inner is None or self.failed:
            return MissionOutput(
                np.zeros((self.n, 3)),
                intent.phase,
                list(intent.events),
                failed=intent.failed,
                reason=intent.reason,
            )
        return self.inner.safety(view, intent)

    def summary(self) -> dict[str, Any]:
        if self.capture is None:  # entered at route
            return {} if self.transport is None else self.transport.summary()
        out: dict[str, Any] = {
            "capture_points": len(self.capture.points),
            "capture_objective": self.capture.objective,
            "form_closure": self.capture.form_closure,
            "hold_capacity": self.capture.hold_capacity,
            "reinforced_points": self.capture.reinforced,
            "assigned": None
            if self.assignment is None
            else [self.cfg.robots[i].id for i in self.assignment],
            "reassignments": self.reassignments,
            "wall_replans": self.replans,
            "unreachable_nodes": len(self.unreachable),
            "robots_lost": [self.cfg.robots[i].id for i in self.lost],
            "outages": self.outage.outages,
            "loss_replans": self.loss_replans,
        }
        if self.inner is not None and hasattr(self.inner, "summary"):
            out.update(self.inner.summary())
        if self.transport is not None:
            out.update(self.transport.summary())
        return out
