"""Pose sensors for the stand-in world: rate, Gaussian noise, dropouts and outliers.

A ``PoseSensor`` wraps nothing: it is fed the true pose at sim time ``t`` and returns the
measurements it would have emitted by then. Randomness comes only from the generator passed in,
so a seed fixes every measurement. ``make_sensors`` builds one sensor per robot and one for the
object from ``cfg.sim`` with child generators spawned from ``cfg.sim.seed``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.config import FleetConfig
from controller.geometry import wrap_angle

Measurement = tuple[float, float, float, float]  # (t s, x m, y m, theta rad)


class PoseSensor:
    """A pose sensor emitting at ``rate_hz`` with seeded noise, dropouts and outliers.

    - noise: x and y get N(0, sigma_xy) (m), theta N(0, sigma_theta) (rad), wrapped to [-pi, pi);
    - ``dropout``: probability that a due measurement is lost;
    - ``outlier_rate``: probability that a measurement is an outlier, displaced by
      ``outlier_magnitude`` metres in a uniformly random direction and turned by a uniform angle
      in ±min(pi, outlier_magnitude) radians;
    - ``jitter``: sample instants move by up to ±jitter/rate_hz (fraction of a period), uniformly.

    Every due sample draws the same numbers whatever happens to it, so two sensors built with the
    same seed stay in step even if their settings differ.
    """

    def __init__(
        self,
        rate_hz: float,
        sigma_xy: float,
        sigma_theta: float,
        dropout: float,
        outlier_rate: float,
        outlier_magnitude: float,
        rng: np.random.Generator,
        jitter: float = 0.0,
        phase: float = 0.0,
        bias: tuple[float, float] = (0.0, 0.0),
    ):
        if rate_hz <= 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        for name, v in (("dropout", dropout), ("outlier_rate", outlier_rate)):
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {v}")
        if not 0.0 <= jitter < 0.5:
            raise ValueError(f"jitter must be in [0, 0.5), got {jitter}")
        self.rate_hz = rate_hz
        self.period = 1.0 / rate_hz
        self.sigma_xy = sigma_xy
        self.sigma_theta = sigma_theta
        self.dropout = dropout
        self.outlier_rate = outlier_rate
        self.outlier_magnitude = outlier_magnitude
        self.jitter = jitter
        self.bias = (float(bias[0]), float(bias[1]))  # m, a fixed offset (motion error)
        self._rng = rng
        self._k = 0  # index of the next nominal sample instant
        self._phase = phase  # s, the first nominal instant
        self._next = phase + self._jitter_offset()
        self.emitted = 0
        self.dropped = 0
        self.outliers = 0

    def _jitter_offset(self) -> float:
        if self.jitter == 0.0:
            return 0.0
        return float(self._rng.uniform(-self.jitter, self.jitter)) * self.period

    def sample(self, t: float, true_pose: np.ndarray) -> list[Measurement]:
        """Measurements due by sim time ``t`` (s) of the true pose (x, y, theta) at ``t``.

        At most one measurement per call (stamped ``t``): when several instants fell due since
        the last call, the missed ones are skipped (the sensor is read slower than its rate).
        """
        if t + 1e-12 < self._next:
            return []
        self._k += 1  # the slot just served, and any missed since
        while self._phase + self._k * self.period <= t + 1e-12:
            self._k += 1
        self._next = self._phase + self._k * self.period + self._jitter_offset()
        u_drop, u_out, u_dir, u_turn = self._rng.random(4)
        noise = self._rng.standard_normal(3)
        if u_drop < self.dropout:
            self.dropped += 1
            return []
        x = float(true_pose[0]) + self.bias[0] + self.sigma_xy * noise[0]
        y = float(true_pose[1]) + self.bias[1] + self.sigma_xy * noise[1]
        th = float(true_pose[2]) + self.sigma_theta * noise[2]
        if u_out < self.outlier_rate:
            self.outliers += 1
            a = 2.0 * math.pi * u_dir
            x += self.outlier_magnitude * math.cos(a)
            y += self.outlier_magnitude * math.sin(a)
            th += min(math.pi, self.outlier_magnitude) * (2.0 * u_turn - 1.0)
        self.emitted += 1
        return [(float(t), x, y, wrap_angle(th))]


@dataclass(frozen=True)
class SensorSet:
    """One pose sensor per robot (by id) and one for the object."""

    robots: dict[str, PoseSensor]
    object: PoseSensor


def make_sensors(cfg: FleetConfig, jitter: float = 0.0) -> SensorSet:
    """Sensors from ``cfg.sim``; generators spawned from ``cfg.sim.seed`` (robots in config
    order, then the object), so the same config gives the same measurements."""
    s = cfg.sim
    children = np.random.SeedSequence(s.seed).spawn(len(cfg.robots) + 1)

    err = np.abs(np.asarray(s.robot_position_error, float))
    biases = np.random.default_rng([s.seed, 4040]).uniform(-1.0, 1.0, (len(cfg.robots), 2)) * err

    def build(rate: float, seq: np.random.SeedSequence, bias=(0.0, 0.0)) -> PoseSensor:
        return PoseSensor(
            rate,
            s.pose_noise.xy,
            s.pose_noise.theta,
            s.dropout,
            s.outlier_rate,
            s.outlier_magnitude,
            np.random.default_rng(seq),
            jitter=jitter,
            bias=bias,
        )

    robots = {
        r.id: build(s.pose_rate_hz, seq, tuple(b))
        for r, seq, b in zip(cfg.robots, children, biases, strict=False)
    }
    return SensorSet(robots=robots, object=build(s.object_pose_rate_hz, children[-1]))
