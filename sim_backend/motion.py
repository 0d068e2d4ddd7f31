"""Scripted motion of the live object: ``line``, ``sine``, ``evade`` and ``static`` (a drive
that holds its start pose); ``inert`` has no drive at all (a plain crate: limp from the start).

Pure functions of time and state. ``reference(t)`` is the pose the script wants at time t;
``target_velocity`` is the world-frame velocity a tracker should follow now: the path's own
velocity plus a bounded pull back onto it (line, sine), or a flight away from the nearest robot
(evade).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.config import MotionSection
from controller.geometry import wrap_angle


@dataclass
class GiveUp:
    """When the live object goes limp: after ``after`` seconds in a row of being thwarted (its
    velocity off its drive's target by more than half the target speed, and by more than
    ``slack`` m/s), as a held or pinned object is. The world decides this from its own physics,
    never from what the controller declares. ``after`` 0: it never gives up."""

    after: float
    slack: float = 0.02  # m/s
    thwarted_for: float = 0.0
    gave_up_at: float | None = None

    @classmethod
    def for_motion(cls, motion: Any) -> GiveUp:
        """The rule for ``object.motion``: an ``inert`` object has no drive to give up."""
        g = cls(motion.give_up_after)
        if motion.kind == "inert":
            g.gave_up_at = 0.0
        return g

    @property
    def alive(self) -> bool:
        return self.gave_up_at is None

    def update(
        self,
        t: float,
        dt: float,
        target: np.ndarray,
        actual: np.ndarray,
        pushed: bool = False,
    ) -> bool:
        """Account ``dt`` seconds ending at ``t`` with target and actual world velocities (vx,
        vy, ...); ``pushed``: something presses on it (a kinematic world's contact, where a
        held object's velocities say nothing). Returns whether the object is still alive."""
        if not self.alive or self.after <= 0:
            return self.alive
        off = float(np.hypot(*(np.asarray(actual[:2]) - np.asarray(target[:2]))))
        speed = float(np.hypot(*np.asarray(target[:2])))
        if pushed or off > max(0.5 * speed, self.slack):
            self.thwarted_for += dt
            if self.thwarted_for >= self.after:
                self.gave_up_at = t
        else:
            self.thwarted_for = 0.0
        return self.alive


@dataclass(frozen=True)
class ObjectScript:
    """The object's scripted drive. ``started_at`` (s of sim time) is when its path begins;
    None: not yet (the drive holds the start pose; ``fleet world`` waits for the operator's
    first resume, ``sim.object_start``)."""

    motion: MotionSection
    start: tuple[float, float, float]
    pull_gain: float = 1.0  # 1/s, gain of the pull back onto the path
    started_at: float | None = 0.0

    def waiting(self) -> bool:
        """Whether the path has not begun yet (the drive holds the start pose)."""
        return self.started_at is None

    def held(self) -> ObjectScript:
        """This script waiting: its path begins at :meth:`begun`."""
        return dataclasses.replace(self, started_at=None)

    def begun(self, t: float) -> ObjectScript:
        """This script with its path begun at ``t`` (s; itself when it had begun already)."""
        return self if self.started_at is not None else dataclasses.replace(self, started_at=t)

    def _axes(self) -> tuple[np.ndarray, np.ndarray]:
        h = self.motion.heading
        u = np.array([math.cos(h), math.sin(h)])
        return u, np.array([-u[1], u[0]])

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose (x, y, theta) and world velocity (vx, vy, wz) of the path at time t."""
        m = self.motion
        p0 = np.array(self.start[:2], dtype=float)
        u, n = self._axes()
        if m.kind in ("static", "inert") or self.started_at is None:
            return np.array([*p0, self.start[2]]), np.zeros(3)
        s = m.speed * max(0.0, t - self.started_at)
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
        if (
            m.kind == "evade"
            and self.started_at is not None
            and robot_xy is not None
            and len(robot_xy)
        ):
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


class ScriptedObject:
    """The live object's side of a world (pybullet or ideal): its drive's ``_script`` and its
    give-up rule ``_give_up``, read and started the same way in both; the world supplies
    ``t`` (sim time)."""

    _script: ObjectScript
    _give_up: GiveUp
    t: float

    @property
    def object_alive(self) -> bool:
        return self._give_up.alive

    @property
    def object_gave_up_at(self) -> float | None:
        return self._give_up.gave_up_at

    def hold_object(self) -> None:
        """The object's drive holds its start pose until :meth:`start_object`."""
        self._script = self._script.held()

    def start_object(self) -> None:
        """The object's path begins now (``fleet world``: at the operator's first resume)."""
        self._script = self._script.begun(self.t)

    @property
    def object_waiting(self) -> bool:
        return self._script.waiting()
