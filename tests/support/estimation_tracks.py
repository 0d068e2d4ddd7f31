"""Simulated robot and object tracks for the estimation tests and bench.

A robot follows its body-frame commands with bounded acceleration plus a small random velocity
disturbance (so the filter's first-order command model is not the truth); poses are measured at
stamps jittered between 20 and 50 Hz with Gaussian noise and a share of 0.5 m outliers, and
delivered with a small random latency (commands sent meanwhile are already known to the filter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from controller.config import EstimationSection, MotionSection
from controller.estimation.fleet import FleetEstimator
from sim_backend.motion import ObjectScript


@dataclass
class Track:
    kind: str
    grid: np.ndarray  # (G,) s
    truth: np.ndarray  # (G,3) x, y, unwrapped theta
    t_cmd: np.ndarray  # (K,) s
    cmd: np.ndarray  # (K,3) body vx, vy, wz
    t_meas: np.ndarray  # (M,) s, stamps
    t_arrive: np.ndarray  # (M,) s, delivery time
    z: np.ndarray  # (M,3)
    outlier: np.ndarray  # (M,) bool

    def truth_at(self, t: np.ndarray | float) -> np.ndarray:
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.stack([np.interp(tt, self.grid, self.truth[:, k]) for k in range(3)], axis=1)
        return out


def measure(
    rng: np.random.Generator,
    truth: np.ndarray,
    sigma_xy: float,
    sigma_theta: float,
    outlier_rate: float,
    outlier_mag: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Noisy (x, y, theta) measurements of truth rows, with outliers displaced by outlier_mag."""
    m = len(truth)
    z = truth.copy()
    z[:, :2] += rng.normal(0.0, sigma_xy, (m, 2))
    z[:, 2] += rng.normal(0.0, sigma_theta, m)
    z[:, 2] = (z[:, 2] + math.pi) % (2 * math.pi) - math.pi
    out = np.zeros(m, dtype=bool)
    out[rng.choice(m, int(round(outlier_rate * m)), replace=False)] = True
    ang = rng.uniform(-math.pi, math.pi, m)
    z[out, 0] += outlier_mag * np.cos(ang[out])
    z[out, 1] += outlier_mag * np.sin(ang[out])
    return z, out


def stamps(rng: np.random.Generator, duration: float, rate: tuple[float, float]) -> np.ndarray:
    """Measurement stamps (s) with gaps uniform between 1/rate[1] and 1/rate[0]."""
    gaps = rng.uniform(1.0 / rate[1], 1.0 / rate[0], int(duration * rate[1]) + 10)
    t = np.cumsum(gaps)
    return t[t < duration]


def simulate_robot(
    kind: str,
    rng: np.random.Generator,
    duration: float = 12.0,
    tick: float = 0.05,
    sigma_xy: float = 0.01,
    sigma_theta: float = math.radians(1.0),
    outlier_rate: float = 0.05,
    outlier_mag: float = 0.5,
    rate: tuple[float, float] = (20.0, 50.0),
    spin: float | None = None,
    max_accel: float = 1.0,
    max_yaw_accel: float = 4.0,
    disturbance: float = 0.02,
    motor_tau: float = 0.1,
    latency: float = 0.015,
    dt: float = 1e-3,
) -> Track:
    """A robot driven by random piecewise-constant commands (or spinning at ``spin`` rad/s)."""
    n = int(round(duration / dt)) + 1
    grid = np.arange(n) * dt
    t_cmd = np.arange(0.0, duration, tick)
    cmd = np.zeros((len(t_cmd), 3))
    target = np.zeros(3)
    next_change = 0.0
    for k, t in enumerate(t_cmd):
        if t >= next_change:
            if spin is not None:
                target = np.array([0.2, 0.0, spin])
            else:
                target = np.array(
                    [rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), rng.uniform(-1.5, 1.5)]
                )
            if kind == "diff":
                target[1] = 0.0
            next_change = t + rng.uniform(0.5, 2.0)
        # The controller rate-limits its commands to the robot's acceleration limits.
        prev = cmd[k - 1] if k else np.zeros(3)
        step = np.array([max_accel, max_accel, max_yaw_accel]) * tick
        cmd[k] = prev + np.clip(target - prev, -step, step)
    pose = np.array([rng.uniform(1, 3), rng.uniform(1, 3), rng.uniform(-math.pi, math.pi)])
    vel = np.zeros(3)
    dist = np.zeros(3)
    truth = np.zeros((n, 3))
    lim = np.array([max_accel, max_accel, max_yaw_accel]) * dt
    ou = math.exp(-dt / 0.5)
    ou_sig = disturbance * math.sqrt(1.0 - ou * ou)
    k = 0
    for i in range(n):
        truth[i] = pose
        t = grid[i]
        while k + 1 < len(t_cmd) and t_cmd[k + 1] <= t:
            k += 1
        # Motor response: first-order lag on the command, bounded by the acceleration limits.
        vel += np.clip((cmd[k] - vel) * (dt / motor_tau), -lim, lim)
        dist = ou * dist + ou_sig * rng.normal(size=3) * np.array([1.0, 1.0, 3.0])
        if kind == "diff":
            dist[1] = 0.0
        v = vel + dist
        c, s = math.cos(pose[2]), math.sin(pose[2])
        pose = pose + dt * np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]])
    t_meas = stamps(rng, duration, rate)
    tr = Track(kind, grid, truth, t_cmd, cmd, t_meas, t_meas, np.zeros((0, 3)), np.zeros(0, bool))
    tr.z, tr.outlier = measure(
        rng, tr.truth_at(t_meas), sigma_xy, sigma_theta, outlier_rate, outlier_mag
    )
    tr.t_arrive = t_meas + rng.uniform(0.0, latency, len(t_meas))
    return tr


