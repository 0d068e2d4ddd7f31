"""The safety filter: the last layer before commands are published, in every phase.

A quadratic program (osqp) changes the nominal world velocities as little as possible,
``min Σ |v_i − v_i^nom|²``, subject to control barrier function constraints for single
integrators (Ames et al.; Robotarium's barrier certificates):

- robot–robot: ``h = |p_i − p_j| − (r_i + r_j + margin)``, ``∇h·(v_i − v_j) ≥ −γ h``;
- robot–static obstacle (the nearest one) and robot–wall: ``∇h·v_i ≥ −γ h``;
- robot–object: the same against the object's velocity at the nearest point, except for a robot
  closing in on its own contact point;
- speed: a box ``|v_x|, |v_y| ≤ v_max/√2`` per robot (a polygonal stand-in for the disc);
- stale robots (no fresh pose) are pinned to zero and become static obstacles for the others.

Differential robots are filtered at a look-ahead point ``p + ℓ·(cos θ, sin θ)``, which is
holonomic (``v = ṗ·h``, ``ω = ṗ·h⊥ / ℓ``); their discs are grown by ℓ.

The sparsity pattern (every pair, one obstacle row, one object row and four wall rows per robot)
is fixed for a fleet, so the osqp problem is set up once and only values change: each call is a
warm-started update, not a rebuild. Pure: arrays in, arrays out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import osqp
import scipy.sparse as sp
from numpy.typing import NDArray

from controller import geometry

FloatArray = NDArray[np.float64]
INF = 1e20


@dataclass(frozen=True)
class SafetyParams:
    margin: float = 0.05  # m kept between discs (and to obstacles, walls, the object)
    contact_margin: float = 0.0  # m between two robots both closing in on their contact points
    gamma: float = 4.0  # 1/s barrier gain
    lookahead: float = 0.05  # m, differential robots' filtered point
    obstacle_margin: float = 0.05  # m to static obstacles and walls

    @classmethod
    def from_config(cls, cfg) -> SafetyParams:
        a = cfg.approach
        return cls(
            margin=a.safety_margin,
            contact_margin=min(a.safety_margin, 0.5 * cfg.capture.clearance),
            gamma=a.barrier_gain,
            lookahead=a.lookahead,
            obstacle_margin=a.safety_margin,
        )


@dataclass
class FilterResult:
    velocities: FloatArray  # (N, 2) filtered world velocities of the filtered points
    status: str  # "solved", "trivial", or osqp's status when infeasible
    stopped: NDArray[np.bool_]  # robots stopped by the filter (infeasible)
    active: int  # constraints at their bound
    changed: float  # max |v − v_nom| (m/s)


@dataclass
class SafetyFilter:
    """One fleet's QP, set up on first use and updated in place every call."""

    radii: FloatArray
    holonomic: NDArray[np.bool_]
    max_speed: FloatArray
    bounds: FloatArray  # [[xmin, ymin], [xmax, ymax]]
    obstacles: list[FloatArray]
    params: SafetyParams = field(default_factory=SafetyParams)

    def __post_init__(self) -> None:
        self.radii = np.asarray(self.radii, dtype=float)
        self.n = len(self.radii)
        n = self.n
        self._grow = np.where(self.holonomic, 0.0, self.params.lookahead)
        self._pi, self._pj = np.triu_indices(n, 1)
        self.n_pairs = len(self._pi)
        self._solver: osqp.OSQP | None = None
        self.solves = 0
        self.infeasible = 0
        self.relaxed = 0
        # row layout: pairs | obstacle | object | walls x-, x+, y-, y+ | velocity box (2N)
        self._r_obs = self.n_pairs
        self._r_obj = self._r_obs + n
        self._r_wall = self._r_obj + n
        self._r_box = self._r_wall + 4 * n
        self.m = self._r_box + 2 * n
        rows, cols = [], []
        for k, (i, j) in enumerate(zip(self._pi, self._pj, strict=True)):
            rows += [k, k, k, k]
            cols += [2 * i, 2 * i + 1, 2 * j, 2 * j + 1]
        for base in (self._r_obs, self._r_obj):
            for i in range(n):
                rows += [base + i, base + i]
                cols += [2 * i, 2 * i + 1]
        for i in range(n):
            for w in range(4):
                rows.append(self._r_wall + 4 * i + w)
                cols.append(2 * i + (0 if w < 2 else 1))
        for c in range(2 * n):
            rows.append(self._r_box + c)
            cols.append(c)
        pattern = sp.csc_matrix(
            (np.arange(1, len(rows) + 1, dtype=float), (rows, cols)), shape=(self.m, 2 * n)
        )
        # osqp wants the values in CSC order: keep the permutation from our order to CSC order
        self._order = np.asarray(pattern.data, dtype=int) - 1
        self._A = pattern
        self._polys = [np.asarray(o, dtype=float) for o in self.obstacles]

    # -- geometry rows
    def _nearest_obstacle(self, pts: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Per point: signed distance to the nearest static obstacle and the unit gradient."""
        n = len(pts)
        best = np.full(n, INF)
        grad = np.zeros((n, 2))
        for poly in self._polys:
            d, g = _polygon_distance_grad(pts, poly)
            closer = d < best
            best = np.where(closer, d, best)
            grad[closer] = g[closer]
        return best, grad

    def filter(
        self,
        points: FloatArray,
        v_nom: FloatArray,
        *,
        stale: NDArray[np.bool_] | None = None,
        object_polygon: FloatArray | None = None,
        object_velocity: FloatArray | None = None,
        object_exempt: NDArray[np.bool_] | None = None,
        closing: NDArray[np.bool_] | None = None,
        centres: FloatArray | None = None,
        headings: FloatArray | None = None,
    ) -> FilterResult:
        """Filter nominal world velocities (N, 2) of the filtered points (N, 2).

        ``object_polygon``: the object's outline in the world now; ``object_velocity``: its
        (vx, vy, wz); ``object_exempt``: robots allowed to touch it (closing in on their point);
        ``closing``: robots closing in (pairs of them keep ``contact_margin`` instead of margin).
        ``centres`` and ``headings``: the robots' centres and headings (differential robots'
        filtered points lie ahead of their centres); the object rows use them.
        """
        n, p = self.n, self.params
        pts = np.asarray(points, dtype=float)
        v_nom = np.asarray(v_nom, dtype=float).copy()
        stale = np.zeros(n, bool) if stale is None else np.asarray(stale, bool)
        closing = np.zeros(n, bool) if closing is None else np.asarray(closing, bool)
        rad = self.radii + self._grow
        vals = np.empty(len(self._order))
        lo = np.full(self.m, -INF)
        hi = np.full(self.m, INF)
        # pairs: 2 (pi − pj)·(vi − vj) / |.| ≥ −γ h
        dp = pts[self._pi] - pts[self._pj]
        dist = np.maximum(np.linalg.norm(dp, axis=1), 1e-9)
        u = dp / dist[:, None]
        both = closing[self._pi] & closing[self._pj]
        h = dist - rad[self._pi] - rad[self._pj] - np.where(both, p.contact_margin, p.margin)
        pair_vals = np.concatenate([u, -u], axis=1).reshape(-1)
        lo[: self.n_pairs] = -p.gamma * h
        # obstacle rows
        d_obs, g_obs = self._nearest_obstacle(pts) if self._polys else (np.full(n, INF), None)
        obs_vals = (g_obs if g_obs is not None else np.zeros((n, 2))).reshape(-1)
        h_obs = d_obs - rad - p.obstacle_margin
        lo[self._r_obs : self._r_obj] = np.where(h_obs < 1.0, -p.gamma * h_obs, -INF)
        # object rows: ∇h·ṗ_i ≥ ∇h·v_obj(at the nearest point) − γ h, on the robot's centre
        # (a differential robot's centre moves with the look-ahead point's velocity projected
        # on its heading, ṗ = h hᵀ ṗ', so the row's coefficients are (∇h·h) h). A robot
        # closing in on its own contact point may touch the object (margin 0), not enter it.
        obj_vals = np.zeros((n, 2))
        if object_polygon is not None:
            centres = pts if centres is None else np.asarray(centres, dtype=float)
            d_o, g_o, near = _polygon_distance_grad(centres, object_polygon, with_point=True)
            coef = g_o.copy()
            if headings is not None:
                hv = np.stack([np.cos(headings), np.sin(headings)], 1)
                diff = ~self.holonomic
                coef[diff] = (np.sum(g_o * hv, axis=1)[:, None] * hv)[diff]
            obj_vals = coef
            v_o = np.zeros((n, 2))
            if object_velocity is not None:
                c = geometry.centroid(object_polygon)
                w = object_velocity[2]
                rel = near - c
                v_o = object_velocity[:2] + w * np.stack([-rel[:, 1], rel[:, 0]], 1)
            exempt = np.zeros(n, bool) if object_exempt is None else np.asarray(object_exempt)
            h_o = d_o - self.radii - np.where(exempt, 0.0, p.margin)
            rhs = np.sum(g_o * v_o, axis=1) - p.gamma * h_o
            lo[self._r_obj : self._r_wall] = np.where(h_o > 1.5, -INF, rhs)
        # walls: x − xmin − r − m ≥ 0 → vx ≥ −γ h, and so on
        (xmin, ymin), (xmax, ymax) = self.bounds
        m_w = rad + p.obstacle_margin
        hw = np.stack(
            [pts[:, 0] - xmin - m_w, xmax - pts[:, 0] - m_w, pts[:, 1] - ymin - m_w,
             ymax - pts[:, 1] - m_w], 1,
        )  # fmt: skip
        sign = np.array([1.0, -1.0, 1.0, -1.0])
        wall_vals = np.tile(sign, n)
        lo[self._r_wall : self._r_box] = (-p.gamma * hw).reshape(-1)
        # velocity box; stale robots pinned to zero
        vb = np.repeat(self.max_speed / np.sqrt(2.0), 2)
        vb[np.repeat(stale, 2)] = 0.0
        lo[self._r_box :] = -vb
        hi[self._r_box :] = vb
        v_nom[stale] = 0.0
        # a violated barrier (h < 0) asks for a recovery speed γ|h|: never more than the box
        # allows, or one bad estimate makes the whole QP infeasible
        cap = 0.9 * vb.reshape(n, 2).min(axis=1)
        lo[self.n_pairs : self._r_box] = np.minimum(
            lo[self.n_pairs : self._r_box],
            np.concatenate([cap, cap, np.repeat(cap, 4)]),
        )
        lo[: self.n_pairs] = np.minimum(lo[: self.n_pairs], cap[self._pi] + cap[self._pj])
        ours = np.concatenate(
            [pair_vals, obs_vals, obj_vals.reshape(-1), wall_vals, np.ones(2 * n)]
        )
        vals[:] = ours[self._order]
        q = -2.0 * v_nom.reshape(-1)
        if self._solver is None:
            self._A.data = vals.copy()
            self._solver = osqp.OSQP()
            self._solver.setup(
                P=sp.eye(2 * n, format="csc") * 2.0, q=q, A=self._A, l=lo, u=hi,
                verbose=False, warm_starting=True, polishing=False,
                eps_abs=1e-5, eps_rel=1e-5, max_iter=4000,
            )  # fmt: skip
        else:
            self._solver.update(q=q, l=lo, u=hi, Ax=vals)
        res = self._solver.solve(raise_error=False)
        self.solves += 1
        status = res.info.status
        if res.info.status_val not in (1, 2):
            # the object may corner a robot against a wall or a neighbour: let it be touched
            # (it is pushed, not crushed) rather than stop the whole fleet
            lo_soft = lo.copy()
            lo_soft[self._r_obj : self._r_wall] = -INF
            self._solver.update(l=lo_soft)
            res = self._solver.solve(raise_error=False)
            self.solves += 1
            self.relaxed += 1
        if res.info.status_val not in (1, 2) or res.x is None or np.any(~np.isfinite(res.x)):
            # infeasible or failed: the robots whose constraints are violated at zero velocity
            # stop, the rest keep the nominal command scaled down; the caller reports it
            self.infeasible += 1
            stopped = np.ones(n, bool)
            return FilterResult(np.zeros((n, 2)), status, stopped, 0, float("nan"))
        v = res.x.reshape(n, 2)
        v[stale] = 0.0
        active = int(np.count_nonzero(np.abs(self._A_times(vals, res.x) - lo) < 1e-4))
        changed = float(np.max(np.linalg.norm(v - v_nom, axis=1))) if n else 0.0
        return FilterResult(v, "solved", np.zeros(n, bool), active, changed)

    def _A_times(self, vals: FloatArray, x: FloatArray) -> FloatArray:
        a = self._A.copy()
        a.data = vals
        return a @ x


def _polygon_distance_grad(
    pts: FloatArray, poly: FloatArray, with_point: bool = False
) -> tuple[FloatArray, ...]:
    """Signed distance from points to a polygon (negative inside), the unit outward gradient,
    and (optionally) the nearest boundary point."""
    poly = np.asarray(poly, dtype=float)
    a = poly
    b = np.roll(poly, -1, axis=0)
    ab = b - a  # (E, 2)
    ap = pts[:, None, :] - a[None]  # (N, E, 2)
    t = np.clip(np.sum(ap * ab, -1) / np.maximum(np.sum(ab * ab, -1), 1e-18), 0.0, 1.0)
    near = a[None] + t[..., None] * ab[None]
    diff = pts[:, None, :] - near
    d = np.linalg.norm(diff, axis=-1)
    k = np.argmin(d, axis=1)
    idx = np.arange(len(pts))
    dist = d[idx, k]
    vec = diff[idx, k] / np.maximum(dist, 1e-12)[:, None]
    inside = geometry.points_in_polygon(pts, poly)
    sd = np.where(inside, -dist, dist)
    grad = np.where(inside[:, None], -vec, vec)
    if with_point:
        return sd, grad, near[idx, k]
    return sd, grad
