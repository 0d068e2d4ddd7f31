"""Scripted motion of the live object: ``line``, ``sine``, ``evade`` and ``static``.

Pure functions of time and state. ``reference(t)`` is the pose the script wants at time t;
``target_velocity`` is the world-frame velocity a tracker should follow now: the path's own
velocity plus a bounded pull back onto it (line, sine), or a flight away from the nearest robot
(evade).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.config import MotionSection
from controller.geometry import wrap_angle


@dataclass(frozen=True)
class ObjectScript:
    motion: MotionSection
    start: tuple[float, float, float]
    pull_gain: float = 1.0  # 1/s, gain of the pull back onto the path

    def _axes(self) -> tuple[np.ndarray, np.ndarray]:
        h = self.motion.heading
        u = np.array([math.cos(h), math.sin(h)])
        return u, np.array([-u[1], u[0]])

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose (x, y, theta) and world velocity (vx, vy, wz) of the path at time t."""
        m = self.motion
        p0 = np.array(self.start[:2], dtype=float)
        u, n = self._axes()
        if m.kind == "static":
            return np.array([*p0, self.start[2]]), np.zeros(3)
        s = m.speed * t
        if m.kind == "sine":
            k = 2.0 * math.pi / m.wavelength
            pos = p0 + s * u + m.amplitude * math.sin(k * s) * n
            vel = m.speed * u + m.amplitude * k * m.speed * math.cos(k * s) * n
        else:  # line and the base drift of evade
            pos = p0 + s * u
            vel = m.speed * u
        return np.array([*pos, self.start[2]]), np.array([*vel, 0.0])

    def target_velocity(
        self, t: float, pose: np.ndarray, robot_xy: np.ndarray | None = None
    ) -> np.ndarray:
        """World-frame (vx, vy, wz) the object's drive should follow now."""
        m = self.motion
        if m.kind == "evade" and robot_xy is not None and len(robot_xy):
            d = np.asarray(pose[:2]) - np.asarray(robot_xy)
            dist = np.linalg.norm(d, axis=1)
            i = int(np.argmin(dist))
            if dist[i] < m.flee_radius and dist[i] > 1e-9:
                away = d[i] / dist[i]
                urgency = 1.0 - dist[i] / m.flee_radius
                v = away * (m.speed + (m.max_speed - m.speed) * urgency)
                wz = -self.pull_gain * wrap_angle(pose[2] - self.start[2])
                return np.array([v[0], v[1], wz])
            u, _ = self._axes()
            wz = -self.pull_gain * wrap_angle(pose[2] - self.start[2])
            return np.array([*(m.speed * u), wz])
        ref, vel = self.reference(t)
        err = ref[:2] - np.asarray(pose[:2])
        pull = self.pull_gain * err
        cap = max(m.speed, 0.05)
        norm = float(np.linalg.norm(pull))
        if norm > cap:
            pull *= cap / norm
        wz = -self.pull_gain * wrap_angle(pose[2] - ref[2])
        return np.array([vel[0] + pull[0], vel[1] + pull[1], wz])