def sine_object(
    rng: np.random.Generator,
    duration: float = 30.0,
    motion: MotionSection | None = None,
    start: tuple[float, float, float] = (2.0, 6.0, 0.3),
    sigma_xy: float = 0.01,
    sigma_theta: float = math.radians(1.0),
    outlier_rate: float = 0.05,
    outlier_mag: float = 0.5,
    rate: tuple[float, float] = (20.0, 50.0),
    dt: float = 1e-3,
) -> Track:
    """The live object on its scripted sine path (the script's reference pose, exact)."""
    script = ObjectScript(motion or MotionSection(kind="sine"), start)
    n = int(round((duration + 1.0) / dt)) + 1
    grid = np.arange(n) * dt
    truth = np.array([script.reference(float(t))[0] for t in grid])
    t_meas = stamps(rng, duration, rate)
    tr = Track("object", grid, truth, np.zeros(0), np.zeros((0, 3)), t_meas, t_meas, *([None] * 2))  # type: ignore[arg-type]
    tr.z, tr.outlier = measure(
        rng, tr.truth_at(t_meas), sigma_xy, sigma_theta, outlier_rate, outlier_mag
    )
    return tr


def _ang(a: np.ndarray) -> np.ndarray:
    return (a + math.pi) % (2 * math.pi) - math.pi


@dataclass
class RunResult:
    statuses: list[str]
    post_err: np.ndarray  # (M,) position error (m) of the posterior at each stamp
    post_head_err: np.ndarray  # (M,) heading error (rad)
    raw_err: np.ndarray  # (M,) position error of the raw measurement
    tick_err: np.ndarray  # (K,) position error of the estimate predicted to each tick
    tick_head_err: np.ndarray
    outlier: np.ndarray
    covariances: list[np.ndarray] = field(default_factory=list)

    def ratio(self, warmup: int = 20) -> float:
        """Posterior position RMSE over the raw inlier measurements' RMSE."""
        keep = ~self.outlier
        keep[:warmup] = False
        good = keep & np.array([s == "accepted" for s in self.statuses])
        return rmse(self.post_err[good]) / rmse(self.raw_err[keep])

    def tick_ratio(self, warmup: int = 20) -> float:
        keep = ~self.outlier
        keep[:warmup] = False
        return rmse(self.tick_err[warmup:]) / rmse(self.raw_err[keep])

    def outliers_rejected(self) -> float:
        st = np.array(self.statuses)
        return float(np.mean(st[self.outlier] == "rejected")) if self.outlier.any() else 1.0

    def good_rejected(self) -> float:
        st = np.array(self.statuses)
        return float(np.mean(st[~self.outlier] == "rejected"))


def rmse(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(e))))


def run_robot(
    track: Track, params: EstimationSection, stale_after: float = 0.3, keep_cov: bool = False
) -> RunResult:
    """Feed a track's commands and measurements to a FleetEstimator in delivery order."""
    est = FleetEstimator([("r", track.kind)], params, stale_after)
    events = [(t, 0, k) for k, t in enumerate(track.t_cmd)]
    events += [(t, 1, m) for m, t in enumerate(track.t_arrive)]
    events.sort()
    statuses = [""] * len(track.t_meas)
    post = np.zeros((len(track.t_meas), 3))
    tick = np.zeros((len(track.t_cmd), 3))
    covs: list[np.ndarray] = []
    for t, what, k in events:
        if what == 0:
            e = est.robot_estimate("r", t)
            tick[k] = (e.x, e.y, e.theta)
            c = track.cmd[k]
            est.command("r", t, c[0], c[1], c[2])
        else:
            ts = track.t_meas[k]
            statuses[k] = est.measure_robot("r", ts, *track.z[k])
            e = est.robot_estimate("r", ts)
            post[k] = (e.x, e.y, e.theta)
            if keep_cov:
                covs.append(est._tracks["r"].P)
    truth_m = track.truth_at(track.t_meas)
    truth_k = track.truth_at(track.t_cmd)
    tick = np.nan_to_num(tick, nan=1e9)
    return RunResult(
        statuses,
        np.linalg.norm(post[:, :2] - truth_m[:, :2], axis=1),
        np.abs(_ang(post[:, 2] - truth_m[:, 2])),
        np.linalg.norm(track.z[:, :2] - truth_m[:, :2], axis=1),
        np.linalg.norm(tick[:, :2] - truth_k[:, :2], axis=1),
        np.abs(_ang(tick[:, 2] - truth_k[:, 2])),
        track.outlier,
        covs,
    )
