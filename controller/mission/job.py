"""The whole job: the capture plan at construction, robot assignment once the first estimates
are in, then the approach-and-arrest mission (pure, per tick).

The plan is the GA's (Sharma Eq. 3, ``controller.planning.capture``), reinforced until the
contacts can hold the object's push (``capture.hold_force``) with the robots' force limits
(``controller.planning.hold``): form closure alone can need several times the push at a contact.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from controller import geometry
from controller.config import FleetConfig
from controller.mission.types import FleetView, Intent, MissionOutput, Phase, Reason
from controller.planning.approach import envelope, interception_times


class MissionError(RuntimeError):
    """The mission cannot be built for this fleet (e.g. no feasible capture plan: the message
    gives the planner's reason)."""


@dataclass(frozen=True)
class CaptureSet:
    """Contact points and their outward normals (M, 2), object frame, and what was checked;
    ``candidates``/``candidate_normals`` (K, 2) are the GA's nodes, ``chosen`` (M,) indices."""

    points: np.ndarray
    normals: np.ndarray
    objective: float
    form_closure: bool
    hold_capacity: float | None  # share of capture.hold_force the contacts resist (≥ 1 holds)
    reinforced: int  # points added to the GA's set so that it holds
    candidates: np.ndarray
    candidate_normals: np.ndarray
    chosen: np.ndarray
    walls: int = 0  # wall contacts the set counts on (an object pinned against a wall)


def plan_capture_set(cfg: FleetConfig, rng: np.random.Generator) -> CaptureSet:
    """The GA's capture points, reinforced to hold ``capture.hold_force`` (MissionError when the
    GA finds no feasible plan, with its reason, or the fleet is too small to hold the object)."""
    from controller.planning.capture import plan_for_fleet

    plan = plan_for_fleet(cfg, rng)
    if not plan.feasible:
        raise MissionError(f"no feasible capture plan: {plan.reason}")
    chosen = np.asarray(plan.chosen, int)
    capacity, added = None, 0
    if cfg.capture.hold_force > 0:
        res = _reinforce(cfg, plan.candidates, plan.normals, chosen)
        if not res.holds:
            raise MissionError(_cannot_hold(cfg, res))
        chosen, capacity, added = res.chosen, res.capacity, res.added
    return CaptureSet(
        plan.candidates[chosen],
        plan.normals[chosen],
        float(plan.objective),
        bool(plan.form_closure),
        capacity,
        added,
        plan.candidates,
        plan.normals,
        chosen,
    )


def _cannot_hold(cfg: FleetConfig, res) -> str:
    weakest = min(rb.max_force for rb in cfg.robots)
    return (
        f"the fleet cannot hold the object: {len(res.chosen)} robots of max_force "
        f"{weakest:g} N resist {100 * res.capacity:.0f} % of capture.hold_force = "
        f"{cfg.capture.hold_force:g} N in the worst direction (more robots, stronger robots, "
        "or a lower hold_force)"
    )


def _reinforce(
    cfg: FleetConfig,
    cand: np.ndarray,
    nrm: np.ndarray,
    chosen: np.ndarray,
    allowed: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
):
    """The GA's set reinforced to hold ``capture.hold_force`` (a set that only has to close the
    object, ``hold_force`` 0, is held to a token load)."""
    from controller.planning.hold import disturbances, reinforce

    poly = geometry.ensure_ccw(cfg.object_polygon())
    c = geometry.centroid(poly)
    r = cfg.max_robot_radius
    centres = cand + r * nrm
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    conflict = d < 2 * r + max(cfg.capture.clearance, cfg.approach.safety_margin)  # as the GA
    np.fill_diagonal(conflict, False)
    force = cfg.capture.hold_force or TOKEN_LOAD
    load = disturbances(force, force * np.sqrt(geometry.polar_moment_per_mass(poly)))
    weakest = min(rb.max_force for rb in cfg.robots)
    ok = np.ones(len(cand), bool) if allowed is None else allowed
    n = len(cfg.robots)
    return reinforce(cand, nrm, c, chosen, ok, conflict, weakest, load, n, fixed=fixed)


TOKEN_LOAD = 0.05  # N: the load a closure-only set (capture.hold_force 0) must hold
# m: an object vertex this close to a wall or an obstacle touches it (an object turned a degree
# or two in a corner keeps both walls; the hold allows 5 cm)
WALL_TOLERANCE = 0.04
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


def replan_pinned(
    cfg: FleetConfig,
    capture: CaptureSet,
    pose: np.ndarray,
    exclude: frozenset[int] = frozenset(),
) -> CaptureSet | None:
    """The capture re-planned for an object pressed against walls or obstacles at ``pose``:
    capture points a robot disc cannot reach there are dropped, the walls count as fixed
    frictionless contacts, and points are added or moved until the set holds. ``exclude``:
    candidate nodes (indices) a robot could not get to. None: no set holds with the fleet (the
    object is ``pinned`` out of reach)."""
    from controller.planning.hold import push_wrenches, wall_contacts

    poly = geometry.ensure_ccw(cfg.object_polygon())
    r = cfg.max_robot_radius
    bounds = cfg.bounds_array() if cfg.world.walls else None
    obstacles = cfg.obstacle_polygons()
    centres = geometry.transform(
        capture.candidates + (r + cfg.capture.clearance) * capture.candidate_normals, pose
    )
    # a robot can stand there only with the safety filter's margin to the wall or obstacle
    reach = r + cfg.approach.safety_margin
    allowed = ~geometry.discs_touch_static(centres, reach, obstacles, bounds, slack=0.0)
    allowed[list(exclude)] = False  # nodes robots were seen not to reach (a closed pocket)
    world = geometry.transform(poly, pose)
    pts, pushes = wall_contacts(world, obstacles, bounds, WALL_TOLERANCE)
    local = geometry.inverse_transform(pts, pose) if len(pts) else pts
    local_push = pushes @ geometry.rot(float(pose[2])) if len(pushes) else pushes
    fixed = push_wrenches(local, local_push, geometry.centroid(poly))
    chosen = np.array([i for i in capture.chosen if allowed[i]], int)
    res = _reinforce(cfg, capture.candidates, capture.candidate_normals, chosen, allowed, fixed)
    if not res.holds or len(res.chosen) == 0:
        return None
    return CaptureSet(
        capture.candidates[res.chosen],
        capture.candidate_normals[res.chosen],
        capture.objective,
        capture.form_closure,
        res.capacity if cfg.capture.hold_force > 0 else None,
        res.added,
        capture.candidates,
        capture.candidate_normals,
        res.chosen,
        walls=len(pts),
    )


class CaptureJob:
    """The capture: the plan at construction, robot assignment once the first estimates are in
    (robots and object), then the approach-and-arrest mission.

    Until every robot is present with a fresh estimate and the object has been seen, every robot
    holds still (phase ``plan``). The assignment minimises the total time for the robots to meet
    their points' stations where the moving object will be (interception at full speed); robots
    left over stay where they are.
    """

    def __init__(self, cfg: FleetConfig, rng: np.random.Generator | None = None) -> None:
        self.cfg = cfg
        self.rng = rng if rng is not None else np.random.default_rng(cfg.capture.seed)
        self.n = len(cfg.robots)
        self.capture = plan_capture_set(cfg, self.rng)
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
        self.transport: Any = None
        self.arrest_t: float | None = None
        self.route_planner: Any = None
        if cfg.object.goal is not None:  # built before the loop: it takes a second
            from controller.mission.transport import route_planner_for

            self.route_planner = route_planner_for(cfg)

    def _assign(self, view: FleetView) -> np.ndarray:
        rows, cols = linear_sum_assignment(self._costs(view))
        out = np.empty(len(rows), dtype=int)
        out[rows] = cols
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

    def plan(self, view: FleetView) -> Intent:
        if self.failed:
            zero = np.zeros((self.n, 2))
            return Intent(zero, Phase.FAILED, stop=True, failed=True, reason=Reason.PINNED)
        if self.transport is not None:
            return self.transport.plan(view)
        if self.inner is None:
            ready = view.object_pose is not None and bool(np.all(view.present & ~view.stale))
            if not ready:
                return Intent(np.zeros((self.n, 2)), Phase.PLAN, stop=True)
            return self._start(view, pinned=False)
        events = self._reassign(view)
        intent = self.inner.plan(view)
        intent.events[:0] = events
        if self._blocked(view):
            return self._replan(view, intent)
        if intent.arrest:
            self.arrest_t = view.t
        wait = self.cfg.transport.start_after
        waited = self.arrest_t is not None and view.t - self.arrest_t >= wait
        if waited and self.cfg.object.goal is not None:
            self._start_transport()
        return intent

    def _start_transport(self) -> None:
        """The object is arrested: from the next tick on, carry it to its goal."""
        from controller.mission.transport import TransportMission

        self.transport = TransportMission(
            self.cfg,
            self.rng,
            self.inner.guard,
            self.assignment,
            self.capture.points,
            self.capture.normals,
            route_planner=self.route_planner,
        )

    def _start(self, view: FleetView, pinned: bool) -> Intent:
        """Assign robots to the capture set and start the approach (the capture event first)."""
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
        }
        intent = self.inner.plan(view)
        intent.events.insert(0, ("capture", data))
        return intent

    def _mission(self, view: FleetView):
        from controller.mission.capture import CaptureMission, CaptureSettings

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

    def _replan(self, view: FleetView, intent: Intent) -> Intent:
        """The object is against a wall: capture it there (the wall a fixed contact), or fail
        fast with ``pinned`` when no set of reachable points holds it."""
        self.blocked_ticks = 0
        pose = np.asarray(view.object_pose, float)
        new = replan_pinned(self.cfg, self.capture, pose, frozenset(self.unreachable))
        if new is None:
            # a standoff first: an object still sliding along a wall or into a corner may
            # come to rest where the walls help (robots keep their stations meanwhile)
            self.pin_fails += 1
            ovel = view.object_velocity
            moving = ovel is not None and float(np.hypot(ovel[0], ovel[1])) > PIN_STILL_SPEED
            if moving or self.pin_fails < PIN_RETRIES:
                return intent
            x, y, th = (float(v) for v in pose)
            detail = (
                "the object is against a wall or an obstacle and no set of capture points a "
                f"robot can reach there holds it with {self.n} robots (object at "
                f"({x:.2f}, {y:.2f}, {math.degrees(th):.0f}°), at rest, {self.pin_fails} tries)"
            )
            events = [
                ("phase", {"phase": str(Phase.FAILED), "t": view.t}),
                ("failure", {"reason": str(Reason.PINNED), "t": view.t, "detail": detail}),
            ]
            self.failed = True
            return Intent(
                np.zeros((self.n, 2)), Phase.FAILED, events, stop=True, failed=True,
                reason=Reason.PINNED,
            )  # fmt: skip
        self.replans += 1
        self.capture = new
        return self._start(view, pinned=True)

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
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
        }
        if self.inner is not None and hasattr(self.inner, "summary"):
            out.update(self.inner.summary())
        if self.transport is not None:
            out.update(self.transport.summary())
        return out
