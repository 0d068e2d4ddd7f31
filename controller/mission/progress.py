"""The object's way along its route while it is carried (pure): the current segment and the
direction it asks for, subgoals reached, what is left of the route, progress and stalls, and
the corridor the object must stay in."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from controller import geometry
from controller.config import FleetConfig, TransportSection, configured
from controller.mission.planners import JobOwned
from controller.planning.transport_model import ObjectModel
from controller.planning.transport_types import RouteSegment

if TYPE_CHECKING:
    from controller.planning.route import RoutePlanner, RouteResult
_TRANSPORT = TransportSection()  # the config's defaults: the settings' defaults of its keys


@dataclass(frozen=True)
class ProgressSettings:
    """``subgoal_tolerance`` (m) and ``subgoal_heading`` (rad): a subgoal counts as reached;
    ``corridor`` (m: farther from the route re-plans it); ``progress_step`` (m of progress that
    resets the stall clock); ``stall_timeout`` (s without it: stalled); ``progress_window`` (m
    of route ahead that the progress measure looks at)."""

    subgoal_tolerance: float = 0.1
    subgoal_heading: float = math.radians(8.0)
    corridor: float = 0.4
    progress_step: float = 0.02
    stall_timeout: float = configured(_TRANSPORT, "stall_timeout")
    progress_window: float = 0.6


def at(pose: np.ndarray, goal: np.ndarray, tol: float, tol_th: float) -> bool:
    """Whether ``pose`` is within ``tol`` m and ``tol_th`` rad of ``goal``."""
    return bool(
        np.linalg.norm(pose[:2] - goal[:2]) <= tol
        and abs(geometry.wrap_angle(pose[2] - goal[2])) <= tol_th
    )


class RouteProgress:
    """The route being followed and how far along it the object is."""

    def __init__(self, model: ObjectModel, goal: np.ndarray, s: ProgressSettings) -> None:
        self.model, self.goal, self.s = model, np.asarray(goal, float), s
        self.route: RouteResult | None = None
        self.subgoal = 0
        self.best_remaining = math.inf
        self.route_j = 0  # the route segment the object was last matched to
        self.progress_t = 0.0

    def begin(self, route: RouteResult, t: float) -> None:
        """A new route (the route planner's result), followed from its first subgoal."""
        self.route = route
        self.subgoal = 0
        self.best_remaining = math.inf
        self.route_j = 0
        self.progress_t = t

    def hold_clock(self, t: float) -> None:
        """The stall clock waits at ``t`` (the carry starting, a re-arrangement under way: no
        progress is due)."""
        self.progress_t = t

    def next_subgoal(self) -> None:
        """The current subgoal reached: on to the next."""
        self.subgoal += 1

    def pause(self, dt: float) -> None:
        """``dt`` s that do not count toward a stall (an outage, a re-arrangement)."""
        self.progress_t += dt

    def segment(self) -> RouteSegment:
        wp = self.route.waypoints
        return RouteSegment.toward(wp, self.route.subgoals[self.subgoal])

    def direction(self, pose: np.ndarray) -> np.ndarray:
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

    def subgoal_reached(self, pose: np.ndarray) -> bool:
        if self.subgoal >= len(self.route.subgoals) - 1:
            return False
        g = self.route.subgoals[self.subgoal]
        return at(pose, g, self.s.subgoal_tolerance, self.s.subgoal_heading)

    def pass_reached(self, pose: np.ndarray) -> None:
        """Subgoals already within tolerance are passed (the route's exact joins can put one a
        hair's turn from the start)."""
        while self.subgoal_reached(pose):
            self.subgoal += 1

    def remaining(self, pose: np.ndarray, commit: bool = False) -> float:
        """What is left of the route (m): the way to a route segment, the rest of that segment
        and every later one, turns counted as arc at the mean radius, at the best segment of a
        window from the last one matched (``commit`` moves the window on). (A straight line to
        the goal would call a detour around an obstacle no progress; a window over the whole
        route would cut through the obstacle to its far side.)"""
        r = self.model.mean_radius
        goal = self.goal
        if self.route is None or len(self.route.waypoints) < 2:
            return float(np.linalg.norm(pose[:2] - goal[:2])) + r * abs(
                geometry.wrap_angle(pose[2] - goal[2])
            )
        wp = self.route.waypoints
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

    def stalled(self, t: float, pose: np.ndarray) -> tuple[str, bool]:
        """(why the object is stalled, or ""; whether it made progress this tick)."""
        rem = self.remaining(pose, commit=True)
        progressed = rem < self.best_remaining - self.s.progress_step
        if progressed:
            self.best_remaining = rem
            self.progress_t = t
        if t - self.progress_t > self.s.stall_timeout:
            return f"no progress for {self.s.stall_timeout:g} s, {rem:.2f} m from the goal", False
        return "", progressed

    def off_route(self, pose: np.ndarray) -> bool:
        wp = self.route.waypoints
        if len(wp) < 2:
            return False
        dist, _ = geometry.point_segment_distance(pose[None, :2], wp[:-1, :2], wp[1:, :2])
        return bool(dist.min() > self.s.corridor)


def plan_route_job(box: JobOwned, cfg: FleetConfig, pose: np.ndarray) -> RouteResult:
    """Job ``route``: the route from ``pose`` (the planner, kept in ``box``, built first when
    there is none)."""
    return box.built(lambda: route_planner_for(cfg)).plan(pose)


def route_planner_for(cfg: FleetConfig) -> RoutePlanner:
    """The object's route planner toward ``object.goal`` (C-space and cost-to-go table built),
    keeping to the ways the whole fleet can push the object (``planning.pushability``: a route
    the robots cannot push along is planned again with the object turned where they can)."""
    from controller.planning.arrangement import TURN_MARGIN
    from controller.planning.pushability import PushDirections
    from controller.planning.route import RoutePlanner

    return RoutePlanner.from_config(cfg, push=PushDirections.from_config(cfg, TURN_MARGIN))
