"""Detours of the capture's approach around static obstacles (planned once, off the tick): a
robot whose straight line to its station crosses an obstacle grown by its radius is held until
its route comes from the planner port (kind ``detour``: a robot roadmap and A* over it), then
follows its waypoints (one with no route found goes straight, the safety filter keeping it
off)."""

from __future__ import annotations

import numpy as np

from controller import geometry
from controller.config import FleetConfig
from controller.mission.capture_phase import CaptureSettings
from controller.mission.planners import PlanSlot
from controller.mission.types import FleetView
from controller.planning.approach import envelope
from controller.planning.roadmap import plan_detours


class Detours:
    """The detour stage of one approach: ``hold`` (N,) the robots waiting for their routes
    (None: none waits)."""

    def __init__(self, cfg: FleetConfig, s: CaptureSettings, planners, obstacles, radii) -> None:
        self.cfg, self.s, self.obstacles, self.radii = cfg, s, obstacles, radii
        self.planned = False
        self.job = PlanSlot(planners, "detour")
        self.robots: list[int] = []
        self.hold: np.ndarray | None = None

    def blocked(
        self, assignment: np.ndarray, centers: np.ndarray, stations: np.ndarray
    ) -> list[tuple[int, int]]:
        """(capture point, robot) of the robots whose straight line to their station crosses
        an obstacle grown by their radius (a cheap test, on the tick)."""
        out = []
        for m, i in enumerate(assignment):
            r = self.radii[i] + self.s.detour_clearance
            grown = [envelope(p, r, 8) for p in self.obstacles]
            seg = np.linspace(centers[i], stations[m], self.s.detour_samples)
            if any(geometry.points_in_polygon(seg, g).any() for g in grown):
                out.append((m, int(i)))
        return out

    def ask(
        self, view: FleetView, assignment: np.ndarray, centers: np.ndarray, stations: np.ndarray
    ) -> None:
        """The blocked robots' routes asked of the planner port; they hold until they come."""
        self.planned = True
        blocked = self.blocked(assignment, centers, stations)
        if not blocked:
            return
        rr = float(self.radii.max()) + self.cfg.approach.safety_margin + self.s.detour_clearance
        self.robots = [i for _, i in blocked]
        self.hold = np.zeros(len(self.radii), bool)
        self.hold[self.robots] = True
        self.job.request(
            view.t,
            plan_detours,
            self.cfg.bounds_array(),
            self.obstacles,
            rr,
            self.cfg.route.robot_resolution,
            np.array([centers[i] for i in self.robots]),
            np.array([stations[m] for m, _ in blocked]),
            self.s.detour_spacing,
        )

    def take(self, t: float, waypoints: dict[int, list[np.ndarray]]) -> None:
        """The routes, once they came, into ``waypoints`` (robot -> its waypoints)."""
        got = self.job.take(t)
        if got is None:
            return
        if got.ok:
            for i, wps in zip(self.robots, got.value, strict=True):
                if wps:
                    waypoints[i] = wps
        self.hold = None
