"""Kalman-filtered pose feedback: per-robot and object filters (filterpy EKF or UKF).

Two layers:

* **Pure filter math** (module functions): motion models with their Jacobians, process noise
  rebuilt for any ``dt``, angle-aware residuals and means, the chi-squared gate and the
  extrapolation of a mean and covariance to a later time. Arrays in, arrays out, no state.
* **A thin stateful holder**, :class:`FleetEstimator`, that keeps one filterpy filter per robot
  and one for the object, each on its own timeline (the stamp of the last measurement it
  processed), and answers queries at a control tick by extrapolating copies.

State vectors (SI units, world frame x east, y north, theta CCW in radians):

* ``omni``:   (x, y, theta, u, v, w)  - u, v are the **body-frame** velocities (forward, left)
* ``diff``:   (x, y, theta, v, w)     - v forward speed; no lateral velocity
* ``object``: (x, y, theta, vx, vy, w) - constant velocity, **world-frame** vx, vy

Robot velocities are kept in the body frame because that is where the control input lives: the
last body-frame command ``c`` sent to the robot drives the velocity states through a first-order
lag, ``dv/dt = (c - v) / command_tau``, with white acceleration noise on top (``process_accel``,
``process_yaw_accel``). Commands are kept with their time stamps, so a prediction across an
interval uses the command that was active in each part of it. Estimates report world-frame
velocities.

Object while alive: constant velocity (a random walk on the world velocity) with
``object_process_accel``. After the arrest event (``set_object_arrested(True)``) it no longer
moves by itself: it keeps the random walk, with ``object_arrested_accel`` (tighter by default: a
held object moves only as fast as the formation's slow, smooth transport commands). If the
runtime also reports the push it commands (``push_object(t, vx, vy, wz)``, world frame, e.g. the
object twist the transport planner asks of the formation), the arrested object's velocity follows
that push through the same first-order lag as a robot's (``command_tau``); a push of zero lets it
come to rest. Without push reports it stays a pure random walk. Push reports are cleared when
the object is released.

Measurement: (x, y, theta) with noise (``meas_xy``, ``meas_theta``). A measurement's own stamp is
used; one not newer than the filter's timeline is dropped and counted (``out_of_order``). Each is
predicted to its stamp, then gated by the squared Mahalanobis distance of its innovation against
the chi-squared quantile (3 dof, ``gate_probability``) computed without touching the filter;
rejected ones are counted. ``reacquire_after`` consecutive rejections that agree with each other
(each within a few noise sigmas plus what ``init_sigma_speed``/``init_sigma_yaw_rate`` allow of
the one before) re-initialise the track from the latest measurement: a robot that was really
moved, or a filter that lost it. Scattered outliers never agree, so they never re-initialise.

A rejected measurement still moves the timeline to its stamp (the filter holds the prior there,
which is a valid state); a non-finite one is rejected without touching the filter.

Latency: ``robot_estimate(now)``, ``robot_arrays(now)`` and ``object_estimate(now)`` predict
copies of the mean and covariance from the filter's timeline to ``now`` (cached per ``now``);
the filter itself stays at its last measurement. Staleness: a track with no *accepted*
measurement for more than ``stale_after`` seconds is stale. Before its first measurement a
track is stale, not initialised, and its pose is NaN (sigmas inf): never publish or plan on it.

UKF: filterpy's ``UnscentedKalmanFilter`` with ``residual_x``/``residual_z``/``x_mean_fn``/
``z_mean_fn`` set to the angle-aware functions, and its sigma points, propagation, unscented
transform and cross-covariance done as vectorised numpy (same maths as filterpy's loops, checked
against them in the tests). EKF: filterpy's ``ExtendedKalmanFilter`` with the nonlinear motion
model and its Jacobian, the Joseph-form update and a wrapped residual.

The holder logs only on changes (a track starts or stops rejecting, re-acquires, turns stale or
fresh), never per tick.
"""

from __future__ import annotations

import bisect
import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

from controller.config import EstimationSection

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

ROBOT_MODELS = ("omni", "diff")
MODELS = ("omni", "diff", "object")
STATE_DIM = {"omni": 6, "diff": 5, "object": 6}
COMMAND_DIM = {"omni": 3, "diff": 2, "object": 3}
YAW_RATE_INDEX = {"omni": 5, "diff": 4, "object": 5}
MEAS_DIM = 3
THETA = 2
REJECT_EPISODE = 3  # consecutive rejections logged as a rejection episode (isolated: counted)
MAX_COMMANDS = 24  # commands kept past the filter's timeline before it is time-updated
MAX_SUBSTEP = 0.05  # s, longest step of the motion integration (a dropout is cut into these)
MAX_GAP = 5.0  # s, longest gap ever integrated (older time is skipped: the track is stale)

# Sigma points: alpha=1, kappa=0 gives non-negative weights (the covariance sum stays PSD).
UKF_ALPHA, UKF_BETA, UKF_KAPPA = 1.0, 2.0, 0.0

STATUS_ACCEPTED = "accepted"
STATUS_REJECTED = "rejected"
STATUS_OUT_OF_ORDER = "out_of_order"
STATUS_INITIALIZED = "initialized"

_TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------- angles


