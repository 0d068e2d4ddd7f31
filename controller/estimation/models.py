"""Motion models of the estimator: state layouts, propagation with Jacobians, process noise.

State vectors (SI units, world frame x east, y north, theta CCW in radians):

* ``omni``:   (x, y, theta, u, v, w)  - u, v are the **body-frame** velocities (forward, left)
* ``diff``:   (x, y, theta, v, w)     - v forward speed; no lateral velocity
* ``object``: (x, y, theta, vx, vy, w) - constant velocity, **world-frame** vx, vy

Pure functions: arrays in, arrays out.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from controller.config import ROBOT_KINDS
from controller.geometry import wrap_angle

FloatArray = NDArray[np.float64]
ROBOT_MODELS = ROBOT_KINDS  # a robot's motion model is its kind
MODELS = (*ROBOT_KINDS, "object")
STATE_DIM = {"omni": 6, "diff": 5, "object": 6}
COMMAND_DIM = {"omni": 3, "diff": 2, "object": 3}
YAW_RATE_INDEX = {"omni": 5, "diff": 4, "object": 5}
MEAS_DIM = 3
THETA = 2
MAX_SUBSTEP = 0.05  # s, longest step of the motion integration (a dropout is cut into these)


def residual(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """``a - b`` for a state or measurement vector (any trailing shape), heading (index 2) wrapped.

    Used as filterpy's ``residual_x``, ``residual_z`` and the EKF's ``residual``.
    """
    d = np.subtract(a, b, dtype=float)
    d[THETA] = wrap_angle(d[THETA])
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
    F = np.eye(len(s)) if jacobian else None
    if dt <= 0.0:
        return np.array(s), F
    if model == "object":
        return _object_motion(s, dt, u, tau, F)
    if model not in ROBOT_MODELS:
        raise ValueError(f"unknown motion model {model!r}; expected one of {MODELS}")
    return _robot_motion(model == "omni", s, dt, u, tau, F)


def _object_motion(
    s: list[float], dt: float, u: ArrayLike | None, tau: float, F: FloatArray | None
) -> tuple[FloatArray, FloatArray | None]:
    """The object: constant velocity, or (pushed) its world velocity following the push."""
    if u is None:  # constant velocity
        s[0] += dt * s[3]
        s[1] += dt * s[4]
        s[2] = wrap_angle(s[2] + dt * s[5])
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
    s[2] = wrap_angle(s[2])
    return np.array(s), F


def _robot_motion(
    omni: bool, s: list[float], dt: float, u: ArrayLike | None, tau: float, F: FloatArray | None
) -> tuple[FloatArray, FloatArray | None]:
    """A robot: body velocities following the command through a first-order lag, integrated in
    sub-steps of at most ``MAX_SUBSTEP`` (with the chained Jacobian when ``F`` is given)."""
    n = len(s)
    steps = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
    h = dt / steps
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
        s[2] = wrap_angle(th + wa * h)
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
        S[:, 2] = wrap_angle(S[:, 2])
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
        S[:, 2] = wrap_angle(S[:, 2] + wa * h)
        S[:, 3] = a * u0 + (1.0 - a) * cu
        if omni:
            S[:, 4] = a * v0 + (1.0 - a) * cv
        S[:, iw] = a * w0 + (1.0 - a) * cw
    return S


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
