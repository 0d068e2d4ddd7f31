"""Contact-force LP for planar quasi-static pushing (Vass, Payandeh, Lantos, Eq. 1 and 2).

The object is pushed slowly over the floor, so the contact forces balance the floor friction
(Eq. 1, quasi-static equilibrium) and the planner wants the smallest such forces (Eq. 2).

Floor friction: a limit surface. The object of mass m on a floor of friction μ needs the force
``F_max = μ·m·g`` to slide and the torque ``τ_max = μ·m·g·r̄`` to spin about its centroid, r̄ its
mean radius (:func:`controller.geometry.mean_radius`; the pybullet world puts its three floor
skids at that radius, so these two are exactly what the sim needs). In between we use the
ellipsoid approximation of the limit surface, ``(|F|/F_max)² + (τ/τ_max)² = 1``, with the
twist along its normal (maximum dissipation). For a commanded twist (v, ω) of the centroid the
pushers must supply the wrench

    W = (F_max²·v, τ_max²·ω) / sqrt(F_max²·|v|² + τ_max²·ω²)          (:func:`required_wrench`)

(pure translation: F_max along v; pure rotation: τ_max about the centroid; zero twist: nothing).
Coulomb friction does not depend on speed, so only the direction of the twist matters.

The LP. Contact i sits at p_i (object frame, m, any origin: the caller passes points relative
to the centroid) with the unit inward normal n_i (the direction the robot pushes) and the
tangent t_i = n_i turned +90°. Unknowns: the normal force f_i ≥ 0 and, when the contact
friction μ_c > 0, the tangential force g_i with |g_i| ≤ μ_c·f_i (the friction cone; in the
plane the cone is exactly two half-planes, no pyramid approximation is needed). Then

    minimise Σ f_i
    subject to Σ f_i·n_i + g_i·t_i = W_xy,
               Σ p_i × (f_i·n_i + g_i·t_i) = W_τ,
               0 ≤ f_i ≤ max_force_i (0 for passive or relocating robots),
               −μ_c·f_i ≤ g_i ≤ μ_c·f_i.

Solved with osqp (1.x, P = 0) on a sparsity pattern built once per (max contact count, with or
without friction); each solve updates q, l, u and the matrix values and warm-starts. Variables
are scaled by the largest active max_force and the torque row by a length (the mean radius), so
one set of tolerances fits all objects. osqp's ADMM answer is then *polished by an active-set
re-solve*: the constraints osqp's dual marks active (else those its primal answer touches) are
made equalities with the equilibrium rows and osqp's point is moved onto them by the least-norm
correction; if that point is feasible, it satisfies complementary slackness with osqp's dual and
is optimal to rounding error. When osqp is not sure (max iterations, inaccurate status) the
problem is first *rescued*: a Farkas test on osqp's multipliers proves infeasibility, or the
iterate is moved onto its active set and accepted when a Lagrangian dual bound proves it optimal
(both exact, a few µs), once as it is and once after more iterations. Only what stays unproven
goes to HiGHS (``scipy.optimize.linprog``) and the result says so (``solver``). With contact
friction 0.3 this takes the HiGHS share from ≈ 17 % to < 1 % (bench/contact_lp.py).

Infeasible is an answer: ``status == "infeasible"`` with ``reason`` one of

- ``no_pushers``: a non-zero wrench is needed and no contact is active;
- ``force_limit``: the needed wrench lies in the cone of the active contacts' wrenches, but
  their ``max_force`` is too small; ``binding`` names the contacts whose limits the
  infeasibility certificate uses;
- ``outside_cone``: no non-negative combination of the active contacts can make the needed
  wrench at any force (nobody pushes on the needed side, or the torque has the wrong sign).

The reason comes from osqp's Farkas certificate (which bounds it leans on); a HiGHS answer
gets it from one more HiGHS solve without the force limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import osqp
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.optimize import linprog, nnls

FloatArray = NDArray[np.float64]
GRAVITY = 9.81  # m/s^2
INF = 1e20

OPTIMAL = "optimal"
INFEASIBLE = "infeasible"
FAILED = "failed"


def required_wrench(
    twist: ArrayLike, mass: float, floor_friction: float, mean_radius: float, g: float = GRAVITY
) -> FloatArray:
    """The wrench (Fx N, Fy N, τ N·m) the contacts must apply to move the object quasi-statically
    with ``twist`` (vx, vy m/s of the centroid, ωz rad/s), all in one frame (the object frame in
    the planners), torque about the centroid. Ellipsoidal limit surface with F_max = μ·m·g and
    τ_max = μ·m·g·r̄ (see the module docstring). Zero twist or zero friction: zero wrench."""
    v = np.asarray(twist, dtype=float)
    f_max = floor_friction * mass * g
    t_max = f_max * mean_radius
    den = math.sqrt((f_max * v[0]) ** 2 + (f_max * v[1]) ** 2 + (t_max * v[2]) ** 2)
    if den <= 1e-15:
        return np.zeros(3)
    return np.array([f_max**2 * v[0], f_max**2 * v[1], t_max**2 * v[2]]) / den


def twist_for_wrench(
    wrench: ArrayLike, mass: float, floor_friction: float, mean_radius: float, g: float = GRAVITY
) -> tuple[FloatArray, bool]:
    """The forward model of the same limit surface: the unit-free twist direction (vx, vy, ωz)
    an applied wrench (N, N, N·m) drives (its normal), and whether it moves the object at all
    (the wrench reaches the limit surface). A wrench inside the surface moves nothing."""
    w = np.asarray(wrench, dtype=float)
    f_max = floor_friction * mass * g
    t_max = f_max * mean_radius
    if f_max <= 0:
        moves = bool(np.linalg.norm(w) > 0)
        return np.array([w[0], w[1], w[2] / max(mean_radius, 1e-9) ** 2]), moves
    level = (w[0] ** 2 + w[1] ** 2) / f_max**2 + w[2] ** 2 / t_max**2
    return np.array([w[0] / f_max**2, w[1] / f_max**2, w[2] / t_max**2]), bool(level >= 1.0 - 1e-9)


@dataclass(frozen=True, eq=False)
class LPResult:
    """One contact-force LP answer.

    status: "optimal", "infeasible" or "failed" (the solvers gave no answer; never expected).
    reason: empty when optimal, else "no_pushers", "force_limit" or "outside_cone".
    normal: (n,) normal force per contact (N), zero for inactive ones; tangential: (n,) force
    along t_i = n_i turned +90° (N). total: Σ normal (N), NaN unless optimal.
    binding: contacts whose max_force the infeasibility certificate uses ("force_limit").
    solver: "osqp", "highs" (fallback) or "none" (answered without a solve);
    iterations: osqp iterations; polished: the active-set re-solve was accepted.
    """

    status: str
    reason: str = ""
    normal: FloatArray = field(default_factory=lambda: np.zeros(0))
    tangential: FloatArray = field(default_factory=lambda: np.zeros(0))
    total: float = math.nan
    binding: tuple[int, ...] = ()
    solver: str = "none"
    iterations: int = 0
    polished: bool = False

    @property
    def feasible(self) -> bool:
        return self.status == OPTIMAL

    def to_dict(self) -> dict[str, object]:
        return {
            "status": self.status,
            "reason": self.reason,
            "normal": [round(float(f), 6) for f in self.normal],
            "tangential": [round(float(f), 6) for f in self.tangential],
            "total": None if math.isnan(self.total) else round(self.total, 6),
            "binding": list(self.binding),
            "solver": self.solver,
        }


def _tangents(normals: FloatArray) -> FloatArray:
    return np.stack([-normals[:, 1], normals[:, 0]], axis=1)


def _cross(p: FloatArray, f: FloatArray) -> FloatArray:
    return p[:, 0] * f[:, 1] - p[:, 1] * f[:, 0]


@dataclass(frozen=True, eq=False)
class _Scaled:
    """The LP in scaled form, z = (f, g) / scale. ``cols_n``/``cols_t`` (3, n): the normal and
    tangential force columns of the equilibrium rows; ``rhs`` (3,); ``upper`` (n,)."""

    cols_n: FloatArray
    cols_t: FloatArray
    rhs: FloatArray
    upper: FloatArray
    mu: float
    scale: float  # N per unit of z


def _scaled(
    pts: FloatArray, nrm: FloatArray, upper: FloatArray, w: FloatArray, mu: float, length: float
) -> _Scaled:
    n = len(pts)
    s = float(upper.max())
    cols_n = np.empty((3, n))
    cols_n[:2] = nrm.T
    cols_n[2] = (pts[:, 0] * nrm[:, 1] - pts[:, 1] * nrm[:, 0]) / length
    cols_t = np.empty((3, n))  # t = n turned +90°: (−n_y, n_x); p × t = p · n
    cols_t[0] = -nrm[:, 1]
    cols_t[1] = nrm[:, 0]
    cols_t[2] = (pts[:, 0] * nrm[:, 0] + pts[:, 1] * nrm[:, 1]) / length
    rhs = np.array([w[0] / s, w[1] / s, w[2] / (length * s)])
    return _Scaled(cols_n, cols_t, rhs, upper / s, mu, s)


def _polish(sc: _Scaled, a: FloatArray, b: FloatArray, tol: float):
    """Active-set re-solve: forces at a bound (or tangential forces on the cone's edge) within
    ``tol`` are fixed (or tied to their normal force); the others get the least-norm correction
    that meets the equilibrium rows exactly. Returns (a, b) if that point is feasible, else None.
    """
    u, mu = sc.upper, sc.mu
    lo_a = a <= tol
    hi_a = (a >= u - tol) & ~lo_a
    free = ~(lo_a | hi_a)
    a_fix = np.where(hi_a, u, 0.0)
    tie = np.zeros(len(a))  # b = tie * mu * a on the cone's edges
    if mu > 0:
        tie = np.where(b >= mu * a - tol, 1.0, np.where(b <= -mu * a + tol, -1.0, 0.0))
    free_b = (tie == 0) & ~lo_a if mu > 0 else np.zeros(len(a), bool)
    col_a = sc.cols_n + sc.cols_t * (tie * mu)[None]
    rhs = sc.rhs - col_a[:, ~free] @ a_fix[~free]
    m = np.hstack([col_a[:, free], sc.cols_t[:, free_b]])
    x0 = np.concatenate([a[free], b[free_b]])
    if m.shape[1] == 0:
        x = x0
    else:
        x = x0 + np.linalg.lstsq(m, rhs - m @ x0, rcond=None)[0]
    if np.abs(m @ x - rhs).max(initial=0.0) > 1e-10 * max(1.0, float(np.abs(sc.rhs).max())):
        return None
    a2 = a_fix.copy()
    a2[free] = x[: free.sum()]
    b2 = tie * mu * a2
    b2[free_b] = x[free.sum() :]
    ok = np.all(a2 >= -1e-12) and np.all(a2 <= u + 1e-12)
    ok = ok and np.all(np.abs(b2) <= mu * a2 + 1e-12)
    return (np.clip(a2, 0.0, u), b2) if ok else None


def _dual_bound(sc: _Scaled, y: FloatArray) -> float:
    """A lower bound on the scaled LP's optimum from any multipliers ``y`` (3,) of the
    equilibrium rows (Lagrangian duality): b·y + Σ u_i·min(0, r_i − μ|s_i|), with the reduced
    costs r_i = 1 − n-column_i·y of the normal forces and s_i = t-column_i·y of the tangential
    ones (the inner minimum over the box and the friction cone, contact by contact)."""
    r = 1.0 - y @ sc.cols_n
    s = np.abs(y @ sc.cols_t) if sc.mu > 0 else 0.0
    return float(sc.rhs @ y + sc.upper @ np.minimum(0.0, r - sc.mu * s))


def _active_dual(sc: _Scaled, a: FloatArray, b: FloatArray, tol: float) -> FloatArray:
    """Equilibrium multipliers that zero the reduced costs of the forces strictly inside their
    bounds (least squares): the dual of the active set the primal point sits on."""
    u, mu = sc.upper, sc.mu
    inside = (a > tol) & (a < u - tol)
    rows, rhs = [], []
    if mu > 0:
        edge = np.where(b >= mu * a - tol, 1.0, np.where(b <= -mu * a + tol, -1.0, 0.0))
        col = sc.cols_n + sc.cols_t * (edge * mu)[None]
        rows += [col[:, inside].T, sc.cols_t[:, (edge == 0) & (a > tol)].T]
        rhs += [np.ones(int(inside.sum())), np.zeros(int(((edge == 0) & (a > tol)).sum()))]
    else:
        rows.append(sc.cols_n[:, inside].T)
        rhs.append(np.ones(int(inside.sum())))
    m, v = np.vstack(rows), np.concatenate(rhs)
    if m.shape[0] == 0:
        return np.zeros(3)
    return np.linalg.lstsq(m, v, rcond=None)[0]


def farkas(sc: _Scaled, y: FloatArray) -> bool:
    """Do the multipliers' direction prove the scaled LP infeasible? With zero costs the dual
    bound b·y + Σ u_i·min(0, −n_i·y − μ|t_i·y|) is positive only if no forces within the box
    and the cones make the wrench (Farkas)."""
    norm = float(np.linalg.norm(y))
    if norm <= 0:
        return False
    d = y / norm
    s = np.abs(d @ sc.cols_t) if sc.mu > 0 else 0.0
    return float(sc.rhs @ d + sc.upper @ np.minimum(0.0, -(d @ sc.cols_n) - sc.mu * s)) > 1e-9


def certified(sc: _Scaled, a: FloatArray, b: FloatArray, y: FloatArray, tol: float) -> bool:
    """Is the feasible scaled point (a, b) optimal within ``tol`` (relative gap)? Tries osqp's
    multipliers and those of the point's own active set; either bound closing the gap proves it."""
    total = float(a.sum())
    for yy in (y, _active_dual(sc, a, b, 1e-7), _active_dual(sc, a, b, 1e-5)):
        if total - _dual_bound(sc, yy) <= tol * max(total, 1e-9):
            return True
    return False


#: active-set tolerances (scaled units) tried, in order, on an iterate osqp did not finish
RESCUE_TOLERANCES = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2)