def wrap(a: Any) -> Any:
    """Wrap an angle or an array of angles (rad) into [-pi, pi)."""
    if np.isscalar(a):
        return _wrap(float(a))  # type: ignore[arg-type]
    return (np.asarray(a, dtype=float) + math.pi) % _TWO_PI - math.pi


def _wrap(a: float) -> float:
    return (a + math.pi) % _TWO_PI - math.pi


def residual(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """``a - b`` for a state or measurement vector (any trailing shape), heading (index 2) wrapped.

    Used as filterpy's ``residual_x``, ``residual_z`` and the EKF's ``residual``.
    """
    d = np.subtract(a, b, dtype=float)
    d[THETA] = (d[THETA] + math.pi) % _TWO_PI - math.pi
    return d


def weighted_mean(sigmas: ArrayLike, weights: ArrayLike) -> FloatArray:
    """Weighted mean of sigma points (rows) with the heading (column 2) as a circular mean.

    Used as filterpy's ``x_mean_fn`` and ``z_mean_fn``.
    """
    s = np.asarray(sigmas, dtype=float)
    w = np.asarray(weights, dtype=float)
    m = w @ s
    m[THETA] = math.atan2(float(w @ np.sin(s[:, THETA])), float(w @ np.cos(s[:, THETA])))
    return m


def _sym(P: FloatArray) -> FloatArray:
    return 0.5 * (P + P.T)


def _is_pd(P: FloatArray) -> bool:
    """Whether a covariance has a Cholesky factor (is positive definite)."""
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return False
    return bool(np.all(np.isfinite(P)))


# --------------------------------------------------------------------------- models


def motion(
    model: str,
    x: ArrayLike,
    dt: float,
    u: ArrayLike | None = None,
    tau: float = 0.15,
    jacobian: bool = True,
) -> tuple[FloatArray, FloatArray | None]:
    """Propagate a state ``dt`` seconds ahead under a constant control input.

    Args:
        model: "omni", "diff" or "object" (see the module docstring for the state layouts).
        x: state vector.
        dt: time step (s), >= 0; integrated in sub-steps of at most ``MAX_SUBSTEP``.
        u: body-frame command (vx m/s, vy m/s, wz rad/s) for omni, (vx, wz) for diff; for
            "object" the world-frame push velocity (vx, vy, wz) of an arrested object. ``None``
            means a zero command for robots and constant velocity for the object.
        tau: time constant (s) with which a robot's velocity follows the command.
        jacobian: also return the Jacobian dF/dx (EKF); skip it for the UKF's sigma points.

    Returns:
        The new state (heading wrapped) and the Jacobian (or ``None``).
    """
    s = np.ravel(np.asarray(x, dtype=float)).tolist()
    n = len(s)
    F = np.eye(n) if jacobian else None
    if dt <= 0.0:
        return np.array(s), F
    steps = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
    h = dt / steps
    if model == "object":
        if u is None:  # constant velocity
            s[0] += dt * s[3]
            s[1] += dt * s[4]
            s[2] = _wrap(s[2] + dt * s[5])
            if F is not None:
                F[0, 3] = F[1, 4] = F[2, 5] = dt
            return np.array(s), F
        # Pushed: the world-frame velocity follows the commanded push velocity (linear model).
        a = math.exp(-dt / tau)
        beta = tau / dt * (1.0 - a)
        for k in range(3):
            c = float(u[k])  # type: ignore[index]
            v0 = s[3 + k]
            s[k] += dt * (beta * v0 + (1.0 - beta) * c)
            s[3 + k] = a * v0 + (1.0 - a) * c
            if F is not None:
                F[k, 3 + k] = dt * beta
                F[3 + k, 3 + k] = a
        s[2] = _wrap(s[2])
        return np.array(s), F
    omni = model == "omni"
    if not omni and model != "diff":
        raise ValueError(f"unknown motion model {model!r}; expected one of {MODELS}")
    if u is None:
        cu, cv, cw = 0.0, 0.0, 0.0
    elif omni:
        cu, cv, cw = (float(c) for c in u)
    else:
        cu, cw = (float(c) for c in u)
        cv = 0.0
    a = math.exp(-h / tau)  # velocity memory over one sub-step
    beta = tau / h * (1.0 - a)  # share of the initial velocity in the sub-step's mean velocity
    iw = 5 if omni else 4
    Fs: FloatArray | None = None
    for _ in range(steps):
        th = s[2]
        u0 = s[3]
        v0 = s[4] if omni else 0.0
        w0 = s[iw]
        ua = beta * u0 + (1.0 - beta) * cu
        va = beta * v0 + (1.0 - beta) * cv
        wa = beta * w0 + (1.0 - beta) * cw
        thm = th + 0.5 * wa * h
        c, sn = math.cos(thm), math.sin(thm)
        dpx = h * (c * ua - sn * va)
        dpy = h * (sn * ua + c * va)
        s[0] += dpx
        s[1] += dpy
        s[2] = _wrap(th + wa * h)
        s[3] = a * u0 + (1.0 - a) * cu
        if omni:
            s[4] = a * v0 + (1.0 - a) * cv
        s[iw] = a * w0 + (1.0 - a) * cw
        if F is not None:
            J = np.eye(n)
            J[0, 2] = -dpy
            J[1, 2] = dpx
            J[0, 3] = h * c * beta
            J[1, 3] = h * sn * beta
            if omni:
                J[0, 4] = -h * sn * beta
                J[1, 4] = h * c * beta
                J[4, 4] = a
            J[0, iw] = -dpy * beta * h * 0.5
            J[1, iw] = dpx * beta * h * 0.5
            J[2, iw] = beta * h
            J[3, 3] = a
            J[iw, iw] = a
            Fs = J if Fs is None else J @ Fs
    return np.array(s), Fs


def motion_batch(
    model: str,
    X: ArrayLike,
    dt: float,
    u: ArrayLike | None = None,
    tau: float = 0.15,
) -> FloatArray:
    """:func:`motion` for many states at once (rows of X, e.g. a UKF's sigma points)."""
    S = np.array(X, dtype=float)
    if dt <= 0.0:
        return S
    if model == "object":
        if u is None:
            S[:, :3] += dt * S[:, 3:6]
        else:
            a = math.exp(-dt / tau)
            beta = tau / dt * (1.0 - a)
            c = np.asarray(u, dtype=float)
            S[:, :3] += dt * (beta * S[:, 3:6] + (1.0 - beta) * c)
            S[:, 3:6] = a * S[:, 3:6] + (1.0 - a) * c
        S[:, 2] = (S[:, 2] + math.pi) % _TWO_PI - math.pi
        return S
    omni = model == "omni"
    if not omni and model != "diff":
        raise ValueError(f"unknown motion model {model!r}; expected one of {MODELS}")
    if u is None:
        cu, cv, cw = 0.0, 0.0, 0.0
    elif omni:
        cu, cv, cw = (float(c) for c in u)  # type: ignore[union-attr]
    else:
        cu, cw = (float(c) for c in u)  # type: ignore[union-attr]
        cv = 0.0
    steps = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
    h = dt / steps
    a = math.exp(-h / tau)
    beta = tau / h * (1.0 - a)
    iw = 5 if omni else 4
    for _ in range(steps):
        u0 = S[:, 3].copy()
        v0 = S[:, 4].copy() if omni else 0.0
        w0 = S[:, iw].copy()
        ua = beta * u0 + (1.0 - beta) * cu
        va = beta * v0 + (1.0 - beta) * cv
        wa = beta * w0 + (1.0 - beta) * cw
        thm = S[:, 2] + 0.5 * wa * h
        c, sn = np.cos(thm), np.sin(thm)
        S[:, 0] += h * (c * ua - sn * va)
        S[:, 1] += h * (sn * ua + c * va)
        S[:, 2] = (S[:, 2] + wa * h + math.pi) % _TWO_PI - math.pi
        S[:, 3] = a * u0 + (1.0 - a) * cu
        if omni:
            S[:, 4] = a * v0 + (1.0 - a) * cv
        S[:, iw] = a * w0 + (1.0 - a) * cw
    return S


def unscented_transform_wrapped(
    sigmas: ArrayLike,
    Wm: ArrayLike,
    Wc: ArrayLike,
    noise_cov: ArrayLike | None = None,
    mean_fn: Any = None,  # noqa: ARG001 - filterpy's UT signature; the heading is always circular
    residual_fn: Any = None,  # noqa: ARG001
) -> tuple[FloatArray, FloatArray]:
    """filterpy's unscented transform, vectorised, with column 2 (heading) treated as an angle:
    circular weighted mean and wrapped deviations. Drop-in ``UT`` for filterpy's UKF."""
    sg = np.asarray(sigmas, dtype=float)
    x = weighted_mean(sg, Wm)
    y = sg - x
    y[:, THETA] = (y[:, THETA] + math.pi) % _TWO_PI - math.pi
    P = (y.T * np.asarray(Wc)) @ y
    if noise_cov is not None:
        P = P + noise_cov
    return x, P


def process_noise(model: str, theta: float, dt: float, q_lin: float, q_yaw: float) -> FloatArray:
    """Discretised continuous white-acceleration process noise Q for a step of ``dt`` seconds.

    Args:
        model: "omni", "diff" or "object".
        theta: heading (rad) at the start of the step (rotates the body-frame velocity blocks).
        dt: step (s).
        q_lin: linear acceleration spectral density ((m/s^2)^2 s), e.g. ``process_accel**2``.
        q_yaw: yaw acceleration spectral density ((rad/s^2)^2 s).

    Returns:
        Symmetric positive semi-definite Q (positive definite for dt > 0).
    """
    n = STATE_DIM[model]
    Q = np.zeros((n, n))
    d1, d2, d3 = dt, dt * dt / 2.0, dt**3 / 3.0
    Q[0, 0] = Q[1, 1] = q_lin * d3
    iw = YAW_RATE_INDEX[model]
    Q[2, 2] = q_yaw * d3
    Q[2, iw] = Q[iw, 2] = q_yaw * d2
    Q[iw, iw] = q_yaw * d1
    if model == "object":
        Q[0, 3] = Q[3, 0] = Q[1, 4] = Q[4, 1] = q_lin * d2
        Q[3, 3] = Q[4, 4] = q_lin * d1
        return Q
    c, s = math.cos(theta), math.sin(theta)
    # cov(world position, body velocity) = R(theta) * q * dt^2 / 2
    Q[0, 3] = Q[3, 0] = q_lin * d2 * c
    Q[1, 3] = Q[3, 1] = q_lin * d2 * s
    Q[3, 3] = q_lin * d1
    if model == "omni":
        Q[0, 4] = Q[4, 0] = -q_lin * d2 * s
        Q[1, 4] = Q[4, 1] = q_lin * d2 * c
        Q[4, 4] = q_lin * d1
    return Q


def world_velocity(model: str, x: ArrayLike) -> FloatArray:
    """World-frame (vx, vy, wz) of a state vector (m/s, m/s, rad/s)."""
    s = np.asarray(x, dtype=float)
    if model == "object":
        return s[3:6].copy()
    c, sn = math.cos(s[2]), math.sin(s[2])
    u = s[3]
    v = s[4] if model == "omni" else 0.0
    return np.array([c * u - sn * v, sn * u + c * v, s[YAW_RATE_INDEX[model]]])


# --------------------------------------------------------------------------- gating


def linear_update(
    x: ArrayLike, P: ArrayLike, z: ArrayLike, R: ArrayLike, H: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """The Kalman update for the linear pose measurement (heading residual wrapped), Joseph
    form so the result stays symmetric positive definite."""
    xs = np.ravel(np.asarray(x, dtype=float))
    Pm = np.asarray(P, dtype=float)
    Hm = np.asarray(H, dtype=float)
    y, S = innovation_linear(xs, Pm, z, R)
    K = np.linalg.solve(S, Hm @ Pm).T
    IKH = np.eye(len(xs)) - K @ Hm
    return xs + K @ y, _sym(IKH @ Pm @ IKH.T + K @ np.asarray(R) @ K.T)


def gate_threshold(probability: float, dof: int = MEAS_DIM) -> float:
    """Chi-squared quantile for the gate; ``probability >= 1`` disables gating (inf)."""
    if probability >= 1.0:
        return math.inf
    return float(chi2.ppf(probability, dof))


def innovation_linear(
    x: ArrayLike, P: ArrayLike, z: ArrayLike, R: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Innovation y = z - Hx (heading wrapped) and its covariance S = H P H^T + R, H = [I3 0]."""
    xs = np.ravel(x)
    y = residual(np.ravel(z), xs[:MEAS_DIM])
    S = np.asarray(P)[:MEAS_DIM, :MEAS_DIM] + R
    return y, S


def innovation_unscented(
    sigmas: ArrayLike,
    Wm: ArrayLike,
    Wc: ArrayLike,
    z: ArrayLike,
    R: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Innovation and its covariance from a UKF's prior sigma points (unscented transform)."""
    zs = np.asarray(sigmas)[:, :MEAS_DIM]
    zp, S = unscented_transform_wrapped(zs, Wm, Wc, R)
    return residual(np.ravel(z), zp), S


def mahalanobis2(y: ArrayLike, S: ArrayLike) -> float:
    """Squared Mahalanobis distance y^T S^-1 y."""
    yv = np.ravel(y)
    return float(yv @ np.linalg.solve(S, yv))


# --------------------------------------------------------------------------- extrapolation

Segment = tuple[float, FloatArray | None]  # (duration s, command or None)


def propagate_ekf(
    model: str,
    x: ArrayLike,
    P: ArrayLike,
    segments: Iterable[Segment],
    tau: float,
    q_lin: float,
    q_yaw: float,
) -> tuple[FloatArray, FloatArray]:
    """Linearised (EKF) propagation of a mean and covariance through piecewise-constant commands."""
    xs = np.ravel(np.asarray(x, dtype=float)).copy()
    Ps = np.array(P, dtype=float)
    for h, u in segments:
        Q = process_noise(model, xs[THETA], h, q_lin, q_yaw)
        xs, F = motion(model, xs, h, u, tau)
        Ps = F @ Ps @ F.T + Q
    return xs, _sym(Ps)


def propagate_ukf(
    model: str,
    x: ArrayLike,
    P: ArrayLike,
    segments: Iterable[Segment],
    tau: float,
    q_lin: float,
    q_yaw: float,
    points: MerweScaledSigmaPoints,
) -> tuple[FloatArray, FloatArray]:
    """Unscented propagation of a mean and covariance through piecewise-constant commands."""
    xs = np.ravel(np.asarray(x, dtype=float)).copy()
    Ps = np.array(P, dtype=float)
    for h, u in segments:
        Q = process_noise(model, xs[THETA], h, q_lin, q_yaw)
        sig = points.sigma_points(xs, Ps)
        f = motion_batch(model, sig, h, u, tau)
        x1, P1 = unscented_transform_wrapped(f, points.Wm, points.Wc, Q)
        P1 = _sym(P1)
        if not _is_pd(P1):
            # sigma points spread past ±π in heading wrap around and the negative central
            # weight can leave an indefinite covariance: take the linearised step instead
            x1, P1 = propagate_ekf(model, xs, Ps, [(h, u)], tau, q_lin, q_yaw)
        xs, Ps = x1, P1
    return xs, Ps


# --------------------------------------------------------------------------- filterpy wrappers


class _PoseEKF(ExtendedKalmanFilter):
    """filterpy's EKF with the nonlinear motion model supplied through ``predict_x``."""

    def predict_nonlinear(self, x_next: FloatArray, F: FloatArray, Q: FloatArray) -> None:
        self._x_next = x_next.reshape(-1, 1)
        self.F = F
        self.Q = Q
        self.predict()

    def predict_x(self, u: Any = 0) -> None:  # noqa: ARG002 - filterpy's signature
        self.x = self._x_next


class PoseSigmaPoints(MerweScaledSigmaPoints):
    """filterpy's Merwe scaled sigma points, computed in one vectorised step, heading wrapped.

    Same points as the parent with ``subtract=residual`` (rows of the upper Cholesky factor of
    (lambda + n) P added to and subtracted from x)."""

    def __init__(self, n: int, alpha: float, beta: float, kappa: float):
        super().__init__(n, alpha, beta, kappa, subtract=residual)
        self._scale = alpha**2 * (n + kappa)  # lambda + n

    def sigma_points(self, x: ArrayLike, P: ArrayLike) -> FloatArray:
        xv = np.ravel(np.asarray(x, dtype=float))
        U = np.linalg.cholesky(self._scale * np.asarray(P, dtype=float)).T  # upper, as scipy's
        sig = np.empty((2 * self.n + 1, self.n))
        sig[0] = xv
        sig[1 : self.n + 1] = xv + U
        sig[self.n + 1 :] = xv - U
        sig[:, THETA] = (sig[:, THETA] + math.pi) % _TWO_PI - math.pi
        return sig


class _PoseUKF(UnscentedKalmanFilter):
    """filterpy's UKF with the sigma points propagated as one batch and a vectorised
    angle-aware unscented transform (same maths as filterpy's loops, ~3x less overhead)."""

    model = "omni"
    tau = 0.15

    def compute_process_sigmas(self, dt: float, fx: Any = None, **fx_args: Any) -> None:
        sigmas = self.points_fn.sigma_points(self.x, self.P)
        self.sigmas_f = motion_batch(self.model, sigmas, dt, fx_args.get("u"), self.tau)

    def predict(self, dt: float | None = None, UT: Any = None, fx: Any = None, **fx_args: Any):
        super().predict(dt, UT or unscented_transform_wrapped, fx, **fx_args)

    def update(self, z: Any, R: Any = None, UT: Any = None, hx: Any = None, **hx_args: Any):
        super().update(z, R, UT or unscented_transform_wrapped, hx, **hx_args)

    def cross_variance(self, x: Any, z: Any, sigmas_f: Any, sigmas_h: Any) -> FloatArray:
        dx = np.asarray(sigmas_f) - x
        dx[:, THETA] = (dx[:, THETA] + math.pi) % _TWO_PI - math.pi
        dz = np.asarray(sigmas_h) - z
        dz[:, THETA] = (dz[:, THETA] + math.pi) % _TWO_PI - math.pi
        return (dx.T * self.Wc) @ dz


def _hx(x: FloatArray) -> FloatArray:
    return np.asarray(x)[:MEAS_DIM]


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
        if filter_name not in ("ekf", "ukf"):
            raise ValueError(f"unknown filter {filter_name!r}; expected 'ekf' or 'ukf'")
        self.model = model
        self.filter_name = filter_name
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
        self.points: MerweScaledSigmaPoints | None = None
        if filter_name == "ekf":
            self.kf: Any = _PoseEKF(self.n, MEAS_DIM)
        else:
            self.points = PoseSigmaPoints(self.n, UKF_ALPHA, UKF_BETA, UKF_KAPPA)
            self.kf = _PoseUKF(
                self.n,
                MEAS_DIM,
                MAX_SUBSTEP,
                _hx,
                self._fx,
                self.points,
                x_mean_fn=weighted_mean,
                z_mean_fn=weighted_mean,
                residual_x=residual,
                residual_z=residual,
            )
            self.kf.model = model
            self.kf.tau = self.tau
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
        self._version += 1
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
        x0[THETA] = _wrap(float(z[THETA]))
        u = self._command_at(t)
        if u is not None and self.model != "object":
            x0[3:] = u  # start from the commanded velocity
        sv, sw = self.init_sigma_speed**2, self.init_sigma_yaw_rate**2
        P0 = np.zeros((self.n, self.n))
        P0[:MEAS_DIM, :MEAS_DIM] = self.R
        for k in range(MEAS_DIM, self.n):
            P0[k, k] = sv
        P0[YAW_RATE_INDEX[self.model], YAW_RATE_INDEX[self.model]] = sw
        if self.filter_name == "ekf":
            self.kf.x = x0.reshape(-1, 1)
        else:
            self.kf.x = x0
        self.kf.P = P0
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
            dth = abs(_wrap(float(z[THETA] - z0[THETA])))
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
            x = self.x
            Q = process_noise(self.model, x[THETA], h, self.q_lin, self.q_yaw)
            if self.filter_name == "ekf":
                x1, F = motion(self.model, x, h, u, self.tau)
                self.kf.predict_nonlinear(x1, F, Q)
            else:
                P0 = self.kf.P.copy()
                self.kf.Q = Q
                self.kf.predict(dt=h, u=u)
                if not _is_pd(_sym(self.kf.P)):
                    # heading sigma points wrapped past ±π: the linearised step instead (the
                    # sigma points for the update are drawn again from the repaired prior)
                    x1, P1 = propagate_ekf(self.model, x, P0, [(h, u)], self.tau, self.q_lin,
                                           self.q_yaw)  # fmt: skip
                    self.kf.x, self.kf.P = x1, P1
                    self.kf.sigmas_f = self.points.sigma_points(x1, P1)
            self.kf.P = _sym(self.kf.P)
        self.t = t

    def innovation(self, z: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Innovation and its covariance for z against the filter's current prior (no mutation)."""
        if self.filter_name == "ekf":
            return innovation_linear(self.x, self.kf.P, z, self.R)
        return innovation_unscented(self.kf.sigmas_f, self.kf.Wm, self.kf.Wc, z, self.R)

    def measure(self, t: float, z: ArrayLike) -> str:
        """Process a pose measurement (x m, y m, theta rad) stamped t (s); returns a status."""
        zv = np.array(np.ravel(z), dtype=float)
        self._version += 1
        self.just_reacquired = False
        if zv.shape != (MEAS_DIM,) or not (np.all(np.isfinite(zv)) and math.isfinite(t)):
            self.rejected += 1  # garbage never touches the filter
            self.invalid += 1
            return STATUS_REJECTED
        zv[THETA] = _wrap(float(zv[THETA]))
        if self.t is None:
            self._initialize(t, zv)
            self._prune_commands()
            return STATUS_INITIALIZED
        if t <= self.t:
            self.out_of_order += 1
            return STATUS_OUT_OF_ORDER
        try:
            self._predict_filter(t)
            y, S = self.innovation(zv)
            self.last_d2 = mahalanobis2(y, S)
        except np.linalg.LinAlgError:  # covariance lost definiteness: start over from z
            self.reacquired += 1
            self.just_reacquired = True
            self._initialize(t, zv)
            self._prune_commands()
            return STATUS_INITIALIZED
        if not self.last_d2 <= self.threshold:
            self.rejected += 1
            self.consecutive_rejected += 1
            if self._extend_run(t, zv) >= self.reacquire_after:
                self.reacquired += 1
                self.just_reacquired = True
                self._initialize(t, zv)
                self._prune_commands()
                return STATUS_INITIALIZED
            self._prune_commands()
            return STATUS_REJECTED
        if self.filter_name == "ekf":
            H = self._H
            self.kf.update(zv.reshape(-1, 1), lambda _x: H, _hx, R=self.R, residual=residual)
            self.kf.x[THETA, 0] = _wrap(float(self.kf.x[THETA, 0]))
        else:
            x_prior, P_prior = self.kf.x.copy(), self.kf.P.copy()
            self.kf.update(zv, R=self.R)
            if not _is_pd(_sym(self.kf.P)):
                # wrapped heading sigma points spoiled the cross-covariance; the measurement is
                # linear (H = [I3 0]), so the Kalman update on the same prior is exact
                self.kf.x, self.kf.P = linear_update(x_prior, P_prior, zv, self.R, self._H)
            self.kf.x[THETA] = _wrap(float(self.kf.x[THETA]))
        self.kf.P = _sym(self.kf.P)
        self.accepted += 1
        self.consecutive_rejected = 0
        self._run.clear()
        self.t_accepted = t
        self._prune_commands()
        return STATUS_ACCEPTED

    # ---- queries

    def state_at(self, now: float) -> tuple[FloatArray, FloatArray]:
        """Mean and covariance extrapolated to ``now`` (s) on copies; ``now`` <= t gives the
        filter's own state. Requires an initialised track."""
        assert self.t is not None
        c = self._cache
        if c is not None and c[0] == now and c[1] == self._version:
            return c[2].copy(), c[3].copy()
        segs = self.segments(self.t, now)
        if not segs:
            x, P = self.x, self.P
        elif self.filter_name == "ekf":
            x, P = propagate_ekf(self.model, self.x, self.P, segs, self.tau, self.q_lin, self.q_yaw)
        else:
            assert self.points is not None
            try:
                x, P = propagate_ukf(
                    self.model, self.x, self.P, segs, self.tau, self.q_lin, self.q_yaw, self.points
                )
            except np.linalg.LinAlgError:  # no sigma points without a Cholesky factor
                x, P = propagate_ekf(
                    self.model, self.x, self.P, segs, self.tau, self.q_lin, self.q_yaw
                )
        self._cache = (now, self._version, x, P)
        return x.copy(), P.copy()

    def stale(self, now: float, stale_after: float) -> bool:
        """True when no measurement was accepted in the last ``stale_after`` seconds."""
        return self.t_accepted is None or now - self.t_accepted > stale_after


# --------------------------------------------------------------------------- holder


@dataclass(frozen=True)
class RobotEstimate:
    """A robot's filtered state at time ``t`` (s): pose (m, m, rad), world velocities (m/s,
    m/s, rad/s), 1-sigma uncertainties (sigma_xy: largest axis of the position ellipse, m;
    sigma_theta: rad), and the filter's bookkeeping. Before the first measurement the pose and
    velocities are NaN, the sigmas inf, ``initialized`` False and ``stale`` True."""

    robot_id: str
    t: float
    x: float
    y: float
    theta: float
    vx: float
    vy: float
    wz: float
    sigma_xy: float
    sigma_theta: float
    stale: bool
    rejected: int
    out_of_order: int
    initialized: bool
    accepted: int = 0
    reacquired: int = 0


@dataclass(frozen=True)
class ObjectEstimate:
    """The object's filtered state at ``t`` (s); fields as in :class:`RobotEstimate`."""

    t: float
    x: float
    y: float
    theta: float
    vx: float
    vy: float
    wz: float
    sigma_xy: float
    sigma_theta: float
    stale: bool
    arrested: bool
    rejected: int
    out_of_order: int
    initialized: bool
    accepted: int = 0
    reacquired: int = 0


def _sigmas(P: FloatArray) -> tuple[float, float]:
    pxy = P[:2, :2]
    tr = 0.5 * (pxy[0, 0] + pxy[1, 1])
    det = pxy[0, 0] * pxy[1, 1] - pxy[0, 1] * pxy[1, 0]
    lam = tr + math.sqrt(max(tr * tr - det, 0.0))
    return math.sqrt(max(lam, 0.0)), math.sqrt(max(P[THETA, THETA], 0.0))


_NAN_STATE = (math.nan,) * 6


class FleetEstimator:
    """One filter per robot plus one for the object; the runtime's view of the world.

    Args:
        robots: (robot_id, kind) pairs, kind "omni" or "diff"; the order of ``robot_arrays``.
        params: the ``[estimation]`` config section.
        stale_after: seconds without an accepted measurement before a track is stale
            (``fleet.stale_after``).
    """

    def __init__(
        self,
        robots: Sequence[tuple[str, str]],
        params: EstimationSection,
        stale_after: float,
    ):
        if not stale_after > 0:
            raise ValueError(f"stale_after must be > 0 s, got {stale_after!r}")
        self.params = params
        self.stale_after = float(stale_after)
        self.ids: tuple[str, ...] = tuple(rid for rid, _ in robots)
        self._tracks: dict[str, TrackFilter] = {}
        for rid, kind in robots:
            if kind not in ROBOT_MODELS:
                raise ValueError(f"robot {rid!r}: unknown kind {kind!r}; expected {ROBOT_MODELS}")
            if rid in self._tracks:
                raise ValueError(f"robot {rid!r} listed twice")
            self._tracks[rid] = TrackFilter(
                kind, params.filter, params, params.process_accel**2, params.process_yaw_accel**2
            )
        self._object = self._make_object_track(arrested=False)
        self._arrested = False
        self._was_rejecting: dict[str, bool] = {}
        self._was_stale: dict[str, bool] = {}

    def _make_object_track(self, arrested: bool) -> TrackFilter:
        p = self.params
        acc = p.object_arrested_accel if arrested else p.object_process_accel
        # Yaw noise scaled like the linear one relative to the robots' ratio.
        yaw = acc * p.process_yaw_accel / p.process_accel
        return TrackFilter("object", p.filter, p, acc**2, yaw**2)

    def _track(self, robot_id: str) -> TrackFilter:
        try:
            return self._tracks[robot_id]
        except KeyError:
            raise KeyError(f"unknown robot id {robot_id!r}; known: {list(self.ids)}") from None

    # ---- inputs

    def command(self, robot_id: str, t: float, vx: float, vy: float, wz: float) -> None:
        """Record the body-frame command (m/s, m/s, rad/s) sent to a robot at t (s).

        A differential robot's vy is ignored (it cannot move sideways).
        """
        tr = self._track(robot_id)
        u = (vx, vy, wz) if tr.model == "omni" else (vx, wz)
        try:
            tr.command(t, u)
        except ValueError as e:
            raise ValueError(f"robot {robot_id!r}: {e}") from None

    def measure_robot(self, robot_id: str, t: float, x: float, y: float, theta: float) -> str:
        """Feed a robot's pose measurement (m, m, rad) stamped t (s).

        Returns "accepted", "rejected", "out_of_order" or "initialized".
        """
        tr = self._track(robot_id)
        status = tr.measure(t, (x, y, theta))
        self._note_gate(robot_id, tr, status)
        return status

    def measure_object(self, t: float, x: float, y: float, theta: float) -> str:
        """Feed the object's pose measurement (m, m, rad) stamped t (s); returns a status."""
        status = self._object.measure(t, (x, y, theta))
        self._note_gate("object", self._object, status)
        return status

    def set_object_arrested(self, arrested: bool) -> None:
        """Switch the object's model between live and arrested (keeps its state; see the
        module docstring). Releasing it forgets the push reports."""
        arrested = bool(arrested)
        if arrested == self._arrested:
            return
        p = self.params
        acc = p.object_arrested_accel if arrested else p.object_process_accel
        self._object.q_lin = acc**2
        self._object.q_yaw = (acc * p.process_yaw_accel / p.process_accel) ** 2
        if not arrested:
            self._object.clear_commands()
        self._object._version += 1
        self._arrested = arrested
        log.info("object filter: %s model", "arrested" if arrested else "live")

    def push_object(self, t: float, vx: float, vy: float, wz: float) -> None:
        """Optional: the world-frame push velocity (m/s, m/s, rad/s) commanded for the arrested
        object from time t (s) on. Ignored while the object is not arrested."""
        if self._arrested:
            self._object.command(t, (vx, vy, wz))

    # ---- outputs

    def robot_estimate(self, robot_id: str, now: float) -> RobotEstimate:
        """A robot's estimate predicted to ``now`` (s) without moving its filter's timeline."""
        tr = self._track(robot_id)
        stale = tr.stale(now, self.stale_after)
        self._note_stale(robot_id, stale)
        if not tr.initialized:
            return RobotEstimate(
                robot_id, now, *_NAN_STATE, math.inf, math.inf, True, 0, tr.out_of_order, False
            )
        x, P = tr.state_at(now)
        v = world_velocity(tr.model, x)
        sxy, sth = _sigmas(P)
        return RobotEstimate(
            robot_id,
            max(now, tr.t or now),
            float(x[0]),
            float(x[1]),
            float(x[2]),
            float(v[0]),
            float(v[1]),
            float(v[2]),
            sxy,
            sth,
            stale,
            tr.rejected,
            tr.out_of_order,
            True,
            tr.accepted,
            tr.reacquired,
        )

    def robot_arrays(self, now: float) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Fleet state at ``now`` (s) in construction order: (N,3) poses (x, y, theta), (N,3)
        world velocities (vx, vy, wz) and an (N,) stale mask. Uninitialised robots are NaN."""
        n = len(self.ids)
        poses = np.full((n, 3), np.nan)
        vels = np.full((n, 3), np.nan)
        stale = np.ones(n, dtype=bool)
        for i, rid in enumerate(self.ids):
            tr = self._tracks[rid]
            stale[i] = tr.stale(now, self.stale_after)
            self._note_stale(rid, bool(stale[i]))
            if tr.initialized:
                x, _ = tr.state_at(now)
                poses[i] = x[:3]
                vels[i] = world_velocity(tr.model, x)
        return poses, vels, stale

    def object_estimate(self, now: float) -> ObjectEstimate:
        """The object's estimate predicted to ``now`` (s)."""
        return self._object_at(now, now)

    def predict_object(self, now: float, horizon: float) -> ObjectEstimate:
        """The object's pose predicted ``horizon`` seconds after ``now`` (constant velocity);
        ``stale`` is judged at ``now``."""
        return self._object_at(now, now + max(0.0, horizon))

    def _object_at(self, now: float, at: float) -> ObjectEstimate:
        tr = self._object
        stale = tr.stale(now, self.stale_after)
        self._note_stale("object", stale)
        if not tr.initialized:
            return ObjectEstimate(
                at,
                *_NAN_STATE,
                math.inf,
                math.inf,
                True,
                self._arrested,
                0,
                tr.out_of_order,
                False,
            )
        x, P = tr.state_at(at)
        sxy, sth = _sigmas(P)
        return ObjectEstimate(
            max(at, tr.t or at),
            *(float(v) for v in x[:6]),
            sxy,
            sth,
            stale,
            self._arrested,
            tr.rejected,
            tr.out_of_order,
            True,
            tr.accepted,
            tr.reacquired,
        )

    # ---- change logging (never per tick)

    def _note_gate(self, name: str, tr: TrackFilter, status: str) -> None:
        if status == STATUS_OUT_OF_ORDER:
            return
        # An isolated outlier is only counted; REJECT_EPISODE in a row start a logged episode.
        rejecting = status == STATUS_REJECTED and tr.consecutive_rejected >= REJECT_EPISODE
        was = self._was_rejecting.get(name, False)
        if was and status == STATUS_REJECTED:
            return
        if tr.just_reacquired:
            log.warning(
                "%s: re-acquired after %d consistent rejected measurements (d2=%.1f)",
                name,
                self.params.reacquire_after,
                tr.last_d2,
            )
            self._was_rejecting[name] = False
            return
        if rejecting and not was:
            log.warning(
                "%s: %d measurements in a row rejected by the gate (d2=%.1f > %.1f), %d so far",
                name,
                tr.consecutive_rejected,
                tr.last_d2,
                tr.threshold,
                tr.rejected,
            )
        elif was and not rejecting:
            log.info("%s: measurements accepted again (%d rejected so far)", name, tr.rejected)
        self._was_rejecting[name] = rejecting

    def _note_stale(self, name: str, stale: bool) -> None:
        was = self._was_stale.get(name)
        if was is None:
            self._was_stale[name] = stale
            return
        if stale != was:
            if stale:
                log.warning(
                    "%s: pose stale (no accepted measurement for %.2f s)", name, self.stale_after
                )
            else:
                log.info("%s: pose fresh", name)
            self._was_stale[name] = stale


__all__ = [
    "FleetEstimator",
    "ObjectEstimate",
    "RobotEstimate",
    "TrackFilter",
    "gate_threshold",
    "innovation_linear",
    "innovation_unscented",
    "mahalanobis2",
    "motion",
    "process_noise",
    "propagate_ekf",
    "propagate_ukf",
    "residual",
    "weighted_mean",
    "world_velocity",
    "wrap",
]
