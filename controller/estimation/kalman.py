"""Kalman filter math on filterpy: EKF/UKF propagation, innovation, the chi-squared gate.

Pure functions and thin filterpy subclasses (vectorised sigma points and unscented transform,
angle-aware residuals). Arrays in, arrays out; no state beyond the filter objects, no clock.
See the package docstring for the timeline, latency and staleness rules.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

from controller.config import FILTERS
from controller.estimation.models import (
    MAX_SUBSTEP,
    MEAS_DIM,
    THETA,
    motion,
    motion_batch,
    process_noise,
    residual,
    weighted_mean,
)
from controller.geometry import wrap_angle

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


# Sigma points: alpha=1, kappa=0 gives non-negative weights (the covariance sum stays PSD).
UKF_ALPHA, UKF_BETA, UKF_KAPPA = 1.0, 2.0, 0.0


# --------------------------------------------------------------------------- angles


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
    y[:, THETA] = wrap_angle(y[:, THETA])
    P = (y.T * np.asarray(Wc)) @ y
    if noise_cov is not None:
        P = P + noise_cov
    return x, P


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


Step = Callable[
    [str, FloatArray, FloatArray, float, "FloatArray | None", float, FloatArray],
    tuple[FloatArray, FloatArray],
]


def _ekf_step(
    model: str, x: FloatArray, P: FloatArray, h: float, u: FloatArray | None, tau: float,
    Q: FloatArray,
) -> tuple[FloatArray, FloatArray]:  # fmt: skip
    x1, F = motion(model, x, h, u, tau)
    return x1, F @ P @ F.T + Q


def _ukf_step(points: MerweScaledSigmaPoints) -> Step:
    """One unscented propagation step with these sigma points (linearised where it fails)."""

    def step(model, xs, Ps, h, u, tau, Q):
        sig = points.sigma_points(xs, Ps)
        f = motion_batch(model, sig, h, u, tau)
        x1, P1 = unscented_transform_wrapped(f, points.Wm, points.Wc, Q)
        P1 = _sym(P1)
        if not _is_pd(P1):
            # sigma points spread past ±π in heading wrap around and the negative central
            # weight can leave an indefinite covariance: take the linearised step instead
            return _ekf_step(model, xs, Ps, h, u, tau, Q)
        return x1, P1

    return step


def propagate(
    model: str,
    x: ArrayLike,
    P: ArrayLike,
    segments: Iterable[Segment],
    tau: float,
    q_lin: float,
    q_yaw: float,
    points: MerweScaledSigmaPoints | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Propagate a mean and covariance through piecewise-constant commands: linearised (EKF)
    without ``points``, unscented with them. Process noise is rebuilt for each segment's length
    and starting heading."""
    step = _ekf_step if points is None else _ukf_step(points)
    xs = np.ravel(np.asarray(x, dtype=float)).copy()
    Ps = np.array(P, dtype=float)
    for h, u in segments:
        Q = process_noise(model, xs[THETA], h, q_lin, q_yaw)
        xs, Ps = step(model, xs, Ps, h, u, tau, Q)
    return xs, _sym(Ps)


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
        sig[:, THETA] = wrap_angle(sig[:, THETA])
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
        dx[:, THETA] = wrap_angle(dx[:, THETA])
        dz = np.asarray(sigmas_h) - z
        dz[:, THETA] = wrap_angle(dz[:, THETA])
        return (dx.T * self.Wc) @ dz


def _hx(x: FloatArray) -> FloatArray:
    return np.asarray(x)[:MEAS_DIM]


# --------------------------------------------------------------------------- holder


# --------------------------------------------------------------------------- strategies


class EkfStrategy:
    """The EKF (``estimation.filter = "ekf"``): filterpy's ExtendedKalmanFilter with the
    nonlinear motion model and its Jacobian, the Joseph-form update and a wrapped residual."""

    name = "ekf"
    stacks = True  # FleetEstimator.measure_robots filters its robots together (estimation.batch)

    def make(self, model: str, n: int, tau: float, fx: Callable[..., FloatArray]) -> Any:
        return _PoseEKF(n, MEAS_DIM)

    def set_state(self, kf: Any, x: FloatArray, P: FloatArray) -> None:
        kf.x = np.asarray(x, dtype=float).reshape(-1, 1)
        kf.P = P

    def predict(
        self, kf: Any, model: str, h: float, u: FloatArray | None, tau: float, Q: FloatArray
    ) -> None:
        x1, F = motion(model, np.ravel(kf.x), h, u, tau)
        kf.predict_nonlinear(x1, F, Q)

    def innovation(self, kf: Any, z: FloatArray, R: FloatArray) -> tuple[FloatArray, FloatArray]:
        return innovation_linear(np.ravel(kf.x), kf.P, z, R)

    def update(self, kf: Any, z: FloatArray, R: FloatArray, H: FloatArray) -> None:
        kf.update(z.reshape(-1, 1), lambda _x: H, _hx, R=R, residual=residual)
        kf.x[THETA, 0] = wrap_angle(float(kf.x[THETA, 0]))

    def propagate(self, model, x, P, segs, tau, q_lin, q_yaw) -> tuple[FloatArray, FloatArray]:
        return propagate(model, x, P, segs, tau, q_lin, q_yaw)