class ContactForceLP:
    """The contact-force LP for up to ``max_contacts`` contacts, solved with a persistent osqp
    workspace (pattern built once, values updated, warm start).

    Layout: variables f (n_max) and, with ``friction``, g (n_max); rows: 3 equilibrium, n_max
    boxes 0 ≤ f ≤ max_force, and with friction 2·n_max cone rows μ·f − g ≥ 0, μ·f + g ≥ 0.
    Contacts beyond those passed, and inactive ones, have the box [0, 0].
    ``eps``: osqp's absolute and relative tolerance on the scaled problem; ``polish``: the
    active-set re-solve; ``max_iter``: osqp iterations before the rescue; ``rescue``: when osqp
    stops short (max iterations, inaccurate), prove its iterate infeasible (Farkas) or move it
    onto its active set and prove that optimal (dual bound), first as it is, then after 3 ×
    ``max_iter`` more iterations; only what stays unproven goes to HiGHS (``fallbacks``).
    """

    #: osqp settings (measured on random instances; alpha = 1 and a fixed rho interval cut the
    #: iterations of these LPs by about a third against osqp's defaults)
    SETTINGS: dict = dict(  # noqa: RUF012
        verbose=False,
        polishing=False,  # osqp's own polish fails on LPs with many optimal answers
        warm_starting=True,
        adaptive_rho_interval=25,
        alpha=1.0,
        check_termination=10,
        eps_prim_inf=1e-6,
        eps_dual_inf=1e-6,
    )

    def __init__(
        self,
        max_contacts: int,
        friction: bool = False,
        eps: float = 1e-6,
        max_iter: int = 1000,
        polish: bool = False,
        rescue: bool = True,
    ):
        if max_contacts < 1:
            raise ValueError(f"max_contacts: expected >= 1, got {max_contacts}")
        self.n_max = n = int(max_contacts)
        self.friction = bool(friction)
        self.eps = float(eps)
        self.max_iter = int(max_iter)
        self.polish = bool(polish)
        self.rescue = bool(rescue)
        self.solves = 0  # osqp solves
        self.fallbacks = 0  # of which went to HiGHS
        self.polished = 0  # of which the active-set re-solve was accepted
        self.rescued = 0  # stopped short, finished by the active set and proved optimal
        self._prob: osqp.OSQP | None = None
        nv = 2 * n if friction else n
        self._m = 3 + 3 * n if friction else 3 + n
        idx = np.arange(n)
        rows = [np.repeat(np.arange(3), n), 3 + idx]
        cols = [np.tile(idx, 3), idx]
        if friction:
            rows += [np.repeat(np.arange(3), n), 3 + n + idx, 3 + 2 * n + idx]
            cols += [np.tile(n + idx, 3), idx, idx]
            rows += [3 + n + idx, 3 + 2 * n + idx]
            cols += [n + idx, n + idx]
        r, c = np.concatenate(rows), np.concatenate(cols)
        tag = sparse.csc_matrix((np.arange(1.0, len(r) + 1), (r, c)), shape=(self._m, nv))
        where = np.empty(len(r), int)
        where[tag.data.astype(int) - 1] = np.arange(len(r))  # list position -> csc position
        self._csc = tag
        self._eq_n = where[: 3 * n].reshape(3, n)
        self._ax0 = np.zeros(len(r))
        self._ax0[where[3 * n : 4 * n]] = 1.0
        if friction:
            self._eq_t = where[4 * n : 7 * n].reshape(3, n)
            self._mu_at = where[7 * n : 9 * n]
            self._ax0[where[9 * n : 10 * n]] = -1.0
            self._ax0[where[10 * n : 11 * n]] = 1.0
        self._q = np.concatenate([np.ones(n), np.zeros(nv - n)])
        self._lo0 = np.zeros(self._m)
        self._hi0 = np.full(self._m, INF)

    def _vectors(self, sc: _Scaled) -> tuple[FloatArray, FloatArray, FloatArray]:
        k = sc.cols_n.shape[1]
        ax = self._ax0.copy()
        ax[self._eq_n[:, :k]] = sc.cols_n
        if self.friction:
            ax[self._eq_t[:, :k]] = sc.cols_t
            ax[self._mu_at] = sc.mu
        lo = self._lo0.copy()
        hi = self._hi0.copy()
        lo[:3] = hi[:3] = sc.rhs
        hi[3 : 3 + self.n_max] = 0.0
        hi[3 : 3 + k] = sc.upper
        return ax, lo, hi

    def _solve_osqp(self, sc: _Scaled):
        ax, lo, hi = self._vectors(sc)
        if self._prob is None:
            a = self._csc.copy()
            a.data = ax
            nv = len(self._q)
            self._prob = osqp.OSQP()
            settings = dict(self.SETTINGS)
            settings.update(eps_abs=self.eps, eps_rel=self.eps, max_iter=self.max_iter)
            self._prob.setup(P=sparse.csc_matrix((nv, nv)), q=self._q, A=a, l=lo, u=hi, **settings)
        else:
            self._prob.update(l=lo, u=hi, Ax=ax)
        return self._prob.solve(raise_error=False)

    def solve(
        self,
        points: ArrayLike,
        normals: ArrayLike,
        max_force: ArrayLike,
        active: ArrayLike,
        wrench: ArrayLike,
        contact_friction: float = 0.0,
        length: float = 1.0,
    ) -> LPResult:
        """Minimal normal forces for ``wrench`` (N, N, N·m about the points' origin).

        points (n, 2) m and normals (n, 2) unit inward (push direction), one frame with the
        wrench; max_force (n,) N; active (n,) bool (passive or relocating contacts: False);
        contact_friction μ_c ≥ 0 (needs ``friction=True`` when > 0); length (m) scales the
        torque row only (use the mean radius). n ≤ max_contacts.
        """
        pts, nrm, upper, w, n = _inputs(points, normals, max_force, active, wrench)
        if n > self.n_max:
            raise ValueError(f"{n} contacts for an LP built for {self.n_max}")
        if contact_friction > 0 and not self.friction:
            raise ValueError("contact_friction > 0 needs ContactForceLP(friction=True)")
        trivial = _trivial(w, upper, n)
        if trivial is not None:
            return trivial
        mu = float(contact_friction) if self.friction else 0.0
        sc = _scaled(pts, nrm, upper, w, mu, max(length, 1e-9))
        self.solves += 1
        res = self._solve_osqp(sc)
        status, iters = int(res.info.status_val), int(res.info.iter)
        if status == 1:
            return self._optimal(sc, np.asarray(res.x, float), n, iters)
        if status == 3:
            reason, binding = _reason(sc, np.asarray(res.prim_inf_cert, float))
            zero = np.zeros(n)
            return LPResult(INFEASIBLE, reason, zero, zero, math.nan, binding, "osqp", iters)
        for extra in (0, 3):  # solved inaccurate, max iterations: try to finish it exactly
            if status not in (2, 7) or not self.rescue:
                break
            if extra:  # osqp goes on from its last iterate (warm start) a while longer
                self._prob.update_settings(max_iter=extra * self.max_iter)
                res = self._prob.solve(raise_error=False)
                self._prob.update_settings(max_iter=self.max_iter)
                status, iters = int(res.info.status_val), iters + int(res.info.iter)
                if status == 1:
                    return self._optimal(sc, np.asarray(res.x, float), n, iters)
            rescued = self._rescue(sc, res, n, iters)
            if rescued is not None:
                return rescued
        self.fallbacks += 1
        return solve_reference(pts, nrm, upper, np.ones(n, bool), w, mu)

    def _rescue(self, sc: _Scaled, res, n: int, iters: int) -> LPResult | None:
        """osqp stopped short (ADMM crawls on degenerate LPs, mostly with contact friction):
        move its iterate onto the active set it points at (:func:`_polish`, loosening the
        tolerance) and accept the point only if a dual bound proves it optimal to 1e-7."""
        z = np.asarray(res.x, float)
        y = -np.asarray(res.y, float)[:3]
        if not np.all(np.isfinite(z)) or not np.all(np.isfinite(y)):
            return None
        if farkas(sc, y):  # the multipliers diverge along a proof of infeasibility
            self.rescued += 1
            reason, binding = _reason(sc, np.concatenate([y, np.ones(n)]))
            zero = np.zeros(n)
            return LPResult(INFEASIBLE, reason, zero, zero, math.nan, binding, "osqp", iters)
        a = z[:n]
        b = z[self.n_max : self.n_max + n] if self.friction else np.zeros(n)
        for tol in RESCUE_TOLERANCES:
            point = _polish(sc, a, b, tol)
            if point is not None and certified(sc, point[0], point[1], y, 1e-7):
                self.rescued += 1
                f, g = point[0] * sc.scale, point[1] * sc.scale
                return LPResult(OPTIMAL, "", f, g, float(f.sum()), (), "osqp", iters, True)
        return None

    def _optimal(self, sc: _Scaled, z: FloatArray, n: int, iters: int) -> LPResult:
        a = z[:n]
        b = z[self.n_max : self.n_max + n] if self.friction else np.zeros(n)
        polished = None
        if self.polish:
            for tol in (10 * self.eps, 1e-4):
                polished = _polish(sc, a, b, tol)
                if polished is not None:
                    break
        if polished is not None:
            self.polished += 1
            a, b = polished
        else:
            a = np.clip(a, 0.0, sc.upper)
            b = np.clip(b, -sc.mu * a, sc.mu * a)
        f, g = a * sc.scale, b * sc.scale
        return LPResult(OPTIMAL, "", f, g, float(f.sum()), (), "osqp", iters, polished is not None)


