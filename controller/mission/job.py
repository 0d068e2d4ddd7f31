"""The whole job: the capture GA plan at construction, robot assignment once the first
estimates are in, then the approach-and-arrest mission (pure, per tick)."""

from __future__ import annotations

from typing import Any

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.mission.types import FleetView, Intent, MissionOutput, Phase


class MissionError(RuntimeError):
    """The mission cannot be built for this fleet (e.g. too few robots for the capture)."""


class CaptureJob:
    """The capture: the GA plan at construction, robot assignment once the first estimates are
    in (robots and object), then the approach-and-arrest mission.

    Until every robot is present with a fresh estimate and the object has been seen, every robot
    holds still (phase ``plan``). The assignment minimises total travel time to the capture
    points at the object's current pose; robots left over stay where they are.
    """

    def __init__(
        self,
        cfg: FleetConfig,
        rng: np.random.Generator | None = None,
    ) -> None:
        from controller.planning.capture import CaptureParams, plan_capture

        self.cfg = cfg
        self.rng = rng if rng is not None else np.random.default_rng(cfg.capture.seed)
        self.n = len(cfg.robots)
        self.capture = plan_capture(
            cfg.object_polygon(),
            cfg.max_robot_radius,
            CaptureParams.from_config(cfg.capture),
            self.rng,
        )
        if not self.capture.form_closure and cfg.capture.closure == "exact":
            raise MissionError("the capture GA found no set of points in form closure")
        if self.capture.robots_needed > self.n:
            raise MissionError(
                f"the capture needs {self.capture.robots_needed} robots; the fleet has {self.n}"
            )
        self.assignment: np.ndarray | None = None
        self.inner: Any = None

    def _assign(self, view: FleetView) -> np.ndarray:
        from controller.planning.capture import assign_robots

        radius = np.array([r.radius for r in self.cfg.robots])
        centres = self.capture.points + radius.max() * self.capture.push_normals
        targets = geometry.transform(centres, view.object_pose)
        speed = np.array([r.max_speed for r in self.cfg.robots])
        return np.asarray(assign_robots(view.poses[:, :2], speed, targets), dtype=int)

    def plan(self, view: FleetView) -> Intent:
        if self.inner is not None:
            return self.inner.plan(view)
        ready = view.object_pose is not None and bool(np.all(view.present & ~view.stale))
        if not ready:
            return Intent(np.zeros((self.n, 2)), Phase.PLAN, stop=True)
        from controller.mission.capture import CaptureMission

        self.assignment = self._assign(view)
        self.inner = CaptureMission(
            self.capture.points,
            self.capture.push_normals,
            self.assignment,
            self.cfg,
            self.rng,
        )
        data = {
            "points": self.capture.points.round(4).tolist(),
            "normals": self.capture.push_normals.round(4).tolist(),
            "robots": [view.ids[i] for i in self.assignment],
            "objective": float(self.capture.objective),
            "form_closure": bool(self.capture.form_closure),
            "robots_needed": int(self.capture.robots_needed),
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
            "capture_objective": float(self.capture.objective),
            "form_closure": bool(self.capture.form_closure),
            "assigned": None
            if self.assignment is None
            else [self.cfg.robots[i].id for i in self.assignment],
        }
        if self.inner is not None and hasattr(self.inner, "summary"):
            out.update(self.inner.summary())
        return out
