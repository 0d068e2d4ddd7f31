"""The whole job: the capture GA plan at construction, robot assignment once the first
estimates are in, then the approach-and-arrest mission (pure, per tick)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.mission.types import FleetView, MissionOutput


class MissionError(ValueError):
    """The mission cannot be built for this fleet (e.g. no feasible capture plan: the message
    gives the planner's reason)."""


class CaptureJob:
    """The capture: the GA plan at construction, robot assignment once the first estimates are
    in (robots and object), then the approach-and-arrest mission. An infeasible plan (no
    closure within the fleet, robots too large, ...) raises MissionError with the reason.

    Until every robot is present with a fresh estimate and the object has been seen, every robot
    holds still (phase ``plan``). The assignment minimises total travel time to the capture
    points at the object's current pose; robots left over stay where they are.
    """

    def __init__(
        self,
        cfg: FleetConfig,
        rng: np.random.Generator | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        from controller.planning.capture import plan_for_fleet

        self.cfg = cfg
        self.clock = clock
        self.rng = rng if rng is not None else np.random.default_rng(cfg.capture.seed)
        self.n = len(cfg.robots)
        self.plan = plan_for_fleet(cfg, self.rng)
        if not self.plan.feasible:
            raise MissionError(f"no feasible capture plan: {self.plan.reason}")
        self.assignment: np.ndarray | None = None
        self.inner: Any = None

    def _assign(self, view: FleetView) -> np.ndarray:
        from controller.planning.capture import assign_robots

        radius = np.array([r.radius for r in self.cfg.robots])
        centres = self.plan.points + radius.max() * self.plan.push_normals
        targets = geometry.transform(centres, view.object_pose)
        speed = np.array([r.max_speed for r in self.cfg.robots])
        return np.asarray(assign_robots(view.poses[:, :2], speed, targets), dtype=int)

    def step(self, view: FleetView) -> MissionOutput:
        if self.inner is not None:
            return self.inner.step(view)
        hold = np.zeros((self.n, 3))
        ready = view.object_pose is not None and bool(np.all(view.present & ~view.stale))
        if not ready:
            return MissionOutput(commands=hold, phase="plan")
        from controller.mission.capture import CaptureMission

        self.assignment = self._assign(view)
        self.inner = CaptureMission(
            self.plan.points,
            self.plan.push_normals,
            self.assignment,
            self.cfg,
            self.rng,
            clock=self.clock,
        )
        data = {
            "points": self.plan.points.round(4).tolist(),
            "normals": self.plan.push_normals.round(4).tolist(),
            "robots": [view.ids[i] for i in self.assignment],
            "objective": float(self.plan.objective),
            "form_closure": bool(self.plan.form_closure),
            "robots_needed": int(self.plan.robots_needed),
        }
        out = self.inner.step(view)
        out.events.insert(0, ("capture", data))
        return out

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "capture_points": len(self.plan.points),
            "capture_objective": float(self.plan.objective),
            "form_closure": bool(self.plan.form_closure),
            "assigned": None
            if self.assignment is None
            else [self.cfg.robots[i].id for i in self.assignment],
        }
        if self.inner is not None and hasattr(self.inner, "summary"):
            out.update(self.inner.summary())
        return out