def _inputs(points, normals, max_force, active, wrench):
    pts = np.asarray(points, float).reshape(-1, 2)
    nrm = np.asarray(normals, float).reshape(-1, 2)
    norm = np.sqrt(nrm[:, 0] ** 2 + nrm[:, 1] ** 2)
    if not np.all(np.abs(norm - 1.0) < 1e-12):
        nrm = nrm / np.maximum(norm, 1e-12)[:, None]
    upper = np.asarray(max_force, float).reshape(-1) * np.asarray(active, bool).reshape(-1)
    upper = np.maximum(upper, 0.0)
    return pts, nrm, upper, np.asarray(wrench, float).reshape(3), len(pts)


def _trivial(w: FloatArray, upper: FloatArray, n: int) -> LPResult | None:
    if not np.any(np.abs(w) > 1e-12):
        return LPResult(OPTIMAL, "", np.zeros(n), np.zeros(n), 0.0)
    if n == 0 or not np.any(upper > 0):
        return LPResult(INFEASIBLE, "no_pushers", np.zeros(n), np.zeros(n))
    return None


def _reason(sc: _Scaled, cert: FloatArray) -> tuple[str, tuple[int, ...]]:
    """Why an LP is infeasible: is the needed wrench in the cone of the active contacts' wrench
    generators (non-negative least squares)? Then the force limits are to blame, and ``binding``
    lists the contacts whose limits osqp's Farkas certificate uses (all active ones if none)."""
    act = sc.upper > 0
    gens = [sc.cols_n[:, act]]
    if sc.mu > 0:
        gens = [
            sc.cols_n[:, act] + sc.mu * sc.cols_t[:, act],
            sc.cols_n[:, act] - sc.mu * sc.cols_t[:, act],
        ]
    _, resid = nnls(np.hstack(gens), sc.rhs)
    if resid > 1e-7 * max(float(np.linalg.norm(sc.rhs)), 1e-12):
        return "outside_cone", ()
    k = len(sc.upper)
    box = cert[3 : 3 + k]
    tol = 1e-6 * max(float(np.abs(cert).max()), 1e-12)
    binding = tuple(int(i) for i in np.flatnonzero((box > tol) & act))
    return "force_limit", binding or tuple(int(i) for i in np.flatnonzero(act))


