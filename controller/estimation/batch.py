"""The EKF of many robots at once: one vectorised prediction, gate and update per model.

The same maths as the per-track path (``models.motion`` with its chained Jacobian,
``models.process_noise``, filterpy's ``ExtendedKalmanFilter.predict``/``update`` in Joseph
form, the wrapped heading residual), on stacks of states: row ``i`` is one robot. A tick of a
50-robot fleet brings some 75 poses; one by one through filterpy they took most of the lab
daemon's tick (``bench/loop.py``), as a few stacked numpy calls per model they do not.
``tests/unit/test_estimation_batch.py`` holds the two paths to the same states.

Pure functions: arrays in, arrays out.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from controller.estimation.models import MAX_SUBSTEP, MEAS_DIM, STATE_DIM, THETA, YAW_RATE_INDEX
from controller.geometry import wrap_angle

FloatArray = NDArray[np.float64]


def sym(P: FloatArray) -> FloatArray:
    """``(P + Pᵀ)/2`` for a stack of matrices (m, n, n)."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def _libm(fn, x: FloatArray) -> FloatArray:
    """``fn`` (``math.sin``, ``cos``, ``exp``) of each element through the C library, as the
    one-robot path computes it: numpy's SIMD versions (AVX-512 where the CPU has it) differ
    from it in the last bits, so the stacked filters gave machine-dependent states and the
    golden logs replayed on one CPU and not on another. ~1 µs per robot."""
    return np.fromiter(map(fn, np.asarray(x, dtype=float).tolist()), float, np.size(x))


def robot_motion_rows(
    omni: bool, X: FloatArray, dt: FloatArray, U: FloatArray, tau: float
) -> tuple[FloatArray, FloatArray]:
    """``models.motion`` for robots, one segment per row: row ``i`` moves ``dt[i]`` s (> 0)
    under the body-frame command ``U[i]`` ((vx, vy, wz) omni, (vx, wz) diff; zeros for none),
    in sub-steps of at most ``MAX_SUBSTEP``. Returns the states (m, n) and their Jacobians
    (m, n, n), chained over the sub-steps."""
    S = np.array(X, dtype=float)
    m, n = S.shape
    dt = np.asarray(dt, dtype=float)
    steps = np.maximum(1, np.ceil(dt / MAX_SUBSTEP - 1e-9)).astype(int)
    h = dt / steps
    a = _libm(math.exp, -h / tau)
    beta = tau / h * (1.0 - a)
    cu = U[:, 0]
    cv = U[:, 1] if omni else np.zeros(m)
    cw = U[:, 2] if omni else U[:, 1]
    iw = 5 if omni else 4
    F = np.broadcast_to(np.eye(n), (m, n, n)).copy()
    rows = np.arange(m)
    for k in range(int(steps.max(initial=0))):
        r = rows if k == 0 else rows[steps > k]
        hr, ar, br = h[r], a[r], beta[r]
        th = S[r, 2]
        u0 = S[r, 3]
        v0 = S[r, 4] if omni else 0.0
        w0 = S[r, iw]
        ua = br * u0 + (1.0 - br) * cu[r]
        va = br * v0 + (1.0 - br) * cv[r]
        wa = br * w0 + (1.0 - br) * cw[r]
        thm = th + 0.5 * wa * hr
        c, sn = _libm(math.cos, thm), _libm(math.sin, thm)
        dpx = hr * (c * ua - sn * va)
        dpy = hr * (sn * ua + c * va)
        S[r, 0] += dpx
        S[r, 1] += dpy
        S[r, 2] = wrap_angle(th + wa * hr)
        S[r, 3] = ar * u0 + (1.0 - ar) * cu[r]
        if omni:
            S[r, 4] = ar * v0 + (1.0 - ar) * cv[r]
        S[r, iw] = ar * w0 + (1.0 - ar) * cw[r]
        J = np.broadcast_to(np.eye(n), (len(r), n, n)).copy()
        J[:, 0, 2] = -dpy
        J[:, 1, 2] = dpx
        J[:, 0, 3] = hr * c * br
        J[:, 1, 3] = hr * sn * br
        if omni:
            J[:, 0, 4] = -hr * sn * br
            J[:, 1, 4] = hr * c * br
            J[:, 4, 4] = ar
        J[:, 0, iw] = -dpy * br * hr * 0.5
        J[:, 1, iw] = dpx * br * hr * 0.5
        J[:, 2, iw] = br * hr
        J[:, 3, 3] = ar
        J[:, iw, iw] = ar
        F[r] = J if k == 0 else J @ F[r]
    return S, F


