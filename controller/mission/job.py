"""The whole job: the capture plan at construction, robot assignment once the first estimates
are in, then the approach-and-arrest mission (pure, per tick).

The plan is the GA's (Sharma Eq. 3, ``controller.planning.capture``), reinforced until the
contacts can hold the object's push (``capture.hold_force``) with the robots' force limits
(``controller.planning.hold``): form closure alone can need several times the push at a contact.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from controller import geometry
from controller.config import FleetConfig
from controller.mission.types import FleetView, Intent, MissionOutput, Phase
from controller.planning.approach import envelope, interception_times


class MissionError(RuntimeError):
    """The mission cannot be built for this fleet (e.g. too few robots for the capture)."""


@dataclass(frozen=True)
class CaptureSet:
    """Contact points and their outward normals (M, 2), object frame, and what was checked."""

    points: np.ndarray
    normals: np.ndarray
    objective: float
    form_closure: bool
    hold_capacity: float | None  # share of capture.hold_force the contacts resist (≥ 1 holds)
    reinforced: int  # points added to the GA's set so that it holds


def plan_capture_set(cfg: FleetConfig, rng: np.random.Generator) -> CaptureSet:
    """The GA's capture points, reinforced to hold ``capture.hold_force`` (MissionError when the
    GA finds no closure, or the fleet is too small to close or to hold the object)."""
    from controller.planning.capture import CaptureParams, plan_capture

    n = len(cfg.robots)
    plan = plan_capture(
        cfg.object_polygon(), cfg.max_robot_radius, CaptureParams.from_config(cfg.capture), rng
    )
    if not plan.form_closure and cfg.capture.closure == "exact":
        raise MissionError("the capture GA found no set of points in form closure")
    if plan.robots_needed > n:
        raise MissionError(f"the capture needs {plan.robots_needed} robots; the fleet has {n}")
    chosen = np.asarray(plan.chosen, int)
    capacity, added = None, 0
    if cfg.capture.hold_force > 0:
        chosen, capacity, added = _reinforce(cfg, plan.candidates, plan.normals, chosen)
    return CaptureSet(
        plan.candidates[chosen],
        plan.normals[chosen],
        float(plan.objective),
        bool(plan.form_closure),
        capacity,
        added,
    )


def _reinforce(cfg: FleetConfig, cand: np.ndarray, nrm: np.ndarray, chosen: np.ndarray):
    from controller.planning.hold import disturbances, reinforce

    poly = geometry.ensure_ccw(cfg.object_polygon())
    c = geometry.centroid(poly)
    r = cfg.max_robot_radius
    centres = cand + r * nrm
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    conflict = d < 2 * r + cfg.capture.clearance
    np.fill_diagonal(conflict, False)
    force = cfg.capture.hold_force
    load = disturbances(force, force * np.sqrt(geometry.polar_moment_per_mass(poly)))
    weakest = min(rb.max_force for rb in cfg.robots)
    res = reinforce(
        cand, nrm, c, chosen, np.ones(len(cand), bool), conflict, weakest, load, len(cfg.robots)
    )
    if not res.holds:
        raise MissionError(
            f"the fleet cannot hold the object: {len(res.chosen)} robots of max_force "
            f"{weakest:g} N resist {100 * res.capacity:.0f} % of capture.hold_force = {force:g} N "
            "in the worst direction (more robots, stronger robots, or a lower hold_force)"
        )
    return res.chosen, res.capacity, res.added


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
        if self.inner is not None:
            return self.inner.plan(view)
        ready = view.object_pose is not None and bool(np.all(view.present & ~view.stale))
        if not ready:
            return Intent(np.zeros((self.n, 2)), Phase.PLAN, stop=True)
        from controller.mission.capture import CaptureMission

        self.assignment = self._assign(view)
        self.inner = CaptureMission(
            self.capture.points, self.capture.normals, self.assignment, self.cfg, self.rng
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
        }
        intent = self.inner.plan(view)
        intent.events.insert(0, ("capture", data))
        return intent

    def safety(self, view: FleetView, intent: Intent) -> MissionOutput:
        if self.inner is None:
            return MissionOutput(np.zeros((self.n, 3)), intent.phase, list(intent.events))
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
        return out
