"""Which robot goes to which capture point (pure): the interception cost of every robot to every
point's station where the moving object will be, the assignment that minimises its total over
the robots available, and re-assignment during the approach when a fast object runs toward
other robots."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from controller import geometry
from controller.config import FleetConfig
from controller.events import ReassignEvent
from controller.mission.types import Event, FleetView
from controller.planning.approach import envelope, interception_times
from controller.planning.capture_set import CaptureSet

REASSIGN_PERIOD = 2.0  # s between looks at a better assignment during the approach
REASSIGN_GAIN = 0.25  # the share of the total interception time a new assignment must save
REASSIGN_MIN_S = 5.0  # s of total interception time it must save at least
REASSIGN_MIN_SPEED = 0.1  # m/s: slower objects keep their first assignment
# the interception search looks this many times ``approach.intercept_horizon`` ahead (at least
# 1 s's worth): a costing, not a plan, so a meeting beyond the tracker's horizon still ranks
COST_HORIZON_FACTOR = 10.0


def interception_costs(cfg: FleetConfig, capture: CaptureSet, view: FleetView) -> np.ndarray:
    """(M, N) s for each robot to meet each capture point's station where the moving object
    will be (interception at full speed, scaled by the detour around the object)."""
    radius = cfg.max_robot_radius
    margin = cfg.approach.envelope_margin
    stations = geometry.transform(
        capture.points + (radius + margin) * capture.normals, view.object_pose
    )
    ovel = np.zeros(3) if view.object_velocity is None else np.asarray(view.object_velocity)
    rel = stations - np.asarray(view.object_pose)[:2]
    vel = ovel[:2] + ovel[2] * np.stack([-rel[:, 1], rel[:, 0]], 1)
    speed = np.array([r.max_speed for r in cfg.robots])
    horizon = max(cfg.approach.intercept_horizon, 1.0) * COST_HORIZON_FACTOR
    oncoming = cfg.approach.intercept == "oncoming"
    cost = interception_times(view.poses[:, :2], stations, vel, speed, horizon, oncoming)
    # a robot behind the object goes around it: scale by the detour around its envelope
    hull = envelope(
        geometry.transform(geometry.ensure_ccw(cfg.object_polygon()), view.object_pose), radius
    )
    around = geometry.distance_around_convex(stations, view.poses[:, :2], hull)
    straight = np.linalg.norm(stations[:, None] - view.poses[None, :, :2], axis=-1)
    return cost * around / np.maximum(straight, 1e-9)


def assign(costs: np.ndarray, available: np.ndarray) -> np.ndarray:
    """Each capture point's robot (M,), among the ``available`` (N,) ones only, the total
    ``costs`` (M, N) least."""
    cols = np.flatnonzero(available)
    rows, picked = linear_sum_assignment(costs[:, cols])
    out = np.empty(len(rows), dtype=int)
    out[rows] = cols[picked]
    return out


class Reassigner:
    """During the approach, every ``REASSIGN_PERIOD`` s: hand the capture points to other robots
    when that meets the object sooner by ``REASSIGN_GAIN`` (the first assignment is made before
    the object's velocity estimate has settled: a fast object runs away from the robots that
    were nearest at first sight, toward others)."""

    def __init__(self) -> None:
        self.last_t = -math.inf  # s: the last assignment or look
        self.count = 0

    def assigned(self, t: float) -> None:
        self.last_t = t

    def look(
        self,
        cfg: FleetConfig,
        capture: CaptureSet,
        view: FleetView,
        current: np.ndarray,
        available: np.ndarray,
    ) -> tuple[np.ndarray | None, list[Event]]:
        """A better assignment than ``current`` (M,), or None; and its events."""
        if view.t - self.last_t < REASSIGN_PERIOD:
            return None, []
        ovel = view.object_velocity
        if ovel is None or float(np.hypot(ovel[0], ovel[1])) < REASSIGN_MIN_SPEED:
            return None, []  # a slow object: the first assignment stands (no thrashing)
        self.last_t = view.t
        cost = interception_costs(cfg, capture, view)
        new = assign(cost, available)
        m = np.arange(len(new))
        now, better = cost[m, current].sum(), cost[m, new].sum()
        gain = now - better
        if not (np.isfinite(better) and gain > REASSIGN_GAIN * now and gain > REASSIGN_MIN_S):
            return None, []
        self.count += 1
        robots = [view.ids[i] for i in new]
        return new, [ReassignEvent(robots=robots, t=view.t, eta_s=[now, better])]