class UkfStrategy:
    """The UKF (``estimation.filter = "ukf"``): filterpy's UnscentedKalmanFilter with Merwe
    sigma points (alpha 1, kappa 0), angle-aware means and residuals, vectorised propagation; a
    step that loses definiteness (heading sigma points wrapped past ±π) falls back to the exact
    linear update or the linearised prediction."""

    name = "ukf"
    stacks = False  # each track on its own (filterpy's UKF)

    def __init__(self) -> None:
        self._points: dict[int, PoseSigmaPoints] = {}

    def points(self, n: int) -> PoseSigmaPoints:
        if n not in self._points:
            self._points[n] = PoseSigmaPoints(n, UKF_ALPHA, UKF_BETA, UKF_KAPPA)
        return self._points[n]

    def make(self, model: str, n: int, tau: float, fx: Callable[..., FloatArray]) -> Any:
        kf = _PoseUKF(
            n,
            MEAS_DIM,
            MAX_SUBSTEP,
            _hx,
            fx,
            PoseSigmaPoints(n, UKF_ALPHA, UKF_BETA, UKF_KAPPA),
            x_mean_fn=weighted_mean,
            z_mean_fn=weighted_mean,
            residual_x=residual,
            residual_z=residual,
        )
        kf.model = model
        kf.tau = tau
        return kf

    def set_state(self, kf: Any, x: FloatArray, P: FloatArray) -> None:
        kf.x = np.asarray(x, dtype=float).copy()
        kf.P = P

    def predict(
        self, kf: Any, model: str, h: float, u: FloatArray | None, tau: float, Q: FloatArray
    ) -> None:
        x0, P0 = np.ravel(kf.x).copy(), kf.P.copy()
        kf.Q = Q
        kf.predict(dt=h, u=u)
        if not _is_pd(_sym(kf.P)):
            # heading sigma points wrapped past ±π: the linearised step instead (the sigma
            # points for the update are drawn again from the repaired prior)
            kf.x, kf.P = _ekf_step(model, x0, P0, h, u, tau, Q)
            kf.sigmas_f = kf.points_fn.sigma_points(kf.x, kf.P)

    def innovation(self, kf: Any, z: FloatArray, R: FloatArray) -> tuple[FloatArray, FloatArray]:
        return innovation_unscented(kf.sigmas_f, kf.Wm, kf.Wc, z, R)

    def update(self, kf: Any, z: FloatArray, R: FloatArray, H: FloatArray) -> None:
        x_prior, P_prior = kf.x.copy(), kf.P.copy()
        kf.update(z, R=R)
        if not _is_pd(_sym(kf.P)):
            # wrapped heading sigma points spoiled the cross-covariance; the measurement is
            # linear (H = [I3 0]), so the Kalman update on the same prior is exact
            kf.x, kf.P = linear_update(x_prior, P_prior, z, R, H)
        kf.x[THETA] = wrap_angle(float(kf.x[THETA]))

    def propagate(self, model, x, P, segs, tau, q_lin, q_yaw) -> tuple[FloatArray, FloatArray]:
        points = self.points(len(np.ravel(x)))
        try:
            return propagate(model, x, P, segs, tau, q_lin, q_yaw, points)
        except np.linalg.LinAlgError:  # no sigma points without a Cholesky factor
            return propagate(model, x, P, segs, tau, q_lin, q_yaw)


#: The filters by their ``estimation.filter`` name (``controller.config.FILTERS``).
STRATEGIES = {s.name: s for s in (EkfStrategy, UkfStrategy)}
assert set(STRATEGIES) == set(FILTERS), "every name in config.FILTERS has a strategy"


def make_strategy(name: str) -> EkfStrategy | UkfStrategy:
    """The filter strategy named by ``estimation.filter``."""
    try:
        return STRATEGIES[name]()
    except KeyError:
        raise ValueError(f"unknown filter {name!r}; expected one of {sorted(STRATEGIES)}") from None
