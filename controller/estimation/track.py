"""``TrackFilter``: one target's Kalman filter (EKF or UKF) on its own measurement timeline.

Commands kept with their stamps, out-of-order and gated measurements, re-acquisition after
consistent rejections, and queries that extrapolate copies to a later time. Pure state: time
is always passed in.
"""

from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from controller.config import EstimationSection
from controller.estimation.kalman import (
    Segment,
    _sym,
    gate_threshold,
    mahalanobis2,
    make_strategy,
)
from controller.estimation.models import (
    COMMAND_DIM,
    MEAS_DIM,
    MODELS,
    STATE_DIM,
    THETA,
    YAW_RATE_INDEX,
    motion,
    process_noise,
)
from controller.geometry import wrap_angle

FloatArray = NDArray[np.float64]


class TrackFilter:
    """One target's filter on its own timeline (internal building block of the holder).

    ``t`` is the stamp of the last measurement processed; queries at a later time extrapolate
    copies and never move it.
    """

    def __init__(
        self,
        model: str,
        filter_name: str,
        params: EstimationSection,
        q_lin: float,
        q_yaw: float,
    ):
        if model not in MODELS:
            raise ValueError(f"unknown model {model!r}; expected one of {MODELS}")
        self.model = model
        self.filter_name = filter_name
        self.strategy = make_strategy(filter_name)
        self.n = STATE_DIM[model]
        self.tau = params.command_tau
        self.q_lin = q_lin
        self.q_yaw = q_yaw
        self.R = np.diag([params.meas_xy**2, params.meas_xy**2, params.meas_theta**2])
        self.init_sigma_speed = params.init_sigma_speed
        self.init_sigma_yaw_rate = params.init_sigma_yaw_rate
        self.reacquire_after = params.reacquire_after
        self.threshold = gate_threshold(params.gate_probability)
        self._H = np.hstack([np.eye(MEAS_DIM), np.zeros((MEAS_DIM, self.n - MEAS_DIM))])
        self.kf: Any = self.strategy.make(model, self.n, self.tau, self._fx)
        self.kf.R = self.R.copy()
        self.t: float | None = None
        self.t_accepted: float | None = None
        self.accepted = 0
        self.rejected = 0
        self.out_of_order = 0
        self.reacquired = 0
        self.invalid = 0  # non-finite or malformed measurements (also counted as rejected)
        self.consecutive_rejected = 0
        self._run: list[tuple[float, FloatArray]] = []  # consistent run of rejected measurements
        self.last_d2 = 0.0
        self.just_reacquired = False
        self._cmd_t: list[float] = []
        self._cmd_u: list[FloatArray] = []
        self._version = 0
        self._cache: tuple[float, int, FloatArray, FloatArray] | None = None

    # ---- state access

    @property
    def initialized(self) -> bool:
        return self.t is not None

    @property
    def x(self) -> FloatArray:
        """Current state at ``t`` (copy)."""
        return np.ravel(self.kf.x).astype(float)

    @property
    def P(self) -> FloatArray:
        """Current covariance at ``t`` (copy)."""
        return np.array(self.kf.P, dtype=float)

    def _fx(self, x: FloatArray, dt: float, u: FloatArray | None = None) -> FloatArray:
        return motion(self.model, x, dt, u, self.tau, jacobian=False)[0]

    # ---- commands

    def command(self, t: float, u: ArrayLike) -> None:
        """Record the command sent at time t (s); it acts from t on."""
        uv = np.asarray(u, dtype=float)
        if uv.shape != (COMMAND_DIM[self.model],) or not np.all(np.isfinite(uv)):
            raise ValueError(
                f"{self.model} command must be {COMMAND_DIM[self.model]} finite numbers, got {u!r}"
            )
        if not math.isfinite(t):
            raise ValueError(f"command time must be finite, got {t!r}")
        i = bisect.bisect_right(self._cmd_t, t)
        self._cmd_t.insert(i, t)
        self._cmd_u.insert(i, uv)
        if self._cache is None or t < self._cache[0]:
            self._version += 1  # a command from the cached time on leaves that state as it is
        if len(self._cmd_t) > MAX_COMMANDS:
            self._bound_history()

    def _bound_history(self) -> None:
        """Without measurements the command history would grow without end: time-update the
        filter over the older half (a plain Kalman prediction) and forget those commands."""
        cut = self._cmd_t[len(self._cmd_t) - MAX_COMMANDS // 2]
        if self.t is None:
            keep = bisect.bisect_right(self._cmd_t, cut) - 1
            del self._cmd_t[:keep]
            del self._cmd_u[:keep]
            return
        if cut > self.t:
            try:
                self._predict_filter(cut)
            except np.linalg.LinAlgError:
                return
        self._prune_commands()

    def clear_commands(self) -> None:
        """Forget every recorded command (predictions fall back to the uncommanded model)."""
        self._cmd_t.clear()
        self._cmd_u.clear()
        self._version += 1

    def _command_at(self, t: float) -> FloatArray | None:
        i = bisect.bisect_right(self._cmd_t, t) - 1
        return self._cmd_u[i] if i >= 0 else None

    def segments(self, t0: float, t1: float) -> list[Segment]:
        """Piecewise-constant command segments covering (t0, t1].

        A gap longer than ``MAX_GAP`` is cut to its last ``MAX_GAP`` seconds: such a track is
        long stale, and integrating a day-long gap (a sender's clock far off ours) in 50 ms
        steps would stall the control loop."""
        if t1 <= t0:
            return []
        t0 = max(t0, t1 - MAX_GAP)
        if not self._cmd_t:
            return [(t1 - t0, None)]
        out: list[Segment] = []
        i = bisect.bisect_right(self._cmd_t, t0)
        u = self._cmd_u[i - 1] if i > 0 else None
        t = t0
        while i < len(self._cmd_t) and self._cmd_t[i] < t1:
            tc = self._cmd_t[i]
            if tc > t:
                out.append((tc - t, u))
                t = tc
            u = self._cmd_u[i]
            i += 1
        out.append((t1 - t, u))
        return out

    def _prune_commands(self) -> None:
        if self.t is None:
            return
        i = bisect.bisect_right(self._cmd_t, self.t) - 1  # keep the one active at t
        if i > 0:
            del self._cmd_t[:i]
            del self._cmd_u[:i]

    # ---- measurement

    def _initialize(self, t: float, z: FloatArray) -> None:
        x0 = np.zeros(self.n)
        x0[:MEAS_DIM] = z
        x0[THETA] = wrap_angle(float(z[THETA]))
        u = self._command_at(t)
        if u is not None and self.model != "object":
            x0[3:] = u  # start from the commanded velocity
        sv, sw = self.init_sigma_speed**2, self.init_sigma_yaw_rate**2
        P0 = np.zeros((self.n, self.n))
        P0[:MEAS_DIM, :MEAS_DIM] = self.R
        for k in range(MEAS_DIM, self.n):
            P0[k, k] = sv
        P0[YAW_RATE_INDEX[self.model], YAW_RATE_INDEX[self.model]] = sw
        self.strategy.set_state(self.kf, x0, P0)
        self.t = t
        self.t_accepted = t
        self.consecutive_rejected = 0
        self._run.clear()

    def _extend_run(self, t: float, z: FloatArray) -> int:
        """Add a rejected measurement to the run of mutually consistent ones; its length."""
        if self._run:
            t0, z0 = self._run[-1]
            dt = t - t0
            dxy = math.hypot(z[0] - z0[0], z[1] - z0[1])
            dth = abs(wrap_angle(float(z[THETA] - z0[THETA])))
            rx, rth = math.sqrt(self.R[0, 0]), math.sqrt(self.R[THETA, THETA])
            ok_xy = dxy <= 4.0 * math.sqrt(2.0) * rx + 3.0 * self.init_sigma_speed * dt
            ok_th = dth <= 4.0 * math.sqrt(2.0) * rth + 3.0 * self.init_sigma_yaw_rate * dt
            if not (ok_xy and ok_th):
                self._run.clear()
        self._run.append((t, z))
        return len(self._run)

    def _predict_filter(self, t: float) -> None:
        assert self.t is not None
        for h, u in self.segments(self.t, t):
            Q = process_noise(self.model, self.x[THETA], h, self.q_lin, self.q_yaw)
            self.strategy.predict(self.kf, self.model, h, u, self.tau, Q)
            self.kf.P = _sym(self.kf.P)
        self.t = t

    def innovation(self, z: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Innovation and its covariance for z against the filter's current prior (no mutation)."""
        return self.strategy.innovation(self.kf, np.ravel(z), self.R)

    def measure(self, t: float, z: ArrayLike) -> str:
        """Process a pose measurement (x m, y m, theta rad) stamped t (s); returns a status."""
        zv, status = self.admit(t, z)
        if status is not None:
            return status
        return self.filter(t, zv)

    def filter(self, t: float, zv: FloatArray) -> str:
        """Predict to ``t``, gate and update with an admitted measurement (``admit``)."""
        try:
            self._predict_filter(t)
        except np.linalg.LinAlgError:  # covariance lost definiteness: start over from z
            return self.restart(t, zv)
        return self.judge(t, zv)

    def judge(self, t: float, zv: FloatArray) -> str:
        """Gate and update with an admitted measurement, the filter already predicted to ``t``."""
        try:
            y, S = self.innovation(zv)
            d2 = mahalanobis2(y, S)
        except np.linalg.LinAlgError:  # covariance lost definiteness: start over from z
            return self.restart(t, zv)
        return self.conclude(t, zv, d2)

    def admit(self, t: float, z: ArrayLike) -> tuple[FloatArray, str | None]:
        """A measurement's checks before the filter: garbage (rejected), the first one
        (initialises), one not newer than the timeline (out of order). Returns the measurement
        (heading wrapped) and its status, or None when it is for the filter to predict, gate and
        update (``measure``, or ``FleetEstimator.measure_robots`` for many tracks at once)."""
        zv = np.array(np.ravel(z), dtype=float)
        self._version += 1
        self.just_reacquired = False
        if zv.shape != (MEAS_DIM,) or not (np.all(np.isfinite(zv)) and math.isfinite(t)):
            self.rejected += 1  # garbage never touches the filter
            self.invalid += 1
            return zv, STATUS_REJECTED
        zv[THETA] = wrap_angle(float(zv[THETA]))
        if self.t is None:
            self._initialize(t, zv)
            self._prune_commands()
            return zv, STATUS_INITIALIZED
        if t <= self.t:
            self.out_of_order += 1
            return zv, STATUS_OUT_OF_ORDER
        return zv, None

    def restart(self, t: float, zv: FloatArray) -> str:
        """Start over from the measurement (the covariance lost definiteness)."""
        self.reacquired += 1
        self.just_reacquired = True
        self._initialize(t, zv)
        self._prune_commands()
        return STATUS_INITIALIZED

    def conclude(
        self, t: float, zv: FloatArray, d2: float, post: tuple[FloatArray, FloatArray] | None = None
    ) -> str:
        """Gate a measurement with squared Mahalanobis distance ``d2`` against the prior at
        ``t`` (the filter already predicted there): rejected (re-acquiring after a consistent
        run) or accepted, the update done here or given as ``post`` (state, covariance)."""
        self.last_d2 = d2
        if not d2 <= self.threshold:
            self.rejected += 1
            self.consecutive_rejected += 1
            if self._extend_run(t, zv) >= self.reacquire_after:
                return self.restart(t, zv)
            self._prune_commands()
            return STATUS_REJECTED
        if post is None:
            self.strategy.update(self.kf, zv, self.R, self._H)
            self.kf.P = _sym(self.kf.P)
        else:
            self.strategy.set_state(self.kf, post[0], post[1])
        self.accepted += 1
        self.consecutive_rejected = 0
        self._run.clear()
        self.t_accepted = t
        self._prune_commands()
        return STATUS_ACCEPTED

    # ---- queries

    def is_cached(self, now: float) -> bool:
        """Whether the state extrapolated to ``now`` is cached (and still current)."""
        c = self._cache
        return c is not None and c[0] == now and c[1] == self._version

    def keep(self, now: float, x: FloatArray, P: FloatArray) -> None:
        """Cache the state extrapolated to ``now`` (computed for many tracks at once)."""
        self._cache = (now, self._version, x, P)

    def state_at(self, now: float) -> tuple[FloatArray, FloatArray]:
        """Mean and covariance extrapolated to ``now`` (s) on copies; ``now`` <= t gives the
        filter's own state. Requires an initialised track."""
        assert self.t is not None
        if self.is_cached(now):
            c = self._cache
            return c[2].copy(), c[3].copy()  # type: ignore[index]
        segs = self.segments(self.t, now)
        if not segs:
            x, P = self.x, self.P
        else:
            x, P = self.strategy.propagate(
                self.model, self.x, self.P, segs, self.tau, self.q_lin, self.q_yaw
            )
        self._cache = (now, self._version, x, P)
        return x.copy(), P.copy()

    def stale(self, now: float, stale_after: float) -> bool:
        """True when no measurement was accepted in the last ``stale_after`` seconds."""
        return self.t_accepted is None or now - self.t_accepted > stale_after


MAX_COMMANDS = 24  # commands kept past the filter's timeline before it is time-updated
MAX_GAP = 5.0  # s, longest gap ever integrated (older time is skipped: the track is stale)
STATUS_ACCEPTED = "accepted"
STATUS_REJECTED = "rejected"
STATUS_OUT_OF_ORDER = "out_of_order"
STATUS_INITIALIZED = "initialized"