def process_noise_rows(
    model: str, theta: FloatArray, dt: FloatArray, q_lin: float, q_yaw: float
) -> FloatArray:
    """``models.process_noise`` for a robot model, per row (heading ``theta[i]``, step
    ``dt[i]``): (m, n, n)."""
    n = STATE_DIM[model]
    m = len(dt)
    Q = np.zeros((m, n, n))
    d1, d2, d3 = dt, dt * dt / 2.0, dt**3 / 3.0
    Q[:, 0, 0] = Q[:, 1, 1] = q_lin * d3
    iw = YAW_RATE_INDEX[model]
    Q[:, 2, 2] = q_yaw * d3
    Q[:, 2, iw] = Q[:, iw, 2] = q_yaw * d2
    Q[:, iw, iw] = q_yaw * d1
    c, s = _libm(math.cos, theta), _libm(math.sin, theta)
    Q[:, 0, 3] = Q[:, 3, 0] = q_lin * d2 * c
    Q[:, 1, 3] = Q[:, 3, 1] = q_lin * d2 * s
    Q[:, 3, 3] = q_lin * d1
    if model == "omni":
        Q[:, 0, 4] = Q[:, 4, 0] = -q_lin * d2 * s
        Q[:, 1, 4] = Q[:, 4, 1] = q_lin * d2 * c
        Q[:, 4, 4] = q_lin * d1
    return Q


def predict_rows(
    model: str,
    X: FloatArray,
    P: FloatArray,
    segments: list[list[tuple[float, FloatArray | None]]],
    tau: float,
    q_lin: float,
    q_yaw: float,
) -> tuple[FloatArray, FloatArray]:
    """The EKF time update of each row through its own piecewise-constant command segments
    (``TrackFilter.segments``), as the per-track path does it: per segment the motion with its
    Jacobian, ``P ← F P Fᵀ + Q`` with Q for the segment's length and starting heading, then
    symmetrised. Returns new stacks; the inputs are not changed."""
    X = np.array(X, dtype=float)
    P = np.array(P, dtype=float)
    omni = model == "omni"
    ncmd = 3 if omni else 2
    lengths = np.array([len(s) for s in segments])
    for j in range(int(lengths.max(initial=0))):
        r = np.flatnonzero(lengths > j)
        h = np.array([segments[i][j][0] for i in r])
        U = np.zeros((len(r), ncmd))
        for k, i in enumerate(r):
            u = segments[i][j][1]
            if u is not None:
                U[k] = u
        Q = process_noise_rows(model, X[r, THETA], h, q_lin, q_yaw)
        X[r], F = robot_motion_rows(omni, X[r], h, U, tau)
        P[r] = sym(F @ P[r] @ np.swapaxes(F, -1, -2) + Q)
    return X, P


def gate_rows(X: FloatArray, P: FloatArray, Z: FloatArray, R: FloatArray) -> FloatArray:
    """Squared Mahalanobis distances of the measurements ``Z`` (m, 3) against the priors:
    ``yᵀ S⁻¹ y`` with ``y = z − Hx`` (heading wrapped), ``S = H P Hᵀ + R``. Raises
    ``numpy.linalg.LinAlgError`` when an S is singular."""
    y = Z - X[:, :MEAS_DIM]
    y[:, THETA] = wrap_angle(y[:, THETA])
    S = P[:, :MEAS_DIM, :MEAS_DIM] + R
    return np.einsum("ij,ij->i", y, np.linalg.solve(S, y[..., None])[..., 0])


def update_rows(
    X: FloatArray, P: FloatArray, Z: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """filterpy's EKF update with ``H = [I₃ 0]`` per row (Joseph form, wrapped residual), the
    heading wrapped and P symmetrised after, as ``EkfStrategy.update`` and ``TrackFilter``."""
    m, n = X.shape
    y = Z - X[:, :MEAS_DIM]
    y[:, THETA] = wrap_angle(y[:, THETA])
    PHT = P[:, :, :MEAS_DIM]
    S = PHT[:, :MEAS_DIM, :] + R
    K = PHT @ np.linalg.inv(S)
    X1 = X + (K @ y[..., None])[..., 0]
    X1[:, THETA] = wrap_angle(X1[:, THETA])
    I_KH = np.broadcast_to(np.eye(n), (m, n, n)).copy()
    I_KH[:, :, :MEAS_DIM] -= K
    P1 = I_KH @ P @ np.swapaxes(I_KH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    return X1, sym(P1)
