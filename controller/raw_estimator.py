"""The unfiltered baseline estimator: the latest measurement is the estimate.

Same interface as ``controller.estimation.FleetEstimator``; used as the baseline the Kalman
filters are measured against, and by tests that need exact, unfiltered feedback.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RawEstimate:
    x: float
    y: float
    theta: float
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0
    sigma_xy: float = 0.0
    sigma_theta: float = 0.0
    stale: bool = False
    rejected: int = 0
    initialized: bool = True


class RawEstimator:
    """Latest measurement per robot and for the object; stale after ``stale_after`` seconds."""

    def __init__(self, robot_ids: list[str], stale_after: float) -> None:
        self.ids = list(robot_ids)
        self.stale_after = stale_after
        self._last: dict[str, tuple[float, float, float, float]] = {}
        self._obj: tuple[float, float, float, float] | None = None
        self.arrested = False

    def command(self, robot_id: str, t: float, vx: float, vy: float, wz: float) -> None:
        pass

    def measure_robot(self, robot_id: str, t: float, x: float, y: float, theta: float) -> str:
        prev = self._last.get(robot_id)
        if prev is not None and t < prev[0]:
            return "out_of_order"
        self._last[robot_id] = (t, x, y, theta)
        return "accepted" if prev is not None else "initialized"

    def measure_object(self, t: float, x: float, y: float, theta: float) -> str:
        if self._obj is not None and t < self._obj[0]:
            return "out_of_order"
        self._obj = (t, x, y, theta)
        return "accepted"

    def robot_estimate(self, robot_id: str, now: float) -> RawEstimate | None:
        m = self._last.get(robot_id)
        if m is None:
            return None
        return RawEstimate(m[1], m[2], m[3], stale=now - m[0] > self.stale_after)

    def robot_arrays(self, now: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        poses = np.zeros((len(self.ids), 3))
        stale = np.ones(len(self.ids), dtype=bool)
        for i, rid in enumerate(self.ids):
            e = self.robot_estimate(rid, now)
            if e is not None:
                poses[i] = (e.x, e.y, e.theta)
                stale[i] = e.stale
        return poses, np.zeros_like(poses), stale

    def object_estimate(self, now: float) -> RawEstimate | None:
        if self._obj is None:
            return None
        t, x, y, th = self._obj
        return RawEstimate(x, y, th, stale=now - t > self.stale_after)

    def predict_object(self, now: float, horizon: float) -> RawEstimate | None:
        return self.object_estimate(now)

    def set_object_arrested(self, arrested: bool) -> None:
        self.arrested = arrested
