"""The sim hub: one world, its sensors, and the measurement queues the sim drivers read.

The hub advances the world in whole physics steps and samples every sensor after each step, so
measurements carry their own sim-time stamps at the sensors' rates, independent of the control
tick. It knows nothing of the bus.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Protocol

import numpy as np

from sim_backend.base import World

Measurement = tuple[float, float, float, float]  # (t, x, y, theta)


class Sensor(Protocol):
    def sample(self, t: float, pose: np.ndarray) -> list[Measurement]:
        """Measurements due at sim time t for the true pose (possibly none)."""
        ...


class PerfectSensor:
    """A noise-free pose sensor at a fixed rate (for ideal runs and tests)."""

    def __init__(self, rate_hz: float) -> None:
        self.period = 1.0 / rate_hz
        self._next = 0.0

    def sample(self, t: float, pose: np.ndarray) -> list[Measurement]:
        if t + 1e-9 < self._next:
            return []
        self._next = max(self._next + self.period, t)
        return [(t, float(pose[0]), float(pose[1]), float(pose[2]))]


class SimHub:
    """Steps a world and collects its sensors' measurements into per-robot queues."""

    def __init__(
        self,
        world: World,
        robot_sensors: dict[str, Sensor],
        object_sensor: Sensor,
        physics_dt: float,
    ) -> None:
        self.world = world
        self.robot_sensors = robot_sensors
        self.object_sensor = object_sensor
        self.dt = physics_dt
        self.robot_queues: dict[str, deque[Measurement]] = {r: deque() for r in robot_sensors}
        self.object_queue: deque[Measurement] = deque()
        self.step_hooks: list[Callable[[float], None]] = []
        self._sample()

    @property
    def t(self) -> float:
        return self.world.t

    def _sample(self) -> None:
        t = self.world.t
        for rid, sensor in self.robot_sensors.items():
            self.robot_queues[rid].extend(sensor.sample(t, self.world.robot_pose(rid)))
        self.object_queue.extend(self.object_sensor.sample(t, self.world.object_pose()))

    def advance_to(self, t_end: float, max_steps: int | None = None) -> int:
        """Step physics until sim time reaches ``t_end``, sampling sensors and running the step
        hooks (e.g. MAVLink vehicle emulators) after every step; at most ``max_steps`` steps
        (a real-time loop with other duties, an agent's, stays responsive and lets the world
        fall behind the clock rather than catch up in one long call). Returns the steps."""
        steps = 0
        while self.world.t + 0.5 * self.dt < t_end and (max_steps is None or steps < max_steps):
            self.world.step(self.dt)
            self._sample()
            for hook in self.step_hooks:
                hook(self.world.t)
            steps += 1
        return steps

    def take_robot(self, robot_id: str) -> list[Measurement]:
        q = self.robot_queues[robot_id]
        out = list(q)
        q.clear()
        return out

    def take_object(self) -> list[Measurement]:
        out = list(self.object_queue)
        self.object_queue.clear()
        return out