def solve_reference(
    points: ArrayLike,
    normals: ArrayLike,
    max_force: ArrayLike,
    active: ArrayLike,
    wrench: ArrayLike,
    contact_friction: float = 0.0,
) -> LPResult:
    """The same LP with HiGHS (``scipy.optimize.linprog``), unscaled: the reference the osqp
    solver is tested and benchmarked against, and its fallback."""
    pts, nrm, upper, w, n = _inputs(points, normals, max_force, active, wrench)
    trivial = _trivial(w, upper, n)
    if trivial is not None:
        return trivial
    mu = max(float(contact_friction), 0.0)
    tang = _tangents(nrm)
    a_eq = np.vstack(
        [
            np.concatenate([nrm[:, 0], tang[:, 0]]),
            np.concatenate([nrm[:, 1], tang[:, 1]]),
            np.concatenate([_cross(pts, nrm), _cross(pts, tang)]),
        ]
    )
    eye = np.eye(n)
    a_ub = np.vstack([np.hstack([-mu * eye, eye]), np.hstack([-mu * eye, -eye])])
    c = np.concatenate([np.ones(n), np.zeros(n)])
    bounds = [(0.0, float(u)) for u in upper] + [(None, None)] * n
    res = linprog(c, A_ub=a_ub, b_ub=np.zeros(2 * n), A_eq=a_eq, b_eq=w, bounds=bounds)
    if res.status == 0:
        f, g = res.x[:n], res.x[n:]
        return LPResult(OPTIMAL, "", f, g, float(f.sum()), solver="highs")
    if res.status == 2:
        relaxed = [(0.0, None if u > 0 else 0.0) for u in upper] + [(None, None)] * n
        res2 = linprog(c, A_ub=a_ub, b_ub=np.zeros(2 * n), A_eq=a_eq, b_eq=w, bounds=relaxed)
        reason = "force_limit" if res2.status == 0 else "outside_cone"
        binding = tuple(int(i) for i in np.flatnonzero(upper > 0)) if res2.status == 0 else ()
        return LPResult(
            INFEASIBLE, reason, np.zeros(n), np.zeros(n), binding=binding, solver="highs"
        )
    return LPResult(FAILED, f"highs: {res.message}", np.zeros(n), np.zeros(n), solver="highs")
