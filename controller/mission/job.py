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
WALL_TOLERANCE = 0.03  # m: an object vertex this close to a wall or an obstacle touches it
PIN_TICKS = 10  # ticks a capture point must stay blocked by a wall before the capture re-plans


def replan_pinned(cfg: FleetConfig, capture: CaptureSet, pose: np.ndarray) -> CaptureSet | None:
    """The capture re-planned for an object pressed against walls or obstacles at ``pose``:
    capture points a robot disc cannot reach there are dropped, the walls count as fixed
    frictionless contacts, and points are added or moved until the set holds. None: no set
    holds with the fleet (the object is ``pinned`` out of reach)."""
    from controller.planning.hold import push_wrenches, wall_contacts

    poly = geometry.ensure_ccw(cfg.object_polygon())
    r = cfg.max_robot_radius
    bounds = cfg.bounds_array() if cfg.world.walls else None
    obstacles = cfg.obstacle_polygons()
    centres = geometry.transform(
        capture.candidates + (r + cfg.capture.clearance) * capture.candidate_normals, pose
    )
    allowed = ~geometry.discs_touch_static(centres, r, obstacles, bounds, slack=0.0)
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
        self.failed = False
        self.transport: Any = None
        self.arrest_t: float | None = None

    def _assign(self, view: FleetView) -> np.ndarray:
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
        cost = cost * around / np.maximum(straight, 1e-9)
        rows, cols = linear_sum_assignment(cost)
        out = np.empty(len(stations), dtype=int)
        out[rows] = cols
        return out

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
        intent = self.inner.plan(view)
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
        )

    def _start(self, view: FleetView, pinned: bool) -> Intent:
        """Assign robots to the capture set and start the approach (the capture event first)."""
        from controller.mission.capture import CaptureMission, CaptureSettings

        self.assignment = self._assign(view)
        settings = CaptureSettings.from_config(self.cfg)
        if self.cfg.object.goal is not None:  # the arrested object is carried, not let go
            settings = dataclasses.replace(settings, settle_s=math.inf)
        self.inner = CaptureMission(
            self.capture.points,
            self.capture.normals,
            self.assignment,
            self.cfg,
            self.rng,
            settings=settings,
        )
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

    def _blocked(self, view: FleetView) -> bool:
        """Whether some capture point has been out of a robot's reach (a wall or an obstacle
        where its disc must go) for ``PIN_TICKS`` ticks, before the fleet closes in."""
        if self.inner.phase not in (Phase.APPROACH, Phase.CLOSE_IN) or self.replans >= 3:
            return False
        r = self.cfg.max_robot_radius
        centres = geometry.transform(
            self.capture.points + (r + self.cfg.capture.clearance) * self.capture.normals,
            view.object_pose,
        )
        bounds = self.cfg.bounds_array() if self.cfg.world.walls else None
        hit = geometry.discs_touch_static(
            centres, r, self.cfg.obstacle_polygons(), bounds, slack=0.0
        )
        self.blocked_ticks = self.blocked_ticks + 1 if hit.any() else 0
        return self.blocked_ticks >= PIN_TICKS

    def _replan(self, view: FleetView, intent: Intent) -> Intent:
        """The object is against a wall: capture it there (the wall a fixed contact), or fail
        fast with ``pinned`` when no set of reachable points holds it."""
        self.replans += 1
        self.blocked_ticks = 0
        pose = np.asarray(view.object_pose, float)
        new = replan_pinned(self.cfg, self.capture, pose)
        if new is None:
            detail = (
                "the object is against a wall or an obstacle and no set of capture points a "
                f"robot can reach there holds it with {self.n} robots"
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
        }
        if self.inner is not None and hasattr(self.inner, "summary"):
            out.update(self.inner.summary())
        if self.transport is not None:
            out.update(self.transport.summary())
        return out
